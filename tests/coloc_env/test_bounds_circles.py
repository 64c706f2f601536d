"""The circles bound on the world's own problem: the heading in the state, driven by the turn-rate noise."""

import numpy as np
import pytest

import coloc_env
from coloc_env.bounds import pcrb, record_play
from coloc_env.bounds.models import circles


def _recursions(problem):
    return [problem.centralized, *problem.local, *problem.delivered]


def test_with_exact_headings_the_heading_state_gives_the_position_only_bound():
    """turn_rate_noise_std = 0: (x, y, phi) with phi exact and the positions alone are one problem (centralized,
    each platform's local, the centre's delivered over a lossy relay), to 1e-9."""
    spec = coloc_env.compose({"name": "circles", "turn_rate_noise_std": 0.0}, {"name": "relay", "loss_at_zero": 0.3},
                             "ukf_ccl", horizon=40)
    for seed in (0, 1):
        core = coloc_env.make_core(spec, batch=1)
        record = record_play(core, np.random.default_rng(seed), "always", None)
        with_heading = circles.problem(core, record, heading_state=True)
        positions = circles.problem(core, record, heading_state=False)
        assert with_heading.centralized.P0.shape == (18, 18) and positions.centralized.P0.shape == (12, 12)
        for a, b in zip(_recursions(with_heading), _recursions(positions), strict=True):
            np.testing.assert_allclose(a.run(), b.run(), rtol=1e-9, atol=1e-12)


def test_the_position_only_state_is_refused_where_the_heading_is_noisy():
    core = coloc_env.make_core(coloc_env.compose("circles", "ideal", "dead_reckoning", horizon=3), batch=1)
    record = record_play(core, np.random.default_rng(0), "always", None)
    with pytest.raises(ValueError, match="heading_state=False needs turn_rate_noise_std = 0"):
        circles.problem(core, record, heading_state=False)


def test_the_heading_error_adds_to_the_dead_reckoning_bound_as_its_integral():
    """A platform with its odometry alone: the bound's lateral variance at step k is the variance of
    dt V sum_{j<k} e(j), e a random walk of dt^2 sigma_omega^2 per step (cov(e(i), e(j)) = min(i, j) dt^2
    sigma_omega^2; a near-straight track: turn_rate tiny), plus the speed noise along the track:
    k dt^2 sigma_v^2 + dt^4 V^2 sigma_omega^2 sum_{i,j<k} min(i, j). A white position noise of the same
    per-step variance would give sum_{j<k} j instead of the double sum."""
    world = {"name": "circles", "num_anchors": 0, "turn_rate": 1e-6, "turn_rate_noise_std": 0.01}
    bound = pcrb(coloc_env.compose(world, "ideal", "dead_reckoning", horizon=30), episodes=1)["local"][:, 0]
    k = np.arange(30)
    dt, v, sv, sw = 0.5, 1.0, 0.5, 0.01
    double_sum = np.array([np.minimum.outer(np.arange(i), np.arange(i)).sum() for i in k])
    expected = k * dt**2 * sv**2 + dt**4 * v**2 * sw**2 * double_sum
    np.testing.assert_allclose(bound, expected, rtol=1e-6)


def test_the_heading_model_ukf_is_above_the_bound_over_seeded_episodes():
    """circles/ideal/ukf_ccl (heading model, the default) at the world's defaults, 12 seeded episodes of 150
    steps (steps >= 10 averaged), policy always: MSE >= pcrb_centralized - 3 SE."""
    episodes, steps, seed = 12, 150, 100
    spec = coloc_env.compose("circles", "ideal", "ukf_ccl", horizon=steps)
    core = coloc_env.make_core(spec, batch=episodes)
    assert type(core.backend.motion_model).__name__ == "OdometryHeadingError"
    core.reset([np.random.default_rng(seed + e) for e in range(episodes)])
    action = np.asarray(core.action_vector("maximum"), float)
    squared = []
    for _ in range(steps):
        core.advance(np.broadcast_to(action, (episodes, core.num_agents, action.size)).copy())
        squared.append(core.info()["position_error"] ** 2)
    per_episode = np.mean(np.array(squared)[10:], axis=(0, 2))
    bound = pcrb(spec, episodes=episodes, seed=seed)["centralized"][10:].mean()
    se = per_episode.std(ddof=1) / np.sqrt(episodes)
    assert per_episode.mean() >= bound - 3 * se, (per_episode.mean(), bound, se)
