"""Bad config values are refused with the field named; values a documented range allows run finitely.

For every preset (``coloc_env.parallel_env(name, **{field: value})``) and every registered part
(``coloc_env.compose(world={"name": w, field: value}, ...)`` with compatible partners), hypothesis
draws a field and a value of the field's kind:

* *always bad* (NaN, strings incl. numeric strings, booleans, None, complex, wrong shapes, a wrong
  choice): a ``ValueError`` whose message names the field;
* *one entry* of an array field set to NaN, ±inf or ±1e308 (the others kept): a ``ValueError`` naming
  the field, or (±1e308 where the documented interval of the entries allows it) a finite short episode;
* *maybe bad* (±inf, ±1e308, tiny positives, 0, negatives, 1e16, scaled arrays, zero matrices):
  either that ``ValueError``, or the value is inside the documented range and a short seeded
  episode gives finite observations and rewards (nothing else may be raised).

The default profile draws a few examples per target, derandomized (the same examples on every run, so
``make test`` is deterministic; the whole module runs in seconds); set
``HYPOTHESIS_PROFILE=slow`` for many more. ``python -m tests.test_bad_config_properties`` runs the
fixed lists exhaustively and prints the number of cases tried and defects found.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import coloc_env
from coloc_env.parts import BACKENDS, NETWORKS, WORLDS
from tests.conftest import MRCLAM_DATASET6, RECORDED_WORLDS

settings.register_profile("default_bad_input", max_examples=12, deadline=None, derandomize=True,
                          suppress_health_check=list(HealthCheck))
settings.register_profile("slow", max_examples=400, deadline=None, suppress_health_check=list(HealthCheck))
PROFILE = "slow" if os.environ.get("HYPOTHESIS_PROFILE") == "slow" else "default_bad_input"
EXAMPLES = settings.get_profile(PROFILE).max_examples

MRCLAM_DATA = MRCLAM_DATASET6  # COLOC_MRCLAM_DATA, else the default beside the clone (tests/conftest.py)
HAVE_MRCLAM = os.path.isdir(MRCLAM_DATA)
STEPS = 3

# Cheap settings of the other fields, so that an episode of a few steps is quick (never the field under test).
# MRCLAM: the moment rules' noise model, which fits nothing; the default "likelihood" would run its fit (seconds to
# minutes, cached per window) for every probed calibration_s and dt.
CHEAP_PRESET = {
    "gps_denied_nbp": {"num_particles": 40, "num_iterations": 1},
    "mrclam_relay": {"data": MRCLAM_DATA, "window_steps": 8, "noise_model": "calibrated"},
    "nlos_horizon": {"horizon": 40},
}
CHEAP_PART = {"dnbp": {"num_particles": 40, "num_iterations": 1},
              "mrclam": {"data": MRCLAM_DATA, "horizon": 8, "noise_model": "calibrated"},
              "mrclam_slices": {"data": MRCLAM_DATA, "horizon": 8}}
SKIP_FIELDS = {"data"}  # a path: the loader's own tests cover it


# --- field kinds -----------------------------------------------------------------------------------
def field_kind(f: dataclasses.Field) -> tuple[str, bool]:
    """(kind, optional): kind is float, int, bool, str or array; optional when None is allowed."""
    annotation = str(f.type)
    optional = "None" in annotation
    base = annotation.replace("| None", "").replace("None |", "").strip()
    if base in ("float", "int", "bool", "str"):
        return base, optional
    return "array", optional


def fields_of(cls) -> list[tuple[str, str, bool, object]]:
    """(name, kind, optional, default) of each config field worth fuzzing."""
    out = []
    for f in dataclasses.fields(cls):
        if f.name in SKIP_FIELDS:
            continue
        kind, optional = field_kind(f)
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore[misc]
        if default is None and kind == "array":
            default = NONE_DEFAULT_EXAMPLES.get(f.name)
        out.append((f.name, kind, optional, default))
    return out


# Valid values of array fields whose default is None (relay_ukf's layout), so that their bad values have a shape.
NONE_DEFAULT_EXAMPLES = {"centres": ((0.0, 0.0), (100.0, 0.0), (0.0, 100.0), (100.0, 100.0)),
                         "start_angles": (0.0, 1.0, 2.0, 3.0), "directions": (1.0, -1.0, 1.0, -1.0)}


def always_bad(kind: str, optional: bool, default) -> list:
    """Values that no documented range allows for this kind of field."""
    common = ["abc", "1.0", "1", b"1", 1 + 0j, complex(1, 1), {"a": 1}]
    if not optional:
        common.append(None)
    if kind == "float":
        return [math.nan, True, False, np.bool_(True), [1.0], (1.0, 2.0), np.array([1.0]), *common]
    if kind == "int":
        return [math.nan, math.inf, 1.5, 2.0, True, False, "3", [2], np.float64(2.0), *common]
    if kind == "bool":
        return ["True", "yes", 1, 0, 1.0, [True], *[c for c in common if c is not None], *([] if optional else [None])]
    if kind == "str":
        return ["no-such-choice", 1, 1.0, True, ["error"], b"error", *([] if optional else [None])]
    try:
        arr = np.asarray(default, dtype=float) if default is not None else np.ones(2)
    except (TypeError, ValueError):  # a tuple of names (nlos_orbit.sensors)
        return ["abc", 1, 1.0, True, ("no-such-name",), (1, 2), *([] if optional else [None])]
    bad = ["abc", 1 + 0j, {"a": 1}, np.full(arr.shape, math.nan), np.full(arr.shape, "1.0"),
           np.full(arr.shape, 1 + 1j), np.full(arr.shape, True), np.zeros(arr.shape + (2,)), np.zeros((7, 5, 3)),
           [[1.0, 2.0], [3.0]]]
    if arr.ndim:
        flat = arr.reshape(-1).copy()
        flat[0] = math.inf
        bad.append(flat.reshape(arr.shape))
    if not optional:
        bad.append(None)
    return bad


def maybe_bad(kind: str, optional: bool, default) -> list:
    """Values that may or may not be in the documented range: refused with the field named, or finite."""
    if kind == "float":
        return [math.inf, -math.inf, 1e308, -1e308, 5e-324, 1e-300, 1e-12, 0.0, -1.0, 1e16, -1e-300, 1e6]
    if kind == "int":
        return [0, -1, 10**12, 2**63, np.int64(1), 1]
    if kind in ("bool", "str"):
        return []
    if default is None:
        return []
    try:
        arr = np.asarray(default, dtype=float)
    except (TypeError, ValueError):
        return []
    with np.errstate(over="ignore"):
        return [arr * 1e308, arr * 1e-300, np.zeros_like(arr), arr * 1e16, -arr, arr * 1e6]


def short_episode(env) -> None:
    """A few seeded steps with sampled actions; observations and rewards must be finite."""
    observations, _ = env.reset(seed=0)
    for o in observations.values():
        assert np.all(np.isfinite(o)), "non-finite observation after reset"
    space = env.action_space(env.possible_agents[0])
    space.seed(0)
    for _ in range(STEPS):
        if not env.agents:
            break
        observations, rewards, *_ = env.step({a: space.sample() for a in env.agents})
        for o in observations.values():
            assert np.all(np.isfinite(o)), "non-finite observation"
        assert all(np.isfinite(r) for r in rewards.values()), "non-finite reward"


# --- targets ---------------------------------------------------------------------------------------
def presets() -> list[str]:
    return [n for n in coloc_env.SCENARIOS if n != "mrclam_relay" or HAVE_MRCLAM]


CHEAP_WORLDS = ("circles", "drift", "target_cv", "gps_denied", "nlos_orbit", "mrclam", "mrclam_slices")
CHEAP_BACKENDS = ("dead_reckoning", "kalman", "centralized_lmmse", "ukf_ccl", "ukf_dcl", "bandwidth_fusion",
                  "prediction_compensation", "range_ls", "dfir", "delay_kalman", "afge", "ukf_se2", "dnbp")
CHEAP_NETWORKS = ("ideal", "broadcast", "relay", "bernoulli_delay", "random_delay", "bandwidth", "gilbert_elliott",
                  "contention")


def partners(kind: str, name: str) -> dict[str, str]:
    """A compatible (world, network, backend) containing ``name`` as its ``kind``, cheapest partners first."""
    def cost(row):
        return (CHEAP_WORLDS.index(row["world"]), CHEAP_BACKENDS.index(row["backend"]),
                CHEAP_NETWORKS.index(row["network"]))
    rows = [r for r in coloc_env.compatibility() if r["ok"] and r[kind] == name
            and (HAVE_MRCLAM or r["world"] not in RECORDED_WORLDS)]
    if not rows:
        return {}
    row = min(rows, key=cost)
    return {"world": row["world"], "network": row["network"], "backend": row["backend"]}


def parts() -> list[tuple[str, str]]:
    out = []
    for registry in (WORLDS, NETWORKS, BACKENDS):
        for name in registry:
            if partners(registry.kind, name):
                out.append((registry.kind, name))
    return out


def make_preset(name: str, field: str, value):
    config = {k: v for k, v in CHEAP_PRESET.get(name, {}).items() if k != field}
    return coloc_env.parallel_env(name, **config, **{field: value})


def make_part(kind: str, name: str, field: str, value):
    trio = partners(kind, name)
    specs = {}
    for k in ("world", "network", "backend"):
        cheap = {f: v for f, v in CHEAP_PART.get(trio[k], {}).items() if not (k == kind and f == field)}
        specs[k] = {"name": trio[k], **cheap}
    specs[kind][field] = value
    return coloc_env.parallel_env(coloc_env.compose(**specs))


def config_class(target) -> type:
    if target[0] == "preset":
        return coloc_env.scenario_class(target[1]).Config
    return {"world": WORLDS, "network": NETWORKS, "backend": BACKENDS}[target[0]][target[1]]


def build(target, field, value):
    if target[0] == "preset":
        return make_preset(target[1], field, value)
    return make_part(target[0], target[1], field, value)


def names_field(message: str, field: str) -> bool:
    return re.search(rf"(^|[^A-Za-z0-9_]){re.escape(field)}([^A-Za-z0-9_]|$)", message) is not None


def classify(target, field, value, must_refuse: bool) -> str:
    """"" when the promise holds; otherwise what went wrong (a defect)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            env = build(target, field, value)
            if must_refuse:
                return f"accepted {value!r}"
            short_episode(env)
    except ValueError as exc:
        if not names_field(str(exc), field):
            return f"ValueError without the field: {exc}"
        return ""
    except AssertionError as exc:
        return f"accepted {value!r}, then {exc}"
    except Exception as exc:  # noqa: BLE001 - any other exception is the defect under test
        return f"{type(exc).__name__}: {exc}"
    return ""


