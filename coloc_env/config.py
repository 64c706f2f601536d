"""Validation helpers shared by every config dataclass.

Each config is a frozen dataclass whose defaults are a paper's setting and
whose ``validate()`` raises ``ValueError`` naming the field and the allowed
range. ``build_config`` turns keyword arguments into such a config and
refuses unknown keys, so a typo never passes silently.
"""

from __future__ import annotations

import contextlib
import dataclasses
import numbers
import re
from typing import Any, TypeVar

import numpy as np

C = TypeVar("C")


class BadInput(ValueError):
    """A value the user gave is refused by a check: a config field, a part, a seed, a count, a flag, a file.

    Every check of this package raises it (it is a ``ValueError``, so ``except ValueError`` still catches
    it), and a config's ``validate()`` turns any ``ValueError`` it raises into one
    (``validate_fields``). The command line exits 2 for it and treats any other exception as an
    internal error (exit 1 with a request to report it): a ``ValueError`` from numpy or from an
    estimator's numerics is a bug, not bad input."""


COMPOSITION_ALIAS = "composition."  # an alias's target for a composition-level option (relay: hop_cost)


def read_aliases(config_cls: type, given: dict[str, Any], prefix: str = ""):
    """The one reading of older names: a config class (a preset's flat config or a part) declares them in its
    ``aliases``, older name -> current name, or -> ``"composition.<option>"`` for a part's name of a
    composition-level option (relay's ``hop_cost``, the composition's ``communication_cost``).

    Returns ``(fields, written, lifted)``: ``given`` with each older name of a field renamed to its current
    name (a composition option's older name stays as written: it is no field of the class); ``written``,
    {``prefix + current``: ``prefix + older``} for each older name given, the names ``refused_as_written``
    puts back into an error; ``lifted``, {option: (older name, value)} for each composition option given under
    a part's name (``coloc_env.composition.compose`` moves it to the composition). Giving both an older name
    and its current one is a ``BadInput`` (names shown as ``prefix + name``)."""
    fields, written, lifted = dict(given), {}, {}
    for alias, name in getattr(config_cls, "aliases", {}).items():
        if alias not in given:
            continue
        if name.startswith(COMPOSITION_ALIAS):
            lifted[name[len(COMPOSITION_ALIAS):]] = (alias, given[alias])
            continue
        if name in given:
            raise BadInput(f"{prefix}{alias} is another name of {prefix}{name}; give only one of them")
        fields[name] = fields.pop(alias)
        written[f"{prefix}{name}"] = f"{prefix}{alias}"
    return fields, written, lifted


@contextlib.contextmanager
def refused_as_written(written: dict[str, str]):
    """A ``BadInput`` raised inside is raised again with each current name of ``written`` ({current: as the user
    wrote it}) replaced by the name the user wrote, so that a value given under an older name (a config's
    ``aliases``) is refused under that name. A name is replaced only where it stands alone: ``num_agents``
    not inside ``world.num_agents`` or ``num_agents_max``."""
    try:
        yield
    except BadInput as exc:
        message = str(exc)
        for name, alias in written.items():
            message = re.sub(rf"(?<![\w.]){re.escape(name)}(?!\w)", alias, message)
        if message == str(exc):
            raise
        raise BadInput(message) from exc


def build_config(config_cls: type[C], kwargs: dict[str, Any]) -> C:
    """Instantiate ``config_cls(**kwargs)`` after rejecting unknown keys, then validate it. A key listed in
    the class's ``aliases`` (older name -> current name) is read as its current name, and an error about
    its value names it as the user wrote it (``refused_as_written``)."""
    names = {f.name for f in dataclasses.fields(config_cls)}
    kwargs, written, _ = read_aliases(config_cls, kwargs)
    unknown = sorted(set(kwargs) - names)
    if unknown:
        aliases = getattr(config_cls, "aliases", {})
        also = f" (and their older names {sorted(aliases)})" if aliases else ""
        raise BadInput(
            f"unknown config key(s) {unknown} for {config_cls.__name__}; allowed keys: {sorted(names)}{also}"
        )
    config = config_cls(**kwargs)
    with refused_as_written(written):
        validate_fields(config)
    return config


