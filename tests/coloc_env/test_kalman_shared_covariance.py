"""The kalman backend's data-independent variants share the Riccati recursion among the copies at the same
step k: every copy's covariance is still the one of its own k (also when copies were reset at different
steps), and each copy's estimate is the one it gets alone."""

import numpy as np
import pytest

import coloc_env
import estimators.lossy_fusion as lf
from coloc_env.backends.fusion import lossy_model
from coloc_env.scenarios.composed import ComposedScenario


def _run(spec, seeds, steps, late_reset=None):
    """Posterior state covariances and estimates (steps, B, n, n) / (steps, B, n) of a batched core; with
    ``late_reset = (step, copy, seed)`` that copy alone is reset with ``default_rng(seed)`` before that step."""
    scenario = ComposedScenario(spec, batch=len(seeds))
    scenario.reset([np.random.default_rng(s) for s in seeds])
    action = scenario.action_vector("maximum")
    actions = np.array(np.broadcast_to(action, (len(seeds), scenario.num_agents, len(action))))
    covs, estimates = [], []
    for k in range(steps):
        if late_reset is not None and k == late_reset[0]:
            scenario.reset([np.random.default_rng(late_reset[2])], env_index=[late_reset[1]])
        scenario.step(actions)
        covs.append(scenario.backend.posterior_state_cov[:, 0].copy())
        estimates.append(scenario.backend.posterior_state[:, 0].copy())
    return np.array(covs), np.array(estimates), scenario


@pytest.mark.parametrize("variant", ["naive", "leader_only", "ideal"])
def test_copies_reset_at_different_steps_keep_their_own_riccati_covariance_and_estimate(variant):
    spec = coloc_env.compose(world={"name": "target_cv", "num_agents": 3, "horizon": 20}, network="bernoulli_delay",
                             backend={"name": "kalman", "variant": variant})
    steps, late = 12, 5
    covs, estimates, scenario = _run(spec, [1, 2, 3], steps, late_reset=(late, 1, 9))
    world = scenario.world
    model = lossy_model(world, scenario.network)
    x0, P0 = world.prior()
    uavs = [0] if variant == "leader_only" else list(range(model.num_uavs))
    _, riccati = lf.kalman_filter(model, x0, P0, np.zeros((steps, len(uavs), model.meas_dim)), uavs=uavs)
    for b in (0, 2):
        np.testing.assert_allclose(covs[:, b], riccati, rtol=0, atol=1e-12)
    np.testing.assert_allclose(covs[:late, 1], riccati[:late], rtol=0, atol=1e-12)
    np.testing.assert_allclose(covs[late:, 1], riccati[:steps - late], rtol=0, atol=1e-12)
    # the reset copy's estimates are those of the copy alone, reset with the same seed
    alone_covs, alone, _ = _run(spec, [9], steps - late)
    np.testing.assert_allclose(estimates[late:, 1], alone[:, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(covs[late:, 1], alone_covs[:, 0], rtol=0, atol=1e-12)
    # and the untouched copies are those of the batched run without the late reset
    _, undisturbed, _ = _run(spec, [1, 2, 3], steps)
    np.testing.assert_allclose(estimates[:, [0, 2]], undisturbed[:, [0, 2]], rtol=0, atol=1e-12)