def targets() -> list[tuple[str, str]]:
    return [("preset", n) for n in presets()] + parts()


def entry_cases(default) -> st.SearchStrategy | None:
    """(one entry of ``default`` set to a hostile value, must_refuse): NaN and ±inf must be refused; ±1e308
    may be allowed by a field's interval (then the episode must stay finite)."""
    if default is None:
        return None
    try:
        arr = np.asarray(default, dtype=float)
    except (TypeError, ValueError):
        return None
    if arr.ndim == 0 or arr.size == 0:
        return None

    def put(index_value):
        index, (value, must) = index_value
        out = arr.copy().reshape(-1)
        out[index % out.size] = value
        return out.reshape(arr.shape), must

    hostile = st.sampled_from([(math.nan, True), (math.inf, True), (-math.inf, True), (1e308, False),
                               (-1e308, False)])
    return st.tuples(st.integers(0, arr.size - 1), hostile).map(put)


def case_strategy(target, slow: bool):
    """(field, value, must_refuse) for one target."""
    fields = fields_of(config_class(target))
    if not fields:
        return None
    choices = []
    for name, kind, optional, default in fields:
        bad = always_bad(kind, optional, default)
        maybe = maybe_bad(kind, optional, default)
        strategies = [st.tuples(st.just(name), st.sampled_from(bad), st.just(True))]
        entries = entry_cases(default) if kind == "array" else None
        if entries is not None:
            strategies.append(entries.map(lambda case, name=name: (name, *case)))
        if maybe:
            strategies.append(st.tuples(st.just(name), st.sampled_from(maybe), st.just(False)))
        if slow and kind == "float":
            strategies.append(st.tuples(st.just(name), st.floats(allow_nan=False), st.just(False)))
            strategies.append(st.tuples(st.just(name), st.text(max_size=4) | st.booleans(), st.just(True)))
        if slow and kind == "int":
            strategies.append(st.tuples(st.just(name), st.integers(-10**6, 10**6), st.just(False)))
        choices.append(st.one_of(strategies))
    return st.one_of(choices)


