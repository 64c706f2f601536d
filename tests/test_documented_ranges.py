"""The range a docstring table documents is the range the check enforces, for every field of every preset
and every registered part.

Each preset module and each part module documents its config in an ``Arguments`` table (``| field |
default | allowed |``; a multi-part module adds a column naming the part, or a heading naming the
class). For every numeric field whose ``allowed`` cell states an interval (``[a, b]``, ``(a, b]``,
``a..b``, ``>= a``, ``(0, inf]``, symbols such as ``N``, ``J`` or ``pi/dt`` evaluated on the
config's defaults), the test builds the env with each endpoint and with the nearest value beyond it:
a closed endpoint is accepted, an open endpoint and every value beyond a bound is a ``ValueError``
naming the field. A one-sided cell (``> 0``) states no maximum, so the largest float must be
accepted. Array fields whose cell says ``entries in [a, b]`` (or ``(n,) in [a, b]``) are checked
the same way with one entry set to the endpoint. Every config field must have a row.
"""

from __future__ import annotations

import dataclasses
import math
import re
import sys
import warnings

import numpy as np
import pytest

import coloc_env
from coloc_env.parts import BACKENDS, NETWORKS, WORLDS
from coloc_env.worlds.circles import default_layout
from tests.test_bad_config_properties import (
    CHEAP_PART,
    CHEAP_PRESET,
    HAVE_MRCLAM,
    make_part,
    make_preset,
    names_field,
    partners,
)

# --- the tables --------------------------------------------------------------------------------------------


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def argument_tables(doc: str) -> list[tuple[str, dict[str, dict[str, str]]]]:
    """Every ``| field | ... | allowed |`` table of ``doc``: (the text of the line before it, {part: {field:
    allowed}}); part is "" unless the table has a column naming the part (``backend``, ``part``)."""
    lines = doc.splitlines()
    tables = []
    i = 0
    while i < len(lines):
        header = _cells(lines[i]) if lines[i].strip().startswith("|") else []
        allowed_col = [j for j, c in enumerate(header) if c.startswith("allowed")]
        if "field" in header and allowed_col:
            col_field, col_allowed = header.index("field"), allowed_col[0]
            col_part = next((header.index(k) for k in ("backend", "world", "network", "part") if k in header), None)
            heading = next((lines[j] for j in range(i - 1, -1, -1) if lines[j].strip()), "")
            rows: dict[str, dict[str, str]] = {}
            last = None
            i += 2
            while i < len(lines) and lines[i].strip().startswith("|"):
                cells = _cells(lines[i])
                cells += [""] * (len(header) - len(cells))
                if cells[col_field]:
                    part = cells[col_part] if col_part is not None else ""
                    last = (part, cells[col_field])
                    rows.setdefault(part, {})[cells[col_field]] = cells[col_allowed]
                elif last is not None:
                    rows[last[0]][last[1]] += " " + cells[col_allowed]
                i += 1
            tables.append((heading, rows))
        i += 1
    return tables


def documented(cls: type) -> dict[str, str]:
    """{field: allowed} of the config class ``cls`` from its module's tables (the ones whose heading names
    ``cls``, or which name none; a row ``a, b | ...`` documents both fields, a cell ``as ``x```` refers to
    the part x's row)."""
    doc = sys.modules[cls.__module__].__doc__ or ""
    own_name = getattr(cls, "name", None)
    found: dict[str, str] = {}
    tables = argument_tables(doc)
    named = [t for t in tables if re.search(rf"\b{cls.__name__}\b", t[0])]
    for _heading, rows in named or [t for t in tables if not re.search(r"``coloc_env\.\w+\.\w+``", t[0])]:
        for part, fields in rows.items():
            if part and part != own_name:
                continue
            for key, allowed in fields.items():
                for name in (k.strip() for k in key.split(",")):
                    found[name] = allowed
    for name, allowed in list(found.items()):
        ref = re.fullmatch(r"as ``(\w+)``", allowed.strip())
        if ref:
            other = {**WORLDS, **NETWORKS, **BACKENDS}[ref.group(1)]
            found[name] = documented(other).get(name, "")
    return found


# --- the intervals -----------------------------------------------------------------------------------------

NUMBER = r"[-+]?(?:\d+\.?\d*(?:e[-+]?\d+)?|inf|pi)"
EXPR = r"[-+*/() .\w]+?"


@dataclasses.dataclass(frozen=True)
class Interval:
    low: str | None
    high: str | None
    low_open: bool
    high_open: bool
    integer: bool
    entries: bool = False  # an array field: every entry in the interval


