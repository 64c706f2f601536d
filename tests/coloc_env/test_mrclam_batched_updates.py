"""``ukf_se2`` on the ``mrclam`` world steps its copies together (stacked UKF-DCL updates, one time update, one
readings call): copy b of a batch equals the same copy run alone (1e-12), and the world's vectorized readings are
the recording's lines by the scenario's rule."""

import dataclasses

import numpy as np
import pytest

import coloc_env
from coloc_env.data import mrclam
from coloc_env.scenarios.composed import ComposedScenario
from tests.conftest import MRCLAM_DATASET6, needs_mrclam

N = mrclam.NUM_ROBOTS
PRESET = coloc_env.PRESETS["mrclam_relay"]
pytestmark = needs_mrclam


def _spec(steps, world=None, network=None, backend=None):
    return coloc_env.compose(
        world=dataclasses.replace(PRESET.world, data=MRCLAM_DATASET6, horizon=steps, **(world or {})),
        network=dataclasses.replace(PRESET.network, **(network or {})),
        backend=dataclasses.replace(PRESET.backend, **(backend or {})))


STATE = ("estimate", "P_ii", "phi", "sigma", "applied", "rejected", "landmarks_applied")


@pytest.mark.parametrize(("world", "backend"), [
    ({}, {}),
    ({"noise_model": "baseline", "robot_sightings": "all"}, {}),  # the gate refuses observations in some copies
    ({}, {"landmark_updates": "relay"}),  # landmark sightings along relay chains too
])
def test_copy_b_of_a_batch_equals_the_copy_alone(world, backend):
    """B = 5 against five B = 1 cores reset with the same seeds, random actions on a lossy relay with a hop limit:
    at every step the chains of one slot have several lengths across the copies (several stacked updates),
    and every copy's estimate, factors and records equal its single run to 1e-12."""
    steps, B, seed = 40, 5, 11
    spec = _spec(steps, world, {"loss_at_zero": 0.3, "max_hops": 3}, backend)
    batch = ComposedScenario(spec, batch=B)
    batch.reset([np.random.default_rng(seed + b) for b in range(B)])
    singles = [ComposedScenario(spec, batch=1) for _ in range(B)]
    for b, single in enumerate(singles):
        single.reset([np.random.default_rng(seed + b)])
    assert len(set(batch.world.start.tolist())) == B
    nvec = batch.action_space().nvec
    rng = np.random.default_rng(3)
    lengths, rejected = set(), 0.0
    for _ in range(steps):
        actions = rng.integers(0, nvec, size=(B, N, len(nvec)))
        batch.step(actions)
        for b, single in enumerate(singles):
            single.step(actions[b:b + 1])
        mine = batch.backend
        lengths |= set(mine.chains.length[mine.partner.reshape(-1) >= 0].tolist())
        rejected += mine.rejected.sum()
        for b, single in enumerate(singles):
            for name in STATE:
                np.testing.assert_allclose(getattr(mine, name)[b], getattr(single.backend, name)[0], rtol=0,
                                           atol=1e-12, err_msg=name)
            np.testing.assert_array_equal(mine.used[b], single.backend.used[0])
            np.testing.assert_array_equal(mine.partner[b], single.backend.partner[0])
    assert len(lengths) >= 3, lengths  # chains of several lengths were updated in the same steps
    if world:
        assert rejected > 0  # and the gate refused some copies' observations, not others'


def _reference_lines(world, a, choice):
    """The lines of step a a copy's robots report, by the rule of the world's docstring, line by line."""
    d, tables, out = world.data, world.tables, []
    s = d.measurements_at(int(a))
    for line in range(s.start, s.stop):
        m, subject = int(d.meas_robot[line]), int(d.meas_subject[line])
        if m >= world.num_agents:
            continue
        if subject > N:  # a landmark sighting: always reported
            out.append(line)
            continue
        n = subject - 1
        first = world.config.robot_sightings == "all" or tables.first_index[a, m, n] == line
        if n < world.num_agents and n != m and first and choice[m] in (n, world.num_agents):
            out.append(line)
    return out


@pytest.mark.parametrize("fields", [{}, {"robot_sightings": "all"}, {"num_agents": 3}, {"dt": 0.5},
                                    {"dt": 0.5, "robot_sightings": "all"}])
def test_vectorized_readings_are_the_recordings_lines(fields):
    """Every copy's observation list and pair matrices against the rule applied line by line (at dt = 0.5 a
    robot often records another twice in one step: the first line only, or all with ``"all"``)."""
    steps, B = 30, 6
    spec = _spec(steps, fields)
    core = ComposedScenario(spec, batch=B)
    core.reset([np.random.default_rng(20 + b) for b in range(B)])
    world, Nw = core.world, core.world.num_agents
    rng = np.random.default_rng(4)
    seen = {"robot": 0, "landmark": 0, "repeated": 0}
    for _ in range(steps):
        choice = rng.integers(0, Nw + 1, size=(B, Nw))
        r = world.readings(choice[..., None])
        a = world.absolute_step()
        for b in range(B):
            lines = _reference_lines(world, a[b], choice[b])
            n = len(lines)
            d = world.data
            assert (r.extra["obs_observer"][b] >= 0).sum() == n
            np.testing.assert_array_equal(r.extra["obs_observer"][b, :n], d.meas_robot[lines])
            sub = d.meas_subject[lines]
            np.testing.assert_array_equal(r.extra["obs_subject"][b, :n], np.where(sub <= N, sub - 1, -1))
            np.testing.assert_array_equal(r.extra["obs_landmark"][b, :n], np.where(sub > N, sub - N - 1, -1))
            np.testing.assert_array_equal(r.extra["obs_z"][b, :n, 0], d.meas_range[lines])
            np.testing.assert_array_equal(r.extra["obs_z"][b, :n, 1], d.meas_bearing[lines])
            np.testing.assert_array_equal(r.extra["obs_cov"][b, :n], world.tables.measurement_cov[lines])
            expected_target = np.where((sub > N)[:, None], world.landmarks[np.maximum(sub - N - 1, 0)], np.nan)
            np.testing.assert_array_equal(r.extra["obs_target"][b, :n], expected_target)
            assert np.isnan(r.extra["obs_z"][b, n:]).all() and (r.extra["obs_observer"][b, n:] == -1).all()
            valid = np.zeros((Nw, Nw), dtype=bool)
            for line in lines:  # the matrices: each pair's first line
                m, s = int(d.meas_robot[line]), int(d.meas_subject[line])
                if s <= N and world.tables.first_index[a[b], m, s - 1] == line:
                    valid[m, s - 1] = True
                    assert r.range[b, m, s - 1] == d.meas_range[line]
                    assert r.extra["bearing"][b, m, s - 1] == d.meas_bearing[line]
                    np.testing.assert_array_equal(r.extra["range_bearing_cov"][b, m, s - 1],
                                                  world.tables.measurement_cov[line])
            np.testing.assert_array_equal(r.range_valid[b], valid)
            assert np.isnan(r.range[b][~valid]).all()
            seen["robot"] += int((sub <= N).sum())
            seen["landmark"] += int((sub > N).sum())
            pairs = d.meas_robot[lines] * (N + 1) + sub
            seen["repeated"] += len(pairs[sub <= N]) - len(set(pairs[sub <= N].tolist()))
        core.step(np.concatenate([choice[..., None], rng.integers(0, Nw + 1, size=(B, Nw, Nw))], axis=-1))
    assert seen["robot"] > 10 and seen["landmark"] > 10, seen
    assert (seen["repeated"] > 0) == (fields.get("robot_sightings") == "all" and fields.get("dt") == 0.5), seen
