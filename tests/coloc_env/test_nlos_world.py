"""World parts of nlos_horizon: path, orbits, RSA, RSS/AOA, LOS/NLOS chain, bounded delay."""

import numpy as np
import pytest

import estimators.afge as af
from coloc_env.networks.blocks.bounded_delay import BoundedRandomDelay
from coloc_env.worlds.blocks.flight import OrbitingNeighbours, TurnSchedulePath
from coloc_env.worlds.blocks.los_nlos import LosNlosChain
from coloc_env.worlds.blocks.radio import ReceiveSearchArea, RssAoaSensor, rsa_radii


def test_path_has_constant_speed_straight_legs_and_turns_by_rate_times_duration():
    path = TurnSchedulePath()
    path.validate()
    x = path.trajectory(1000)
    speed = np.linalg.norm(x[:, 2:], axis=1)
    np.testing.assert_allclose(speed, 20.0, rtol=1e-12)
    steps = np.linalg.norm(np.diff(x[:, :2], axis=0), axis=1)
    assert np.all(steps <= 20.0 + 1e-9) and np.all(steps > 19.9)  # chord of an arc <= arc length
    heading = np.unwrap(np.arctan2(x[:, 3], x[:, 2]))
    assert heading[200] == pytest.approx(0.0, abs=1e-12)
    assert heading[260] == pytest.approx(np.deg2rad(3.0) * 60, rel=1e-12)
    assert heading[560] == pytest.approx(0.0, abs=1e-9)
    # on a straight leg, the position moves by exactly v T along the heading
    np.testing.assert_allclose(x[301, :2] - x[300, :2], x[300, 2:], atol=1e-9)
    assert not path.in_turn(1000)[199] and path.in_turn(1000)[200] and not path.in_turn(1000)[260]
    shifted = path.trajectory(1000, start=(0.0, 100.0), shift=40)
    np.testing.assert_allclose(shifted[240:300, 2:], x[200:260, 2:], atol=1e-9)
    with pytest.raises(ValueError, match="turn_windows"):
        TurnSchedulePath(turn_windows=((5, 3),) * 4).validate()


def test_neighbours_orbit_inside_their_ranges_with_stratified_bearings():
    orbits = OrbitingNeighbours()
    orbits.validate()
    params = orbits.sample(np.random.default_rng(0), (500,))
    assert np.all((params.radius >= 150) & (params.radius <= 900))
    sector = np.floor(params.phase / (2 * np.pi / 8)).astype(int)
    np.testing.assert_array_equal(sector, np.broadcast_to(np.arange(8), (500, 8)))
    offsets = orbits.offsets(params, 50)
    assert offsets.shape == (50, 500, 8, 2)
    dist = np.linalg.norm(offsets, axis=-1)
    assert np.all(dist >= params.radius - params.wobble - 1e-9) and np.all(dist <= params.radius + params.wobble + 1e-9)
    with pytest.raises(ValueError, match="radius_range"):
        OrbitingNeighbours(radius_range=(900, 150)).validate()


def test_rsa_radii_invert_the_path_loss_and_the_area_is_an_annulus():
    sensor = RssAoaSensor(af.SignalModel())
    r_inf, r_sup = rsa_radii(20.0, -90.0, -35.0, 2.2, 2.4e9, 1.0)
    assert r_inf < r_sup
    assert sensor.mean_rss(r_sup) == pytest.approx(-90.0, abs=1e-9)
    assert sensor.mean_rss(r_inf) == pytest.approx(-35.0, abs=1e-9)
    area = ReceiveSearchArea(30.0, 1000.0)
    np.testing.assert_array_equal(area.contains([10.0, 30.0, 500.0, 1000.0, 1000.1]), [False, True, True, True, False])
    with pytest.raises(ValueError, match="r_inf"):
        ReceiveSearchArea(50.0, 40.0).validate()
    with pytest.raises(ValueError, match="p_max_dbm"):
        rsa_radii(20.0, -35.0, -90.0, 2.2, 2.4e9)


def test_nlos_weakens_the_rss_and_biases_the_aoa_by_the_configured_amounts():
    signal = af.SignalModel()
    sensor = RssAoaSensor(signal)
    sensor.validate()
    rng = np.random.default_rng(1)
    n = 200_000
    target, sender = np.array([500.0, 0.0]), np.zeros(2)
    white = rng.standard_normal((n, 2))
    rss_los, aoa_los = sensor.measure(target, sender, np.zeros(n), white)
    rss_nlos, aoa_nlos = sensor.measure(target, sender, np.ones(n), white)
    mean = sensor.mean_rss(500.0)
    assert rss_los.mean() == pytest.approx(mean, abs=0.03)
    assert rss_nlos.mean() == pytest.approx(mean - 6.0, abs=0.05)
    assert rss_nlos.std() == pytest.approx(np.hypot(2.0, 4.0), rel=0.01)
    assert aoa_los.mean() == pytest.approx(0.0, abs=1e-5)
    assert aoa_nlos.mean() == pytest.approx(np.deg2rad(1.0), abs=1e-4)
    # the estimator's correction with the true mode removes the bias
    _, _, r_hat = af.packet_fixes(signal, np.zeros((n, 2)), rss_nlos, aoa_nlos, np.ones(n))
    assert np.median(r_hat) == pytest.approx(500.0, rel=0.01)


