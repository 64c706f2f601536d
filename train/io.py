"""Atomic writes: a result file is either the old one or the complete new one, never half."""

from __future__ import annotations

import json
import os
import tempfile
from typing import Any

import numpy as np


def _atomic(path: str, write) -> None:
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=".tmp-", suffix=os.path.basename(path))
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


def save_figure(path: str, figure) -> None:
    """Save a matplotlib figure as PNG atomically and close it."""
    _atomic(path, lambda fh: figure.savefig(fh, format="png", dpi=110, bbox_inches="tight"))
    import matplotlib.pyplot as plt

    plt.close(figure)


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
