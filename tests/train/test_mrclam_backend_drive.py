"""coloc reproduce mrclam drives the backends: its DCL (``ukf_se2``) and IL (``dead_reckoning``) are the
composition's, run by the ``mrclam`` world's replay, and still equal an independent UKF-CCL and time update."""

from __future__ import annotations

import numpy as np
import pytest

import coloc_env
import estimators.ukf_relay_se2 as se2
from coloc_env.data import mrclam, mrclam_noise
from tests.conftest import MRCLAM_DATASET6 as DATASET6
from tests.conftest import needs_mrclam

N = mrclam.NUM_ROBOTS
STEPS = 150  # 15 s: enough landmark sightings after robot-robot ones for the local and relayed UTs to part


def _ccl(d, model, gate):
    """UKF-CCL and dead reckoning written out here, over every line of ``d`` in file order."""
    from train.reproduce.mrclam import INITIAL_STD

    u = model.odometry(d, np.arange(d.steps))
    q = model.odometry_var(u)
    P0 = np.diag(np.tile(np.square(INITIAL_STD), N))
    x, P = d.groundtruth[0].copy(), P0.copy()
    x_il, P_il = x.copy(), P0.copy()
    xs, ps, il = [], [], []
    for k in range(d.steps):
        s = d.measurements_at(k)
        for r, sub, rg, b in zip(d.meas_robot[s], d.meas_subject[s], d.meas_range[s], d.meas_bearing[s], strict=True):
            z, R = np.array([rg, b]), model.measurement_cov(float(rg))
            if sub <= N:
                x, P, _ = se2.ccl_update(x, P, int(r), z, R, measured=int(sub) - 1, gate=gate)
            else:
                x, P, _ = se2.ccl_update(x, P, int(r), z, R, landmark=d.landmarks[sub - N - 1], gate=gate)
        xs.append(x)
        ps.append(P)
        il.append(x_il)
        x, P = se2.time_update(x, P, u[k], d.dt, q[k])
        x_il, P_il = se2.time_update(x_il, P_il, u[k], d.dt, q[k])
    return np.array(xs), np.array(ps), np.array(il)


@needs_mrclam
@pytest.mark.parametrize("inflate", [True, False])
def test_reproduction_dcl_through_the_backend_is_ccl(inflate):
    from train.reproduce import mrclam as reproduction

    d = mrclam.load_cached(DATASET6).window(0, STEPS)
    noise = mrclam_noise.calibrate_noise(d, mrclam_noise.calibration_seconds(d))
    messages = []
    result = reproduction.run_filters(d, noise, progress=messages.append, inflate_measurements=inflate)
    model = mrclam_noise.NoiseModel.from_calibration(noise, inflate_measurements=inflate)
    x, P, il = _ccl(d, model, reproduction.GATE)
    blocks = P.reshape(STEPS, N, 3, N, 3)[:, np.arange(N), :, np.arange(N), :].transpose(1, 0, 2, 3)
    np.testing.assert_allclose(result["estimate"]["DCL"], x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(result["cov"]["DCL"], blocks, rtol=0, atol=1e-9)
    np.testing.assert_allclose(result["estimate"]["IL"], il, rtol=0, atol=1e-9)
    assert result["max_abs_diff"] < 1e-9 and messages == ["step 0/150"]
    assert result["counts"]["landmark"] > 0 and result["counts"]["robot"] > 0


@needs_mrclam
def test_local_landmark_updates_are_a_different_estimator():
    """Why the reproduction relays landmark sightings: on [m] alone the UT spans 3 dimensions, not 3N."""
    from train.reproduce import mrclam as reproduction

    d = mrclam.load_cached(DATASET6).window(0, STEPS)
    noise = mrclam_noise.calibrate_noise(d, mrclam_noise.calibration_seconds(d))
    relayed = reproduction.run_filters(d, noise)["estimate"]["DCL"]
    spec = coloc_env.compose(world={"name": "mrclam", "data": DATASET6, "horizon": STEPS - 1, "start": 0,
                                    "calibration_s": noise["calibration_s"], "robot_sightings": "all"},
                             network="ideal", backend="ukf_se2")
    world = spec.world.build(1, spec.episode_steps)
    network = spec.network.build(N, 1, "chain")
    backend = spec.backend.build(world, network, 1)
    world.fixes_needed = False
    rngs = np.random.default_rng(0).spawn(3)
    world.reset(rngs[:1], np.arange(1))
    network.reset(rngs[1:2], np.arange(1))
    backend.reset(rngs[2:], np.arange(1))
    local = []
    for _ in range(STEPS):
        readings = world.readings(np.full((1, N, 1), N))
        network.begin(world.k, world.positions(), np.zeros((1, N, 0), np.int64))
        backend.update(readings, np.zeros((1, N, 0)))
        local.append(backend.estimate[0].copy())
        backend.predict(readings.inputs)
        world.advance()
    assert np.abs(np.array(local) - relayed).max() > 1e-6


def test_new_options_are_validated():
    with pytest.raises(ValueError, match="world.measurement_inflation"):
        coloc_env.compose(world={"name": "mrclam", "noise_model": "baseline", "measurement_inflation": False},
                          network="ideal", backend="ukf_se2")
    with pytest.raises(ValueError, match="world.robot_sightings"):
        coloc_env.compose(world={"name": "mrclam", "robot_sightings": "every"}, network="ideal", backend="ukf_se2")
    with pytest.raises(ValueError, match="backend.landmark_updates"):
        coloc_env.compose(world="mrclam", network="ideal", backend={"name": "ukf_se2", "landmark_updates": "all"})


@needs_mrclam
def test_run_filters_needs_the_run_or_a_prefix():
    from train.reproduce import mrclam as reproduction

    d = mrclam.load_cached(DATASET6).window(10, 50)
    with pytest.raises(ValueError, match="prefix"):
        reproduction.run_filters(d, mrclam_noise.calibrate_noise(d, 4.0))