def parse_interval(text: str, kind: str) -> Interval | None:
    """The interval an ``allowed`` cell states first, or None where it states none."""
    entries = kind == "array"
    if entries:
        m = re.search(r"(?:entries|\))\s+(?:in|each in)\s+([\[(].*?[\])])", text)
        if not m:
            return None
        text = m.group(1)
    m = re.search(rf"(^|[\s:,])([\[(])\s*({EXPR})\s*,\s*({EXPR})\s*([\])])", text)
    if m:
        return Interval(m.group(3).strip(), m.group(4).strip(), m.group(2) == "(", m.group(5) == ")",
                        kind == "int", entries)
    m = re.search(rf"(?:^|[\s:,])({EXPR})\s*\.\.\s*({EXPR})(?:\s|$|,|;|:)", text)
    if m and kind == "int":
        return Interval(m.group(1).strip(), m.group(2).strip(), False, False, True)
    m = re.match(r"\s*(?:\w+\s+)?(>=|>)\s*([-+]?[\w.]+)", text)
    if m:
        return Interval(m.group(2), None, m.group(1) == ">", False, kind == "int")
    return None


def evaluate(expr: str | None, names: dict) -> float | None:
    """``expr`` ("1e6", "-2N", "pi/dt", "N-1", "num_agents") with the config's names; None where it refers to
    something the defaults do not fix."""
    if expr is None:
        return None
    source = re.sub(r"(\d)\s*([A-Za-z_(])", r"\1*\2", expr.replace("^", "**"))
    source = re.sub(r"(?<![\w.])(\d+(?:\.\d*)?)\*e([-+]?\d)", r"\1e\2", source)  # 1*e6 -> 1e6
    try:
        value = eval(source, {"__builtins__": {}}, {"pi": math.pi, "inf": math.inf, **names})  # noqa: S307
    except Exception:  # noqa: BLE001 - a symbol the defaults do not fix (a part's N)
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        return None
    return float(value)


LAYOUT = ("centres", "start_angles", "directions")

# --- the targets -------------------------------------------------------------------------------------------

HAVE = {"mrclam": HAVE_MRCLAM}


def preset_targets():
    return [("preset", n) for n in coloc_env.SCENARIOS if n != "mrclam_relay" or HAVE_MRCLAM]


def part_targets():
    return [(r.kind, name) for r in (WORLDS, NETWORKS, BACKENDS) for name in r if partners(r.kind, name)]


def config_class(target) -> type:
    if target[0] == "preset":
        return coloc_env.scenario_class(target[1]).Config
    return {"world": WORLDS, "network": NETWORKS, "backend": BACKENDS}[target[0]][target[1]]


def names_of(target, config_cls) -> dict:
    """The defaults a symbol in a cell may refer to: the config's fields (cheap settings applied) and the
    usual symbols (N agents, J neighbours, D the buffer, n the state's size)."""
    names = {f.name: getattr(config_cls(), f.name) for f in dataclasses.fields(config_cls)
             if f.name != "data"}
    if target[0] == "preset":
        names.update(CHEAP_PRESET.get(target[1], {}))
    else:
        names.update(CHEAP_PART.get(target[1], {}))
    for key in ("num_platforms", "num_agents"):
        if key in names:
            names["N"] = names[key]
    if "num_neighbours" in names:
        names["J"] = names["num_neighbours"]
    if "buffer_length" in names:
        names["D"] = names["buffer_length"]
    for symbol, key in (("N_min", "window_min"), ("N_max", "window_max"), ("M", "group_size")):
        if key in names:
            names[symbol] = names[key]
    for key in ("transition", "initial_state"):
        if key in names and names[key] is not None:
            names["n"] = np.asarray(names[key]).shape[0]
            break
    return names


def build(target, field: str, value) -> None:
    if target[0] == "preset":
        make_preset(target[1], field, value)
    else:
        make_part(*target, field, value)


def field_kind(f: dataclasses.Field) -> str:
    base = str(f.type).replace("| None", "").replace("None |", "").strip()
    return base if base in ("float", "int", "bool", "str") else "array"


