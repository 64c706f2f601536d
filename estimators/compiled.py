"""What the numba kernels of ``estimators`` share (numba itself is imported by each module on first use)."""

from __future__ import annotations

import types


def renamed(fn, suffix: str):
    """A copy of the function ``fn`` under the name ``fn.__name__ + suffix`` (same code, globals and closure).

    numba's disk cache files a function's compiled forms by its name and signature, not by ``parallel``: a
    serial and a threaded form of one function share an entry, and the next process's dispatcher of one form
    may load the other's code: a kernel meant to run serially would then run threaded (or the reverse),
    giving the same numbers at the other form's speed. Compiling the threaded form from a renamed copy gives
    it its own cache entry.
    """
    copy = types.FunctionType(fn.__code__, fn.__globals__, fn.__name__ + suffix, fn.__defaults__, fn.__closure__)
    copy.__qualname__ = fn.__qualname__ + suffix
    copy.__module__ = fn.__module__
    return copy


def in_namespace(fn, namespace: dict, suffix: str = ""):
    """A copy of ``fn`` (``renamed`` with ``suffix``) whose globals are ``namespace``: compiled, the names it
    calls resolve there (a kernel's compiled helpers), while ``fn`` itself keeps calling its module's."""
    copy = renamed(fn, suffix)
    result = types.FunctionType(copy.__code__, namespace, copy.__name__, copy.__defaults__, copy.__closure__)
    result.__qualname__, result.__module__ = copy.__qualname__, copy.__module__
    return result
