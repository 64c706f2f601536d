"""World parts: linear motion, linear sensors, bandwidth budgets."""

import itertools

import numpy as np
import pytest

from coloc_env.networks.blocks import BandwidthBudget
from coloc_env.worlds.blocks import LinearMotion, LinearSensor


def test_paper_budget_has_108_selections_and_relaxed_has_216():
    budget = BandwidthBudget()
    budget.validate()
    assert budget.feasible.shape == (108, 3, 3)
    # independent count: 3 neighbours, 1..3 components each, totals 5 (or <= 5)
    sizes = {k: sum(1 for s in itertools.product((0, 1), repeat=3) if sum(s) == k) for k in (1, 2, 3)}
    exact = sum(sizes[a] * sizes[b] * sizes[c] for a, b, c in itertools.product((1, 2, 3), repeat=3)
                if a + b + c == 5)
    relaxed = sum(sizes[a] * sizes[b] * sizes[c] for a, b, c in itertools.product((1, 2, 3), repeat=3)
                  if a + b + c <= 5)
    assert exact == 108 and relaxed == 216
    assert len(BandwidthBudget(exact_budget=False).feasible) == relaxed
    assert np.all(budget.feasible.sum(axis=(1, 2)) == 5)
    assert len({f.tobytes() for f in budget.feasible}) == 108


def test_relative_and_absolute_selections_round_trip():
    budget = BandwidthBudget()
    rng = np.random.default_rng(0)
    rel = budget.feasible[rng.integers(0, 108, size=(7, 4))]  # (7, N, N-1, n)
    full = budget.full_selection(rel)
    assert full.shape == (7, 4, 4, 3)
    assert np.all(full[:, np.arange(4), np.arange(4)])
    np.testing.assert_array_equal(budget.relative_selection(full), rel)
    # neighbour k of receiver i is node (i + 1 + k) mod N
    np.testing.assert_array_equal(full[:, 1, 3], rel[:, 1, 1])
    assert np.all(budget.index_of(rel) >= 0)


@pytest.mark.parametrize("kwargs, field", [
    ({"budget": 10}, "budget"), ({"budget": 2}, "budget"), ({"max_per_link": 4}, "max_per_link"),
    ({"min_per_link": 4}, "min_per_link"), ({"num_nodes": 1}, "num_nodes"), ({"budget": 2.5}, "budget"),
])
def test_budget_no_selection_can_meet_is_refused(kwargs, field):
    with pytest.raises(ValueError, match=field):
        BandwidthBudget(**kwargs).validate()


def test_linear_motion_steps_and_samples_its_covariance():
    W = np.diag([0.02, 0.05, 0.03])
    motion = LinearMotion(np.eye(3) * 0.9, np.array([0.5, 0.5, 0.5]), W)
    motion.validate()
    x = np.ones((4, 3))
    np.testing.assert_allclose(motion.step(x, np.zeros((4, 3))), 0.9 + 0.5)
    noise = motion.sample_noise(np.random.default_rng(0), (200_000,))
    np.testing.assert_allclose(np.cov(noise.T), W, atol=2e-3)
    with pytest.raises(ValueError, match="process_noise"):
        LinearMotion(np.eye(2), np.zeros(2), np.array([[1.0, 2.0], [2.0, 1.0]])).validate()
    with pytest.raises(ValueError, match="drift"):
        LinearMotion(np.eye(3), np.zeros(2), W).validate()


def test_linear_sensor_measures_and_validates():
    sensor = LinearSensor(np.array([[1.0, 0.0, 0.0]]), np.array([[0.1]]))
    sensor.validate(3)
    np.testing.assert_allclose(sensor.measure(np.array([[2.0, 3.0, 4.0]]), np.array([[0.5]])), [[2.5]])
    with pytest.raises(ValueError, match="noise"):
        LinearSensor(np.eye(2), np.zeros((2, 2))).validate(2)
    with pytest.raises(ValueError, match="measurement"):
        LinearSensor(np.eye(2), np.eye(2)).validate(3)