def is_real(value: Any) -> bool:
    """A real number: int, float, a numpy integer or floating scalar (or 0-d array); never a bool,
    a string, None or a complex number."""
    if isinstance(value, (bool, np.bool_)):
        return False
    if isinstance(value, numbers.Real):
        return True
    return isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iuf"


def is_integer(value: Any) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def field_type_problem(config: Any, prefix: str = "") -> str:
    """The first field of the dataclass ``config`` whose value is not of its annotated kind, in words
    (``"speed must be a number, got 'abc'"``); "" when every field is. ``float`` fields take real
    numbers, ``int`` fields integers, ``bool`` fields True/False, ``str`` fields strings, a ``tuple``
    field a numeric array (when its default is one); ``| None`` allows None."""
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        annotation = str(f.type)
        optional = "None" in annotation
        if value is None and optional:
            continue
        base = annotation.replace("| None", "").replace("None |", "").strip()
        name = f"{prefix}{f.name}"
        if base == "float" and not is_real(value):
            return f"{name} must be a number, got {value!r}"
        if base == "int" and not is_integer(value):
            return f"{name} must be an integer, got {value!r}"
        if base == "bool" and not isinstance(value, (bool, np.bool_)):
            return f"{name} must be True or False, got {value!r}"
        if base == "str" and not isinstance(value, str):
            return f"{name} must be a string, got {value!r}"
        if base == "tuple" and f.default is not dataclasses.MISSING and f.default is not None:
            try:
                numeric_default = np.asarray(f.default).dtype.kind in "iuf"
            except (TypeError, ValueError):
                numeric_default = False
            if numeric_default:
                try:
                    kind = np.asarray(value).dtype.kind
                except (TypeError, ValueError):
                    kind = "O"
                if kind not in "iuf":
                    return f"{name} must be a numeric array, got {value!r}"
    return ""


def validate_fields(config: Any, prefix: str = "", validate=None) -> None:
    """``config.validate()`` (or ``validate()``), turning any error that a wrongly typed field caused
    (a ``TypeError`` in a derived value, numpy's "could not convert") into a ``BadInput`` naming the
    field. A ``ValueError`` that already names that field keeps its message (it states the range); any
    ``ValueError`` of ``validate()`` leaves as a ``BadInput``."""
    try:
        (validate or config.validate)()
    except Exception as exc:
        problem = field_type_problem(config, prefix)
        if not problem:
            if isinstance(exc, ValueError) and not isinstance(exc, BadInput):
                raise BadInput(str(exc)) from exc  # whatever validate() refuses is the input's fault
            raise
        field = problem.split(" must ", 1)[0]
        if isinstance(exc, ValueError) and field in str(exc):
            if not isinstance(exc, BadInput):
                raise BadInput(str(exc)) from exc
            raise
        raise BadInput(problem) from exc


