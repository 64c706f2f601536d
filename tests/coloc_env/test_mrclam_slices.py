"""World ``mrclam_slices``: the pseudo-fix, the slice table, episodes, per-copy readings and the checks."""

from __future__ import annotations

import dataclasses
import os

import numpy as np
import pytest

import coloc_env
import estimators.ukf_relay_se2 as se2
from coloc_env.data import mrclam, mrclam_navigation
from coloc_env.worlds.mrclam_slices import MrclamSlices, build_slices, slice_table
from tests.conftest import MRCLAM_DATASET6, MRCLAM_SKIP_REASON

N = mrclam.NUM_ROBOTS


def test_pseudo_fix_from_true_pose_is_the_position():
    rng = np.random.default_rng(3)
    pose = np.column_stack([rng.uniform(-3, 3, 50), rng.uniform(-3, 3, 50), rng.uniform(-np.pi, np.pi, 50)])
    landmark = rng.uniform(-5, 5, (50, 2))
    z = se2.observe(pose, landmark)
    np.testing.assert_allclose(mrclam_navigation.pseudo_fix(landmark, z[:, 0], z[:, 1], pose[:, 2]), pose[:, :2],
                               atol=1e-9, rtol=0)
    # the offset carries the fix by a known displacement
    np.testing.assert_allclose(mrclam_navigation.pseudo_fix(landmark, z[:, 0], z[:, 1], pose[:, 2], [0.5, -0.25]),
                               pose[:, :2] + [0.5, -0.25], atol=1e-9, rtol=0)
    # isotropic std: the larger of the radial and the tangential (bearing + heading) parts
    assert mrclam_navigation.fix_std(2.0, 0.01, 0.0004, 0.0021) == pytest.approx(np.sqrt(4 * 0.0025))
    assert mrclam_navigation.fix_std(2.0, 0.09, 0.0004, 0.0021) == pytest.approx(0.3)


@pytest.fixture(scope="module")
def run():
    """Dataset 6's replay tables and whole-run slice table (the world's cache)."""
    if not os.path.isdir(MRCLAM_DATASET6):
        pytest.skip(MRCLAM_SKIP_REASON)
    path = MRCLAM_DATASET6
    world = MrclamSlices(data=path)
    replay, table = world.tables()
    return path, replay, table


def test_pseudo_fix_with_vicon_pose_on_dataset6(run):
    d = run[1].data
    i = np.flatnonzero(d.meas_subject > N)[:40]
    pose = d.groundtruth[d.meas_step[i], d.meas_robot[i]]
    landmark = d.landmarks[d.meas_subject[i] - N - 1]
    z = se2.observe(pose, landmark)
    np.testing.assert_allclose(mrclam_navigation.pseudo_fix(landmark, z[:, 0], z[:, 1], pose[:, 2]), pose[:, :2],
                               atol=1e-9, rtol=0)


def test_the_whole_run_table_starts_with_the_slices_of_its_first_stretch(run):
    """The own navigation filters and the tracks are causal: the first 60 slices of the whole-run table are, bit
    for bit, the slices built from the first 60 s alone."""
    _, replay, table = run
    first = build_slices(replay.data, replay.noise_model, 10, num_slices=60)
    assert first.dt == table.dt
    for f in dataclasses.fields(first):
        if f.name != "dt":
            np.testing.assert_array_equal(getattr(first, f.name), getattr(table, f.name)[:60], f.name)


def test_slice_mapping(run):
    _, replay, sl = run
    assert len(sl) == (replay.data.steps - 1) // 10 + 1 and sl.truth.shape == (len(sl), N, 2) and sl.dt == 1.0
    assert np.array_equal(sl.adjacency, np.swapaxes(sl.adjacency, 1, 2))
    assert np.array_equal(sl.ranges, np.swapaxes(sl.ranges, 1, 2))
    assert not sl.adjacency[:, np.arange(N), np.arange(N)].any()
    assert np.array_equal(sl.normal, sl.fix_std > 0) and sl.normal.any() and (~sl.normal).any()
    # the pseudo-fixes of the first 100 s lie within 3 of their stated std of Vicon (not overconfident there)
    err = np.linalg.norm(sl.fix[:100] - sl.truth[:100], axis=-1)[sl.normal[:100]]
    assert np.all(err < 3.0 * sl.fix_std[:100][sl.normal[:100]])
    assert np.all(sl.range_std[sl.adjacency.any(axis=(1, 2))] > 0) and np.all(sl.accel_std > 0)


def _readings(world, steps):
    out = []
    for _ in range(steps):
        out.append(world.readings(np.zeros((world.batch, world.num_agents, 0), np.int64)))
        world.advance()
    return out


