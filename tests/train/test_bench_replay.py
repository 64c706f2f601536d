"""The estimator rows that replay a backend's recorded estimator calls (train.bench): nlos_horizon, lossy_fusion and
bandwidth_fusion. relay_ukf's and mrclam_relay's are tested in test_cli.py."""

import dataclasses
import importlib

import numpy as np
import pytest

from train import bench
from train.bench import replay

# (preset, copies, steps): small batches; nlos_horizon's steps cross its D = 3 buffer, lossy_fusion's and
# bandwidth_fusion's take a little of their episodes
REPLAYED = [("nlos_horizon", 3, 6), ("lossy_fusion", 4, 8), ("bandwidth_fusion", 4, 8)]


def _shape(value):
    """The structure of an argument or result: array shapes and dtypes, through tuples, dicts and dataclasses."""
    if isinstance(value, np.ndarray):
        return ("array", value.shape, value.dtype.str)
    if isinstance(value, (tuple, list)):
        return tuple(_shape(v) for v in value)
    if isinstance(value, dict):
        return tuple((k, _shape(v)) for k, v in sorted(value.items()))
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        fields = dataclasses.fields(value)
        return (type(value).__name__, tuple((f.name, _shape(getattr(value, f.name))) for f in fields))
    return type(value).__name__


def _bits(value):
    """The result's bytes (NaN payloads and signed zeros included), for an exact comparison."""
    if isinstance(value, np.ndarray):
        return (value.shape, value.dtype.str, np.ascontiguousarray(value).tobytes())
    if isinstance(value, (tuple, list)):
        return tuple(_bits(v) for v in value)
    if isinstance(value, dict):
        return tuple((k, _bits(v)) for k, v in sorted(value.items()))
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return tuple(_bits(getattr(value, f.name)) for f in dataclasses.fields(value))
    return value


def _log_calls(patch, name, log):
    """Wrap each function of BACKEND_CALLS[name] where the backend looks it up: its outermost calls append
    (function, argument structure, argument bits before the call, result bits, whether the call left its
    arguments' bits as they were)."""
    depth = [0]
    for module_name, attribute in bench.BACKEND_CALLS[name]:
        module = importlib.import_module(module_name)
        fn = getattr(module, attribute)

        def logged(*args, _fn=fn, _name=attribute, **kwargs):
            outer = depth[0] == 0
            entry = (_name, _shape(args), _shape(kwargs), _bits(args), _bits(kwargs)) if outer else None
            depth[0] += 1
            try:
                out = _fn(*args, **kwargs)
            finally:
                depth[0] -= 1
            if outer:
                log.append((*entry, _bits(out), (_bits(args), _bits(kwargs)) == entry[3:]))
            return out

        patch.setattr(module, attribute, logged)


@pytest.mark.parametrize("name, batch, steps", REPLAYED)
def test_a_replayed_estimator_row_makes_the_envs_own_calls_with_the_envs_results(name, batch, steps, monkeypatch):
    """One cycle of the replay calls the functions the env's backend called over the same steps, in the same order,
    with the same arguments (structure and bits) and gets the env's results bit for bit. No call writes into its
    arguments, so recording them whole is faithful: the second cycle repeats the first."""
    import coloc_env

    _, tape = bench.record_backend_calls(name, batch, steps=steps)
    assert len(tape.steps) == steps and all(tape.steps)
    assert not tape.state  # pure functions: every argument recorded
    env_calls, replayed = [], []
    source = bench.ActionSource(name)
    venv = coloc_env.vector_env(name, num_envs=batch, seed=0)
    venv.reset()  # its calls (the first state) are not a step's
    with monkeypatch.context() as patch:
        _log_calls(patch, name, env_calls)
        for _ in range(steps):
            venv.step(source([venv.scenario]))
        venv.close()
    with monkeypatch.context() as patch:
        _log_calls(patch, name, replayed)
        step = bench.replay_step(tape)
        for _ in range(2 * steps):
            step()
    first, second = replayed[:len(replayed) // 2], replayed[len(replayed) // 2:]
    assert [c[:3] for c in first] == [c[:3] for c in env_calls]
    assert [c[0] for c in env_calls] == [key[1] for calls in tape.steps for key, _, _ in calls]
    assert all(c[-1] for c in env_calls + replayed)  # no argument written in place
    for k, (ours, theirs) in enumerate(zip(first, env_calls, strict=True)):
        assert ours[3:] == theirs[3:], f"call {k} ({ours[0]}) differs"
    assert first == second


def test_the_nlos_horizon_row_replays_the_afge_filter_of_every_step():
    """Each step of nlos_horizon's backend: the packet fixes, their fusion over the D + 1 buffered stamps, the
    re-run stacks of every horizon and the predictive costs, on the env's shapes (B, N, D + 1, J) and (B, N, S)."""
    import coloc_env

    B = 2
    _, tape = bench.record_backend_calls("nlos_horizon", B, steps=4)
    core = coloc_env.vector_env("nlos_horizon", num_envs=B, seed=0).scenario
    N, D, J, S = core.num_agents, core.D, core.J, core.S
    for calls in tape.shapes():
        names = [c[0] for c in calls]
        assert names == ["mode_weight", "packet_fixes", "fuse_packets", "buffer_estimates", "fused_fix",
                         "predictive_costs"]
        fuse, costs = calls[2], calls[5]
        assert fuse[1][1] == (B, N, D + 1, J) and fuse[1][6] == (B, N, D + 1)
        assert costs[1][2] == (B, N, S, 4, 4)
    stack = tape.steps[-1][3][1][1]  # buffer_estimates' final stack: a copy, not the backend's
    assert stack.info.shape == (B, N, S, 4, 4)


def test_recorded_arguments_are_copies_that_keep_their_layout():
    """A state dataclass is copied field by field (the backend writes into its arrays at a reset), a frozen model
    is passed as it is, and a broadcast argument stays a broadcast of the same values."""
    import estimators.afge as af

    stack = af.empty_stack((2, 3), 4)
    motion = af.MotionModel()
    lags = np.broadcast_to(np.arange(4)[None, None, :], (2, 3, 4))
    copied_stack, copied_motion, copied_lags = replay._copied((stack, motion, lags))
    stack.info[:] = 7.0
    assert copied_stack is not stack and not np.any(copied_stack.info == 7.0)
    assert copied_motion is motion
    assert copied_lags.strides[:2] == (0, 0) and np.array_equal(copied_lags, lags)
    assert not np.shares_memory(copied_lags, lags)