def as_array(name: str, value: Any, shape: tuple[int, ...] | None = None, ndim: int | None = None,
             bound: float | None = None) -> np.ndarray:
    """A finite float array of the given shape, or ``ValueError`` naming ``name``.

    Only real numbers: strings (numeric or not), booleans, None and complex numbers are refused, never
    coerced."""
    try:
        raw = np.asarray(value)
        if raw.dtype.kind not in "iuf":
            raise TypeError(f"dtype {raw.dtype}")
        arr = raw.astype(float)
    except (TypeError, ValueError) as exc:
        raise BadInput(f"{name} must be an array of real numbers, got {value!r}") from exc
    if shape is not None and arr.shape != tuple(shape):
        raise BadInput(f"{name} must have shape {tuple(shape)}, got {arr.shape}")
    if ndim is not None and arr.ndim != ndim:
        raise BadInput(f"{name} must be a {ndim}-d array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise BadInput(f"{name} must be finite, got {value!r}")
    if bound is not None and arr.size and np.abs(arr).max() > bound:
        raise BadInput(f"{name} entries must be in [-{bound:g}, {bound:g}], got {np.abs(arr).max():g}")
    return arr


def check_entries(name: str, arr: np.ndarray, low: float, high: float, low_open: bool = False) -> None:
    """Every entry of the finite array ``arr`` in ``[low, high]`` (``(low, high]`` if ``low_open``), or
    ``ValueError`` naming ``name``, the interval and the first entry outside it."""
    arr = np.asarray(arr, float)
    below = arr <= low if low_open else arr < low
    bad = below | (arr > high) | ~np.isfinite(arr)
    if np.any(bad):
        interval = f"{'(' if low_open else '['}{low:g}, {high:g}]"
        raise BadInput(f"{name} entries must be in {interval}, got {float(arr[bad].reshape(-1)[0])!r} "
                         f"at index {tuple(int(i) for i in np.argwhere(bad)[0])}")


def check_stable(name: str, matrix: np.ndarray, max_radius: float = 1.001) -> None:
    """A transition matrix whose spectral radius is at most ``max_radius`` (a state and covariance that
    stay finite over 1e5 steps), or ``ValueError`` naming ``name``."""
    radius = float(np.abs(np.linalg.eigvals(matrix)).max())
    if radius > max_radius:
        raise BadInput(f"{name} must have spectral radius <= {max_radius:g} (the state and covariance stay "
                         f"finite over the horizon), got {radius:.6g}")


def check_psd(name: str, value: Any, n: int | None = None, strict: bool = False,
              bound: float | None = None) -> np.ndarray:
    """A symmetric positive (semi-)definite ``(n, n)`` matrix (entries at most ``bound`` in magnitude), or
    ``ValueError`` naming ``name``."""
    arr = as_array(name, value, ndim=2, bound=bound)
    if arr.shape[0] != arr.shape[1] or (n is not None and arr.shape[0] != n):
        expected = f"({n}, {n})" if n is not None else "square"
        raise BadInput(f"{name} must be a {expected} covariance matrix, got shape {arr.shape}")
    if not np.allclose(arr, arr.T, atol=1e-12, rtol=1e-9):
        raise BadInput(f"{name} must be symmetric")
    smallest = np.linalg.eigvalsh(arr).min()
    if smallest < (1e-12 if strict else -1e-12):
        kind = "positive definite" if strict else "positive semi-definite"
        raise BadInput(f"{name} must be {kind} (smallest eigenvalue {smallest:.3g})")
    return arr


# Seeds: non-negative integers (numpy's SeedSequence takes no negative entropy); the upper end keeps
# ``seed + b`` of every vector copy an int64 (what a results file and SB3 store).
SEED_MAX = 2**63 - 1
# The most copies one vector env holds (each copy holds its episode's draws).
MAX_NUM_ENVS = 100_000


def check_seed(name: str, seed: Any, copies: int = 1) -> int | None:
    """None, or a seed: an integer in [0, SEED_MAX - copies + 1] (so that ``seed + b`` for the ``copies``
    copies is one too); a string, a float (even 1.0), a boolean or NaN is a ``ValueError`` naming ``name``."""
    if seed is None:
        return None
    high = SEED_MAX - copies + 1
    if not is_integer(seed) or not 0 <= int(seed) <= high:
        raise BadInput(f"{name} must be None or an integer in [0, {high}], got {seed!r}")
    return int(seed)


def check_count(name: str, value: Any, low: int, high: int) -> int:
    """An integer count in [low, high], or ``ValueError`` naming ``name``."""
    check_range(name, value, low, high, integer=True)
    return int(value)


# The largest entries of nlos_orbit's (low, high) pairs: orbit radii (m) and wobble rates (rad/s).
ORBIT_LIMITS = {"orbit_radius": 1e7, "orbit_wobble_rate": 10.0}

# The smallest standard deviation (m, m/s^2) or kernel bandwidth (m) a particle filter's config may set: it
# divides by them squared, and a subnormal sigma squares to 0 (numba raises ZeroDivisionError there).
MIN_STD = 1e-3


def check_range(name: str, value: Any, low: float | None, high: float, integer: bool = False,
                low_open: bool = False, high_open: bool = False, low_label: str | None = None,
                high_label: str | None = None) -> None:
    """``low <= value <= high`` (``low < value`` if ``low_open``, ``value < high`` if ``high_open``), or
    ``ValueError`` naming ``name`` and the range in interval notation (``(0.0, 1.0]``).

    The value must be a real number (an integer if ``integer``): a string (even "1.0"), a boolean,
    None or a complex number is refused, never coerced. NaN is always refused; ``inf`` only where the
    closed range includes it (``high=inf``, ``high_open`` False: an unlimited distance). ``low`` and
    ``high`` are in the field's own unit (a ``*_deg`` field is checked in degrees). ``low_label`` /
    ``high_label`` name a bound another field sets (``high_label="num_agents"`` reads ``[0, num_agents =
    3]``), so that the message names the field whose value moved it; ``low=None`` with a ``low_label`` is a
    bound not known yet (checked where it is): the message names it alone (``(-2 num_agents, 1000000.0]``) and
    only NaN, a non-number and the high bound are refused here."""
    lo = (f"{low_label} = {low}" if low is not None else low_label) if low_label else f"{low}"
    hi = f"{high_label} = {high}" if high_label else f"{high}"
    if low is None:
        low = -np.inf
    interval = f"{'(' if low_open else '['}{lo}, {hi}{')' if high_open else ']'}"
    if integer and not is_integer(value):
        raise BadInput(f"{name} must be an integer in {interval}, got {value!r}")
    if not is_real(value):
        raise BadInput(f"{name} must be a number in {interval}, got {value!r}")
    v = float(value)
    below = v <= low if low_open else v < low
    above = v >= high if high_open else v > high
    if np.isnan(v) or below or above:
        raise BadInput(f"{name} must be in {interval}, got {value!r}")


def check_distance(name: str, value, allow_inf: bool = True) -> None:
    """A positive distance in metres, (0, inf] (``inf`` meaning unlimited; (0, 1e12] without ``allow_inf``);
    else ``ValueError`` naming ``name``."""
    check_range(name, value, 0.0, np.inf if allow_inf else 1e12, low_open=True)


def check_step_windows(name: str, value: Any, windows: np.ndarray, high: int = 10_000_000) -> None:
    """[start, end) windows of integer steps: ``0 <= start < end <= high``, or ``ValueError`` naming ``name``."""
    kind = np.asarray(value).dtype.kind
    if kind not in "iu" or np.any(windows < 0) or np.any(windows > high) or np.any(windows[..., 1] <= windows[..., 0]):
        raise BadInput(f"{name} must be [start, end) integer steps with 0 <= start < end <= {high}, got {value!r}")


def check_choice(name: str, value: Any, choices: tuple) -> None:
    """``value`` is one of ``choices`` (and of the same type: ``True`` is not ``1``; numpy's ``np.True_`` is
    ``True``), or ``ValueError``."""
    if isinstance(value, np.bool_):
        value = bool(value)
    try:
        ok = any((isinstance(value, str) if isinstance(c, str) else type(value) is type(c)) and value == c
                 for c in choices)
    except Exception:  # noqa: BLE001 - an array compared with a choice
        ok = False
    if not ok:
        raise BadInput(f"{name} must be one of {choices}, got {value!r}")


def module_names(module: str, names: dict[str, Any], deprecated: dict[str, str] | None = None, stacklevel: int = 2):
    """A module-level ``__getattr__`` (PEP 562) for ``module`` that computes each of ``names`` on access
    (``names[name]()``: a table read from the registries, so it is never stale). A name in ``deprecated`` also
    warns ``"{module}.{name} is deprecated: {reason}"`` (DeprecationWarning, pointed at the caller's line).
    Any other name is the usual AttributeError. ``stacklevel`` 3 where the module's own ``__getattr__`` calls the
    returned function (to import this module lazily)."""
    import warnings

    def __getattr__(name: str):
        if name not in names:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        if deprecated and name in deprecated:
            warnings.warn(f"{module}.{name} is deprecated: {deprecated[name]}", DeprecationWarning,
                          stacklevel=stacklevel)
        return names[name]()

    return __getattr__