def test_copies_replay_their_own_stretch_with_their_own_sigmas(run):
    """Copies of a batch start at slices drawn from their generators (start=None); each copy's readings are those
    of a one-copy world with that fixed start, sigmas included, and the sigmas differ between the copies."""
    path = run[0]
    seeds = [20, 21, 22]
    batched = MrclamSlices(data=path, horizon=20).build(3, 20)
    batched.reset([np.random.default_rng(s) for s in seeds], np.arange(3))
    assert len(set(batched.start)) == 3
    both = _readings(batched, 20)
    for b in range(3):
        alone = MrclamSlices(data=path, horizon=20, start=int(batched.start[b])).build(1, 20)
        alone.reset([np.random.default_rng(0)], np.arange(1))
        np.testing.assert_array_equal(alone.initial_belief()[0][0], batched.initial_belief()[0][b])
        for r, one in zip(both, _readings(alone, 20), strict=True):
            for field in ("inputs", "range", "range_valid", "fix", "fix_valid"):
                np.testing.assert_array_equal(getattr(r, field)[b], getattr(one, field)[0], field)
            for key, value in one.extra.items():
                np.testing.assert_array_equal(r.extra[key][b], value[0], key)
    assert any(np.ptp(r.extra["range_std"]) > 0 for r in both)


def test_fewer_robots_and_no_ranges(run):
    """num_agents=3 reads robots 0..2 only (their sigmas: the largest over them); ranges=False has no range."""
    path, _, sl = run
    world = MrclamSlices(data=path, num_agents=3, horizon=50, start=0).build(1, 50)
    world.reset([np.random.default_rng(0)], np.arange(1))
    readings = _readings(world, 50)
    for t, r in enumerate(readings):
        np.testing.assert_array_equal(r.range_valid[0], sl.adjacency[t, :3, :3])
        np.testing.assert_array_equal(r.fix_valid[0], sl.normal[t, :3])
        if sl.adjacency[t, :3, :3].any():
            assert r.extra["range_std"][0] <= max(sl.range_std[t], 1e-3)
    assert any(r.range_valid.any() for r in readings)
    quiet = MrclamSlices(data=path, horizon=50, start=0, ranges=False).build(1, 50)
    quiet.reset([np.random.default_rng(0)], np.arange(1))
    assert not any(r.range_valid.any() for r in _readings(quiet, 50))


def test_a_run_too_short_for_the_episode_names_the_field(run):
    path, _, sl = run
    S = len(sl)
    with pytest.raises(ValueError, match=rf"world.horizon must be in \[1, {S}\] slices for this run of {S} slices"):
        coloc_env.parallel_env(coloc_env.compose({"name": "mrclam_slices", "data": path, "horizon": S + 1},
                                                 "broadcast", "range_ls"))
    with pytest.raises(ValueError, match=rf"world.start must be in \[0, {S - 100}\] for a horizon of 100 slices"):
        coloc_env.parallel_env(coloc_env.compose({"name": "mrclam_slices", "data": path, "start": S - 99},
                                                 "broadcast", "range_ls"))


def test_bad_fields_name_the_field_and_range():
    with pytest.raises(ValueError, match=r"world.slice_steps must be in \[1, 600\]"):
        MrclamSlices(slice_steps=0).validate()
    with pytest.raises(ValueError, match=r"world.region must be \(lo, hi\) with lo < hi, got \(2.0, 1.0\)"):
        MrclamSlices(region=(2.0, 1.0)).validate()
    with pytest.raises(ValueError, match=r"world.num_agents must be in \[2, 5\]"):
        MrclamSlices(num_agents=6).validate()


def test_the_table_is_cached_and_read_only(run):
    path, _, sl = run
    assert slice_table(os.path.realpath(path), 10, "calibrated", None) is sl
    with pytest.raises(ValueError, match="read-only"):
        sl.fix[0, 0, 0] = 1.0


def test_the_model_based_bound_gains_from_the_ranges_only(run):
    """Over the same episodes the centralized bound is below each robot's local one (the ranges add information)
    and, without ranges, equals it; the local bound does not depend on the ranges."""
    path = run[0]

    def bounds(ranges):
        world = {"name": "mrclam_slices", "data": path, "horizon": 20, "ranges": ranges}
        return coloc_env.pcrb(coloc_env.compose(world, "broadcast", "dead_reckoning"), episodes=2, seed=0)

    ranged, quiet = bounds(True), bounds(False)
    assert ranged["model_based"] and np.all(ranged["centralized"] <= ranged["local"] * (1 + 1e-9))
    assert np.any(ranged["centralized"] < 0.99 * ranged["local"])
    np.testing.assert_allclose(quiet["centralized"], quiet["local"], rtol=1e-9, atol=0)
    np.testing.assert_allclose(quiet["local"], ranged["local"], rtol=1e-12, atol=0)
