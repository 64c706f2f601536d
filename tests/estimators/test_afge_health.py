"""AFGE and DFIR stay finite, symmetric and positive semi-definite at their documented extremes.

Two roots, each tested at the estimator level (both the numpy reference and the compiled kernels)
and through the env at the settings where they first showed:

* the information-form predict subtracted two nearly equal matrices where the process noise of
  one step dwarfs the fixes (``period = 1e4`` s: 1.5e7 m of position noise per step), and the
  rounding made Y indefinite; it is now formed in Joseph form (a sum of congruences);
* two observed stamps make Y invertible only in exact arithmetic: with ``sigma_db = 100`` a
  fix's range r_hat = d0 10^(eps / 10n) spans tens of decades, one stamp's information can be
  1e-20 of the other's, and the Schur complement of the inverse was exactly zero (a
  ``ZeroDivisionError`` in the compiled kernel); the inverse is now guarded and such a slot has no
  estimate (the output is the prediction).
"""

import numpy as np
import pytest

import agents
import coloc_env
import estimators.afge as af
import estimators.afge_kernels as afk
from coloc_env.scenarios.composed import ComposedScenario
from tests.test_covariance_health import _check_health, _covariances

COMPILED = [False, pytest.param(True, marks=pytest.mark.skipif(afk.compiled("buffer") is None,
                                                              reason="numba not installed"))]
NOISE_AT_MAXIMUM = {"accel_sigma": 1e3, "sigma_nav": 1e4, "sigma_db": 100.0, "sigma_theta_deg": 180.0,
                    "nlos_sigma_db": 100.0, "nlos_sigma_deg": 180.0}


def _anisotropic_fixes(rng, batch, range_var, cross_var):
    """Fused fixes (Y, y) with range variance ``range_var`` and cross-range ``cross_var``; bearings
    spread, but every third stamp nearly the same bearing (east)."""
    out = []
    for k in range(40):
        th = rng.uniform(0, 2 * np.pi, batch) if k % 3 else rng.uniform(0, 0.01, batch)
        c, s = np.cos(th), np.sin(th)
        rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
        R = rot @ np.diag([range_var, cross_var]) @ np.swapaxes(rot, -1, -2)
        Y = np.linalg.inv(R)
        Y = 0.5 * (Y + np.swapaxes(Y, -1, -2))
        y = (Y @ (1e3 * rng.standard_normal((batch, 2, 1))))[..., 0]
        out.append((Y, y))
    return out


def _assert_psd(P, valid, what):
    P = np.where(valid[..., None, None], P, np.eye(P.shape[-1]))
    assert np.all(np.isfinite(P)), f"{what} not finite"
    np.testing.assert_array_equal(P, np.swapaxes(P, -1, -2), err_msg=f"{what} not symmetric")
    eig = np.linalg.eigvalsh(P)
    ratio = eig[..., 0] / eig[..., -1]
    assert ratio.min() >= -1e-9, f"{what} indefinite: smallest / largest eigenvalue {ratio.min():.3g}"


@pytest.mark.parametrize("compiled", COMPILED)
@pytest.mark.parametrize("period, range_var, cross_var", [(1e4, 1e8, 1.0), (1e3, 1e8, 1.0), (1e4, 1e13, 1e2)])
def test_the_stack_stays_psd_when_one_step_of_process_noise_dwarfs_the_fixes(compiled, period, range_var,
                                                                            cross_var):
    """Every horizon's information and position covariance stay PSD over 40 stamps (D = 0) at a long
    period with anisotropic fixes (the short Woodbury form went indefinite here within a few stamps)."""
    rng = np.random.default_rng(3)
    motion, batch = af.MotionModel(period, 0.3), 64
    stack = af.empty_stack((batch,), 30)
    for k, (Y, y) in enumerate(_anisotropic_fixes(rng, batch, range_var, cross_var)):
        stack, x, P, valid = af.buffer_estimates(motion, stack, k, Y[:, None], y[:, None], np.ones((batch, 1), bool),
                                                 compiled=compiled)
        _assert_psd(P[..., :2, :2], valid, f"P at stamp {k}")
        _assert_psd(stack.info[:, 2:], np.ones(stack.info.shape[:2], bool)[:, 2:], f"Y at stamp {k}")
    assert valid.mean() > 0.9  # the guard is a guard: it does not discard the estimates themselves


