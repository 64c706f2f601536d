"""Backends ``dnbp`` and ``range_ls``: per-step noise and velocity readings, and dnbp's range gate."""

import dataclasses

import numpy as np
import pytest

from coloc_env.backends.particles import Dnbp, RangeLs
from coloc_env.networks.broadcast import Broadcast
from coloc_env.worlds.gps_denied import GpsDenied

N, STEPS = 6, 4
STEP_NOISE = {"gps_std": 1.7, "range_std": 0.8, "accel_std": 0.05}  # the world's: 3, 2 and 0.3


def _world(batch=1, **fields):
    """A gps_denied world of ``batch`` copies of one episode (the same seed in every copy)."""
    world = GpsDenied(num_agents=N, horizon=STEPS + 1, **fields).build(batch, STEPS + 1)
    world.reset([np.random.default_rng(11) for _ in range(batch)], np.arange(batch))
    return world


def _readings(world, extra=None):
    """The world's readings of its steps, with ``extra`` added (each value repeated over the copies)."""
    out = []
    for _ in range(STEPS):
        r = world.readings(np.zeros((world.batch, N, 0), np.int64))
        r.extra = {key: np.repeat(np.asarray(value, float)[None], world.batch, axis=0)
                   for key, value in (extra or {}).items()}
        out.append(r)
        world.advance()
    return out


def _backend(config, world, seed=4, batch=1):
    network = Broadcast().build(N, batch, config.message_kind, config.rounds)
    backend = config.build(world, network, batch)
    idx = np.arange(batch)
    network.reset([np.random.default_rng(0) for _ in idx], idx)
    backend.reset([np.random.default_rng(seed + b) for b in idx], idx)
    return backend, network


def _run(backend, network, readings, batch=1):
    out = []
    for k, r in enumerate(readings):
        network.begin(np.full(batch, k), np.zeros((batch, N, 2)), np.ones((batch, N, backend.config.rounds), np.int64))
        backend.step(r, np.zeros((batch, N, 0)))
        out.append(backend.posterior_position.copy())
    return np.array(out)


@pytest.mark.parametrize("config", [Dnbp(num_particles=40), RangeLs(min_anchors=2)], ids=["dnbp", "range_ls"])
def test_per_step_noise_equals_a_backend_built_with_that_noise(config):
    """The readings' per-step sigmas act as the world's noise would: the same estimates, to 1e-9, as the backend
    built on a world with those sigmas, from the same start (its particles or KF) and generator."""
    readings = _readings(_world(), STEP_NOISE)
    plain = [dataclasses.replace(r, extra={}) for r in readings]
    stepped, net_a = _backend(config, _world())
    built, net_b = _backend(config, _world(gps_std=1.7, range_std=0.8, accel_noise_std=0.05))
    for name in ("prior", "prior_bandwidth", "belief") if isinstance(config, Dnbp) else ("mean", "cov"):
        getattr(built.state, name)[:] = getattr(stepped.state, name)
    a = _run(stepped, net_a, readings)
    b = _run(built, net_b, plain)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
    assert not np.allclose(a, _run(*_backend(config, _world()), plain))  # the sigmas matter here


@pytest.mark.parametrize("config", [Dnbp(num_particles=40), RangeLs()], ids=["dnbp", "range_ls"])
def test_velocity_reading_moves_the_prior_by_velocity_dt(config):
    """With sigma_acc = 0 and no acceleration input, the prediction moves each particle (the KF mean) by v dt and
    leaves its velocity at v (a KF velocity variance of 0)."""
    v = np.random.default_rng(2).normal(0.0, 5.0, (N, 2))
    world = _world()
    r = _readings(world, {"velocity": v, "accel_std": 0.0})[0]
    r.inputs[:] = 0.0
    backend, network = _backend(config, _world())
    _run(backend, network, [r])
    if isinstance(config, Dnbp):
        moved = backend.state.prior[0, ..., :2] - backend.state.belief[0, ..., :2]
        np.testing.assert_allclose(moved, np.broadcast_to(v[:, None] * world.dt, moved.shape), rtol=0, atol=1e-9)
        np.testing.assert_allclose(backend.state.prior[0, ..., 2:], np.broadcast_to(v[:, None], moved.shape),
                                   rtol=0, atol=1e-12)
    else:
        np.testing.assert_allclose(backend.state.mean[0, :, :2] - backend.estimate[0], v * world.dt, rtol=0,
                                   atol=1e-9)
        np.testing.assert_array_equal(backend.state.cov[0, :, 2:, 2:], 0.0)


@pytest.mark.parametrize("config", [Dnbp(num_particles=30), RangeLs(min_anchors=2)], ids=["dnbp", "range_ls"])
def test_per_copy_sigmas_act_as_each_copy_alone(config):
    """Two copies with different per-step sigmas: each gives what the same readings give at B = 1 with its own
    sigmas and its own generator (dnbp: the model holds a (B,) array of each sigma then)."""
    noise = [dict(STEP_NOISE), {"gps_std": 0.6, "range_std": 3.0, "accel_std": 0.4}]
    singles = [_run(*_backend(config, _world(), seed=4 + b), _readings(_world(), n)) for b, n in enumerate(noise)]
    both = _readings(_world(batch=2), STEP_NOISE)
    for r in both:
        for key in STEP_NOISE:
            r.extra[key][1] = noise[1][key]
    backend, network = _backend(config, _world(batch=2), batch=2)
    out = _run(backend, network, both, batch=2)
    for b in range(2):
        np.testing.assert_allclose(out[:, b], singles[b][:, 0], rtol=0, atol=1e-9)
    assert not np.allclose(singles[0], singles[1])  # the sigmas matter here
    if isinstance(config, Dnbp):
        np.testing.assert_array_equal(backend.model.range_std, [STEP_NOISE["range_std"], 3.0])


def test_range_gate_drops_a_misread_range_and_keeps_the_others():
    world = _world(range_std=0.5)
    r = _readings(world)[0]
    held = np.argwhere(r.range_valid[0])
    assert len(held) >= 2
    s, t = held[0]
    r.range[0, s, t] += 100.0  # metres off: a misread
    backend, network = _backend(Dnbp(num_particles=40, range_gate=10.83), _world(range_std=0.5))
    _run(backend, network, [r])
    expected = np.zeros((1, N, N), bool)
    expected[0, s, t] = True
    np.testing.assert_array_equal(backend.last_gated, expected)


def test_range_gate_is_checked():
    with pytest.raises(ValueError, match=r"backend.range_gate must be in \(0.0, 1000000000000.0\], got 0.0"):
        Dnbp(range_gate=0.0).check("backend.")
