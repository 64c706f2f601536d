"""The compiled AFGE kernels compute what the numpy block form does.

:func:`estimators.afge.buffer_estimates` (the buffer re-run of every horizon and the
estimates) and :func:`estimators.afge.fuse_packets` (selection and complementary fusion) run
numba kernels where numba is installed; ``compiled=False`` is the numpy reference. Both are
held equal to 1e-9 here on delayed, partly empty buffers, on the Kalman form (no shift, a
per-element sigma_a^2, min_stamps = 0), and through a whole ``nlos_horizon`` rollout with
random actions (every step filters twice: the last mask, then the agent's).
"""

import numpy as np
import pytest

import coloc_env
import estimators.afge as af
import estimators.afge_kernels as afk

pytest.importorskip("numba")

TOL = {"rtol": 1e-9, "atol": 1e-9}


def _buffers(rng, shape, D, steps):
    """Fused observations (Y, y, gamma) per step for the D + 1 buffer stamps, some stamps empty."""
    out = []
    for _ in range(steps):
        A = rng.normal(size=(*shape, D + 1, 2, 2))
        Y = A @ np.swapaxes(A, -1, -2) * 0.05 + 0.01 * np.eye(2)
        y = (Y @ rng.normal(scale=50.0, size=(*shape, D + 1, 2, 1)))[..., 0]
        gamma = rng.random((*shape, D + 1)) < 0.7
        out.append((np.where(gamma[..., None, None], Y, 0.0), np.where(gamma[..., None], y, 0.0), gamma))
    return out


def _assert_stacks_equal(fast, slow):
    final_fast, *est_fast = fast
    final_slow, *est_slow = slow
    np.testing.assert_allclose(final_fast.info, final_slow.info, **TOL)
    np.testing.assert_allclose(final_fast.vector, final_slow.vector, **TOL)
    np.testing.assert_array_equal(final_fast.stamps, final_slow.stamps)
    for a, b in zip(est_fast[:2], est_slow[:2], strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * max(1.0, np.abs(b).max()))
    np.testing.assert_array_equal(est_fast[2], est_slow[2])


@pytest.mark.parametrize("stack_size, D", [(30, 3), (7, 0), (5, 4)])
def test_compiled_buffer_re_run_equals_the_numpy_stack(stack_size, D):
    """Copies at different times (k from -1 to 14: early stamps inactive), horizons shifted in,
    delayed packets re-filtered: the final stack, x, P and validity agree at every step."""
    rng = np.random.default_rng(stack_size + D)
    shape = (3, 2)
    motion = af.MotionModel()
    fast = slow = af.empty_stack(shape, stack_size)
    k0 = np.array([[0, -1], [3, 0], [1, 2]])
    for step, (Y, y, gamma) in enumerate(_buffers(rng, shape, D, 13)):
        k = k0 + step
        a = af.buffer_estimates(motion, fast, k, Y, y, gamma, compiled=True)
        b = af.buffer_estimates(motion, slow, k, Y, y, gamma, compiled=False)
        _assert_stacks_equal(a, b)
        fast, slow = a[0], b[0]
    assert slow.stamps.max() >= 2  # estimates existed, not only the placeholders


def test_compiled_kalman_form_equals_the_numpy_stack():
    """shift=False from a prior (S = 1), sigma_a^2 per element, min_stamps = 0 (run_kalman's call)."""
    rng = np.random.default_rng(7)
    shape, D = (4,), 2
    motion = af.MotionModel()
    prior = af.prior_stack(rng.normal(size=(*shape, 4)), np.diag([100.0, 100.0, 4.0, 4.0]))
    accel_var = rng.uniform(0.1, 4.0, size=shape)
    fast = slow = prior
    for step, (Y, y, gamma) in enumerate(_buffers(rng, shape, D, 10)):
        a = af.buffer_estimates(motion, fast, step, Y, y, gamma, shift=False, accel_var=accel_var, min_stamps=0,
                                compiled=True)
        b = af.buffer_estimates(motion, slow, step, Y, y, gamma, shift=False, accel_var=accel_var, min_stamps=0,
                                compiled=False)
        _assert_stacks_equal(a, b)
        fast, slow = a[0], b[0]


@pytest.mark.parametrize("shape", [(3, 4, 2, 5), (40, 4, 6, 8)])  # serial, and threaded from 4096 packets
def test_compiled_packet_fixes_equal_numpy(shape):
    """Mode weights 0, 1 and in between (known / blind / mean), senders shared by a stamp's packets."""
    rng = np.random.default_rng(shape[0])
    signal = af.SignalModel()
    sender = rng.normal(scale=300.0, size=(*shape[:-1], 1, 2))
    rss = rng.uniform(-95.0, -40.0, size=shape)
    aoa = rng.uniform(-np.pi, np.pi, size=shape)
    m = rng.choice([0.0, 1.0, signal.p_nlos], size=shape)
    fast = af.packet_fixes(signal, sender, rss, aoa, m, compiled=True)
    slow = af.packet_fixes(signal, sender, rss, aoa, m, compiled=False)
    for a, b in zip(fast, slow, strict=True):
        assert a.shape == b.shape
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=0)