@pytest.mark.parametrize("compiled", COMPILED)
def test_a_horizon_whose_second_stamp_carries_no_information_has_no_estimate(compiled):
    """Two observed stamps, the second with 1e-20 of the first's information (sigma_db = 100 dB):
    Y is singular to rounding, the slot is invalid, nothing divides by zero."""
    motion = af.MotionModel()
    stack = af.empty_stack((2,), 3)
    strong = np.array([[0.17, 0.1155], [0.1155, 0.0789]])
    Ys = [np.stack([strong, strong]), np.stack([1e-20 * strong, strong])]
    for k, Y in enumerate(Ys):
        y = (Y @ np.array([100.0, 50.0]))
        stack, x, P, valid = af.buffer_estimates(motion, stack, k, Y[:, None], y[:, None], np.ones((2, 1), bool),
                                                 compiled=compiled)
    assert not valid[0, 1] and valid[1, 1]  # horizon N = 2 of copy 0 has no estimate, copy 1's has
    assert np.all(np.isfinite(x)) and np.all(np.isfinite(P))
    np.testing.assert_allclose(x[1, 1, :2], [100.0, 50.0], rtol=1e-9)


def _run_preset(config: dict, policy: str, seed: int, steps: int) -> None:
    env = coloc_env.parallel_env("nlos_horizon", **config)
    pol = agents.make_policy(policy, env, seed=seed) if policy == "random" else agents.make_policy(policy, env)
    _play_healthy(env, pol, seed, steps)


def _run_composition(world: dict, network, backend: str, seed: int, steps: int) -> None:
    env = coloc_env.parallel_env(coloc_env.compose(world=world, network=network, backend=backend))
    _play_healthy(env, agents.make_policy("random", env, seed=seed), seed, steps)


def _play_healthy(env, policy, seed: int, steps: int) -> None:
    """``steps`` steps from ``reset(seed)``: after each, every covariance of the backend healthy, rewards finite."""
    obs, _ = env.reset(seed=seed)
    for step in range(steps):
        obs, rewards, *_ = env.step(policy.act(obs))
        for name, cov in _covariances(env.unwrapped.scenario.backend).items():
            _check_health(name, cov, step)
        assert all(np.isfinite(r) for r in rewards.values()), f"reward not finite at step {step}"


@pytest.mark.parametrize("config, policy, seed, steps", [
    ({"sigma_db": 100.0}, "random", 0, 12),
    ({"sigma_db": 100.0}, "paper", 2, 20),
    ({"period": 1e4}, "random", 0, 12),
    (NOISE_AT_MAXIMUM, "random", 0, 12),
], ids=["sigma_db-100-random", "sigma_db-100-paper", "period-1e4-random", "noise-max-random"])
def test_nlos_horizon_stays_healthy_at_its_extremes(config, policy, seed, steps):
    _run_preset(config, policy, seed, steps)


def _run_batched(world: dict, network, backend: str, seed: int, steps: int) -> None:
    """Two copies of the composition's core, as tests/test_covariance_health.py steps them."""
    scenario = ComposedScenario(coloc_env.compose(world=world, network=network, backend=backend), batch=2)
    scenario.reset(np.random.default_rng(seed).spawn(2))
    space = scenario.action_space()
    space.seed(seed)
    for step in range(steps):
        scenario.step(np.stack([np.stack([space.sample() for _ in range(scenario.num_agents)]) for _ in range(2)]))
        for name, cov in _covariances(scenario.backend).items():
            _check_health(name, cov, step)
        assert np.all(np.isfinite(scenario.reward())), f"reward not finite at step {step}"


def test_the_afge_composition_stays_healthy_at_the_longest_period():
    _run_composition({"name": "nlos_orbit", "period": 1e4}, "random_delay", "afge", 0, 25)


@pytest.mark.parametrize("world, backend", [
    ({"name": "nlos_orbit", "sigma_db": 100.0}, "afge"),
    ({"name": "nlos_orbit", **NOISE_AT_MAXIMUM}, "afge"),
    ({"name": "nlos_orbit", **NOISE_AT_MAXIMUM}, "dfir"),
], ids=["afge-sigma_db-100", "afge-noise-max", "dfir-noise-max"])
def test_afge_and_dfir_compositions_stay_healthy_at_their_extremes(world, backend):
    _run_batched(world, "random_delay", backend, 0, 30)


@pytest.mark.slow
def test_nlos_horizon_stays_healthy_over_a_long_run_at_sigma_db_60():
    _run_preset({"sigma_db": 60.0}, "random", 1, 400)


@pytest.mark.parametrize("buffer_length", [3, 1000])
def test_dfir_stays_healthy_at_sigma_db_100_with_the_default_and_the_longest_buffer(buffer_length):
    network = {"name": "random_delay", "buffer_length": buffer_length,
               "delay_probs": (0.6, 0.2, 0.1, 0.05) + (0.0,) * (buffer_length - 3)}
    _run_composition({"name": "nlos_orbit", "sigma_db": 100.0}, network, "dfir", 3, 5)
