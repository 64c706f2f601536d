"""Pinned numbers: what every preset and a few reproductions compute on seeded runs, through the public API.

A change that moves the code between parts (worlds, networks, backends, the presets' bindings) must leave
these numbers as they are; each pin below says what its stream is where that is not obvious:

* ``test_seeded_rollout``: per scenario, ``parallel_env(name, **OVERRIDES[name])`` reset with
  seed 3 and played for at most 25 steps (or until the episode ends) by ``paper`` and by
  ``random`` (both ``make_policy(..., seed=0)``); pinned are the number of steps, the sum of all
  rewards, the sum over steps and agents of ``infos[a]["position_error"]`` (``"error"`` where a preset
  reports no position error), the sum of ``infos[a]["trace"]`` and the sum of the first agent's final observation.
* ``test_vector_env``: per scenario, ``vector_env(name, num_envs=3, seed=5, **OVERRIDES[name])``
  reset and stepped 10 times with actions drawn, one per sub-env and step, from its
  ``action_space`` seeded with ``action_space.seed(0)``; pinned are the sum of the rewards and
  of the final observation.
* ``test_reproduction``: a few numbers of the paper reproductions (``train/reproduce/``),
  from their own public functions on small run counts with fixed seeds.

Bit-identity pins: every pin except the three marked ``deterministic`` in
:data:`REPRODUCTION` is a pin of a random stream (the rollouts, the vector env and the seeded
Monte Carlo reproductions). They hold only while every generator is seeded and consumed exactly
as now: a change in what is drawn, in which order or from which generator moves them by far
more than the tolerance. The tolerance (``rel=1e-9, abs=1e-12``) only absorbs floating-point
reassociation (a sum or a matmul done in another order or batch), not a different draw. The
three ``deterministic`` pins (zhao2020's exact and greedy J_50, fu2017's covariance traces) use
no random numbers at all.

A change that alters any of these values must say why in its commit message. A deliberate
change to a random stream (or to a model) gets a new pin together with its reason: run
``.venv/bin/python -m tests.test_pinned_numbers`` to print the current values as the literals
below. mrclam_relay needs the MRCLAM dataset 6 (``../shared/data/mrclam/MRCLAM_Dataset6`` next
to the repository, as ``tests/coloc_env/test_mrclam_relay.py`` finds it); its cases skip
without it.

Notes: the ``paper`` policy of relay_ukf draws its random partners from its own generator, so
it is built with ``seed=0`` here (``make_policy("paper", env)`` without a seed would draw
fresh entropy and give a different rollout every run). Observation sums are taken in float64
of the float32 observations, rewards likewise.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

import agents
import coloc_env
from coloc_env.config import build_config

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
from tests.conftest import MRCLAM_DATASET6 as DATASET6  # noqa: E402
from tests.conftest import MRCLAM_SKIP_REASON  # noqa: E402

REL, ABS = 1e-9, 1e-12

RESET_SEED = 3
MAX_STEPS = 25
POLICY_SEED = 0
VEC_COPIES, VEC_SEED, VEC_STEPS, VEC_ACTION_SEED = 3, 5, 10, 0

# small configs where a default episode is slow; the same for the rollout and the vector env
OVERRIDES = {
    "bandwidth_fusion": {},
    "lossy_fusion": {},
    "relay_ukf": {"horizon": 60},
    "gps_denied_nbp": {"num_particles": 50, "horizon": 10},
    "nlos_horizon": {"horizon": 60},
    "mrclam_relay": {"data": DATASET6, "window_steps": 30},
    "contention_localization": {},
}


def _needs_data(name: str) -> None:
    if name == "mrclam_relay" and not os.path.isdir(DATASET6):
        pytest.skip(MRCLAM_SKIP_REASON)


def _config(name: str, **overrides):
    return build_config(coloc_env.scenario_class(name).Config, overrides)


# --- what is computed --------------------------------------------------------------------------
def seeded_rollout(name: str, policy_name: str, **config) -> dict:
    env = coloc_env.parallel_env(name, **OVERRIDES[name], **config)
    policy = agents.make_policy(policy_name, env, seed=POLICY_SEED)
    first = env.possible_agents[0]
    observations, _ = env.reset(seed=RESET_SEED)
    steps, reward, error, trace = 0, 0.0, 0.0, None
    while env.agents and steps < MAX_STEPS:
        observations, rewards, _, _, infos = env.step(policy.act(observations))
        steps += 1
        for agent in env.possible_agents:
            if agent in rewards:
                reward += float(rewards[agent])
            if agent in infos:
                info = infos[agent]
                error += float(info["position_error"] if "position_error" in info else info["error"])
                if "trace" in info:
                    trace = (trace or 0.0) + float(info["trace"])
    obs_sum = float(np.sum(np.asarray(observations[first], dtype=np.float64)))
    return {"steps": steps, "reward": reward, "error": error, "trace": trace, "obs_sum": obs_sum}


def vector_rollout(name: str, **config) -> dict:
    venv = coloc_env.vector_env(name, num_envs=VEC_COPIES, seed=VEC_SEED, **OVERRIDES[name], **config)
    venv.action_space.seed(VEC_ACTION_SEED)
    observation = venv.reset()
    reward = 0.0
    for _ in range(VEC_STEPS):
        actions = np.stack([venv.action_space.sample() for _ in range(venv.num_envs)])
        observation, rewards, _, _ = venv.step(actions)
        reward += float(np.sum(np.asarray(rewards, dtype=np.float64)))
    venv.close()
    return {"reward": reward, "obs_sum": float(np.sum(np.asarray(observation, dtype=np.float64)))}


def _zhao2020_exact_j50(which: int) -> float:
    import estimators.bandwidth_fusion as bf
    from coloc_env.scenarios.bandwidth_fusion import paper_selection, paper_weights

    config = _config("bandwidth_fusion")
    curves = bf.expected_cost(config.fusion_model(), np.asarray(config.initial_cov, float), paper_selection("T1"),
                              paper_weights("P1"), config.horizon)
    return float(curves[which].sum())


def _zhao2020_greedy_j50() -> float:
    from train.reproduce import zhao2020

    return float(zhao2020.greedy_exact_curve(_config("bandwidth_fusion")).sum())


def _zhao2020_paper_policy_costs() -> float:
    from train.reproduce import zhao2020

    return float(zhao2020.paper_policy_costs([0, 1, 2, 3], _config("bandwidth_fusion")).sum())


def _fu2017_block(key: str, name: str) -> float:
    from train.reproduce import fu2017

    block = fu2017.monte_carlo_block(2, 5, 7, 0, _config("lossy_fusion"))  # L = 2, 5 runs, seed 7, block 0
    return float(np.sum(block[key][name])) if key == "own" else float(np.mean(block[key][name]))


def _wang2019_block(estimator: str) -> float:
    from train.reproduce import wang2019

    block = wang2019.monte_carlo_block(0, 2, 0, _config("relay_ukf", horizon=100))  # block 0, 2 runs, seed 0
    return float(block["per_run"][wang2019.ESTIMATORS.index(estimator)].mean())


def _wan2014_paper_policy_costs() -> float:
    from train.reproduce import wan2014

    return float(wan2014.paper_policy_costs([0, 1], _config("gps_denied_nbp", horizon=10, num_particles=50)).sum())


def _wan2014_point_dnbp() -> float:
    from train.reproduce import wan2014

    base = {"num_agents": 6, "horizon": 4, "num_particles": 30, "num_normal": 3}
    return float(wan2014.evaluate_point({}, base, 2, 0)["dnbp"]["err_fault"])  # 2 runs, seed 0


def _gao2016_paper_policy_costs() -> float:
    from train.reproduce import gao2016

    return float(gao2016.paper_policy_costs([0, 1], _config("nlos_horizon", horizon=300, num_agents=2)).sum())


# id -> (function, kind)
REPRODUCTION = {
    "zhao2020_exact_J50_T1P1": (lambda: _zhao2020_exact_j50(0), "deterministic"),
    "zhao2020_greedy_exact_J50": (_zhao2020_greedy_j50, "deterministic"),
    "zhao2020_paper_policy_costs_seeds0-3_sum": (_zhao2020_paper_policy_costs, "random stream"),
    "fu2017_centralized_own_trace_sum_L2": (lambda: _fu2017_block("own", "centralized"), "deterministic"),
    "fu2017_distributed_mse_L2_5runs_seed7": (lambda: _fu2017_block("errors", "distributed"), "random stream"),
    "wang2019_DCL_error_2runs_seed0_K100": (lambda: _wang2019_block("DCL"), "random stream"),
    "wang2019_IL_error_2runs_seed0_K100": (lambda: _wang2019_block("IL"), "random stream"),
    "wan2014_paper_policy_costs_seeds0-1_sum": (_wan2014_paper_policy_costs, "random stream"),
    "wan2014_evaluate_point_dnbp_err_fault": (_wan2014_point_dnbp, "random stream"),
    "gao2016_paper_policy_costs_seeds0-1_sum": (_gao2016_paper_policy_costs, "random stream"),
}

# --- the pins ---------------------------------------------------------------------------------
PINNED_ROLLOUTS = {
    # drift / bandwidth / bandwidth_fusion with the preset's action codec: the world draws the episode from the
    # episode's generator, the bandwidth network draws nothing. "error" sums position_error (m), "trace" sums
    # tr Sigma_i (m^2).
    "bandwidth_fusion": {
        "paper": {"steps": 25, "reward": -17.268696353831736, "error": 39.658217579576494,
                  "trace": 14.7804029124928, "obs_sum": 1.0942295528948307},
        "random": {"steps": 25, "reward": -21.09272043628452, "error": 42.829322103017724,
                   "trace": 17.675288143042007, "obs_sum": -5.0589263513684273},
    },
    # target_cv / bernoulli_delay / prediction_compensation: the truth and measurements are the world's draws,
    # the link outcomes the bernoulli_delay network's counter-based draws (from its own child generator).
    "lossy_fusion": {
        "paper": {"steps": 25, "reward": -3249.2816163220373, "error": 356.01476929565069,
                  "trace": 748.00516142952438, "obs_sum": 277.7098069190979},
        "random": {"steps": 25, "reward": -6599.0181326089833, "error": 421.04619878503433,
                   "trace": 1220.6779506897374, "obs_sum": 276.60244297981262},
    },
    "relay_ukf": {
        "paper": {"steps": 25, "reward": -54.656640250591714, "error": 54.656640250591735,
                  "trace": 64.637742502185972, "obs_sum": 4.0415788190439343},
        "random": {"steps": 25, "reward": -53.720614082882371, "error": 53.720614082882378,
                   "trace": 71.076467009166166, "obs_sum": 4.335314329713583},
    },
    # gps_denied / broadcast / dnbp; the action space is MultiDiscrete([2] * n_iter), which the random policy
    # and action_space.sample() draw from; "trace" sums the belief's trace.
    "gps_denied_nbp": {
        "paper": {"steps": 10, "reward": -614.84513619304971, "error": 524.69452478183109,
                  "trace": 7310.4069644574474, "obs_sum": 10.991077452898026},
        "random": {"steps": 10, "reward": -632.49680010031682, "error": 543.25190951594016,
                   "trace": 14765.286277102658, "obs_sum": 13.202908396720886},
    },
    # nlos_orbit / random_delay / afge, receiving before deciding: the truth, readings and prior are the world's
    # draws, the packet delays the random_delay network's counter-based draws (from its own child generator);
    # the observation's entries are clipped to the backend's finite bounds.
    "nlos_horizon": {
        "paper": {"steps": 25, "reward": -12710.078499146035, "error": 383.99771754895926,
                  "trace": 21416.532797315038, "obs_sum": 18.500539391488928},
        "random": {"steps": 25, "reward": -15415.544588529767, "error": 554.20384274637775,
                   "trace": 23771.313393904766, "obs_sum": 22.448304407298565},
    },
    # its default noise model, "likelihood" (the calibrated model's numbers: PINNED_MRCLAM_CALIBRATED)
    "mrclam_relay": {
        "paper": {"steps": 25, "reward": -2.0469074545795491, "error": 2.0469074545795496,
                  "trace": 0.12929362583600221, "obs_sum": -3.2232460975646973},
        "random": {"steps": 25, "reward": -1.8835560719774556, "error": 1.8835560719774558,
                   "trace": 0.1338183160661747, "obs_sum": -2.8186411875922204},
    },
    # gps_denied / contention / ukf_ccl; "paper" is round_robin; the medium has no draws (the decisions decide)
    "contention_localization": {
        "paper": {"steps": 25, "reward": -1870.9519567919222, "error": 1870.9519567919222,
                  "trace": 106033.93463019808, "obs_sum": 36.651711821556091},
        "random": {"steps": 25, "reward": -3977.6768720289192, "error": 3977.6768720289192,
                   "trace": 200451.9321992613, "obs_sum": 38.605718970298767},
    },
}

PINNED_VECTOR = {
    "bandwidth_fusion": {"reward": -21.77453984785825, "obs_sum": -67.099833246320486},
    "lossy_fusion": {"reward": -36945.847672462463, "obs_sum": 749.73463612422347},
    "relay_ukf": {"reward": -62.415704756975174, "obs_sum": 44.729118637206284},
    "gps_denied_nbp": {"reward": -2156.5431070327759, "obs_sum": 213.53660087287426},
    "nlos_horizon": {"reward": -156932.33562774584, "obs_sum": 288.53796964552021},
    "mrclam_relay": {"reward": -0.74640592327341437, "obs_sum": -62.069581491509609},
    "contention_localization": {"reward": -2783.2435924112797, "obs_sum": 1125.2625467926264},
}

# mrclam_relay with the noise model it defaulted to before "likelihood" (coloc/mrclam_relay-v1's): the same
# numbers as then, bit for bit up to REL
PINNED_MRCLAM_CALIBRATED = {
    "paper": {"steps": 25, "reward": -1.4354103416799124, "error": 1.4354103416799122,
              "trace": 0.057701297776787661, "obs_sum": -4.1268091201782227},
    "random": {"steps": 25, "reward": -1.3734166102313323, "error": 1.3734166102313321,
               "trace": 0.05865494495909393, "obs_sum": -3.783578165777726},
    "vector": {"reward": -0.73232610011473298, "obs_sum": -73.095227561937847},
}

PINNED_REPRODUCTION = {
    "zhao2020_exact_J50_T1P1": 30.564674250432525,
    "zhao2020_greedy_exact_J50": 27.972655455118463,
    "zhao2020_paper_policy_costs_seeds0-3_sum": 107.08535205212901,
    "fu2017_centralized_own_trace_sum_L2": 2038.8361504805816,
    # run r of the block is the lossy_fusion world and network reset with default_rng([7, 2, r]) (the link
    # outcomes are the network's counter-based draws), as the reproduction drives the compositions
    "fu2017_distributed_mse_L2_5runs_seed7": 137.09716962026596,
    "wang2019_DCL_error_2runs_seed0_K100": 1.2267641113962275,
    "wang2019_IL_error_2runs_seed0_K100": 1.5412870579730336,
    "wan2014_paper_policy_costs_seeds0-1_sum": 9.0799336811929816,
    "wan2014_evaluate_point_dnbp_err_fault": 6.4651841215442927,
    "gao2016_paper_policy_costs_seeds0-1_sum": 9.3517665805268457,
}


# --- the tests ---------------------------------------------------------------------------------
def _assert_pinned(actual: dict, pinned: dict) -> None:
    assert set(actual) == set(pinned)
    for key, value in pinned.items():
        if value is None or isinstance(value, int):
            assert actual[key] == value, key
        else:
            assert actual[key] == pytest.approx(value, rel=REL, abs=ABS), key


@pytest.mark.parametrize("name", coloc_env.SCENARIOS, ids=coloc_env.SCENARIOS)
def test_seeded_rollout(name):
    _needs_data(name)
    for policy_name in ("paper", "random"):
        _assert_pinned(seeded_rollout(name, policy_name), PINNED_ROLLOUTS[name][policy_name])


@pytest.mark.parametrize("name", coloc_env.SCENARIOS, ids=coloc_env.SCENARIOS)
def test_vector_env(name):
    _needs_data(name)
    _assert_pinned(vector_rollout(name), PINNED_VECTOR[name])


def test_mrclam_relay_with_the_calibrated_model_keeps_its_numbers():
    _needs_data("mrclam_relay")
    for policy_name in ("paper", "random"):
        _assert_pinned(seeded_rollout("mrclam_relay", policy_name, noise_model="calibrated"),
                       PINNED_MRCLAM_CALIBRATED[policy_name])
    _assert_pinned(vector_rollout("mrclam_relay", noise_model="calibrated"), PINNED_MRCLAM_CALIBRATED["vector"])


@pytest.mark.parametrize("case", list(REPRODUCTION), ids=list(REPRODUCTION))
def test_reproduction(case):
    function, _kind = REPRODUCTION[case]
    assert function() == pytest.approx(PINNED_REPRODUCTION[case], rel=REL, abs=ABS)


def test_every_scenario_is_pinned():
    assert set(PINNED_ROLLOUTS) == set(PINNED_VECTOR) == set(coloc_env.SCENARIOS) == set(OVERRIDES)
    assert set(PINNED_REPRODUCTION) == set(REPRODUCTION)


# --- re-pinning: print the current values as the literals above ----------------------------------
def _literal(value, indent: int = 0) -> str:
    """``value`` as a Python literal, floats with 17 significant digits, dicts wrapped at 120 columns."""
    if isinstance(value, float):
        return f"{value:.17g}"
    if isinstance(value, dict):
        lines, line = [], "{"
        for k, v in value.items():
            item = f'"{k}": {_literal(v)}, '
            if len(line) + len(item) + indent > 118:
                lines.append(line.rstrip())
                line = " " * (indent + 1)
            line += item
        return "\n".join([*lines, line[:-2] + "}"])
    return repr(value)


def _print_pins() -> None:
    have_data = os.path.isdir(DATASET6)
    print("PINNED_ROLLOUTS = {")
    for name in coloc_env.SCENARIOS:
        if name == "mrclam_relay" and not have_data:
            print(f"    # {name}: no data at {DATASET6}")
            continue
        print(f'    "{name}": {{')
        for policy_name in ("paper", "random"):
            head = f'        "{policy_name}": '
            print(f"{head}{_literal(seeded_rollout(name, policy_name), len(head))},")
        print("    },")
    print("}\n\nPINNED_VECTOR = {")
    for name in coloc_env.SCENARIOS:
        if name == "mrclam_relay" and not have_data:
            continue
        head = f'    "{name}": '
        print(f"{head}{_literal(vector_rollout(name), len(head))},")
    print("}\n\nPINNED_REPRODUCTION = {")
    for case, (function, _kind) in REPRODUCTION.items():
        print(f'    "{case}": {_literal(function())},')
    print("}")


if __name__ == "__main__":
    _print_pins()