@pytest.mark.parametrize("shape", [(3, 4), (1100, 4)])  # the serial kernel, and the threaded one from 4096
def test_compiled_predictive_costs_equal_numpy(shape):
    """From the estimates of a real buffer re-run (SPD covariances, invalid horizons among them) and
    fused fixes of which some share one R by broadcasting."""
    rng = np.random.default_rng(len(shape) + shape[0])
    motion = af.MotionModel()
    stack = af.empty_stack(shape, 12)
    for Y, y, gamma in _buffers(rng, shape, 2, 6):
        stack, x, P, valid = af.buffer_estimates(motion, stack, 5, Y, y, gamma)
    assert valid.any() and not valid.all()
    z = rng.normal(scale=50.0, size=(*shape, 2))
    A = rng.normal(size=(shape[-1], 2, 2))
    R = A @ np.swapaxes(A, -1, -2) + 0.5 * np.eye(2)  # (N, 2, 2): broadcast over the copies
    fast = af.predictive_costs(motion, x, P, valid, z, R, compiled=True)
    slow = af.predictive_costs(motion, x, P, valid, z, R, compiled=False)
    assert fast.shape == slow.shape == (*shape, 12)
    np.testing.assert_array_equal(np.isinf(fast), ~valid)
    np.testing.assert_allclose(fast[valid], slow[valid], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("weighting, n_strongest, min_packets", [("distance", 4, 1), ("information", 3, 2),
                                                                  ("distance", 8, 2)])
def test_compiled_fusion_equals_numpy_with_rss_ties_masks_and_delays(weighting, n_strongest, min_packets):
    rng = np.random.default_rng(n_strongest)
    signal = af.SignalModel()
    shape, J = (5, 4), 8
    rss = np.round(rng.uniform(-90, -60, size=(*shape, J)))  # whole dB: many exact ties
    rss[..., 3] = rss[..., 5]  # and certain ones (ties go to the lower index)
    aoa = rng.uniform(-np.pi, np.pi, size=(*shape, J))
    nav = rng.normal(scale=30.0, size=(*shape, J, 2))
    modes = rng.random((*shape, J)) < 0.3
    delays = rng.integers(0, 6, size=(*shape, J))
    lags = rng.integers(-1, 4, size=shape)
    keep = rng.random((*shape, J)) < 0.8
    args = (signal, rss, aoa, nav, modes, delays, lags, keep, n_strongest, "known", weighting, min_packets)
    fast = af.fuse_packets(*args, compiled=True)
    slow = af.fuse_packets(*args, compiled=False)
    np.testing.assert_array_equal(fast[3], slow[3])  # the packets used
    np.testing.assert_array_equal(fast[2], slow[2])  # gamma
    assert slow[2].any() and not slow[2].all()
    np.testing.assert_allclose(fast[0], slow[0], **TOL)
    np.testing.assert_allclose(fast[1], slow[1], rtol=1e-9, atol=1e-9 * np.abs(slow[1]).max())


def _rollout(steps=40, batch=4):
    env = coloc_env.vector_env("nlos_horizon", num_envs=batch, seed=3, horizon=60)
    out = [env.reset()]
    env.action_space.seed(5)
    for _ in range(steps):
        actions = np.stack([env.action_space.sample() for _ in range(env.num_envs)])
        observation, reward, _, _ = env.step(actions)
        out += [observation, reward]
    backend = env.scenario.backend
    pending = backend.pending
    return out + [pending["x"], pending["P"], backend.costs(pending, "predictive")]


def test_nlos_horizon_rollout_with_random_actions_equals_the_numpy_path(monkeypatch):
    fast = _rollout()
    monkeypatch.setattr(afk, "compiled_kernels", dict)  # as where numba is not installed: the numpy reference
    slow = _rollout()
    for a, b in zip(fast, slow, strict=True):
        a, b = np.asarray(a, float), np.asarray(b, float)
        finite = np.isfinite(b)
        np.testing.assert_array_equal(np.isfinite(a), finite)
        np.testing.assert_allclose(a[finite], b[finite], rtol=1e-9, atol=1e-9 * max(1.0, np.abs(b[finite]).max()))


def test_compiled_without_numba_and_an_unknown_weighting_are_refused(monkeypatch):
    motion = af.MotionModel()
    Y, y, gamma = _buffers(np.random.default_rng(0), (2,), 1, 1)[0]
    with pytest.raises(ValueError, match="weighting must be one of"):
        af.fuse_packets(af.SignalModel(), np.zeros(3), np.zeros(3), np.zeros((3, 2)), np.zeros(3, bool),
                        np.zeros(3, int), 0, np.ones(3, bool), 2, weighting="nearest")
    monkeypatch.setattr(afk, "compiled_kernels", dict)
    with pytest.raises(ValueError, match="compiled=True needs numba"):
        af.buffer_estimates(motion, af.empty_stack((2,), 4), 0, Y, y, gamma, compiled=True)


@pytest.mark.parametrize("name", ["buffer", "fuse", "costs", "fixes"])
def test_threaded_kernels_have_their_own_cache_entry(name):
    """numba files cached code by function name and signature, not by ``parallel``: a threaded form compiled
    from the serial function itself shared its entry and ran serial (estimators.compiled.in_namespace)."""
    serial, threaded = afk.compiled(name)
    assert threaded.py_func.__name__ == serial.py_func.__name__ + "_threaded"
    assert threaded.py_func.__qualname__ == serial.py_func.__qualname__ + "_threaded"  # what the cache files by
    assert threaded.targetoptions.get("parallel") and not serial.targetoptions.get("parallel")
