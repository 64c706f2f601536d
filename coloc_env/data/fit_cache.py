"""An on-disk cache of fits that take seconds (the MRCLAM likelihood fit: 17-24 s per process; the
``bandwidth_fusion`` ``oracle_static`` search, ``agents.bandwidth_fusion.oracle_static_search``: about 13 s).

``cached(name, key, compute, validate)`` returns the value stored under ``key`` or computes, stores and
returns it. The caller's ``key`` is a digest of everything the value depends on (for the MRCLAM fit:
the data it reads, the noise model's parameters, the fit's settings and the fit's code,
``coloc_env.data.mrclam_noise.fit_noise_scales``), so a changed input or code looks up another entry.

Where: the folder ``cache_dir`` names; by default ``$COLOC_FIT_CACHE`` if it is set (``off`` disables
the disk cache: every process fits again), else ``$XDG_CACHE_HOME/coloc/fits``, else
``~/.cache/coloc/fits``. A folder that cannot be created or written is no error: the value is
computed and not stored.

Entries: one JSON file per key, ``<name>-<first 32 hex digits of key>.json``, holding the format,
the whole key, the value and a SHA-256 digest of the key and value; ``cached_arrays`` stores a dict of numpy
arrays (the MRCLAM robots' own navigation over a whole run: about 5 s per process) as
``<name>-<first 32 hex digits>.npz``, with the key and a digest of the key and of each array's name, dtype,
shape and bytes beside them. An entry is used only when it
parses, its format, key and digest match, and the caller's ``validate`` accepts the value; a corrupt,
truncated, stale (another key) or rejected entry is computed again and replaced, never trusted.

Writes are atomic (a temporary file in the folder, renamed over the entry) and happen under an
exclusive lock (``fcntl.flock`` on ``<entry>.lock``): processes that miss at once (``pytest -n 2``)
wait on the lock, and all but the first find the entry the first one wrote. Without ``fcntl`` (not
POSIX) there is no lock: each process that misses computes, and the last rename wins (the same
value). ``STATS`` counts, per process, the values computed (``"computed"``) and read from disk
(``"disk"``).
"""

from __future__ import annotations

import collections
import contextlib
import hashlib
import json
import os
import tempfile
import zipfile
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

ENV_VAR = "COLOC_FIT_CACHE"
OFF = "off"
FORMAT = 1

STATS: collections.Counter = collections.Counter()


def cache_dir(folder: str | os.PathLike | None = None) -> str | None:
    """The cache folder (module docstring): ``folder`` if given, else ``$COLOC_FIT_CACHE``, else the user's cache
    folder; None when the disk cache is off (``folder`` or the variable is ``"off"``)."""
    if folder is None:
        folder = os.environ.get(ENV_VAR) or os.path.join(
            os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "coloc", "fits")
    folder = os.fspath(folder)
    return None if folder == OFF else folder


def entry_path(folder: str, name: str, key: str, suffix: str = ".json") -> str:
    return os.path.join(folder, f"{name}-{key[:32]}{suffix}")


def _digest(key: str, value: Any) -> str:
    return hashlib.sha256(json.dumps({"key": key, "value": value}, sort_keys=True).encode()).hexdigest()


def read(path: str, key: str, validate: Callable[[Any], bool]) -> Any | None:
    """The value of the entry at ``path`` if it is sound and for ``key`` (module docstring), else None."""
    try:
        with open(path, "rb") as fh:
            entry = json.loads(fh.read().decode())
        value = entry["value"]
        sound = (entry["format"] == FORMAT and entry["key"] == key and entry["digest"] == _digest(key, value)
                 and validate(value))
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
    return value if sound else None


def write(path: str, key: str, value: Any) -> None:
    """The entry for ``key`` at ``path``, atomically (a temporary file renamed over it)."""
    payload = json.dumps({"format": FORMAT, "key": key, "value": value, "digest": _digest(key, value)},
                         indent=1, sort_keys=True).encode()
    _write_atomically(path, payload + b"\n")


def _arrays_digest(key: str, arrays: dict) -> str:
    h = hashlib.sha256(key.encode())
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(repr((name, a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def read_arrays(path: str, key: str, validate: Callable[[dict], bool]) -> dict | None:
    """The arrays of the ``.npz`` entry at ``path`` if it is sound and for ``key``, else None."""
    try:
        with np.load(path, allow_pickle=False) as entry:
            stored = {name: entry[name] for name in entry.files}
        meta = json.loads(str(stored.pop("__entry__")))
        sound = (meta["format"] == FORMAT and meta["key"] == key and meta["digest"] == _arrays_digest(key, stored)
                 and validate(stored))
    except (OSError, ValueError, KeyError, TypeError, AttributeError, EOFError, zipfile.BadZipFile):
        return None
    return stored if sound else None


def write_arrays(path: str, key: str, arrays: dict) -> None:
    """The ``.npz`` entry for ``key`` at ``path``, atomically."""
    import io

    meta = json.dumps({"format": FORMAT, "key": key, "digest": _arrays_digest(key, arrays)})
    buffer = io.BytesIO()
    np.savez(buffer, __entry__=np.array(meta), **arrays)
    _write_atomically(path, buffer.getvalue())


def _write_atomically(path: str, payload: bytes) -> None:
    folder = os.path.dirname(path)
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tmp-", suffix=os.path.basename(path))
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(payload)
        mask = os.umask(0)  # mkstemp creates 0600 files; an entry gets the permissions of any file the user creates
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


@contextlib.contextmanager
def _locked(path: str) -> Iterator[None]:
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock (module docstring)
        yield
        return
    with open(path, "a") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)


def cached(name: str, key: str, compute: Callable[[], Any], validate: Callable[[Any], bool],
           folder: str | os.PathLike | None = None) -> Any:
    """The value stored under ``key`` in the cache folder (``cache_dir(folder)``), or ``compute()`` stored there.

    ``name`` names the kind of value in the file name; ``validate`` says whether a stored value is usable
    (the right fields, finite, in range); ``compute`` returns a JSON-serializable value."""
    return _cached(name, key, compute, validate, folder, read, write, ".json")


def cached_arrays(name: str, key: str, compute: Callable[[], dict], validate: Callable[[dict], bool],
                  folder: str | os.PathLike | None = None) -> dict:
    """``cached`` for a value that is a dict of numpy arrays (name -> array), stored as a ``.npz`` entry; the
    arrays read back are the ones stored, bit for bit."""
    return _cached(name, key, compute, validate, folder, read_arrays, write_arrays, ".npz")


def _cached(name, key, compute, validate, folder, read, write, suffix):
    directory = cache_dir(folder)
    if directory is None:
        STATS["computed"] += 1
        return compute()
    path = entry_path(directory, name, key, suffix)
    value = read(path, key, validate)
    if value is not None:
        STATS["disk"] += 1
        return value
    try:
        os.makedirs(directory, exist_ok=True)
        lock = _locked(path + ".lock")
        lock.__enter__()
    except OSError:  # the folder cannot be written: compute, store nothing
        STATS["computed"] += 1
        return compute()
    try:
        value = read(path, key, validate)  # another process may have written it while this one waited
        if value is not None:
            STATS["disk"] += 1
            return value
        value = compute()
        STATS["computed"] += 1
        with contextlib.suppress(OSError):
            write(path, key, value)
        return value
    finally:
        lock.__exit__(None, None, None)
