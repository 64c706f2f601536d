"""range_ls works on neighbour lists: UAVs that are nobody's neighbour change no other UAV's update (1e-9)."""

from __future__ import annotations

import numpy as np

import estimators.range_ls as rl


def _arrays(rng, N):
    """N UAVs in a 400 m square, every third one faulty: (positions, normal, mean, fix, adjacency, ranges)."""
    p = rng.uniform(0.0, 400.0, (N, 2))
    d = np.linalg.norm(p[:, None] - p[None], axis=-1)
    adjacency = (d > 0) & (d < 300.0)
    noise = np.triu(rng.normal(0.0, 2.0, d.shape), 1)
    ranges = np.where(adjacency, d + noise + noise.T, 0.0)
    normal = np.arange(N) % 3 != 0
    return p, normal, p + rng.normal(0.0, 20.0, p.shape), p + rng.normal(0.0, 3.0, p.shape), adjacency, ranges


def _update(normal, mean_p, fix, adjacency, ranges):
    mean = np.zeros((1, len(normal), 4))
    mean[0, :, :2] = mean_p
    state = rl.initial_state(mean, np.diag([400.0, 400.0, 4.0, 4.0]))
    return rl.update(rl.LsParams(), state, normal[None], fix[None], adjacency[None], ranges[None], 3.0, 2.0)


def test_uavs_out_of_everyones_range_change_nothing():
    N, far = 12, 30
    p, normal, mean_p, fix, adjacency, ranges = _arrays(np.random.default_rng(7), N)
    post, estimate, cov, fixed = _update(normal, mean_p, fix, adjacency, ranges)
    # 30 more GPS-normal UAVs 1e5 m away: nobody's neighbour (a wider padding of every neighbour list)
    q = 1e5 + np.random.default_rng(8).uniform(0.0, 400.0, (far, 2))
    total = N + far
    wide_adjacency = np.zeros((total, total), bool)
    wide_adjacency[:N, :N] = adjacency
    wide_ranges = np.zeros((total, total))
    wide_ranges[:N, :N] = ranges
    post_w, estimate_w, cov_w, fixed_w = _update(np.r_[normal, np.ones(far, bool)], np.vstack([mean_p, q]),
                                          np.vstack([fix, q]), wide_adjacency, wide_ranges)
    assert fixed.any()
    np.testing.assert_array_equal(fixed_w[:, :N], fixed)
    np.testing.assert_allclose(estimate_w[:, :N], estimate, atol=1e-9, rtol=0)
    np.testing.assert_allclose(cov_w[:, :N], cov, atol=1e-9, rtol=0)
    np.testing.assert_allclose(post_w.cov[:, :N], post.cov, atol=1e-9, rtol=0)
    np.testing.assert_allclose(post_w.mean[:, :N], post.mean, atol=1e-9, rtol=0)
