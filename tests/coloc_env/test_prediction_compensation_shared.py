"""The prediction_compensation backend computes the followers' filter covariances once for the copies at the same
slot: every copy still sees those of its own slot (also when copies were reset at different slots), and each
copy's fused estimate is the one it gets alone."""

import numpy as np
import pytest

import coloc_env
import estimators.lossy_fusion as lf
from coloc_env.scenarios.composed import ComposedScenario


def _run(spec, seeds, steps, late_reset=None):
    """Per step, the fused estimates and covariances (steps, B, n[, n]) and the followers' own P(k|k)
    (steps, B, L-1, n, n) of a batched core; with ``late_reset = (step, copy, seed)`` that copy alone is reset
    with ``default_rng(seed)`` before that step."""
    scenario = ComposedScenario(spec, batch=len(seeds))
    scenario.reset([np.random.default_rng(s) for s in seeds])
    action = scenario.action_vector("maximum")
    actions = np.array(np.broadcast_to(action, (len(seeds), scenario.num_agents, len(action))))
    fused, fused_cov, followers = [], [], []
    for k in range(steps):
        if late_reset is not None and k == late_reset[0]:
            scenario.reset([np.random.default_rng(late_reset[2])], env_index=[late_reset[1]])
        scenario.step(actions)
        fusion = scenario.backend.fusion
        fused.append(fusion.fused.copy())
        fused_cov.append(fusion.fused_cov.copy())
        followers.append(np.array(fusion.packet_cov[:, :, 0]))
    return np.array(fused), np.array(fused_cov), np.array(followers), scenario


@pytest.mark.parametrize("reading", lf.READINGS)
def test_copies_reset_at_different_slots_keep_their_own_follower_covariances_and_estimates(reading):
    spec = coloc_env.compose(world={"name": "target_cv", "num_agents": 3, "horizon": 20}, network="bernoulli_delay",
                             backend={"name": "prediction_compensation", "reading": reading})
    steps, late = 12, 5
    fused, fused_cov, followers, scenario = _run(spec, [1, 2, 3], steps, late_reset=(late, 1, 9))
    model = scenario.backend.model
    x0, P0 = scenario.world.prior()
    # a follower's own filter reads every slot: its covariance is the Riccati recursion of its own readings
    for f in (1, 2):
        _, riccati = lf.kalman_filter(model, x0, P0, np.zeros((steps, 1, model.meas_dim)), uavs=[f])
        for b in (0, 2):
            np.testing.assert_allclose(followers[:, b, f - 1], riccati, rtol=0, atol=1e-12)
        np.testing.assert_allclose(followers[:late, 1, f - 1], riccati[:late], rtol=0, atol=1e-12)
        np.testing.assert_allclose(followers[late:, 1, f - 1], riccati[:steps - late], rtol=0, atol=1e-12)
    # the reset copy's fused estimates are those of the copy alone, reset with the same seed
    alone, alone_cov, alone_followers, _ = _run(spec, [9], steps - late)
    np.testing.assert_allclose(fused[late:, 1], alone[:, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(fused_cov[late:, 1], alone_cov[:, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(followers[late:, 1], alone_followers[:, 0], rtol=0, atol=1e-12)
    # and the untouched copies are those of the batched run without the late reset
    undisturbed, undisturbed_cov, _, _ = _run(spec, [1, 2, 3], steps)
    np.testing.assert_allclose(fused[:, [0, 2]], undisturbed[:, [0, 2]], rtol=0, atol=1e-12)
    np.testing.assert_allclose(fused_cov[:, [0, 2]], undisturbed_cov[:, [0, 2]], rtol=0, atol=1e-12)
    # the estimates are real: the copies differ
    assert not np.allclose(fused[:, 0], fused[:, 2])