# --- lossy_fusion (fu2017): constant-velocity target and on-time / late / lost links ---------------

def test_constant_velocity_target_matrices_and_noise():
    from coloc_env.worlds.blocks.target import ConstantVelocityTarget

    target = ConstantVelocityTarget(axes=3, period=2.0, accel_noise=5.0)
    target.validate()
    per_axis = np.array([[1.0, 2.0], [0.0, 1.0]])
    np.testing.assert_array_equal(target.transition[2:4, 2:4], per_axis)
    np.testing.assert_array_equal(target.transition[0:2, 2:4], 0.0)
    # Q per axis = q [[T^4/4, T^3/2], [T^3/2, T^2]]
    np.testing.assert_allclose(target.process_noise[4:6, 4:6], 5.0 * np.array([[4.0, 4.0], [4.0, 4.0]]))
    np.testing.assert_array_equal(target.position_matrix @ np.arange(6.0), [0.0, 2.0, 4.0])
    rng = np.random.default_rng(0)
    w = target.sample_noise(rng, (20000,))
    np.testing.assert_allclose(np.cov((w @ target.noise_gain.T).T), target.process_noise, rtol=0.05, atol=0.5)
    x0 = np.array([100.0, 10.0, 100.0, 10.0, 100.0, 0.0])
    noise = target.sample_noise(rng, (4, 7))
    path = target.trajectory(np.broadcast_to(x0, (4, 6)), noise)
    assert path.shape == (4, 8, 6)
    x = x0.copy()
    for k in range(7):
        x = target.transition @ x + target.noise_gain @ noise[2, k]
        np.testing.assert_allclose(path[2, k + 1], x, atol=1e-12)
    for kwargs, field in (({"period": 0.0}, "period"), ({"accel_noise": -1.0}, "accel_noise"),
                          ({"axes": 0}, "axes")):
        with pytest.raises(ValueError, match=field):
            ConstantVelocityTarget(**kwargs).validate()


@pytest.mark.parametrize("period", [0.1, 0.37, 1.0])
def test_a_batch_of_trajectories_equals_each_copy_drawn_alone(period):
    """The world draws every reset copy's trajectory at once: copy b must not depend on the batch around it (matrix
    products of a batch round differently from one row's at T = 0.1), and it follows Phi x + G w to rounding."""
    from coloc_env.worlds.blocks.target import ConstantVelocityTarget

    target = ConstantVelocityTarget(axes=3, period=period, accel_noise=5.0)
    rng = np.random.default_rng(3)
    x0, noise = rng.normal(0.0, 300.0, (257, 6)), target.sample_noise(rng, (257, 50))
    batch = target.trajectory(x0, noise)
    for b in (0, 100, 256):
        np.testing.assert_array_equal(batch[b], target.trajectory(x0[b], noise[b]))
        np.testing.assert_array_equal(batch[b], target.trajectory(x0[b:b + 1], noise[b:b + 1])[0])
    x = x0[100]
    for k in range(50):
        x = target.transition @ x + target.noise_gain @ noise[100, k]
    np.testing.assert_allclose(batch[100, -1], x, rtol=1e-12, atol=1e-9)