def test_los_nlos_chain_is_stationary_at_pi_with_sojourn_one_over_p10():
    chain = LosNlosChain(0.3, 0.1)
    chain.validate()
    assert chain.p01 == pytest.approx(0.3 * 0.1 / 0.7)
    modes = chain.sample(np.random.default_rng(2), 4000, (200,))
    assert modes.mean() == pytest.approx(0.3, abs=0.01)
    assert modes[0].mean() == pytest.approx(0.3, abs=0.07)  # started from pi
    leave = (modes[:-1] == 1) & (modes[1:] == 0)
    assert leave.sum() / (modes[:-1] == 1).sum() == pytest.approx(0.1, abs=0.005)
    for kwargs, field in [({"p_nlos": 1.2}, "p_nlos"), ({"p10": -0.1}, "p10"), ({"p_nlos": 0.9, "p10": 0.5}, "p01"),
                          ({"p_nlos": 1.0, "p10": 0.1}, "p_nlos")]:
        with pytest.raises(ValueError, match=field):
            LosNlosChain(**kwargs).validate()


@pytest.mark.parametrize("p_nlos, p10", [(0.3, 0.1), (0.0, 0.5), (1.0, 0.0), (0.5, 0.9), (0.6, 0.6), (0.2, 1.0)])
def test_los_nlos_chain_sample_follows_its_recursion_step_by_step(p_nlos, p10):
    """sample() has no loop over steps; its modes are the recursion's, given the same uniforms. (0.5, 0.9) and
    (0.6, 0.6) have p01 > 1 - p10, where a step can flip the mode (the negating maps)."""
    chain = LosNlosChain(p_nlos, p10)
    chain.validate()
    for steps, size in ((1, ()), (2, (3,)), (400, (4, 8))):
        modes = chain.sample(np.random.default_rng(11), steps, size)
        u = np.random.default_rng(11).random((steps, *size))
        assert modes.dtype == np.int8 and modes.shape == u.shape
        expected = u[0] < p_nlos
        np.testing.assert_array_equal(modes[0], expected)
        for k in range(1, steps):
            expected = np.where(expected, u[k] < 1.0 - p10, u[k] < chain.p01)
            np.testing.assert_array_equal(modes[k], expected)


def test_bounded_delay_frequencies_and_losses():
    delay = BoundedRandomDelay()
    delay.validate()
    tau = delay.sample(np.random.default_rng(3), (400_000,))
    freq = np.bincount(tau, minlength=5) / len(tau)
    np.testing.assert_allclose(freq, [0.6, 0.2, 0.1, 0.05, 0.05], atol=0.003)
    assert tau.max() == delay.buffer_length + 1 == 4  # a lost packet's code is D + 1
    # each packet arrives at most once: at exactly one k = s + tau
    stamps = np.arange(len(tau[:1000]))
    arrivals = np.stack([delay.arrivals(tau[:1000], stamps, k) for k in range(1010)])
    assert arrivals.sum(axis=0).max() == 1
    np.testing.assert_array_equal(arrivals.sum(axis=0), tau[:1000] <= 3)
    for kwargs, field in [({"probabilities": (0.6, 0.5, 0.1, 0.0)}, "sum"), ({"probabilities": (1.0,)}, "entries"),
                          ({"probabilities": (-0.1, 0.5, 0.1, 0.1)}, "delay_probs")]:
        with pytest.raises(ValueError, match=field):
            BoundedRandomDelay(**kwargs).validate()


def test_the_radio_checks_its_angles_in_the_degrees_it_names():
    """The sensor holds its angles in radians but its fields are named (and given) in degrees."""
    import dataclasses

    from coloc_env.worlds.blocks.radio import RssAoaSensor
    from estimators.afge import SignalModel

    base = SignalModel()
    RssAoaSensor(dataclasses.replace(base, sigma_theta=np.radians(180.0))).validate()  # the bound itself is allowed
    with pytest.raises(ValueError, match=r"sigma_theta_deg must be in \(0(\.0)?, 180(\.0)?\], got 200"):
        RssAoaSensor(dataclasses.replace(base, sigma_theta=np.radians(200.0))).validate()
    with pytest.raises(ValueError, match=r"nlos_bias_deg must be in \[-180(\.0)?, 180(\.0)?\], got -190"):
        RssAoaSensor(dataclasses.replace(base, nlos_bias_theta=np.radians(-190.0))).validate()