def cases(target):
    """(field, interval text, [(value, accepted)]) for each field of ``target`` whose cell states an interval."""
    cls = config_class(target)
    rows = documented(cls)
    names = names_of(target, cls)
    out = []
    for f in dataclasses.fields(cls):
        kind = field_kind(f)
        if kind in ("bool", "str") or f.name == "data":
            continue
        allowed = rows.get(f.name, "")
        interval = parse_interval(allowed, kind)
        if interval is None:
            continue
        low, high = evaluate(interval.low, names), evaluate(interval.high, names)
        probes = []
        if interval.integer:
            if low is not None and math.isfinite(low):
                lo = math.floor(low) + 1 if interval.low_open else math.ceil(low)
                probes += [(lo, True), (lo - 1, False)]
            if high is not None and math.isfinite(high):
                hi = math.ceil(high) - 1 if interval.high_open else math.floor(high)
                probes += [(hi, True), (hi + 1, False)]
        else:
            if low is not None:
                if math.isfinite(low):
                    probes += [(low, not interval.low_open), (float(np.nextafter(low, -math.inf)), False)]
                    if interval.low_open:
                        probes.append((float(np.nextafter(low, math.inf)), True))
            if interval.high is None:  # one-sided: no maximum
                probes.append((float(np.finfo(float).max), True))
            elif high is not None:
                if math.isfinite(high):
                    probes += [(high, not interval.high_open), (float(np.nextafter(high, math.inf)), False)]
                    if interval.high_open:
                        probes.append((float(np.nextafter(high, -math.inf)), True))
                else:
                    probes.append((high, not interval.high_open))
        if interval.entries:
            default = getattr(cls(), f.name)
            if default is None and f.name in LAYOUT:  # the circles layout of the config's N
                default = default_layout(int(names["N"]))[LAYOUT.index(f.name)]
            if default is None:
                continue
            base = np.asarray(default, float)
            probes = [(_with_entry(base, v), ok) for v, ok in probes if base.size]
        out.append((f.name, allowed, probes))
    return out


def _with_entry(base: np.ndarray, value: float) -> np.ndarray:
    arr = base.copy().reshape(-1)
    arr[-1] = value
    return arr.reshape(base.shape)


# A cell that states a rule between this field and another one's (a documented endpoint may be refused for the
# other field's default value, with this field named).
SECOND_RULE = r"at most|with the world|and [<>]=|checked at build|sum <=|<= 1 - |low <= high"


def coupled(message: str, field: str, target) -> bool:
    """The message names ``field`` and another field of the config (a rule between two fields: a documented
    endpoint of one may be refused with the other's default, and the message says so)."""
    others = [f.name for f in dataclasses.fields(config_class(target)) if f.name != field]
    return any(names_field(message, other) for other in others)


TARGETS = preset_targets() + part_targets()


@pytest.mark.parametrize("target", TARGETS, ids="/".join)
def test_every_field_has_a_row_in_the_arguments_table(target):
    cls = config_class(target)
    rows = documented(cls)
    missing = [f.name for f in dataclasses.fields(cls) if f.name not in rows]
    assert not missing, f"{'/'.join(target)}: fields without a row in the Arguments table: {missing}"


@pytest.mark.parametrize("target", TARGETS, ids="/".join)
def test_the_documented_range_is_the_enforced_range(target):
    problems = []
    for field, allowed, probes in cases(target):
        for value, accepted in probes:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    build(target, field, value)
                outcome = "accepted"
            except ValueError as exc:
                message = str(exc)
                if not names_field(message, field):
                    outcome = f"refused without the field: {message}"
                elif accepted and (coupled(message, field, target) or re.search(SECOND_RULE, allowed)):
                    outcome = "accepted"  # a combination with another field's value, named in the message
                else:
                    outcome = "refused" if not accepted else f"refused: {message}"
            except Exception as exc:  # noqa: BLE001 - anything else is a defect
                outcome = f"{type(exc).__name__}: {exc}"
            if outcome != ("accepted" if accepted else "refused"):
                shown = value if np.ndim(value) == 0 else f"an entry = {np.asarray(value).reshape(-1)[-1]!r}"
                problems.append(f"{field}={shown!r} (documented: {allowed!r}) should be "
                                f"{'accepted' if accepted else 'refused'}: {outcome}"[:400])
    assert not problems, f"{'/'.join(target)}:\n" + "\n".join(problems)


