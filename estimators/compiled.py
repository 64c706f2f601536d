"""What the numba kernels of ``estimators`` share (numba itself is imported by each module on first use)."""

from __future__ import annotations

import types


def in_namespace(fn, namespace: dict, suffix: str = ""):
    """A copy of ``fn`` under the name and qualified name ``+ suffix``, whose globals are ``namespace``: compiled,
    the names it calls resolve there (a kernel's compiled helpers), while ``fn`` itself keeps calling its module's.

    numba's disk cache files a function's compiled forms by its qualified name and signature, not by
    ``parallel``: a serial and a threaded form of one function share an entry, and the next process's
    dispatcher of one form may load the other's code: a kernel meant to run threaded would then run serially
    (or the reverse), giving the same numbers at the other form's speed. Compiling the threaded form from a
    copy with its own qualified name (``suffix="_threaded"``) gives it its own cache entry.
    """
    copy = types.FunctionType(fn.__code__, namespace, fn.__name__ + suffix, fn.__defaults__, fn.__closure__)
    copy.__qualname__ = fn.__qualname__ + suffix
    copy.__module__ = fn.__module__
    return copy