def test_bernoulli_delay_link_frequencies_and_indicator_covariance():
    from coloc_env.networks.blocks.delay_links import LATE, LOST, ON_TIME, BernoulliDelayLink

    link = BernoulliDelayLink(on_time=0.4, late=0.3)
    link.validate()
    codes = link.sample(np.random.default_rng(1), (200, 500))
    assert codes.dtype == np.int8 and set(np.unique(codes)) == {ON_TIME, LATE, LOST}
    freq = np.array([(codes == c).mean() for c in (ON_TIME, LATE, LOST)])
    np.testing.assert_allclose(freq, link.probabilities, atol=4 * np.sqrt(0.25 / codes.size))
    xi = np.stack([(codes == ON_TIME).ravel(), (codes == LATE).ravel()]).astype(float)
    np.testing.assert_allclose(np.cov(xi), link.indicator_cov(), atol=0.005)
    assert link.indicator_cov()[0, 1] == pytest.approx(-0.12)  # exclusive outcomes: Cov(xi1, xi2) = -a1 a2
    same = BernoulliDelayLink().sample(np.random.default_rng(1), (200, 500))
    np.testing.assert_array_equal(codes, same)
    with pytest.raises(ValueError, match="p_on \\+ p_late"):
        BernoulliDelayLink(0.8, 0.3).validate("p_on", "p_late")
    with pytest.raises(ValueError, match="late"):
        BernoulliDelayLink(0.4, -0.1).validate()
    with pytest.raises(ValueError, match="on_time"):
        BernoulliDelayLink(1.5, 0.0).validate()


# --- relay_ukf (wang2019): unicycle and circles, odometry and range sensors, relay chains -----------

def test_unicycle_rollout_equals_stepping_and_circles_close():
    from coloc_env.worlds.blocks import CircularTracks, UnicycleMotion

    motion = UnicycleMotion(dt=0.5)
    rng = np.random.default_rng(0)
    speed, turn = rng.uniform(0.5, 1.5, (3, 20)), rng.normal(0, 0.1, (3, 20))
    positions, headings = motion.rollout(np.zeros((3, 2)), np.array([0.0, 1.0, 2.0]), speed, turn)
    p, h = np.zeros((3, 2)), np.array([0.0, 1.0, 2.0])
    for k in range(20):
        p, h = motion.step(p, h, speed[:, k], turn[:, k])
        np.testing.assert_allclose(positions[:, k + 1], p, atol=1e-12)
        np.testing.assert_allclose(headings[:, k + 1], h, atol=1e-12)
    tracks = CircularTracks(np.array([[0.0, 0.0], [10.0, 5.0]]), np.array([0.0, np.pi]), np.array([1.0, -1.0]))
    tracks.validate()
    truth, heading, _, omega = tracks.trajectory(2000)
    radii = np.linalg.norm(truth - tracks.centres, axis=-1)
    np.testing.assert_allclose(radii, tracks.radius, atol=1e-9)  # every vertex on its circle
    assert tracks.radius == pytest.approx(1.0 / 0.015, rel=1e-4)
    angle = np.unwrap(np.arctan2(*(truth - tracks.centres)[..., ::-1].transpose(2, 0, 1)), axis=0)
    assert np.all(np.diff(angle[:, 0]) > 0) and np.all(np.diff(angle[:, 1]) < 0)  # ccw and cw
    np.testing.assert_allclose(np.diff(angle, axis=0)[0], 0.5 * omega, atol=1e-12)
    for kwargs, field in (({"directions": np.array([1.0, 0.5])}, "directions"),
                          ({"centres": np.zeros((2, 3))}, "centres"), ({"speed": -1.0}, "speed"),
                          ({"dt": 0.0}, "dt"), ({"turn_rate": 0.0}, "turn_rate")):
        base = {"centres": np.zeros((2, 2)), "start_angles": np.zeros(2), "directions": np.ones(2)}
        with pytest.raises(ValueError, match=field):
            CircularTracks(**(base | kwargs)).validate()


