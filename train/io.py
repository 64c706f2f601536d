"""Atomic writes: a result file is either the old one or the complete new one, never half.

A result *folder* holds several files written one after the other, so it cannot be
replaced atomically as a whole; ``result_folder`` marks it instead: an
``INCOMPLETE`` file is written before the first result and removed after the last,
so a folder interrupted half way (Ctrl-C, a crash) says so.

A write goes to a temporary file ``.tmp-<random><name>`` beside its target, renamed over the
target when complete; an error or Ctrl-C removes it, but a process killed outright (SIGKILL, a
power cut) leaves it behind. ``result_folder`` removes such leftovers (``TEMPORARY_PREFIX``
files directly in the folder) when a run starts writing into it: one command writes a
result folder at a time (they share its ``INCOMPLETE`` marker), so every temporary there
at the start is a dead writer's.
"""

from __future__ import annotations

import contextlib
import datetime
import json
import os
import tempfile
from collections.abc import Iterator
from typing import Any

import numpy as np

from coloc_env.config import BadInput

TEMPORARY_PREFIX = ".tmp-"  # an atomic write's file before its rename (module docstring)


def _atomic(path: str, write) -> None:
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=TEMPORARY_PREFIX, suffix=os.path.basename(path))
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
        # mkstemp creates 0600 files; a result file gets the permissions of any file the user creates
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _jsonable(value: Any):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        return float(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def write_json(path: str, data: Any) -> None:
    payload = json.dumps(_jsonable(data), indent=2, sort_keys=False).encode()
    _atomic(path, lambda fh: fh.write(payload + b"\n"))


def write_text(path: str, text: str) -> None:
    _atomic(path, lambda fh: fh.write(text.encode()))


def save_model(path: str, model) -> None:
    """Save a stable-baselines3 model's zip atomically: Ctrl-C or a full disk mid-save leaves the previous file
    (or none), never a half-written zip or a temporary file beside it."""
    _atomic(path, model.save)


def copy_file(source: str, path: str) -> None:
    """Copy ``source`` to ``path`` atomically (as ``save_model``)."""
    import shutil

    def write(fh) -> None:
        with open(source, "rb") as src:
            shutil.copyfileobj(src, fh)

    _atomic(path, write)


def save_figure(path: str, figure) -> None:
    """Save a matplotlib figure as PNG atomically and close it."""
    _atomic(path, lambda fh: figure.savefig(fh, format="png", dpi=110, bbox_inches="tight"))
    import matplotlib.pyplot as plt

    plt.close(figure)


INCOMPLETE = "INCOMPLETE"


def _nearest_existing(path: str) -> str:
    """``path`` or its closest ancestor that exists (``/`` at worst)."""
    current = os.path.abspath(path)
    while not os.path.lexists(current):
        parent = os.path.dirname(current)
        if parent == current:
            break
        current = parent
    return current


def check_output_folder(folder: str | os.PathLike) -> str:
    """Prove that ``folder`` is, or can become, a folder where files can be written; create nothing.

    Called before any computing, so a bad ``--out`` fails at once rather than after the
    run. Writability is probed by creating (and removing) a temporary file in the folder
    or in its nearest existing ancestor: permission bits alone do not tell (root, ACLs,
    read-only mounts, ``/proc``). Returns the path as text; ValueError naming it otherwise.
    """
    if not isinstance(folder, (str, os.PathLike)) or not os.fspath(folder):
        raise BadInput(f"output folder must be a non-empty path, got {folder!r}")
    folder = os.fspath(folder)
    existing = _nearest_existing(folder)
    if not os.path.isdir(existing):
        if existing == os.path.abspath(folder):
            raise BadInput(f"output folder {folder!r} is an existing file, not a folder")
        raise BadInput(f"output folder {folder!r} cannot be created: {existing!r} is a file, not a folder")
    try:
        fd, probe = tempfile.mkstemp(dir=existing, prefix=".probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        where = "" if existing == os.path.abspath(folder) else f" (nothing can be created in {existing!r})"
        raise BadInput(f"output folder {folder!r} is not writable{where}: {exc.strerror or exc}") from exc
    return folder


@contextlib.contextmanager
def result_folder(folder: str, command: str) -> Iterator[str]:
    """Write into ``folder`` under an ``INCOMPLETE`` marker, removed only when the block finishes; the
    temporaries a killed run left there are removed first (``clear_stale_temporaries``).

    The marker (written atomically first) names the command and when it started; an
    interrupt or an error leaves it in place, beside whatever was written so far. When
    the block fails before writing anything, the folder is left as it was found (a
    folder this call created is removed again), so refused input leaves no trace.
    """
    check_output_folder(folder)
    existing = _nearest_existing(folder)
    marker = os.path.join(folder, INCOMPLETE)
    had_marker = os.path.exists(marker)
    clear_stale_temporaries(folder)
    started = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    write_text(marker, f"{command}\nstarted {started} and has not finished: the files beside this one may be "
                       "partial or from an earlier run. Run the command again to complete this folder.\n")
    try:
        yield folder
    except BaseException:
        if not had_marker and os.listdir(folder) == [INCOMPLETE]:
            os.unlink(marker)
            current = os.path.abspath(folder)
            while current != existing and not os.listdir(current):  # the folders this call created
                os.rmdir(current)
                current = os.path.dirname(current)
        raise
    os.unlink(marker)


def clear_stale_temporaries(folder: str) -> list[str]:
    """Remove the temporaries (``TEMPORARY_PREFIX`` files) that killed writers left directly in ``folder``;
    returns their names. Subfolders and every other file are left alone; a folder that does not exist
    holds none."""
    if not os.path.isdir(folder):
        return []
    removed = []
    for entry in os.scandir(folder):
        if entry.name.startswith(TEMPORARY_PREFIX) and entry.is_file(follow_symlinks=False):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(entry.path)
                removed.append(entry.name)
    return sorted(removed)


def read_json(path: str, default: Any = None) -> Any:
    if not os.path.isfile(path):
        return default
    with open(path) as fh:
        return json.load(fh)


def claims_table(claims: list[dict]) -> list[str]:
    """Markdown rows of a reproduction's claims: claim, our numbers, criterion, holds (bold "no")."""
    lines = ["| claim | our numbers | criterion | holds |", "|---|---|---|---|"]
    for c in claims:
        lines.append(f"| {c['claim']} | {c['ours']} | {c['criterion']} | {'yes' if c['holds'] else '**no**'} |")
    return lines