TARGETS = targets()


@pytest.mark.parametrize("target", [t for t in TARGETS if fields_of(config_class(t))], ids="/".join)
def test_a_bad_value_is_refused_with_the_field_named_or_runs_finitely(target):
    strategy = case_strategy(target, slow=PROFILE == "slow")

    @settings(settings.get_profile(PROFILE))
    @given(strategy)
    def check(case):
        field, value, must_refuse = case
        defect = classify(target, field, value, must_refuse)
        assert not defect, f"{'/'.join(target)}.{field}={value!r}: {defect}"

    check()


@pytest.mark.parametrize("value", [True, "1.0", None, 1 + 0j])
def test_the_issue_cases_name_the_field_and_the_range(value):
    with pytest.raises(ValueError, match=r"speed must be a number in \(0.0, 10000.0\], got"):
        coloc_env.parallel_env("relay_ukf", speed=value)


def test_derived_values_come_after_validation():
    with pytest.raises(ValueError, match="d0"):
        coloc_env.parallel_env("nlos_horizon", d0=None)
    with pytest.raises(ValueError, match="drift"):
        coloc_env.parallel_env("bandwidth_fusion", drift="abc")
    with pytest.raises(ValueError, match="delay_probs"):
        coloc_env.parallel_env("nlos_horizon", delay_probs=1.0)
    with pytest.raises(ValueError, match="component_cost"):
        coloc_env.parallel_env("bandwidth_fusion", component_cost="1.0")