def test_odometry_heading_variance_and_range_sensor():
    from coloc_env.worlds.blocks import OdometrySensor, RangeSensor, UnicycleMotion

    odometry = OdometrySensor(speed_noise_std=0.5, turn_rate_noise_std=1e-3)
    odometry.validate()
    rng = np.random.default_rng(1)
    speed_noise, turn_noise = odometry.sample_noise(rng, (20000, 100))
    assert speed_noise.std() == pytest.approx(0.5, rel=0.01)
    heading = UnicycleMotion(0.5).headings(np.zeros(20000), turn_noise)  # heading error of a known start
    np.testing.assert_allclose(heading[:, [10, 50, 99]].var(axis=0),
                               odometry.heading_variance(np.array([10, 50, 99]), 0.5), rtol=0.05)
    with pytest.raises(ValueError, match="speed_noise_std"):
        OdometrySensor(-1.0).validate()
    sensor = RangeSensor(noise_var=4.0, max_range=50.0)
    sensor.validate()
    a, b = np.array([[0.0, 0.0], [0.0, 0.0]]), np.array([[30.0, 40.0], [60.0, 0.0]])
    np.testing.assert_allclose(sensor.measure(a, b, np.array([1.0, -1.0])), [51.0, 59.0])
    np.testing.assert_array_equal(sensor.in_range(a, b), [True, False])
    assert sensor.sample_noise(rng, (50000,)).var() == pytest.approx(4.0, rel=0.03)
    RangeSensor(max_range=float("inf")).validate()
    with pytest.raises(ValueError, match="max_range"):
        RangeSensor(max_range=0.0).validate()
    with pytest.raises(ValueError, match="noise_var"):
        RangeSensor(noise_var=0.0).validate()


def test_relay_chain_follows_choices_and_reports_each_stop_reason():
    from coloc_env.networks.blocks import RelayChainLinks
    from coloc_env.networks.blocks.relay_chain import STOP_REASONS

    positions = np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0], [100.0, 0.0]])
    B = 6
    pos = np.broadcast_to(positions, (B, 4, 2))
    # copy: 0 complete, 1 stops by choice, 2 revisit, 3 out of range, 4 hop budget (via max_hops), 5 lost
    choice = np.array([[9, 2, 3, 4], [9, 4, 3, 4], [9, 0, 3, 4], [9, 2, 3, 4], [9, 2, 3, 4], [9, 2, 3, 4]])
    uniforms = np.full((B, 3), 0.99)
    uniforms[5, 1] = 0.0  # the hop 1 -> 2 is lost
    links = RelayChainLinks(comm_range=50.0, loss_at_zero=0.5)  # u = 0.99 never loses, u = 0 always
    links.validate(4)
    chain = links.resolve(pos, np.zeros(B, int), np.ones(B, int), choice, uniforms)
    reasons = [STOP_REASONS[s] for s in chain.stop]
    assert reasons[:4] == ["out_of_range", "stopped", "revisit", "out_of_range"]
    np.testing.assert_array_equal(chain.chain[0], [0, 1, 2, -1])
    assert reasons[5] == "lost" and chain.length[5] == 2
    full = RelayChainLinks().resolve(pos, np.zeros(B, int), np.ones(B, int), choice, np.ones((B, 3)))
    assert STOP_REASONS[full.stop[0]] == "complete" and full.length[0] == 4
    np.testing.assert_allclose(full.hop_distance[0], [10.0, 10.0, 80.0])
    np.testing.assert_array_equal(full.next_hop(4)[0], [1, 2, 3, -1])
    np.testing.assert_array_equal(full.position_of(4)[0], [0, 1, 2, 3])
    budget = RelayChainLinks(max_hops=1).resolve(pos, np.zeros(B, int), np.ones(B, int), choice, np.ones((B, 3)))
    assert STOP_REASONS[budget.stop[4]] == "hop_budget" and np.all(budget.length == 2)
    lossy = RelayChainLinks(loss_at_zero=0.1, loss_length=20.0, hop_cost_per_m2=0.01)
    p = lossy.loss_probability(np.array([0.0, 10.0, 100.0]))
    assert p[0] == pytest.approx(0.1) and np.all(np.diff(p) > 0) and p[-1] < 1
    np.testing.assert_allclose(lossy.cost(np.array([10.0, np.nan])), [1.0, 0.0])
    for kwargs, field in (({"max_hops": 4}, "max_hops"), ({"loss_at_zero": 1.5}, "loss_at_zero"),
                          ({"comm_range": -1.0}, "comm_range"), ({"hop_cost_per_m2": -1.0}, "hop_cost_per_m2")):
        with pytest.raises(ValueError, match=field):
            RelayChainLinks(**kwargs).validate(4)
