"""The gps_denied world's fixed-density option and its size limits."""

from __future__ import annotations

import numpy as np
import pytest

import coloc_env
from coloc_env.worlds.gps_denied import GpsDenied


def drawn(config, B=2, T=6):
    world = config.build(B, T)
    world.draw_episode([np.random.default_rng(b) for b in range(B)], np.arange(B))
    return world


def test_density_sets_the_side_and_keeps_neighbours_per_uav_roughly_constant():
    assert GpsDenied(num_agents=10, density=40.0).side == 500.0 == GpsDenied(num_agents=40).side
    assert GpsDenied(num_agents=40, density=40.0).side == pytest.approx(1000.0)
    # density 40 at N = 10 is the default square: the same episodes, bit for bit
    a, b = drawn(GpsDenied(num_agents=10)), drawn(GpsDenied(num_agents=10, density=40.0))
    np.testing.assert_array_equal(a.truth, b.truth)
    np.testing.assert_array_equal(a.ranges, b.ranges)
    # fixed area: neighbours per UAV grow with N; fixed density: they stay within a band (over 4 copies)
    neighbours = {}
    for density in (None, 40.0):
        for N in (20, 80):
            world = drawn(GpsDenied(num_agents=N, density=density), B=4)
            neighbours[density, N] = world.adjacency[:, 0].sum(axis=-1).mean()
    assert neighbours[None, 80] > 3.0 * neighbours[None, 20]
    assert 0.6 < neighbours[40.0, 80] / neighbours[40.0, 20] < 1.5


def test_the_region_follows_the_side():
    world = drawn(GpsDenied(num_agents=40, density=10.0))
    (x0, x1), _ = world.region()
    assert x1 == pytest.approx(2000.0)
    assert world.truth[:, 0, :, :2].max() <= 2000.0


@pytest.mark.parametrize("field,value,match", [
    ("density", 0.0, r"world.density must be in \[0.001, 1000000"),
    ("density", float("nan"), "world.density"),
    ("num_agents", 129, r"world.num_agents must be in \[2, 128\]"),
])
def test_bad_sizes_name_the_field_and_range(field, value, match):
    with pytest.raises(ValueError, match=match):
        coloc_env.compose(world={"name": "gps_denied", field: value}, network="broadcast", backend="dead_reckoning")


def test_an_80_uav_composition_runs():
    spec = coloc_env.compose(world={"name": "gps_denied", "num_agents": 80, "density": 40.0}, network="broadcast",
                             backend="range_ls")
    venv = coloc_env.vector_env(spec, num_envs=2, seed=0)
    venv.reset()
    obs, reward, done, info = venv.step(np.stack([venv.action_space.sample() for _ in range(venv.num_envs)]))
    assert reward.shape == (160,) and np.isfinite(reward).all()