def test_a_degree_field_reports_its_range_in_degrees():
    with pytest.raises(ValueError, match=r"sigma_theta_deg must be in \[1e-06, 180.0\], got 200"):
        coloc_env.parallel_env("nlos_horizon", sigma_theta_deg=200)
    with pytest.raises(ValueError, match=r"sigma_theta_deg must be in \[1e-06, 180.0\], got 200"):
        coloc_env.compose(world={"name": "nlos_orbit", "sigma_theta_deg": 200}, network="random_delay",
                          backend="afge")


@pytest.mark.parametrize("name, field, value", [
    ("relay_ukf", "centres", ((1e308, 0.0), (100.0, 0.0), (0.0, 100.0), (100.0, 100.0))),
    ("relay_ukf", "start_angles", (0.0, 1.0, 2.0, -1e300)),
    ("gps_denied_nbp", "nominal_velocity", (20.0, 1e308)),
    ("nlos_horizon", "prior_std", (50.0, 50.0, 1e308, 5.0)),
    ("nlos_horizon", "orbit_radius", (150.0, 1e308)),
    ("nlos_horizon", "orbit_wobble_rate", (-1.0, 0.01)),
])
def test_a_huge_entry_of_an_array_field_is_refused_naming_the_field(name, field, value):
    with pytest.raises(ValueError, match=rf"^(?:{name}: )?{field} entries must be in [\[(]"):
        coloc_env.parallel_env(name, **{field: value})


@pytest.mark.parametrize("world, field, value", [
    ("circles", "centres", ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (2.0, 2.0), (3.0, -1e7))),
    ("gps_denied", "nominal_velocity", (-1e5, 0.0)),
    ("nlos_orbit", "prior_std", (50.0, 0.0, 5.0, 5.0)),
    ("nlos_orbit", "turn_rates_deg", (3.0, -3.0, 3.0, 1e5)),
])
def test_a_part_refuses_an_entry_outside_its_range(world, field, value):
    with pytest.raises(ValueError, match=rf"^world.{field} entries must be in "):
        coloc_env.compose(world={"name": world, field: value}, network="ideal", backend="dead_reckoning")


