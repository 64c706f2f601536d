"""Long-run health of every backend that keeps a covariance: symmetric, positive semi-definite
and finite at every step of a long episode under random decisions.

Each case composes a cheap world / network pair the backend runs on, steps two seeded copies for
``STEPS`` steps (10^3 by default, 10^4 with ``-m slow``) with actions drawn from the action space
(so every decision a backend exposes, fusion weights and horizons included, is exercised off its
default), and checks after every step each covariance the backend reports: the per-agent position
blocks (``posterior_position_cov``), the estimated target state's (``posterior_state_cov``) and a
joint covariance where the backend keeps one (``cov``). Symmetry is checked relative to the matrix's
scale and the smallest eigenvalue against -1e-9 of the largest, so a covariance that drifts
indefinite by rounding over 10^4 steps fails here, not in a user's Cholesky.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re

import numpy as np
import pytest

import coloc_env
from coloc_env.scenarios.composed import ComposedScenario

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
from tests.conftest import MRCLAM_DATASET6 as DATASET6  # noqa: E402
from tests.conftest import MRCLAM_SKIP_REASON, RECORDED_WORLDS  # noqa: E402

# backend -> (world, network): cheap parts on which it runs
CASES = {
    "bandwidth_fusion": ("drift", "bandwidth"),
    "centralized_lmmse": ("target_cv", "bernoulli_delay"),
    "prediction_compensation": ("target_cv", "bernoulli_delay"),
    "kalman": ("target_cv", "bernoulli_delay"),
    "ukf_ccl": ("circles", "ideal"),
    "ukf_dcl": ("circles", "relay"),  # lossy hops: truncated chains and the consistent update
    "range_ls": ("gps_denied", {"name": "broadcast", "comm_range": 300.0}),
    "dnbp": ({"name": "gps_denied", "num_agents": 4}, {"name": "broadcast", "comm_range": 300.0}),
    "afge": ("nlos_orbit", "random_delay"),
    "dfir": ("nlos_orbit", "random_delay"),
    "delay_kalman": ("nlos_orbit", "random_delay"),
    "ukf_se2": ({"name": "mrclam", "data": DATASET6}, "relay"),
}
BACKEND_OPTIONS = {"dnbp": {"num_particles": 16, "num_iterations": 2, "initial_threshold": 2}}


def _covariances(backend) -> dict[str, np.ndarray]:
    found = {}
    for name in ("posterior_position_cov", "posterior_state_cov", "cov"):
        value = getattr(backend, name, None)
        if isinstance(value, np.ndarray) and value.ndim >= 3 and value.shape[-1] == value.shape[-2]:
            found[name] = value
    return found


def _check_health(name: str, cov: np.ndarray, step: int) -> None:
    assert np.all(np.isfinite(cov)), f"{name} not finite at step {step}"
    scale = np.maximum(np.abs(cov).max(axis=(-2, -1), keepdims=True), 1e-300)
    asym = np.abs(cov - np.swapaxes(cov, -1, -2)) / scale
    assert asym.max() <= 1e-9, f"{name} not symmetric at step {step}: relative asymmetry {asym.max():.3g}"
    eig = np.linalg.eigvalsh(0.5 * (cov + np.swapaxes(cov, -1, -2)))
    worst = (eig[..., 0] / np.maximum(eig[..., -1], 1e-300)).min()
    assert eig[..., 0].min() >= -1e-9 * np.abs(eig[..., -1]).max() - 1e-300, (
        f"{name} indefinite at step {step}: smallest / largest eigenvalue {worst:.3g}")


@pytest.mark.parametrize("steps", [1_000, pytest.param(10_000, marks=pytest.mark.slow)])
@pytest.mark.parametrize("backend", sorted(CASES))
def test_covariances_stay_symmetric_psd_and_finite_over_a_long_run(backend, steps):
    world, network = CASES[backend]
    if backend == "ukf_se2" and not os.path.isdir(DATASET6):
        pytest.skip(MRCLAM_SKIP_REASON)
    if backend == "ukf_se2":  # a window of the recorded run: its length is what the data allow
        steps = min(steps, 5_000)
    part = {"name": backend, **BACKEND_OPTIONS.get(backend, {})}
    _run_checked(coloc_env.compose(world=world, network=network, backend=part, horizon=steps), steps)


def _run_checked(spec, steps: int) -> None:
    backend = spec.backend.name
    scenario = ComposedScenario(spec, batch=2)
    scenario.reset(np.random.default_rng(17).spawn(2))
    space = scenario.action_space()
    space.seed(3)
    seen = set()
    for step in range(steps):
        actions = np.stack([np.stack([space.sample() for _ in range(scenario.num_agents)]) for _ in range(2)])
        scenario.step(actions)
        covariances = _covariances(scenario.backend)
        seen |= set(covariances)
        for name, cov in covariances.items():
            _check_health(f"{backend} {name}", cov, step)
        assert np.all(np.isfinite(scenario.reward())), f"{backend} reward not finite at step {step}"
    assert seen, f"{backend} reported no covariance"


def test_the_check_catches_a_covariance_that_goes_indefinite():
    """wang2019's own rule on truncated chains (truncation="paper") loses positive definiteness within a few
    hundred steps: the health check (or the backend's own clear error) must say so."""
    spec = coloc_env.compose(world={"name": "circles", "num_agents": 4, "num_anchors": 0},
                             network={"name": "relay", "loss_at_zero": 0.0, "max_hops": 1},
                             backend={"name": "ukf_dcl", "truncation": "paper"}, horizon=1_000)
    with pytest.warns(UserWarning, match="truncation='paper'"), \
            pytest.raises((AssertionError, ValueError), match="indefinite|positive definite"):
        _run_checked(spec, 1_000)


# --- every documented extreme -------------------------------------------------------------------------------
# Each numeric field of each preset and each part at its documented minimum and at its maximum, one at a time,
# plus every noise field of the target at its maximum together; each run from seeds 0 and 1 (the two copies of
# vector_env(seed=0)) with random actions (the action space's sample, seeded) for STRESS_STEPS steps (or the
# episode, if shorter), checking every covariance the backend reports (symmetric, PSD, finite), every estimate
# and every reward finite after each step. ``make test`` runs STRESS_STEPS = 30; ``make stress`` 1000
# (COLOC_STRESS_STEPS). An open end (0, ...] is run just inside it: low + 1e-6 max(1, |low|).
# The episode-length fields (horizon, window_steps) are not varied: they set how many steps run, not what a step
# computes, and their maxima (10^5..10^9 steps) would only pre-draw episodes far longer than any run here.
STRESS_STEPS = int(os.environ.get("COLOC_STRESS_STEPS", "30"))
# Ends whose cost grows with the value far beyond the rest (a particle filter at 5000 particles: ~20 s per step
# on one core) run COSTLY_STEPS steps under `make stress` and are left out of `make test`.
COSTLY = {("num_particles", "max")}
# Ends of a recorded world's calibration window that need a new likelihood fit of the MRCLAM noise model (minutes;
# the fits of the default window ship with the tests): `make stress` only.
NEW_FIT = {("mrclam", "calibration_s", "max"), ("mrclam", "dt", "min"), ("mrclam_relay", "calibration_s", "max"),
           ("mrclam_relay", "dt", "min")}
COSTLY_STEPS = 2
STRESS = os.environ.get("COLOC_STRESS") == "1"
# A documented end that a rule between two fields refuses with the other field's default runs with the other
# field moved to a value the rule allows (target name, field, end) -> the other fields (a part: per kind).
COMPANIONS = {
    ("bandwidth_fusion", "num_agents", "min"): {"budget": 2},
    ("bandwidth_fusion", "num_agents", "max"): {"budget": 30},
    ("bandwidth_fusion", "min_per_link", "max"): {"budget": 9},
    ("bandwidth_fusion", "max_per_link", "min"): {"min_per_link": 0, "budget": 0},
    ("lossy_fusion", "on_time_probability", "max"): {"late_probability": 0.0},
    ("lossy_fusion", "late_probability", "max"): {"on_time_probability": 0.0},
    ("relay_ukf", "dt", "max"): {"turn_rate": 1e-4},
    ("gps_denied_nbp", "num_agents", "min"): {"initial_threshold": 2},
    ("nlos_horizon", "num_neighbours", "min"): {"n_strongest": 1, "min_packets": 1},
    ("nlos_horizon", "p_nlos", "max"): {"p10": 0.0},
    ("nlos_horizon", "buffer_length", "min"): {"delay_probs": (0.9,)},
    ("nlos_horizon", "buffer_length", "max"): {"delay_probs": (0.9,) + (0.0,) * 998 + (0.1,), "window_min": 1000,
                                               "window_max": 1000, "group_size": 1, "window_centre": 1000},
    ("nlos_horizon", "window_min", "min"): {"buffer_length": 1, "delay_probs": (0.7, 0.2)},
    ("nlos_horizon", "window_min", "max"): {"group_size": 1, "window_centre": 30},
    ("nlos_horizon", "window_max", "min"): {"window_min": 2, "buffer_length": 1, "delay_probs": (0.7, 0.2),
                                            "group_size": 1, "window_centre": 2},
    ("circles", "num_agents", "min"): {"world": {"num_anchors": 2}},
    ("circles", "dt", "max"): {"world": {"turn_rate": 1e-4}},
    ("nlos_orbit", "p_nlos", "max"): {"world": {"p10": 0.0}},
    ("mrclam_slices", "slice_steps", "max"): {"world": {"horizon": 10}},
    ("bernoulli_delay", "on_time_probability", "max"): {"network": {"late_probability": 0.0}},
    ("bernoulli_delay", "late_probability", "max"): {"network": {"on_time_probability": 0.0}},
    ("random_delay", "buffer_length", "min"): {"network": {"delay_probs": (0.9,)}},
    ("random_delay", "buffer_length", "max"): {"network": {"delay_probs": (0.9,) + (0.0,) * 999 + (0.1,)}},
    ("afge", "n_strongest", "max"): {"world": {"num_neighbours": 32}},
    ("afge", "min_packets", "max"): {"world": {"num_neighbours": 32}},
    ("afge", "window_min", "max"): {"backend": {"group_size": 1, "window_centre": 30}},
    ("afge", "window_max", "min"): {"backend": {"window_min": 2, "group_size": 1, "window_centre": 2}},
    ("dfir", "n_strongest", "max"): {"world": {"num_neighbours": 32}},
    ("dfir", "min_packets", "max"): {"world": {"num_neighbours": 32}},
    ("delay_kalman", "n_strongest", "max"): {"world": {"num_neighbours": 32}},
    ("delay_kalman", "min_packets", "max"): {"world": {"num_neighbours": 32}},
}
NOT_VARIED = {"horizon", "window_steps", "data"}
NOISE = re.compile(r"noise|(^|_)std$|^sigma|_sigma|_var$|_sigma_")
HAVE_MRCLAM = os.path.isdir(DATASET6)


def _extremes(target) -> list[tuple[str, str, object]]:
    """(label, field, value) of each documented end of each numeric field of ``target``, and ("noise max",
    fields, values) for every noise field at its maximum together."""
    from tests.test_documented_ranges import config_class, documented, evaluate, field_kind, names_of, parse_interval

    cls = config_class(target)
    rows = documented(cls)
    names = names_of(target, cls)
    out, noise = [], {}
    for f in dataclasses.fields(cls):
        kind = field_kind(f)
        if kind not in ("int", "float") or f.name in NOT_VARIED:
            continue
        interval = parse_interval(rows.get(f.name, ""), kind)
        if interval is None:
            continue
        for end, text, is_open in (("min", interval.low, interval.low_open), ("max", interval.high,
                                                                                 interval.high_open)):
            value = evaluate(text, names)
            if value is None or not math.isfinite(value) and kind == "int":
                continue
            if is_open and math.isfinite(value):
                step = 1 if kind == "int" else 1e-6 * max(1.0, abs(value))
                value = value + step if end == "min" else value - step
            value = int(value) if kind == "int" else float(value)
            out.append((f"{f.name}={end}", f.name, value))
            if end == "max" and kind == "float" and NOISE.search(f.name) and not f.name.startswith("initial"):
                noise[f.name] = value
    if len(noise) > 1:
        out.append(("noise=max", tuple(noise), tuple(noise.values())))
    return out


def _stress_targets():
    from tests.test_documented_ranges import part_targets, preset_targets

    return [t for t in preset_targets() + part_targets()
            if HAVE_MRCLAM or not set(RECORDED_WORLDS) & {t[1], *_trio(t)}]


def _trio(target) -> tuple:
    from tests.test_bad_config_properties import partners

    return () if target[0] == "preset" else tuple(partners(*target).values())


def _stress_venv(target, fields: dict, companions: dict | None = None):
    """vector_env(seed=0, num_envs=2) of ``target`` with ``fields`` set (the rest at their defaults, a dnbp
    backend's particles kept cheap unless they are the field under test)."""
    from tests.test_bad_config_properties import partners

    cheap = {"num_particles": 40, "num_iterations": 2}
    if target[0] == "preset":
        config = {"data": DATASET6} if target[1] == "mrclam_relay" else {}
        if target[1] == "gps_denied_nbp":
            config.update({k: v for k, v in cheap.items() if k not in fields})
        config.update(companions or {})
        return coloc_env.vector_env(target[1], num_envs=2, seed=0, **config, **fields)
    trio = partners(*target)
    specs = {}
    for kind in ("world", "network", "backend"):
        spec = {"name": trio[kind]}
        if trio[kind] in RECORDED_WORLDS:
            spec["data"] = DATASET6
        if trio[kind] == "dnbp":
            spec.update({k: v for k, v in cheap.items() if not (kind == target[0] and k in fields)})
        spec.update((companions or {}).get(kind, {}))
        if kind == target[0]:
            spec.update(fields)
        specs[kind] = spec
    return coloc_env.vector_env(coloc_env.compose(**specs), num_envs=2, seed=0)


def _stress_cases():
    cases = []
    for target in _stress_targets():
        for label, field, value in _extremes(target):
            end = label.rsplit("=", 1)[1]
            case_id = f"{'/'.join(target)}:{label}"
            costly = (field, end) in COSTLY or (target[1], field, end) in NEW_FIT
            marks = [] if STRESS or not costly else [pytest.mark.skip(
                reason=f"{field} at its {end}: `make stress` only (COLOC_STRESS=1)")]
            cases.append(pytest.param(target, field, value, end, id=case_id, marks=marks))
    return cases


def _run_extreme(target, field, value, end: str, steps: int) -> None:
    fields = dict(zip(field, value, strict=True)) if isinstance(field, tuple) else {field: value}
    if (field, end) in COSTLY:
        steps = min(steps, COSTLY_STEPS)
    companions = COMPANIONS.get((target[1], field, end)) if isinstance(field, str) else None
    try:
        venv = _stress_venv(target, fields, companions)
    except ValueError as exc:  # an end refused with the defaults of another field (a rule between two fields)
        names = [f for f in fields if re.search(rf"\b{f}\b", str(exc))]
        assert names, f"refused without naming {list(fields)}: {exc}"
        pytest.skip(f"documented end refused with the other fields' defaults: {exc}")
    scenario = venv.scenario
    venv.reset()
    space = scenario.action_space()
    space.seed(5)
    name = "/".join(target)
    for step in range(min(steps, scenario.horizon)):
        actions = np.stack([np.stack([space.sample() for _ in range(scenario.num_agents)]) for _ in range(2)])
        with np.errstate(all="ignore"):
            scenario.step(actions)
        for cov_name, cov in _covariances(scenario.backend).items():
            _check_health(f"{name} {cov_name}", cov, step)
        info = scenario.info()
        estimate = info.get("estimated_position")
        assert estimate is None or np.all(np.isfinite(estimate)), f"{name}: estimate not finite at step {step}"
        assert np.all(np.isfinite(scenario.reward())), f"{name}: reward not finite at step {step}"


@pytest.mark.parametrize("target, field, value, end", _stress_cases())
def test_every_documented_extreme_stays_healthy(target, field, value, end):
    _run_extreme(target, field, value, end, STRESS_STEPS)
