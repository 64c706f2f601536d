"""``coloc bench``: throughput of every registered scenario, measured in one run.

Per scenario, in env-steps per second (one copy advancing one time step with
all its agents; agent-steps = env-steps x N):

* ``parallel_env``  a Python loop over the PettingZoo env (B = 1);
* ``supersuit``     SuperSuit's ``concat_vec_envs_v1`` over B copies;
* ``vector_env``    coloc's batched SB3 VecEnv at B = 1, 64, 1024 (copy b plays
  the episode of seed b, as in training);
* ``vector_env, one episode``  the same with every copy playing episode 0, for
  the scenarios whose work per copy depends on the episode
  (``ONE_EPISODE_ROWS``: gps_denied_nbp), so that the rows at different B
  time the same work per copy and show what batching itself buys;
* ``estimator step``  the raw batched estimator step at the same B, where the
  scenario registers one in ``ESTIMATOR_STEPS``; the table's ``env / est.``
  column (``env_time_over_estimator`` in the JSON, on the vector_env row) is the
  env's time per step over it, so the env's overhead is read off directly.
  Every preset's row but gps_denied_nbp's replays the estimator calls its
  backend made in a recorded vector_env rollout at that B
  (``BACKEND_CALLS``, ``record_backend_calls``, ``replay_step``):
  the same functions on the same shapes and inputs as the env's step
  (relay_ukf, mrclam_relay, nlos_horizon, lossy_fusion, bandwidth_fusion).
  gps_denied_nbp's steps dNBP over its own sampled episode at the env's sizes;
* peers            for relay_ukf, filterpy's ``UnscentedKalmanFilter`` doing one
  full-chain range update one copy at a time (``PEERS``), beside our
  ``dcl_update`` doing the same update for the B copies at once;
* ``pcrb, one episode``  ``coloc_env.pcrb`` of one episode (its play, backend idle where it
  may be, and the recursion), in env-steps per second, beside the backend's step;
* ``vmas``          VMAS's batched ``simple_spread`` with 4 agents on the CPU at
  the same B, when ``vmas`` is installed (``pip install 'coloc[bench]'``).

Every env is driven by its ``paper`` policy's actions, computed once and tiled,
except where those change over an episode and use no measurement at reset
(relay_ukf, mrclam_relay: ``ActionSource``).
Writes ``OUT/bench/bench.json`` (atomic) and ``OUT/bench/throughput.png``.
No test asserts a speed: this is where speed is reported.

``coloc bench --against REF`` (``run_against``) measures the current
tree and a previous commit side by side in one run: REF is exported with
``git archive`` into a temporary folder, and per scenario the same rows are
measured for the current tree and for REF, each in its own subprocess of the
same interpreter with that tree first on ``sys.path`` (so the same installed
libraries, the same batches and the same machine load), in two alternating
rounds (current, REF, REF, current) keeping each row's best rate. Writes
``OUT/bench/against.json`` with both rates and the ratio current / REF per
(scenario, what, batch).
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import gc
import inspect
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable

import numpy as np

from coloc_env.config import BadInput
from train import hyperparams
from train.io import save_figure, write_json, write_text

BATCHES = (1, 64, 1024)
PCRB_ROW = "pcrb, one episode"  # the bound's computation (its own play of the episode and its recursion)


def _rate(fn: Callable[[], None], min_seconds: float, warm_up: int = 5) -> float:
    """Calls per second of ``fn`` over at least ``min_seconds`` (after warm-up calls and a full garbage
    collection: the setup of a large batch leaves a one-off collection of ~0.4 s that would otherwise land in
    the timed window, as timeit avoids by disabling the collector). ``warm_up`` calls, because a compiled
    kernel (the relay chains' numba pass) is compiled at its first use, which the first step of an episode
    may not reach (no platform measures at reset)."""
    for _ in range(warm_up):
        fn()
    gc.collect()
    count, start = 0, time.perf_counter()
    while True:
        fn()
        count += 1
        elapsed = time.perf_counter() - start
        if elapsed >= min_seconds:
            return count / elapsed


def _gps_denied_nbp_episode(batch: int, num_particles: int = 100):
    """(model, episode arrays stacked over B copies, initial dNBP state, per-copy generators) at the defaults."""
    import estimators.dnbp as dn
    from coloc_env.config import build_config
    from coloc_env.scenarios.gps_denied_nbp import GpsDeniedNbpConfig
    from coloc_env.worlds.gps_denied import sample_episode
    from train.reproduce.wan2014 import dnbp_model

    config = build_config(GpsDeniedNbpConfig, {"num_particles": num_particles})
    model = dnbp_model(config)
    episodes = [sample_episode(config.parts()[0], np.random.default_rng([0, b])) for b in range(batch)]
    rngs = [np.random.default_rng([1, b]) for b in range(batch)]
    stack = {k: np.stack([getattr(e, k) for e in episodes]) for k in
             ("gps_normal", "gps_fix", "adjacency", "ranges", "accel")}
    state = dn.initial_state(model, rngs, "warm", np.stack([e.init_position for e in episodes]),
                             np.stack([e.init_velocity for e in episodes]), config.velocity_spread)
    return config, model, stack, state, rngs


def _gps_denied_nbp_inputs(stack: dict, k: int) -> tuple:
    """dNBP's per-step inputs of step k: (gps_normal, gps_fix, deliver over the adjacency, ranges, accel)."""
    from coloc_env.primitives.broadcast_medium import BroadcastMedium

    return (stack["gps_normal"][:, k], stack["gps_fix"][:, k], BroadcastMedium().over(stack["adjacency"][:, k]),
            stack["ranges"][:, k], stack["accel"][:, k])


def _gps_denied_nbp_estimator_step(batch: int, num_particles: int = 100) -> Callable[[], None]:
    """One dNBP time step (``estimators.dnbp.step``, paper schedule) for B copies, cycling the episode."""
    import estimators.dnbp as dn

    config, model, stack, state, rngs = _gps_denied_nbp_episode(batch, num_particles)
    box = {"state": state, "k": 0}

    def step() -> None:
        k = box["k"] % config.horizon
        box["state"], _ = dn.step(model, box["state"], *_gps_denied_nbp_inputs(stack, k), rngs)
        box["k"] += 1

    return step


def _gps_denied_nbp_particle_rows(min_seconds: float, batch: int | None = None, steps: int | None = None
                                  ) -> list[dict]:
    """Time per fault-UAV step of dNBP (Table 1's unit) at M = 50, 100, 200, 300, over the first steps.

    B = 16 copies (the reproduction's batch) and 10 steps; 4 and 3 in quick mode.
    """
    import estimators.dnbp as dn

    quick = min_seconds < 1.0
    batch = batch or (4 if quick else 16)
    steps = steps or (3 if quick else 10)
    rows = []
    for M in (50, 100, 200, 300):
        config, model, stack, state, rngs = _gps_denied_nbp_episode(batch, M)
        dn.step(model, state, *_gps_denied_nbp_inputs(stack, 0), [np.random.default_rng(2) for _ in rngs])  # warm-up
        elapsed, fault_steps = 0.0, 0
        for k in range(steps):
            start = time.perf_counter()
            state, _ = dn.step(model, state, *_gps_denied_nbp_inputs(stack, k), rngs)
            elapsed += time.perf_counter() - start
            fault_steps += int((~stack["gps_normal"][:, k]).sum())
        rate = steps / elapsed
        rows.append({"scenario": "gps_denied_nbp", "what": f"dNBP step, M = {M}", "batch": batch,
                     "env_steps_per_s": rate * batch, "agent_steps_per_s": rate * batch * config.num_agents,
                     "time_per_fault_uav_step_s": elapsed / max(fault_steps, 1)})
    return rows


CONTENTION_BENCH = {"num_agents": 40, "batch": 8, "backend": "range_ls"}


def _contention_rows(min_seconds: float) -> list[dict]:
    """A ``contention`` step against a ``broadcast`` step in one run: gps_denied with N = 40 UAVs at the scaling
    rows' density (``scaling_world``), B = 8 copies, one slot, the same backend (``range_ls``: its update is
    cheap, so the rows show the network's own cost; a UKF's step would hide it) and the same actions, one UAV
    transmitting per step (k mod N), with which the two networks deliver the same messages (nothing collides):
    the same backend work, and ``time_over_broadcast`` is the contention step's time over the broadcast one's.
    A second pair plays ``always`` (every UAV transmits: on contention everything collides, so the backend
    fuses less there)."""
    import coloc_env

    N, B, backend = CONTENTION_BENCH["num_agents"], CONTENTION_BENCH["batch"], CONTENTION_BENCH["backend"]
    world = scaling_world(N, "fixed density")
    rows = []
    for schedule in ("one UAV per step", "always"):
        rates = {}
        for network in ("broadcast", {"name": "contention", "slots": 1}):
            venv = coloc_env.vector_env(coloc_env.compose(world=world, network=network, backend=backend),
                                        num_envs=B, seed=0)
            core = venv.scenario
            base = np.broadcast_to(core.action_vector("minimum" if schedule != "always" else "maximum"), (B, N, 1))
            box = {"k": 0}
            actions = [base.copy() for _ in range(N)]
            if schedule != "always":
                for k in range(N):
                    actions[k][:, k % N] = 1

            actions = [a.reshape(B * N, 1) for a in actions]  # the vec env's sub-envs: copies x agents

            def step(venv=venv, box=box, actions=actions) -> None:  # it resets a finished copy itself
                venv.step(actions[box["k"] % N])
                box["k"] += 1

            venv.reset()
            name = network if isinstance(network, str) else network["name"]
            rates[name] = _rate(step, min_seconds)
            venv.close()
        for name, rate in rates.items():
            row = {"scenario": "contention_localization",
                   "what": f"gps_denied/{name}/{backend} N = {N}, 1 slot, {schedule}", "batch": B,
                   "env_steps_per_s": rate * B, "agent_steps_per_s": rate * B * N}
            if name == "contention":
                row["time_over_broadcast"] = rates["broadcast"] / rate
            rows.append(row)
    return rows


# Scenarios too expensive per step for the default batches (dNBP: an M x M kernel per message): each preset's
# ``BENCH_BATCHES`` in train/hyperparams/<preset>.py.
SCENARIO_BATCHES: dict[str, tuple[int, ...]] = {name: tuple(batches) for name, batches
                                                in hyperparams.presets_declaring("BENCH_BATCHES").items()}
# Extra rows a scenario reports (name -> fn(min_seconds) -> rows).
EXTRA_BENCHES: dict[str, Callable[[float], list[dict]]] = {"gps_denied_nbp": _gps_denied_nbp_particle_rows,
                                                           "contention_localization": _contention_rows}
# Scenarios whose work per copy depends on the episode (dNBP: how many messages arrive, how many proposals the
# truncated kernel prunes): a vector_env of B copies plays episodes 0..B-1, so its rows at B = 1 and B = 4 time
# different work. These also get a row with every copy playing episode 0 (ONE_EPISODE), where only B changes
# (a preset's ``BENCH_ONE_EPISODE`` in train/hyperparams/<preset>.py).
ONE_EPISODE_ROWS = tuple(name for name, on in hyperparams.presets_declaring("BENCH_ONE_EPISODE").items() if on)
ONE_EPISODE = "vector_env, one episode"
# what one_episode_rate and _rate's sources need where --against runs them in a reference tree's process
_ONE_EPISODE_PREAMBLE = "from __future__ import annotations\nimport gc\nimport time\n\nimport numpy as np\n\n"


def one_episode_rate(coloc_env, name: str, batch: int, paper: np.ndarray, min_seconds: float) -> float:
    """Steps per second (``_rate``) of ``vector_env(name, num_envs=batch)`` with every copy seeded 0 (the same
    episode in each copy) and the paper actions ``paper`` (N, ...) tiled: constant actions only (gps_denied_nbp's).

    ``coloc bench --against`` also runs this source and ``_rate``'s in the reference tree's process, on that
    tree's coloc_env, for a tree whose bench has no such row: they use only their arguments, numpy, gc and time.
    It sets the env's ``_copy_seeds``, from which every version of the batched VecEnv reseeds copy b at reset."""
    venv = coloc_env.vector_env(name, num_envs=batch, seed=0)
    venv._copy_seeds = [0] * batch
    venv.reset()
    tiled = np.tile(paper, (batch, *([1] * (paper.ndim - 1))))
    try:
        return _rate(lambda: venv.step(tiled), min_seconds)
    finally:
        venv.close()


def _relay_ukf_inputs(batch: int, platforms: int = 4):
    rng = np.random.default_rng(0)
    estimate = rng.normal(scale=20.0, size=(batch, platforms, 2))
    root = rng.normal(scale=0.3, size=(batch, 2 * platforms, 2 * platforms))
    cov = root @ np.swapaxes(root, -1, -2) + 0.1 * np.eye(2 * platforms)
    z = np.linalg.norm(estimate[:, 0] - estimate[:, 1], axis=-1) + 0.5
    return estimate, cov, z


def _relay_ukf_full_chain_update(batch: int, platforms: int = 4) -> Callable[[], None]:
    """One UKF-DCL range update relayed along the full chain 0 -> 1 -> 2 -> 3 for B copies, on synthetic
    dense covariances: the work of the filterpy peer, not the env's step (that is the estimator row)."""
    import estimators.ukf_relay as ukf

    estimate, cov, z = _relay_ukf_inputs(batch, platforms)
    chain = np.broadcast_to(np.arange(platforms), (batch, platforms))

    def step() -> None:
        ukf.dcl_update(estimate, cov, chain, np.full(batch, platforms), z, 1.0)

    return step


def _relay_ukf_filterpy_loop(batch: int, platforms: int = 4) -> Callable[[], None]:
    """The same range update by filterpy's ``UnscentedKalmanFilter``, one copy at a time (the peer)."""
    from train.reproduce.wang2019 import filterpy_ccl_update

    estimate, cov, z = _relay_ukf_inputs(batch, platforms)

    def step() -> None:
        for b in range(batch):
            filterpy_ccl_update(estimate[b], cov[b], 0, 1, float(z[b]), 1.0)

    return step


# Peers measured beside a scenario's estimator, each after the row of our estimator doing the peer's work:
# (label, factory(batch) -> step callable, our label, our factory).
PEERS: dict[str, tuple[str, Callable[[int], Callable[[], None]], str, Callable[[int], Callable[[], None]]]] = {
    "relay_ukf": ("filterpy UnscentedKalmanFilter loop", _relay_ukf_filterpy_loop,
                  "UKF-DCL full-chain update (peer's work)", _relay_ukf_full_chain_update),
}


# --- estimator rows that replay the env's own estimator calls ---------------------------------------------------
# Per preset, the estimator functions its backend calls in a step, where the backend looks them up
# (module, attribute), with the names of the leading arguments that are the backend's own state arrays
# (updated in place; empty: a pure function, every argument recorded) and whether the function returns
# new values of them (the backend assigns them into its arrays) or updates them in place.
BACKEND_CALLS: dict[str, dict[tuple[str, str], tuple[tuple[str, ...], bool]]] = {
    "relay_ukf": {("estimators.ukf_relay", "range_updates"): (("estimate", "cov"), False),
                  ("estimators.ukf_relay", "fix_updates"): (("estimate", "cov"), False),
                  ("estimators.ukf_relay", "dcl_update"): ((), False),
                  ("coloc_env.backends.ukf", "predict_joint"): ((), False)},
    # ukf_ccl at the centre: the same joint-UKF updates as relay_ukf's, without the chains
    "contention_localization": {("estimators.ukf_relay", "range_updates"): (("estimate", "cov"), False),
                                ("estimators.ukf_relay", "fix_updates"): (("estimate", "cov"), False),
                                ("coloc_env.backends.ukf", "predict_joint"): ((), False)},
    "mrclam_relay": {("estimators.ukf_relay_se2", "dcl_update_rows"): (("estimate", "P_ii", "phi", "sigma"), False),
                     ("estimators.ukf_relay_se2", "time_update_batch"): (("estimate", "P_ii", "phi"), True)},
    # The afge backend's estimator math. Every one returns new arrays and writes into none of its arguments, and
    # the backend replaces (never updates in place) its stack and last estimates, so all are recorded whole.
    # Left out: ahg_group, which the backend calls only to lay out the observation's AHG group (the env's view),
    # and its inline prediction (two batched 4 x 4 products, no function to record). The preset never calls
    # in_sample_costs, smooth_costs or ahg_select (predictive costs; its agent, not the backend, runs AHG),
    # listed for the backend's other settings.
    "nlos_horizon": {("estimators.afge", name): ((), False) for name in (
        "mode_weight", "packet_fixes", "fuse_packets", "buffer_estimates", "fused_fix", "predictive_costs",
        "in_sample_costs", "smooth_costs", "ahg_select")},
    # Both return a new state and leave the one passed unchanged; node_covariances is the view of the exact
    # covariance the backend reports every step.
    "lossy_fusion": {("estimators.lossy_fusion", "distributed_step"): ((), False)},
    "bandwidth_fusion": {("estimators.bandwidth_fusion", "step"): ((), False),
                         ("estimators.bandwidth_fusion", "node_covariances"): ((), False)},
}
REPLAY_SAMPLES = 2048  # env-steps recorded for a replay: 2048 / B steps, at least 8, at most one episode


def _copied(value):
    if isinstance(value, np.ndarray):
        if any(stride == 0 and size > 1 for stride, size in zip(value.strides, value.shape, strict=True)):
            # a broadcast argument stays one: the kernels' _flat copies it to full size, and a replay handed
            # the full array would skip that copy
            compact = value[tuple(slice(0, 1) if stride == 0 else slice(None) for stride in value.strides)]
            return np.broadcast_to(compact.copy(), value.shape)
        return value.copy()
    if isinstance(value, (tuple, list)):
        return type(value)(_copied(v) for v in value)
    if isinstance(value, dict):
        return {k: _copied(v) for k, v in value.items()}
    if dataclasses.is_dataclass(value) and not isinstance(value, type) and not value.__dataclass_params__.frozen:
        # an estimator's state (HorizonStack, FusionState, DistributedState): the backend may later write into
        # the arrays it passed (a reset assigns rows in place); frozen ones are models, read only
        out = copy.copy(value)
        for field in dataclasses.fields(value):
            object.__setattr__(out, field.name, _copied(getattr(value, field.name)))
        return out
    return value


class BackendTape:
    """The calls a preset's backend made into its estimator functions (``BACKEND_CALLS``) over the steps
    of a vector_env rollout: ``steps[t]`` lists step t's calls in order, each ``(key, args, kwargs)`` with
    copies of the arguments as they were at the call, the state arguments left out; ``state`` holds a copy
    of each state array as the first call that passed it saw it (the state before the first step)."""

    def __init__(self, calls: dict):
        self.calls = calls
        self.steps: list[list[tuple]] = []
        self.state: dict[str, np.ndarray] = {}
        self._state_ids: dict[str, int] = {}

    def record(self, key, args, kwargs) -> None:
        names, _ = self.calls[key]
        for name, value in zip(names, args, strict=False):
            if name not in self._state_ids:
                self._state_ids[name], self.state[name] = id(value), value.copy()
            elif id(value) != self._state_ids[name]:
                raise RuntimeError(f"{key[1]}: the backend passed a new {name} array; a replay needs one")
        self.steps[-1].append((key, _copied(args[len(names):]), _copied(kwargs)))

    def shapes(self) -> list[list[tuple]]:
        """Per step, each call's (function name, shapes of its array arguments): what the test compares."""
        def shape(v):
            return np.shape(v) if isinstance(v, np.ndarray) else None
        return [[(key[1], tuple(shape(a) for a in args), tuple((k, shape(v)) for k, v in sorted(kwargs.items())))
                 for key, args, kwargs in step] for step in self.steps]


def record_backend_calls(name: str, batch: int, steps: int | None = None, seed: int = 0,
                         source: ActionSource | None = None):
    """Step a ``vector_env(name)`` of ``batch`` copies with the actions of its vector_env row (``ActionSource``)
    for ``steps`` steps (default ``REPLAY_SAMPLES`` / B, at least 8, at most one episode), recording
    its backend's estimator calls. Returns (the env, after those steps; the ``BackendTape``)."""
    import importlib

    import coloc_env

    calls = BACKEND_CALLS[name]
    source = source or ActionSource(name)
    venv = coloc_env.vector_env(name, num_envs=batch, seed=seed)
    venv.reset()
    horizon = int(venv.scenario.horizon)
    steps = steps or min(horizon, max(8, -(-REPLAY_SAMPLES // batch)))
    if steps > horizon:
        raise BadInput(f"record at most one episode ({horizon} steps), got {steps}")
    tape = BackendTape(calls)
    patched, depth = [], [0]

    def wrap(key, fn):
        def recorded(*args, **kwargs):
            if depth[0] == 0:  # the backend's call, not one the estimator makes of another recorded function
                tape.record(key, args, kwargs)
            depth[0] += 1
            try:
                return fn(*args, **kwargs)
            finally:
                depth[0] -= 1
        return recorded

    try:
        for key in calls:
            module = importlib.import_module(key[0])
            patched.append((module, key[1], getattr(module, key[1])))
            setattr(module, key[1], wrap(key, patched[-1][2]))
        for _ in range(steps):
            tape.steps.append([])
            venv.step(source([venv.scenario]))
    finally:
        for module, attribute, fn in reversed(patched):
            setattr(module, attribute, fn)
    return venv, tape


def replay_step(tape: BackendTape) -> Callable[[], None]:
    """One env step's estimator calls per call, cycling over the tape's steps: the recorded arguments, with
    the state arrays (copies of the recorded start) carried from call to call as the backend carries its
    own, restored to the start when the cycle begins again (as the env resets). Each function is looked up
    where the backend looks it up, at each call."""
    import importlib

    modules = {key: importlib.import_module(key[0]) for key in tape.calls}
    state = {name: value.copy() for name, value in tape.state.items()}
    box = {"t": 0}

    def step() -> None:
        t = box["t"]
        if t == 0:
            for name, value in tape.state.items():
                np.copyto(state[name], value)
        for key, args, kwargs in tape.steps[t]:
            names, returns_state = tape.calls[key]
            out = getattr(modules[key], key[1])(*(state[n] for n in names), *args, **kwargs)
            if returns_state:
                for n, value in zip(names, out, strict=True):
                    state[n][...] = value
        box["t"] = (t + 1) % len(tape.steps)

    step.state = state  # the replayed state arrays (the test compares them with the env's)
    return step


def _replayed_estimator_step(name: str) -> Callable[[int], Callable[[], None]]:
    """The estimator row of a preset in ``BACKEND_CALLS``: its backend's estimator calls recorded from a
    vector_env of B copies driven as its vector_env row is, replayed (``replay_step``)."""

    def factory(batch: int) -> Callable[[], None]:
        venv, tape = record_backend_calls(name, batch)
        venv.close()
        return replay_step(tape)

    factory.__doc__ = f"{name}: the env's own estimator calls, recorded and replayed"
    return factory


ESTIMATOR_STEPS: dict[str, Callable[[int], Callable[[], None]]] = {
    **{name: _replayed_estimator_step(name) for name in BACKEND_CALLS},
    "gps_denied_nbp": _gps_denied_nbp_estimator_step,
}


def _paper_actions(name: str) -> np.ndarray:
    """The paper policy's actions at reset, (N, *action_shape), in agent order."""
    import agents
    import coloc_env

    env = coloc_env.parallel_env(name)
    observations, _ = env.reset(seed=0)
    actions = agents.make_policy("paper", env).act(observations)
    return np.stack([np.asarray(actions[a]) for a in env.possible_agents])


class ActionSource:
    """The actions that drive a preset's env rows and its recorded estimator calls: ``source(cores)`` gives
    the actions (sum of the cores' batches x N, *shape) of the next step of the given scenario cores.

    By default the paper policy's actions at reset, tiled: bandwidth_fusion's, lossy_fusion's and
    gps_denied_nbp's do not change over an episode (nlos_horizon's AHG horizon does; it is tiled from
    reset too). relay_ukf's and mrclam_relay's change, and their reset actions use no measurement at all
    (only the measuring platform ranges, and at reset none measures; at its first step no robot recorded
    another), so those envs did no range update in the bench; they are driven by the paper's work instead:

    * ``relay_ukf``: platform i ranges with i + 1 and relays to i + 1 (mod N), fixed: every measurement the
      world draws is ranged and its chain m -> m + 1 -> ... reaches all N platforms, the paper's complete
      chain (the paper's partner is random, the work the same);
    * ``mrclam_relay``: the paper policy's actions at each copy's data step (a table over the run's steps
      made by ``agents.mrclam_relay.paper_actions`` from the recorded flags its observation shows),
      looked up per step.
    """

    def __init__(self, name: str):
        self.name = name
        self.paper = _paper_actions(name)
        self.num_agents = self.paper.shape[0]
        self._tiles: dict[int, np.ndarray] = {}
        self._table: np.ndarray | None = None
        if name == "relay_ukf":
            N = self.num_agents
            ring = (np.arange(N) + 1) % N
            self.paper = np.stack([ring, ring], axis=-1).astype(self.paper.dtype)

    def constant(self) -> bool:
        return self.name != "mrclam_relay"

    def tiled(self, batch: int) -> np.ndarray:
        if batch not in self._tiles:
            self._tiles[batch] = np.tile(self.paper, (batch, *([1] * (self.paper.ndim - 1))))
        return self._tiles[batch]

    def table(self, core) -> np.ndarray:
        """mrclam_relay: the paper policy's actions (T, N, 1 + N) at every data step of the run."""
        if self._table is None:
            from agents.mrclam_relay import paper_actions

            N = self.num_agents
            self._table = paper_actions(core.world.tables.first_index[:, :N, :N] >= 0)
        return self._table

    def __call__(self, cores) -> np.ndarray:
        if self.constant():
            return self.tiled(sum(core.batch for core in cores))
        steps = np.concatenate([core.world.absolute_step() for core in cores])
        table = self.table(cores[0])
        return table[np.minimum(steps, len(table) - 1)].reshape(-1, *table.shape[2:])


def _supersuit_cores(venv) -> list:
    return [markov_env.par_env.scenario for markov_env in venv.venv.venv.vec_envs]


def bench_scenario(name: str, min_seconds: float, batches=BATCHES) -> list[dict]:
    import coloc_env
    from train.training import make_supersuit_vec_env, seed_supersuit_vec_env

    rows: list[dict] = []
    source = ActionSource(name)
    num_agents = source.num_agents
    batches = SCENARIO_BATCHES.get(name, batches)

    def add(what: str, batch: int, calls_per_s: float) -> None:
        rows.append({"scenario": name, "what": what, "batch": batch, "env_steps_per_s": calls_per_s * batch,
                     "agent_steps_per_s": calls_per_s * batch * num_agents})

    env = coloc_env.parallel_env(name)
    env.reset(seed=0)

    def loop_step() -> None:
        if not env.agents:
            env.reset()
        actions = source([env.scenario])
        env.step({a: actions[i] for i, a in enumerate(env.possible_agents)})

    add("parallel_env loop", 1, _rate(loop_step, min_seconds))

    supersuit_batch = min(64, max(batches))
    supersuit = make_supersuit_vec_env(name, supersuit_batch, {})
    seed_supersuit_vec_env(supersuit, 0)
    supersuit.reset()
    cores = _supersuit_cores(supersuit)
    add("supersuit concat_vec_envs_v1", supersuit_batch, _rate(lambda: supersuit.step(source(cores)), min_seconds))
    supersuit.close()

    for batch in batches:
        venv = coloc_env.vector_env(name, num_envs=batch, seed=0)
        venv.reset()
        core = [venv.scenario]
        add("vector_env", batch, _rate(lambda venv=venv, core=core: venv.step(source(core)), min_seconds))
        venv.close()
        if name in ONE_EPISODE_ROWS:
            add(ONE_EPISODE, batch, one_episode_rate(coloc_env, name, batch, source.paper, min_seconds))
        if name in ESTIMATOR_STEPS:
            add("estimator step", batch, _rate(ESTIMATOR_STEPS[name](batch), min_seconds))
        if name in PEERS:
            label, factory, ours, our_factory = PEERS[name]
            add(ours, batch, _rate(our_factory(batch), min_seconds))
            add(label, batch, _rate(factory(batch), min_seconds))
    # the posterior Cramér-Rao bound of one episode (coloc_env.pcrb: the play and the recursion), per env-step
    steps = coloc_env.make_core(name, batch=1).horizon
    add(PCRB_ROW, 1, steps * _rate(lambda: coloc_env.pcrb(name, episodes=1, seed=0), min_seconds))
    if name in EXTRA_BENCHES:
        rows += EXTRA_BENCHES[name](min_seconds)
    return rows


def bench_vmas(min_seconds: float, batches=BATCHES) -> list[dict]:
    """VMAS's batched simple_spread (4 agents, CPU), the leading batched simulator, if installed."""
    try:
        import torch
        import vmas
    except ImportError:
        return []
    rows = []
    for batch in batches:
        env = vmas.make_env("simple_spread", num_envs=batch, device="cpu", continuous_actions=True, n_agents=4,
                            seed=0)
        env.reset()
        actions = [torch.zeros(batch, 2) for _ in range(4)]
        rate = _rate(lambda env=env, actions=actions: env.step(actions), min_seconds)
        rows.append({"scenario": "vmas simple_spread", "what": "vmas (torch, CPU)", "batch": batch,
                     "env_steps_per_s": rate * batch, "agent_steps_per_s": rate * batch * 4})
    return rows


REFERENCE_SCENARIOS = ("vmas simple_spread",)  # drawn in every panel as a grey reference, not a panel of its own


def _figure(rows: list[dict], path: str) -> None:
    """One panel per preset (its env rows, estimator step and peers, each line labelled in the
    panel's own short legend, below the panel), VMAS as a dashed grey reference in every panel: a
    single axes with every series in one legend (26 entries) hid the lines it described."""
    import math

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    series: dict[str, dict[str, list[tuple[int, float]]]] = {}
    for row in rows:
        series.setdefault(row["scenario"], {}).setdefault(row["what"], []).append(
            (row["batch"], row["env_steps_per_s"]))
    panels = [name for name in series if name not in REFERENCE_SCENARIOS]
    references = {name: series[name] for name in REFERENCE_SCENARIOS if name in series}
    columns = min(3, max(1, len(panels)))
    lines = max(1, math.ceil(len(panels) / columns))
    from train.plotting import label, plain_log_ticks

    # one colour per series across panels (a series keeps its colour wherever it appears)
    names = list(dict.fromkeys(what for name in panels for what in series[name]))
    colour = {what: f"C{k % 10}" for k, what in enumerate(names)}
    fig, axes = plt.subplots(lines, columns, figsize=(5.2 * columns, 5.0 * lines), squeeze=False)
    for ax, name in zip(axes.flat, panels, strict=False):
        for what, points in series[name].items():
            points.sort()
            batches, rates = zip(*points, strict=True)
            # a single point (a dNBP size M, a peer at one B) as an open marker of its own colour, no line
            # (dNBP's sizes M, all at one B, as triangles: the colour cycle repeats past ten series)
            style = "o-" if len(points) > 1 else ("^" if what.startswith("dNBP step") else "D")
            ax.loglog(batches, rates, style, color=colour[what], label=what, markersize=4 if len(points) > 1 else 5,
                      markerfacecolor=None if len(points) > 1 else "none")
        for ref_name, whats in references.items():
            for what, points in whats.items():
                points.sort()
                batches, rates = zip(*points, strict=True)
                ax.loglog(batches, rates, "--", color="0.6", linewidth=1, label=f"{ref_name} ({what})")
        ax.set_title(name, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.set_xlabel(label("batch B", "copies"), fontsize=8)
        plain_log_ticks(ax, "x")
        plain_log_ticks(ax, "y")
        # below the panel, not on it: inside, the legend of a panel with five or more lines covered them
        ax.legend(fontsize=6.5, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2, frameon=False)
    for ax in axes.flat:
        ax.set_ylabel(label("throughput", "env-steps/s"), fontsize=8)
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    fig.suptitle(f"coloc bench: throughput vs batch size ({os.cpu_count()}-core CPU)")
    fig.tight_layout()
    save_figure(path, fig)


def add_overheads(rows: list[dict]) -> None:
    """On each vector_env row with an estimator row of the same scenario and batch: ``env_time_over_estimator``,
    the env's time per step over the estimator step's (the estimator's rate over the env's; 1 = no overhead)."""
    estimator = {(r["scenario"], r["batch"]): r["env_steps_per_s"] for r in rows if r["what"] == "estimator step"}
    for row in rows:
        key = (row["scenario"], row["batch"])
        if row["what"] == "vector_env" and key in estimator and row["env_steps_per_s"] > 0:
            row["env_time_over_estimator"] = estimator[key] / row["env_steps_per_s"]


def run(out: str, quick: bool = False, scenarios: list[str] | None = None) -> list[dict]:
    from rich.console import Console
    from rich.table import Table

    import coloc_env

    min_seconds = 0.15 if quick else 1.5
    names = scenarios or list(coloc_env.SCENARIOS)
    console = Console()
    rows: list[dict] = []
    with console.status("benchmarking") as status:
        for name in names:
            status.update(f"benchmarking {name}")
            rows += bench_scenario(name, min_seconds)
        status.update("benchmarking vmas (if installed)")
        rows += bench_vmas(min_seconds)
    add_overheads(rows)
    table = Table(title="coloc bench (env-step: one copy advancing one step with all its agents; "
                        "env / est.: the vector_env's time per step over its estimator step's)")
    for column in ("scenario", "what", "B", "env-steps/s", "agent-steps/s", "env / est."):
        table.add_column(column, justify="right" if column != "what" and column != "scenario" else "left")
    for row in rows:
        overhead = row.get("env_time_over_estimator")
        table.add_row(row["scenario"], row["what"], str(row["batch"]), f"{row['env_steps_per_s']:,.0f}",
                      f"{row['agent_steps_per_s']:,.0f}", "" if overhead is None else f"{overhead:.2f}x")
    console.print(table)
    for row in rows:
        if "time_over_broadcast" in row:
            console.print(f"{row['scenario']} {row['what']} (B = {row['batch']}): a contention step takes "
                          f"{row['time_over_broadcast']:.2f}x a broadcast step")
        if "time_per_fault_uav_step_s" in row:
            console.print(f"{row['scenario']} {row['what']} (B = {row['batch']}): "
                          f"{1e3 * row['time_per_fault_uav_step_s']:.1f} ms per fault-UAV step")
    folder = os.path.join(out, "bench")
    write_json(os.path.join(folder, "bench.json"), {"quick": quick, "cpu_count": os.cpu_count(), "rows": rows})
    _figure(rows, os.path.join(folder, "throughput.png"))
    return rows


# --- coloc bench --against REF ----------------------------------------------------------------------------------
# Run in a subprocess with a tree first on sys.path: that tree's bench_scenario over the given batches, rows to a file.
# Only names that every version of train/bench.py has are used (bench_scenario, SCENARIO_BATCHES, EXTRA_BENCHES).
_DRIVER = """
import json, sys
spec = json.loads(sys.argv[1])
import train, train.bench as bench
bench.SCENARIO_BATCHES = {spec["name"]: tuple(spec["batches"])}
if not spec["extras"]:
    bench.EXTRA_BENCHES = {}
rows = bench.bench_scenario(spec["name"], spec["min_seconds"], tuple(spec["batches"]))
if spec["name"] in spec["one_episode"] and not hasattr(bench, "ONE_EPISODE_ROWS"):  # a tree before that row
    import coloc_env
    space = {}
    exec(spec["one_episode_source"], space)
    paper = bench._paper_actions(spec["name"])
    for batch in spec["batches"]:
        rate = space["one_episode_rate"](coloc_env, spec["name"], batch, paper, spec["min_seconds"])
        rows.append({"scenario": spec["name"], "what": spec["one_episode_label"], "batch": batch,
                     "env_steps_per_s": rate * batch, "agent_steps_per_s": rate * batch * paper.shape[0]})
with open(spec["out"], "w") as f:
    json.dump({"source": train.__file__, "rows": rows}, f)
"""


def repository_root() -> str:
    """The git work tree this package is imported from."""
    here = os.path.dirname(os.path.abspath(__file__))
    return subprocess.run(["git", "-C", here, "rev-parse", "--show-toplevel"], check=True, capture_output=True,
                          text=True).stdout.strip()


def export_commit(ref: str, folder: str, root: str | None = None) -> str:
    """Write the tree of commit ``ref`` into ``folder`` (``git archive``: the repository is only read);
    returns the full commit id."""
    root = root or repository_root()
    commit = subprocess.run(["git", "-C", root, "rev-parse", "--verify", f"{ref}^{{commit}}"], check=True,
                            capture_output=True, text=True).stdout.strip()
    archive = subprocess.run(["git", "-C", root, "archive", "--format=tar", commit], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", folder], input=archive, check=True)
    return commit


def bench_tree(tree: str, name: str, min_seconds: float, batches, extras: bool = True,
               timeout: float | None = None) -> dict:
    """Rows of ``tree``'s ``bench_scenario(name)`` measured in a subprocess with ``tree`` first on sys.path.

    Returns {"rows": [...], "source": the imported train/__init__.py} or {"error": text} when that tree
    cannot run the scenario (e.g. it did not exist there)."""
    with tempfile.TemporaryDirectory(prefix="coloc-bench-") as scratch:
        out = os.path.join(scratch, "rows.json")
        spec = {"name": name, "min_seconds": min_seconds, "batches": list(batches), "extras": extras, "out": out,
                "one_episode": list(ONE_EPISODE_ROWS), "one_episode_label": ONE_EPISODE,
                "one_episode_source": _ONE_EPISODE_PREAMBLE + inspect.getsource(_rate)
                + inspect.getsource(one_episode_rate)}
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([tree, os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep),
                   MPLBACKEND="Agg")
        try:
            done = subprocess.run([sys.executable, "-c", _DRIVER, json.dumps(spec)], cwd=tree, env=env,
                                  capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            return {"error": f"timed out after {timeout} s"}
        if done.returncode != 0 or not os.path.exists(out):
            lines = (done.stderr or done.stdout).strip().splitlines()
            return {"error": lines[-1] if lines else f"exit {done.returncode}"}
        with open(out) as f:
            result = json.load(f)
    if not os.path.abspath(result["source"]).startswith(os.path.abspath(tree) + os.sep):
        raise RuntimeError(f"the bench of {tree} imported {result['source']} instead")
    return result


def compare_rows(current: list[dict], reference: list[dict]) -> list[dict]:
    """Join rows on (scenario, what, batch): both env-step rates and the ratio current / reference."""
    ref = {(r["scenario"], r["what"], r["batch"]): r["env_steps_per_s"] for r in reference}
    cur = {(r["scenario"], r["what"], r["batch"]): r["env_steps_per_s"] for r in current}
    keys = list(cur) + [k for k in ref if k not in cur]
    return [{"scenario": k[0], "what": k[1], "batch": k[2], "reference_env_steps_per_s": ref.get(k),
             "current_env_steps_per_s": cur.get(k),
             "ratio": cur[k] / ref[k] if k in cur and k in ref and ref[k] > 0 else None} for k in keys]


def _best(rounds: list[list[dict]]) -> list[dict]:
    """Per (scenario, what, batch) the row with the highest rate over the rounds (the least disturbed one)."""
    best: dict[tuple, dict] = {}
    for rows in rounds:
        for row in rows:
            key = (row["scenario"], row["what"], row["batch"])
            if key not in best or row["env_steps_per_s"] > best[key]["env_steps_per_s"]:
                best[key] = row
    return list(best.values())


def run_against(out: str, ref: str, quick: bool = False, scenarios: list[str] | None = None,
                min_seconds: float | None = None, extras: bool = True, rounds: int = 2) -> list[dict]:
    """``coloc bench --against REF``: the current tree and commit REF measured side by side (see the module doc).

    Per scenario the two trees are measured in ``rounds`` alternating rounds (current, REF, REF, current, ...:
    a load that drifts during the run affects both alike) and each row keeps its best rate."""
    from rich.console import Console
    from rich.table import Table

    import coloc_env

    min_seconds = min_seconds if min_seconds is not None else (0.15 if quick else 1.5)
    names = scenarios or list(coloc_env.SCENARIOS)
    root = repository_root()
    console = Console()
    rows: list[dict] = []
    errors: dict[str, dict[str, str]] = {}
    with tempfile.TemporaryDirectory(prefix="coloc-against-") as folder:
        commit = export_commit(ref, folder, root)
        with console.status("benchmarking") as status:
            for name in names:
                batches = SCENARIO_BATCHES.get(name, BATCHES)
                measured: dict[str, list[list[dict]]] = {"current": [], ref: []}
                for k in range(rounds):
                    order = [("current", root), (ref, folder)]
                    for label, tree in order if k % 2 == 0 else order[::-1]:
                        status.update(f"benchmarking {name} ({label}, round {k + 1} of {rounds})")
                        result = bench_tree(tree, name, min_seconds, batches, extras)
                        if "error" in result:
                            errors.setdefault(name, {})[label] = result["error"]
                        measured[label].append(result.get("rows", []))
                rows += compare_rows(_best(measured["current"]), _best(measured[ref]))
    table = Table(title=f"coloc bench --against {ref} ({commit[:7]}): env-steps/s, ratio = current / {ref}")
    for column in ("scenario", "what", "B", ref, "current", "ratio"):
        table.add_column(column, justify="left" if column in ("scenario", "what") else "right")

    def rate(value):
        return "-" if value is None else f"{value:,.1f}" if value < 100 else f"{value:,.0f}"

    for row in rows:
        table.add_row(row["scenario"], row["what"], str(row["batch"]), rate(row["reference_env_steps_per_s"]),
                      rate(row["current_env_steps_per_s"]), "-" if row["ratio"] is None else f"{row['ratio']:.2f}x")
    console.print(table)
    for name, failed in errors.items():
        for label, text in failed.items():
            console.print(f"{name} ({label}): not measured: {text}")
    write_json(os.path.join(out, "bench", "against.json"),
               {"reference": ref, "reference_commit": commit, "quick": quick, "min_seconds": min_seconds,
                "rounds": rounds, "cpu_count": os.cpu_count(), "rows": rows, "errors": errors})
    return rows


# --- coloc bench --scaling ---------------------------------------------------------------------------------------
# env-steps/s of vector_env(compose(gps_denied with N agents, network, backend), B copies) against N: every
# composition of the gps_denied world the current tree can run (and the UKFs over ``ideal`` too, where UKF-DCL
# computes UKF-CCL's numbers, and over ``gilbert_elliott``, bursty loss beside broadcast's: what its link chains
# cost), at a fixed start square and at a fixed density.
SCALING_SIZES = (5, 10, 20, 40, 80)
SCALING_BATCHES = (8, 64)
SCALING_DENSITY = 40.0  # UAVs per km^2: the default 500 m square at N = 10
SCALING_LAYOUTS = ("fixed area", "fixed density")
SCALING_EXTRA_NETWORKS = {"ukf_ccl": ("ideal", "gilbert_elliott"), "ukf_dcl": ("ideal", "gilbert_elliott")}
SCALING_CAP_S = 120.0  # per row and tree: the sizes not measured within it print "over cap"
SCALING_QUICK = {"sizes": (5, 10), "batches": (8,), "min_seconds": 0.05, "cap": 60.0}
_SCALING_PREAMBLE = "from __future__ import annotations\nimport gc\nimport json\nimport time\n\nimport numpy as np\n\n"


def scaling_world(num_agents: int, layout: str) -> dict:
    """The gps_denied world of one scaling cell as a plain dict (every version of the world takes it): the fixed
    density is given as the ``area`` (side) it implies, ``GpsDenied(density=...).side``, so that a tree without
    the ``density`` field draws the same episodes."""
    from coloc_env.worlds.gps_denied import GpsDenied

    if layout not in SCALING_LAYOUTS:
        raise BadInput(f"layout must be one of {SCALING_LAYOUTS}, got {layout!r}")
    world = {"name": "gps_denied", "num_agents": int(num_agents)}
    if layout == "fixed density":
        world["area"] = GpsDenied(num_agents=int(num_agents), density=SCALING_DENSITY).side
    return world


def scaling_compositions() -> list[tuple[str, str]]:
    """(backend, network) of every row: each backend that runs on gps_denied over broadcast, in the registry's
    order, then the UKFs over ideal and over gilbert_elliott (``SCALING_EXTRA_NETWORKS``)."""
    import coloc_env

    ok = [r["backend"] for r in coloc_env.compatibility() if r["world"] == "gps_denied"
          and r["network"] == "broadcast" and r["ok"]]
    pairs = [(b, "broadcast") for b in dict.fromkeys(ok)]
    pairs += [(b, net) for b in dict.fromkeys(ok) for net in SCALING_EXTRA_NETWORKS.get(b, ())]
    return pairs


def scaling_rate(coloc_env, world: dict, network: str, backend: str, batch: int, min_seconds: float) -> float:
    """Env-steps per second (copies x steps) of ``vector_env(compose(world, network, backend), num_envs=batch,
    seed=0)`` under random actions (a pool of 16 drawn from the action space seeded 0, cycled), timed by
    ``_rate`` after one step. Uses only its arguments, numpy and ``_rate``: ``--against`` runs this
    source in the reference tree's process."""
    spec = coloc_env.compose(world=world, network=network, backend=backend)
    venv = coloc_env.vector_env(spec, num_envs=batch, seed=0)
    try:
        venv.reset()
        venv.action_space.seed(0)
        pool = [np.stack([venv.action_space.sample() for _ in range(venv.num_envs)]) for _ in range(16)]
        box = {"k": 0}

        def step() -> None:
            venv.step(pool[box["k"] % len(pool)])
            box["k"] += 1

        return _rate(step, min_seconds) * batch
    finally:
        venv.close()


def scaling_cells(coloc_env, spec: dict) -> None:
    """One row of one tree: the sizes in order, each cell appended to ``spec["out"]`` as a JSON line as soon as it
    is measured (the caller kills the process at the row's cap and keeps what was written). A size the tree
    refuses (a ValueError, e.g. more agents than it allows) is written with its message."""
    for size, world in zip(spec["sizes"], spec["worlds"], strict=True):
        try:
            rate = scaling_rate(coloc_env, world, spec["network"], spec["backend"], spec["batch"],
                                spec["min_seconds"])
            cell = {"N": size, "env_steps_per_s": rate}
        except ValueError as exc:
            cell = {"N": size, "error": str(exc).splitlines()[0]}
        with open(spec["out"], "a") as f:
            f.write(json.dumps(cell) + "\n")


_SCALING_DRIVER = """
import json, sys
spec = json.loads(sys.argv[1])
space = {}
exec(spec["source"], space)
import coloc_env
space["scaling_cells"](coloc_env, spec)
"""


def _scaling_source() -> str:
    return _SCALING_PREAMBLE + "".join(inspect.getsource(f) for f in (_rate, scaling_rate, scaling_cells))


def scaling_row(tree: str, backend: str, network: str, layout: str, batch: int, sizes, min_seconds: float,
                cap: float, single_thread: bool = False) -> dict[int, dict]:
    """{N: cell} of one row measured in a subprocess with ``tree`` first on sys.path, killed after ``cap``
    seconds; a size with no cell is over the cap. ``single_thread``: BLAS, numba and dNBP's pool on one thread."""
    with tempfile.TemporaryDirectory(prefix="coloc-scaling-") as scratch:
        out = os.path.join(scratch, "cells.jsonl")
        spec = {"source": _scaling_source(), "backend": backend, "network": network, "batch": int(batch),
                "sizes": [int(n) for n in sizes], "worlds": [scaling_world(n, layout) for n in sizes],
                "min_seconds": float(min_seconds), "out": out}
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([tree, os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep),
                   MPLBACKEND="Agg")
        if single_thread:
            env.update({name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                                               "NUMBA_NUM_THREADS", "COLOC_THREADS")})
        error = None
        try:
            done = subprocess.run([sys.executable, "-c", _SCALING_DRIVER, json.dumps(spec)], cwd=tree, env=env,
                                  capture_output=True, text=True, timeout=cap)
            if done.returncode != 0:
                lines = (done.stderr or done.stdout).strip().splitlines()
                error = lines[-1] if lines else f"exit {done.returncode}"
        except subprocess.TimeoutExpired:
            pass
        cells = {}
        if os.path.exists(out):
            with open(out) as f:
                for line in f:
                    cell = json.loads(line)
                    cells[cell["N"]] = cell
    if error is not None:
        for n in sizes:
            cells.setdefault(n, {"N": n, "error": error})
    return cells


def growth_exponent(sizes, rates) -> float | None:
    """The least-squares slope of log(time per env-step) against log N over the measured sizes (time per step
    ~ N^slope); None with fewer than two."""
    points = [(n, r) for n, r in zip(sizes, rates, strict=True) if r is not None and r > 0]
    if len(points) < 2:
        return None
    n, r = np.array(points, float).T
    return float(np.polyfit(np.log(n), -np.log(r), 1)[0])


def _scaling_entry(cells: dict[int, dict], sizes) -> dict:
    rates = [cells.get(n, {}).get("env_steps_per_s") for n in sizes]
    status = ["ok" if r is not None else "refused" if "error" in cells.get(n, {}) else "over cap"
              for n, r in zip(sizes, rates, strict=True)]
    growth = (rates[sizes.index(20)] / rates[sizes.index(40)]
              if 20 in sizes and 40 in sizes and rates[sizes.index(20)] and rates[sizes.index(40)] else None)
    errors = {str(n): c["error"] for n, c in cells.items() if "error" in c}
    return {"env_steps_per_s": rates, "status": status, "exponent": growth_exponent(sizes, rates),
            "time_growth_20_to_40": growth, "errors": errors}


def run_scaling(out: str, quick: bool = False, against: str | None = None, cap: float | None = None,
                sizes=None, batches=None, compositions=None, layouts=SCALING_LAYOUTS,
                min_seconds: float | None = None, reference_tree: str | None = None,
                workers: int = 1) -> list[dict]:
    """``coloc bench --scaling``: env-steps/s against N (``SCALING_SIZES``) for every row of
    ``scaling_compositions`` x layout x B (``SCALING_BATCHES``), each row in its own subprocess stopped
    after ``cap`` seconds (the sizes left print "over cap"), with the growth exponent of each row (the log-log
    slope of time per step against N) and the growth of the time per step from N = 20 to 40. With ``against``
    REF, each row is measured for the current tree and for commit REF (exported by ``git archive``) one after
    the other, alternating which goes first, and each cell gets the ratio current / REF. ``reference_tree``: a
    folder holding REF's files instead of a git ref (``against`` then only labels it). ``workers`` > 1 runs that
    many rows at once, each process on one thread (BLAS, numba and dNBP's pool), for a machine with that many
    idle cores; the current and REF runs of a row then run side by side.
    Writes ``OUT/bench/scaling.json``, ``scaling.md`` and the log-log figure ``OUT/bench/scaling.png`` (atomic)."""
    from rich.console import Console
    from rich.table import Table

    sizes = tuple(sizes or (SCALING_QUICK["sizes"] if quick else SCALING_SIZES))
    batches = tuple(batches or (SCALING_QUICK["batches"] if quick else SCALING_BATCHES))
    cap = float(cap if cap is not None else SCALING_QUICK["cap"] if quick else SCALING_CAP_S)
    min_seconds = float(min_seconds if min_seconds is not None else SCALING_QUICK["min_seconds"] if quick else 1.0)
    pairs = list(compositions or scaling_compositions())
    console = Console(width=max(160, Console().width))  # the table is wide: never wrap its cells
    root = repository_root() if against and not reference_tree else \
        os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    rows: list[dict] = []
    commit = None
    against = against or (os.path.basename(os.path.normpath(reference_tree)) if reference_tree else None)
    with contextlib.ExitStack() as stack:
        trees = [("current", root)]
        if reference_tree:
            trees.append((against, os.path.abspath(reference_tree)))
        elif against:
            folder = stack.enter_context(tempfile.TemporaryDirectory(prefix="coloc-against-"))
            commit = export_commit(against, folder, root)
            trees.append((against, folder))
        status = stack.enter_context(console.status("benchmarking"))
        jobs = []  # (row, key, tree) in the alternating order
        for layout in layouts:
            for backend, network in pairs:
                for batch in batches:
                    row = {"layout": layout, "backend": backend, "network": network, "batch": batch}
                    order = trees if len(rows) % 2 == 0 else trees[::-1]
                    jobs += [(row, "current" if label == "current" else "reference", tree) for label, tree in order]
                    rows.append(row)

        def measure(job) -> None:
            row, key, tree = job
            status.update(f"{row['layout']}: {row['backend']} over {row['network']}, B = {row['batch']} ({key})")
            cells = scaling_row(tree, row["backend"], row["network"], row["layout"], row["batch"], sizes,
                                min_seconds, cap, single_thread=workers > 1)
            row[key] = _scaling_entry(cells, sizes)

        if workers > 1:
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(workers) as pool:
                list(pool.map(measure, jobs))
        else:
            for job in jobs:
                measure(job)
        for row in rows:
            if against:
                cur, ref = row["current"]["env_steps_per_s"], row["reference"]["env_steps_per_s"]
                row["ratio"] = [c / r if c and r else None for c, r in zip(cur, ref, strict=True)]
    table = Table(title="coloc bench --scaling: env-steps/s against N (gps_denied, random actions)"
                  + (f", ratio = current / {against}" if against else ""))
    for column in ("layout", "backend", "network", "B", "tree", *[f"N={n}" for n in sizes], "slope", "t40/t20"):
        table.add_column(column, justify="left" if column in ("layout", "backend", "network", "tree") else "right")

    def rate(value, state):
        return state if value is None else f"{value:,.1f}" if value < 100 else f"{value:,.0f}"

    def fmt(value, form):
        return "-" if value is None else form.format(value)

    for row in rows:
        entries = [("current", row["current"])] + ([(against, row["reference"])] if against else [])
        for label, entry in entries:
            table.add_row(row["layout"], row["backend"], row["network"], str(row["batch"]), label,
                          *[rate(v, s) for v, s in zip(entry["env_steps_per_s"], entry["status"], strict=True)],
                          fmt(entry["exponent"], "{:.2f}"), fmt(entry["time_growth_20_to_40"], "{:.1f}x"))
        if against:
            table.add_row(row["layout"], row["backend"], row["network"], str(row["batch"]), "ratio",
                          *[fmt(r, "{:.2f}x") for r in row["ratio"]], "", "")
    console.print(table)
    folder = os.path.join(out, "bench")
    write_text(os.path.join(folder, "scaling.md"), scaling_markdown(rows, sizes, against))
    write_json(os.path.join(folder, "scaling.json"),
               {"sizes": list(sizes), "batches": list(batches), "layouts": list(layouts), "cap_s": cap,
                "min_seconds": min_seconds, "density_per_km2": SCALING_DENSITY, "reference": against,
                "reference_commit": commit, "quick": quick, "cpu_count": os.cpu_count(), "rows": rows})
    _scaling_figure(rows, sizes, against, os.path.join(folder, "scaling.png"))
    return rows


def scaling_markdown(rows: list[dict], sizes, against: str | None = None) -> str:
    """The scaling table as Markdown: per row the current rates (env-steps/s), "over cap" or "refused" where
    none, the growth exponent and the time growth from N = 20 to 40; with ``against``, REF's row and the
    ratios current / REF below it."""
    def rate(value, state):
        return state if value is None else f"{value:,.1f}" if value < 100 else f"{value:,.0f}"

    def fmt(value, form):
        return "-" if value is None else form.format(value)

    head = ["layout", "backend", "network", "B", "tree", *[f"N = {n}" for n in sizes], "slope", "t(40) / t(20)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * 5 + ["---:"] * (len(sizes) + 2)) + "|"]
    for row in rows:
        entries = [("current", row["current"])] + ([(against, row["reference"])] if against else [])
        for label, entry in entries:
            cells = [rate(v, s) for v, s in zip(entry["env_steps_per_s"], entry["status"], strict=True)]
            lines.append("| " + " | ".join([row["layout"], f"`{row['backend']}`", row["network"], str(row["batch"]),
                                            str(label), *cells, fmt(entry["exponent"], "{:.2f}"),
                                            fmt(entry["time_growth_20_to_40"], "{:.1f}x")]) + " |")
        if against:
            lines.append("| " + " | ".join([row["layout"], f"`{row['backend']}`", row["network"], str(row["batch"]),
                                            "ratio", *[fmt(r, "{:.2f}x") for r in row["ratio"]], "", ""]) + " |")
    return "\n".join(lines) + "\n"


def _scaling_figure(rows: list[dict], sizes, against: str | None, path: str) -> None:
    """Time per env-step against N, log-log, one panel per (layout, B); the reference tree dashed; legends
    below the panels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter

    from train.plotting import label, plain_log_ticks

    panels = list(dict.fromkeys((r["layout"], r["batch"]) for r in rows))
    fig, axes = plt.subplots(1, max(1, len(panels)), figsize=(5.4 * max(1, len(panels)), 5.2), squeeze=False)
    for ax, (layout, batch) in zip(axes.flat, panels, strict=False):
        for k, row in enumerate(r for r in rows if (r["layout"], r["batch"]) == (layout, batch)):
            color = f"C{k % 10}"
            entries = [("", row["current"], "o-")] + ([(f" ({against})", row["reference"], "s--")] if against else [])
            for suffix, entry, style in entries:
                points = [(n, 1.0 / v) for n, v in zip(sizes, entry["env_steps_per_s"], strict=True) if v]
                if not points:
                    continue
                n, t = zip(*points, strict=True)
                slope = "" if entry["exponent"] is None else f", slope {entry['exponent']:.1f}"
                ax.loglog(n, t, style, color=color, markersize=4,
                          label=f"{row['backend']} / {row['network']}{suffix}{slope}")
        ax.set_title(f"{layout}, B = {batch}", fontsize=10)
        ax.set_xlabel(label("agents N", "agents"))
        ax.set_ylabel(label("time per env-step", "s"))
        ax.xaxis.set_major_locator(FixedLocator([n for n in sizes]))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _pos: f"{value:g}"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        plain_log_ticks(ax, "y")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6.5, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, frameon=False)
    fig.suptitle(f"coloc bench --scaling: gps_denied, random actions ({os.cpu_count()}-core CPU)")
    fig.tight_layout()
    save_figure(path, fig)
