"""``coloc bench``'s estimator rows that replay the env's own estimator calls: a vector_env rollout's backend
calls into its estimator functions (``BACKEND_CALLS``) recorded (``record_backend_calls``) and replayed
(``replay_step``), and the actions that drive a preset's rows (``ActionSource``)."""

from __future__ import annotations

import copy
import dataclasses
import importlib
from collections.abc import Callable

import numpy as np

from coloc_env.config import BadInput

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


def replayed_estimator_step(name: str) -> Callable[[int], Callable[[], None]]:
    """The estimator row of a preset in ``BACKEND_CALLS``: its backend's estimator calls recorded from a
    vector_env of B copies driven as its vector_env row is, replayed (``replay_step``)."""

    def factory(batch: int) -> Callable[[], None]:
        venv, tape = record_backend_calls(name, batch)
        venv.close()
        return replay_step(tape)

    factory.__doc__ = f"{name}: the env's own estimator calls, recorded and replayed"
    return factory


def paper_actions(name: str) -> np.ndarray:
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
        self.paper = paper_actions(name)
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