def test_a_part_given_as_a_dict_refuses_a_scalar_where_an_array_belongs():
    with pytest.raises(ValueError, match=r"^network.delay_probs must be a 1-d array"):
        coloc_env.compose(world="nlos_orbit", network={"name": "random_delay", "delay_probs": 1},
                          backend="dead_reckoning")


def _validated(target, field, value):
    """The config of ``target`` with ``field=value``, validated (no env built: no data read)."""
    from coloc_env.config import build_config
    from coloc_env.parts import make_config
    cls = config_class(target)
    # the data, and the noise model a field may need (MRCLAM's measurement_inflation=False: "calibrated")
    kept = ("data", "noise_model")
    if target[0] == "preset":
        return build_config(cls, {**{k: v for k, v in CHEAP_PRESET.get(target[1], {}).items() if k in kept},
                                  field: value})
    return make_config(cls, {**{k: v for k, v in CHEAP_PART.get(target[1], {}).items() if k == "noise_model"},
                             field: value}, target[0])


BOOL_FIELDS = [(t, name) for t in TARGETS for name, kind, _, _ in fields_of(config_class(t)) if kind == "bool"]


@pytest.mark.parametrize("target, field", BOOL_FIELDS, ids=lambda v: "/".join(v) if isinstance(v, tuple) else v)
@pytest.mark.parametrize("value", [np.bool_(True), np.bool_(False)])
def test_every_boolean_field_takes_numpy_booleans(target, field, value):
    config = _validated(target, field, value)
    assert bool(getattr(config, field)) is bool(value)


def test_an_error_names_the_field_the_user_wrote():
    with pytest.raises(ValueError, match=r"^bandwidth_fusion: measurement_noise must be \(m, m\) with m = 1, the "
                                         r"rows of measurement"):
        coloc_env.parallel_env("bandwidth_fusion", measurement=((1.0, 0.0, 0.0),))
    with pytest.raises(ValueError, match=r"world.measurement_noise .* the rows of world.measurement"):
        coloc_env.compose(world={"name": "drift", "measurement": ((1.0, 0.0, 0.0),)}, network="ideal",
                          backend="kalman")
    with pytest.raises(ValueError, match=r"^nlos_horizon: turn_windows must have shape \(3, 2\), one \[start, end\) "
                                         r"per entry of turn_rates_deg"):
        coloc_env.parallel_env("nlos_horizon", turn_rates_deg=(1.0, 2.0, 3.0))
    with pytest.raises(ValueError, match=r"^world.turn_windows .* per entry of world.turn_rates_deg"):
        coloc_env.compose(world={"name": "nlos_orbit", "turn_rates_deg": (1.0, 2.0, 3.0)}, network="ideal",
                          backend="dead_reckoning")
    with pytest.raises(ValueError, match=r"turn_rate must be in \[1e-06, pi/dt = "):
        coloc_env.parallel_env("relay_ukf", dt=3600.0)


def count_all() -> tuple[int, list[str]]:
    """Every fixed case of every target: (cases tried, defects)."""
    tried, defects = 0, []
    for target in TARGETS:
        for name, kind, optional, default in fields_of(config_class(target)):
            for must, values in ((True, always_bad(kind, optional, default)), (False, maybe_bad(kind, optional,
                                                                                                   default))):
                for value in values:
                    tried += 1
                    defect = classify(target, name, value, must)
                    if defect:
                        defects.append(" ".join(f"{'/'.join(target)}.{name}={value!r}: {defect}".split())[:300])
            if kind == "array" and entry_cases(default) is not None:
                arr = np.asarray(default, dtype=float)
                for index in range(arr.size):
                    for hostile, must in ((math.nan, True), (math.inf, True), (1e308, False), (-1e308, False)):
                        value = arr.copy().reshape(-1)
                        value[index] = hostile
                        value = value.reshape(arr.shape)
                        tried += 1
                        defect = classify(target, name, value, must)
                        if defect:
                            defects.append(" ".join(f"{'/'.join(target)}.{name}[{index}]={hostile!r}: "
                                                    f"{defect}".split())[:300])
    return tried, defects


if __name__ == "__main__":
    n, found = count_all()
    print("\n".join(found))
    print(f"config cases tried: {n}, defects: {len(found)}")
