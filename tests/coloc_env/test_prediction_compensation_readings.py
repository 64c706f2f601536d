"""The ``prediction_compensation`` backend's ``reading`` option runs the estimator's reading of (29)."""

import numpy as np
import pytest

import coloc_env
import estimators.lossy_fusion as lf
from tests.coloc_env.test_target_compositions import _always, _episode, _stack, _uniform_outcomes, paper_model


@pytest.mark.parametrize("reading", lf.READINGS)
def test_each_reading_equals_the_estimator_s_distributed_filter(reading):
    """On the episode and link outcomes the composition drew (L = 3, the paper's decisions: zero tilts), the
    backend's fused estimate and covariance are lf.distributed_filter's with the same reading, to 1e-9."""
    seed, L = 5, 3
    spec = coloc_env.compose(world={"name": "target_cv", "num_agents": L, "horizon": 40}, network="bernoulli_delay",
                             backend={"name": "prediction_compensation", "reading": reading})
    infos, _, env = _episode(spec, _always, seed)
    world = env.unwrapped.scenario.world
    outcome = _uniform_outcomes(env, len(infos))
    assert {lf.ON_TIME, lf.LATE, lf.LOST} <= set(np.unique(outcome[:, 1:]))
    model = paper_model(L)
    x0, P0 = world.prior()
    estimates, covariances = lf.distributed_filter(model, x0, P0, world.observations[0], outcome, reading=reading)
    got = _stack(infos, "estimated_position", env)
    for i in range(L):  # the leader's fused estimate, reported by every agent
        np.testing.assert_allclose(got[:, i], estimates[:, [0, 2]], rtol=0, atol=1e-9)
    np.testing.assert_allclose(_stack(infos, "trace", env)[:, 0], covariances[:, 0, 0] + covariances[:, 2, 2],
                               rtol=1e-12, atol=1e-9)


def test_the_readings_differ_over_a_lossy_network_and_a_bad_reading_is_named():
    spec = {r: coloc_env.compose(world="target_cv", network="bernoulli_delay",
                                 backend={"name": "prediction_compensation", "reading": r}) for r in lf.READINGS}
    runs = {r: _stack(_episode(s, _always, 2, steps=30)[0], "estimated_position", coloc_env.parallel_env(s))
            for r, s in spec.items()}
    assert not np.allclose(runs["forward"], runs["current"]) and not np.allclose(runs["forward"], runs["age_aware"])
    with pytest.raises(ValueError, match=r"backend.reading must be one of .*'forward'.*got 'fresh'"):
        coloc_env.compose(world="target_cv", network="bernoulli_delay",
                          backend={"name": "prediction_compensation", "reading": "fresh"})