def test_the_parser_reads_the_table_forms():
    assert parse_interval("[1e-6, pi/dt] rad/s (smaller: ...)", "float") == Interval("1e-6", "pi/dt", False,
                                                                                      False, False)
    assert parse_interval("(0, 1e4] m/s", "float") == Interval("0", "1e4", True, False, False)
    assert parse_interval("2..16", "int") == Interval("2", "16", False, False, True)
    assert parse_interval("1..N-1 hops per measurement, None = no limit", "int") == Interval("1", "N-1", False,
                                                                                            False, True)
    assert parse_interval("> 0 m", "float") == Interval("0", None, True, False, False)
    assert parse_interval("lam in (0, 1) [chosen]", "float") == Interval("0", "1", True, True, False)
    assert parse_interval("(n,) in [-1e6, 1e6]: xhat", "array") == Interval("-1e6", "1e6", False, False, False,
                                                                             True)
    assert parse_interval('"error", "trace"', "float") is None
    assert evaluate("-2N", {"N": 4}) == -8.0
    assert evaluate("pi/dt", {"dt": 0.5}) == pytest.approx(2 * math.pi)
    assert evaluate("1e6", {}) == 1e6
    assert evaluate("J", {}) is None


def test_relay_ukf_takes_a_ukf_lambda_inside_minus_2n():
    env = coloc_env.parallel_env("relay_ukf", ukf_lambda=-5.0, horizon=5)
    observations, _ = env.reset(seed=0)
    assert all(np.all(np.isfinite(o)) for o in observations.values())
    with pytest.raises(ValueError, match=r"ukf_lambda must be in \(-2 num_agents = -8.0, 1000000.0\], got -8"):
        coloc_env.parallel_env("relay_ukf", ukf_lambda=-8.0)
    with pytest.raises(ValueError, match=r"backend.ukf_lambda must be in \(-2 world.num_agents = -12.0, 1000000.0\]"):
        coloc_env.parallel_env(coloc_env.compose(world="circles", network="relay",
                                                 backend={"name": "ukf_dcl", "ukf_lambda": -12.0}))


@pytest.mark.parametrize("value", [float("nan"), float("inf"), 1e308, "abc", -9.0])
@pytest.mark.parametrize("backend", ["ukf_ccl", "ukf_dcl"])
def test_a_refused_ukf_lambda_names_the_tables_range(value, backend):
    """Every refusal of ``ukf_lambda`` states the table's (-2N, 1e6]: a value refused before the team is known
    names N, one refused against the team gives N's value too; never another range."""
    with pytest.raises(ValueError, match=r"^relay_ukf: ukf_lambda must be (a number )?in \(-2 num_agents( = -8.0)?, "
                                         r"1000000.0\], got"):
        coloc_env.parallel_env("relay_ukf", ukf_lambda=value)
    with pytest.raises(ValueError, match=r"^backend.ukf_lambda must be (a number )?in \(-2 world.num_agents"
                                         r"( = -12.0)?, 1000000.0\], got"):
        low = -13.0 if value == -9.0 else value  # circles: 6 agents, -2N = -12
        coloc_env.parallel_env(coloc_env.compose(world="circles", network="relay",
                                                 backend={"name": backend, "ukf_lambda": low}))


@pytest.mark.parametrize("value", [1.0, 2.0, 0.0])
def test_smoothing_states_its_open_interval(value):
    with pytest.raises(ValueError, match=r"^nlos_horizon: smoothing must be in \(0.0, 1.0\), got"):
        coloc_env.parallel_env("nlos_horizon", smoothing=value)
    with pytest.raises(ValueError, match=r"^backend.smoothing must be in \(0.0, 1.0\), got"):
        coloc_env.compose(world="nlos_orbit", network="random_delay", backend={"name": "afge", "smoothing": value})


@pytest.mark.parametrize("value", [1e308, float("inf"), 1e13])
def test_a_distance_takes_any_positive_length(value):
    spec = coloc_env.compose(world="gps_denied", network={"name": "broadcast", "comm_range": value},
                             backend="range_ls")
    assert spec.network.comm_range == value
    with pytest.raises(ValueError, match=r"network.comm_range must be in \(0.0, inf\], got -1"):
        coloc_env.compose(world="gps_denied", network={"name": "broadcast", "comm_range": -1.0}, backend="range_ls")


def test_a_bound_set_by_another_field_names_it():
    with pytest.raises(ValueError, match=r"turn_rate must be in \[1e-06, pi/dt = 0.00087\d*\], got 0.015"):
        coloc_env.parallel_env("relay_ukf", dt=3600.0)
    with pytest.raises(ValueError, match=r"world.num_anchors must be in \[0, world.num_agents = 2\], got 3"):
        coloc_env.compose(world={"name": "circles", "num_agents": 2}, network="ideal", backend="range_ls")
