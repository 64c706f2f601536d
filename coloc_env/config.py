"""Validation helpers shared by every config dataclass.

Each config is a frozen dataclass whose defaults are a paper's setting and
whose ``validate()`` raises ``ValueError`` naming the field and the allowed
range. :func:`build_config` turns keyword arguments into such a config and
refuses unknown keys, so a typo never passes silently.
"""

from __future__ import annotations

import dataclasses
from typing import Any, TypeVar

import numpy as np

C = TypeVar("C")


def build_config(config_cls: type[C], kwargs: dict[str, Any]) -> C:
    """Instantiate ``config_cls(**kwargs)`` after rejecting unknown keys, then validate it."""
    names = {f.name for f in dataclasses.fields(config_cls)}
    unknown = sorted(set(kwargs) - names)
    if unknown:
        raise ValueError(
            f"unknown config key(s) {unknown} for {config_cls.__name__}; allowed keys: {sorted(names)}"
        )
    config = config_cls(**kwargs)
    config.validate()
    return config


def as_array(name: str, value: Any, shape: tuple[int, ...] | None = None, ndim: int | None = None) -> np.ndarray:
    """A finite float array of the given shape, or ``ValueError`` naming ``name``."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be numeric, got {value!r}") from exc
    if shape is not None and arr.shape != tuple(shape):
        raise ValueError(f"{name} must have shape {tuple(shape)}, got {arr.shape}")
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name} must be a {ndim}-d array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return arr


def check_psd(name: str, value: Any, n: int | None = None, strict: bool = False) -> np.ndarray:
    """A symmetric positive (semi-)definite ``(n, n)`` matrix, or ``ValueError`` naming ``name``."""
    arr = as_array(name, value, ndim=2)
    if arr.shape[0] != arr.shape[1] or (n is not None and arr.shape[0] != n):
        expected = f"({n}, {n})" if n is not None else "square"
        raise ValueError(f"{name} must be a {expected} covariance matrix, got shape {arr.shape}")
    if not np.allclose(arr, arr.T, atol=1e-12, rtol=1e-9):
        raise ValueError(f"{name} must be symmetric")
    smallest = np.linalg.eigvalsh(arr).min()
    if smallest < (1e-12 if strict else -1e-12):
        kind = "positive definite" if strict else "positive semi-definite"
        raise ValueError(f"{name} must be {kind} (smallest eigenvalue {smallest:.3g})")
    return arr


def check_range(name: str, value: Any, low: float, high: float, integer: bool = False,
                low_open: bool = False) -> None:
    """``low <= value <= high`` (``low < value`` if ``low_open``), or ``ValueError`` naming ``name``."""
    if integer and (isinstance(value, bool) or not isinstance(value, (int, np.integer))):
        raise ValueError(f"{name} must be an integer in [{low}, {high}], got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a number in [{low}, {high}], got {value!r}") from exc
    below = v <= low if low_open else v < low
    if not np.isfinite(v) or below or v > high:
        bracket = "(" if low_open else "["
        raise ValueError(f"{name} must be in {bracket}{low}, {high}], got {value!r}")


def check_choice(name: str, value: Any, choices: tuple) -> None:
    if value not in choices:
        raise ValueError(f"{name} must be one of {choices}, got {value!r}")
