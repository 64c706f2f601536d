"""Posterior Cramér–Rao bounds of a composition over the seeded episodes an evaluation plays.

>>> import coloc_env
>>> bounds = coloc_env.pcrb("target_cv/bernoulli_delay/kalman", episodes=8, seed=0)
>>> bounds["centralized"].shape          # (K, N), m^2

``pcrb`` builds one copy of the composition's core per episode, resets episode e with
seed ``seed + e`` (the episode an evaluation's ``env.reset(seed=seed + e)`` plays; one copy
each, so any backend's batching is beside the point), steps it under the policy, and
records what the world read (the ranges taken, the fixes that existed) and what the
network delivered (each packet's delay). The world's bound model
(``coloc_env.bound_models``, one module per world, each stating its estimation
problem) turns that record into the per-step Fisher information, transition Jacobians
and process noises; ``estimators.bounds.filtering_bound`` runs one recursion on the
D-terms averaged over the E episodes (Tichavský, Muravchik and
Nehorai 1998). Three bounds, each (K, N) in m^2 (agent n's trace of the bound's
position block at step k, after the readings of k; a shared target's bound for every
agent):

| key            | information                                                                 |
|----------------|-----------------------------------------------------------------------------|
| ``centralized``| every reading of every agent, fused centrally (unlimited communication)      |
| ``local``      | each agent with only its own readings: own motion inputs, own fixes, readings |
|                | of known anchors (no communication); a range to another agent is not its own  |
|                | information without that agent's position                                    |
| ``delivered``  | per receiver: its own readings plus every reading another agent's packet       |
|                | carried to it, counted at the step it was *measured* from the step it arrives  |
|                | (a lag-augmented state [x(k), ..., x(k - D)], D the network's longest delay)   |

``delivered`` is defined where a packet carries its sender's reading of the step it is
stamped with (the ``kalman`` and ``centralized_lmmse`` backends' packets of z_i(k), whose
leader's bound is every agent's since every agent reports the leader's estimate; the
``nlos_orbit`` neighbours' RSS/AOA packets to ``afge`` and ``dfir``; ``ukf_ccl``'s ranges and
fixes to its centre, agent 0, whose estimates every agent reads), and for backends that
send nothing (``dead_reckoning``: delivered = local). It is left out where a message
carries an estimate (``prediction_compensation``, ``bandwidth_fusion``, ``dnbp``'s
beliefs, ``ukf_dcl``'s and ``ukf_se2``'s relayed location information, ``range_ls``): an
estimate summarizes the sender's whole history, and what that is worth to the receiver
depends on what the sender itself received, so a per-reading account would be no bound.
By construction local >= delivered >= centralized (each adds information to the one before),
for the receiver's own columns; where the delivered bound is a fusing agent's (a shared estimate), another
agent's local bound can be below it (its own fixes need not reach the centre).

Policies: ``"always"`` and ``"silent"`` play every transport decision at its maximum /
minimum with the default sensing and backend decisions
(``coloc_env.scenarios.composed.ComposedScenario.action_vector``, in the parts'
blocks, so a preset's own codec is bypassed: its world and seeds are the preset's);
``"random"`` draws every block uniformly from a generator seeded with ``seed``; a callable
``act(observations) -> actions`` (dicts over the agents, as the PettingZoo env passes
them) is stepped through the scenario's own codec, and a sequence of E callables plays one
per episode (``coloc evaluate`` replays the actions its rows played that way). Under a
policy that reads no observation (a name, or a callable with ``blind = True``) a backend
whose messages do not define the bound is not run (the world's readings never depend on
it), unless the preset's own step reads the backend's result (``gps_denied_nbp``); the
``nlos_orbit`` neighbours' packets are then asked of the network by the bound model's
stand-in (the same counter-based draws as the backend's call: a test holds them equal).

Where each episode is a problem of its own (``mrclam``: recorded windows, each conditioned on
its trajectory), the bound model asks for one recursion per episode and the mean of their
bounds (``BoundProblem.per_episode``). A mean of per-episode bounds is a bound on the averaged
MSE only where what differs between the episodes is known to the estimator *and* independent of
the noises it faces (then each is the bound conditioned on it, E[J(U)^-1] >= (E J(U))^-1); where
the Jacobians are evaluated at a truth that differs through noise the estimator does not observe,
or the readings taken depend on earlier readings (a policy that chooses from its estimates), it
is not, and the averaged D-terms are.

``mrclam`` (recorded data) has no generative model: its bound is model-based (the
world's calibrated noise model along each recorded window's Vicon trajectory, one recursion
per window, then their mean) and says so (``"model_based"``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimators.bounds import DEFAULT_REGULARIZATION, filtering_bound

__all__ = ["BoundProblem", "Record", "Recursion", "pcrb", "position_traces", "lag_augmented"]

POLICIES = ("always", "silent", "random")


@dataclass
class Recursion:
    """One filtering-bound recursion: prior P0 (n, n), mean reading information (K, n, n), F and Q (K-1, [E,] n, n)
    (None: identity / none), and ``positions`` (N, 2) the state indices of each reported agent's position."""

    P0: np.ndarray
    info: np.ndarray
    F: np.ndarray | None
    Q: np.ndarray | None
    positions: np.ndarray

    def run(self, regularization: float = DEFAULT_REGULARIZATION) -> np.ndarray:
        """(K, N) position traces of the bound."""
        return position_traces(filtering_bound(self.P0, self.info, self.F, self.Q, regularization), self.positions)


@dataclass
class BoundProblem:
    """What a world's bound model returns: ``centralized`` one recursion over the joint state; ``local`` and
    ``delivered`` lists of recursions, each giving some agents' columns (``*_agents``: which)."""

    centralized: Recursion
    local: list[Recursion]
    local_agents: list[np.ndarray]
    delivered: list[Recursion] | None = None
    delivered_agents: list[np.ndarray] | None = None
    model_based: bool = False
    delivered_reason: str = ""
    # each episode its own problem (a recorded window, conditioned on its trajectory): run per episode, then the
    # mean of the episodes' bounds, instead of one recursion on averaged D-terms
    per_episode: bool = False


def position_traces(P: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """(K, N): tr of P[k] over each row of ``positions`` (N, 2) state indices."""
    positions = np.asarray(positions)
    return np.stack([P[:, i, i] + P[:, j, j] for i, j in positions], axis=-1)


@dataclass
class Record:
    """What one episode's play read and carried, by step (lists of length K).

    ``readings[k]`` the world's ``coloc_env.worlds.base.Readings`` of k (one copy); ``packets[k]`` the delay
    arrays (N, N) [t, s] of every ``Network.packets`` call stamped k; ``node_packets[k]`` the (N, J) delays of the
    ``Network.node_packets`` calls stamped k; ``broadcasts[k]`` each ``Network.broadcast`` call's delivered
    matrix (N, N) [t, s] by its slot (a ``Network.messages_to`` call's message j as the broadcast of its slot).
    """

    steps: int
    readings: list = field(default_factory=list)
    packets: list = field(default_factory=list)
    node_packets: list = field(default_factory=list)
    broadcasts: list = field(default_factory=list)  # [k]: {slot: delivered (N, N) [t, s]} of Network.broadcast

    def first_arrival(self, kind: str = "packets") -> np.ndarray | None:
        """(K, S, R) int: the earliest delay of the packet stamped k from sender s at receiver r over every call of
        that kind (-1: none arrived); None where no call was made."""
        calls = self.packets if kind == "packets" else self.node_packets
        if not any(calls):
            return None
        shape = next(c[0].shape for c in calls if c)
        out = np.full((self.steps, *shape), -1, dtype=np.int64)
        for k, stamped in enumerate(calls):
            for delay in stamped:
                better = (delay >= 0) & ((out[k] < 0) | (delay < out[k]))
                out[k] = np.where(better, delay, out[k])
        return out


def _record_play(core, episode_rng: np.random.Generator, policy, rng: np.random.Generator | None) -> Record:
    """Reset ``core`` (one copy) with ``episode_rng`` and step it to its horizon under ``policy``, recording
    readings and deliveries (the world's and the network's methods wrapped on the instances for the play, then
    restored; the reset is recorded too: a backend that receives before deciding reads step 0 there)."""
    steps = int(core.horizon)
    record = Record(steps)
    record.readings = [None] * steps
    record.packets = [[] for _ in range(steps)]
    record.node_packets = [[] for _ in range(steps)]
    record.broadcasts = [{} for _ in range(steps)]
    world, network = core.world, core.network
    world_readings, packets, node_packets = world.readings, network.packets, network.node_packets
    broadcast, messages_to = network.broadcast, network.messages_to

    def stamp(k) -> int:
        return int(np.max(np.asarray(k)))

    def readings(sensing):
        out = world_readings(sensing)
        k = stamp(world.k)
        if k < steps:
            record.readings[k] = out
        return out

    def on_packets(*args, **kwargs):
        delay = packets(*args, **kwargs)
        k = stamp(network._k)
        if k < steps:
            record.packets[k].append(np.array(delay[0]))
        return delay

    def on_node_packets(*args, **kwargs):
        delay = node_packets(*args, **kwargs)
        k = stamp(network._k)
        if k < steps:
            record.node_packets[k].append(np.array(delay[0]))
        return delay

    def on_broadcast(senders, listening, floats, slot=0):
        delivered = broadcast(senders, listening, floats, slot)
        k = stamp(network._k)
        if k < steps:
            record.broadcasts[k][slot] = np.array(delivered[0])
        return delivered

    def on_messages_to(senders, receiver, floats, slots):
        # J one-off messages to one receiver, each the broadcast call of its slot (Network.messages_to): recorded
        # as that call's delivered matrix, [sender, receiver] the outcome
        delivered = messages_to(senders, receiver, floats, slots)
        k = stamp(network._k)
        if k < steps:
            senders0 = np.asarray(senders, int)[0]
            for j, slot in enumerate(np.broadcast_to(np.asarray(slots, int), senders0.shape)):
                matrix = record.broadcasts[k].setdefault(int(slot), np.zeros((core.num_agents,) * 2, bool))
                if senders0[j] >= 0:
                    matrix[senders0[j], receiver] |= bool(delivered[0, j])
        return delivered

    world.readings, network.packets, network.node_packets = readings, on_packets, on_node_packets
    network.broadcast, network.messages_to = on_broadcast, on_messages_to
    # what the world reads depends on the actions only, never on the backend's state: under a policy that reads no
    # observation (a name, or a callable marked ``blind``), a backend whose messages do not define the bound need
    # not run, nor one whose packets the world's own nodes send (the bound model's stand-in asks the network)
    from coloc_env.bound_models import delivered_kind, stand_in

    blind = not callable(policy) or bool(getattr(policy, "blind", False))
    kind = delivered_kind(core.composition.backend.name)
    substitute = stand_in(core) if kind == "readings" else None
    from coloc_env.scenarios.composed import ComposedScenario

    own_step = type(core).advance is not ComposedScenario.advance  # a preset that reads the backend's step
    idle = blind and not own_step and (kind != "readings" or substitute is not None)
    if idle:
        core.backend.step = lambda readings, decisions: None if core.receives_ahead or substitute is None \
            else substitute(readings)
        core.backend.receive = lambda readings, idx: None if substitute is None else substitute(readings)
    try:
        core.reset([episode_rng])
        _play(core, steps, policy, rng)
    finally:
        del world.readings, network.packets, network.node_packets, network.broadcast, network.messages_to
        if idle:
            del core.backend.step, core.backend.receive
    return record


def _block_actions(core, which: str, rng: np.random.Generator | None) -> np.ndarray:
    B, N = core.batch, core.num_agents
    if which in ("maximum", "minimum"):
        vector = np.asarray(core.action_vector(which), float)
        return np.broadcast_to(vector, (B, N, vector.size)).copy()
    columns = []
    for blk in core.blocks:
        size = (B, N, blk.size)
        columns.append(rng.integers(0, blk.choices, size=size).astype(float) if blk.discrete
                       else rng.uniform(blk.low, blk.high, size=size))
    return np.concatenate(columns, axis=-1) if columns else np.zeros((B, N, 0))


def _play(core, steps: int, policy, rng) -> None:
    if callable(policy):
        names = list(core.agent_names)
        for _ in range(steps):
            obs = core.observation()
            rows = []
            for b in range(core.batch):
                actions = policy({a: obs[b, i] for i, a in enumerate(names)})
                rows.append(np.stack([np.asarray(actions[a], float) for a in names]))
            core.step(np.stack(rows))
        return
    which = {"always": "maximum", "silent": "minimum", "random": "random"}[policy]
    for _ in range(steps):
        # in the parts' blocks (a preset's codec bypassed): the world and its seeds are the preset's
        core.advance(_block_actions(core, which, rng))


def lag_augmented(P0: np.ndarray, F: np.ndarray | None, Q: np.ndarray | None, lags: int):
    """(P0_a, F_a, Q_a) of the state [x(k), x(k-1), ..., x(k-lags)]: F_a shifts the copies down, Q_a = diag(Q, 0).

    F and Q (K-1, n, n) common to the episodes (a per-episode Q is first reduced to (E[Q^-1])^-1 by the caller)."""
    n = P0.shape[0]
    m = n * (lags + 1)
    P0a = np.kron(np.eye(lags + 1), P0)
    if F is None and Q is None:
        return P0a, None, None
    steps = (F if F is not None else Q).shape[0]
    Fa = np.zeros((steps, m, m))
    Fa[:, :n, :n] = np.eye(n) if F is None else F
    for d in range(lags):
        Fa[:, (d + 1) * n:(d + 2) * n, d * n:(d + 1) * n] = np.eye(n)
    Qa = np.zeros((steps, m, m))
    if Q is not None:
        Qa[:, :n, :n] = Q
    return P0a, Fa, Qa


def delivered_recursion(P0, F, Q, sender_info: np.ndarray, arrival: np.ndarray, lags: int,
                        positions: np.ndarray) -> Recursion:
    """One episode's lag-augmented recursion of one receiver: ``sender_info`` (K, S, n, n) the information of
    sender s's reading of k, ``arrival`` (K, S) its first delay at this receiver (-1: never; its own readings 0),
    ``lags`` D the network's longest delay (longer ones are dropped: they arrive after... never, for the
    networks here). The reading of k arriving after d steps enters at step k + d on the copy x(k) = lag d."""
    K, S, n, _ = sender_info.shape
    P0a, Fa, Qa = lag_augmented(P0, F, Q, lags)
    m = n * (lags + 1)
    info = np.zeros((K, m, m))
    for d in range(lags + 1):
        weight = (arrival[:K - d] == d).astype(float)  # (K - d, S): readings of k arriving at k + d
        block = np.einsum("ks,ksij->kij", weight, sender_info[:K - d])
        info[d:, d * n:(d + 1) * n, d * n:(d + 1) * n] += block
    return Recursion(P0a, info, Fa, Qa, positions)


def _resolve(spec_or_name):
    import coloc_env

    if isinstance(spec_or_name, coloc_env.Composition):
        return spec_or_name
    if coloc_env.is_composition_name(spec_or_name):
        return coloc_env.composition_named(spec_or_name)
    if isinstance(spec_or_name, str) and spec_or_name in coloc_env.PRESETS:
        return coloc_env.PRESETS[spec_or_name]
    raise ValueError(f"pcrb: spec must be a Composition, a preset name {list(coloc_env.PRESETS)} or "
                     f"WORLD/NETWORK/BACKEND, got {spec_or_name!r}")


def pcrb(spec_or_name, episodes: int = 16, seed: int = 0, policy="always",
         regularization: float = DEFAULT_REGULARIZATION, **config) -> dict:
    """The posterior Cramér–Rao bounds of a composition (module docstring): a dict with ``"centralized"``,
    ``"local"`` and, where defined, ``"delivered"``, each (K, N) in m^2, plus ``"model_based"`` (bool) and, where
    ``delivered`` is left out, ``"delivered_reason"``.

    | argument        | allowed                                                                    |
    |-----------------|----------------------------------------------------------------------------|
    | spec_or_name    | a Composition, a preset name or ``WORLD/NETWORK/BACKEND``                    |
    | episodes        | 1..100000 (E; episode e is reset with seed ``seed + e``)                    |
    | seed            | an integer >= 0                                                            |
    | policy          | ``"always"``, ``"silent"``, ``"random"``, a callable act(observations), or a  |
    |                 | sequence of E callables (episode e plays the e-th: seeded per-episode policies) |
    | regularization  | [0, 1e-3]: relative ridge on a per-episode singular Q (estimators.bounds)   |
    | config          | a preset's flat config keywords (``data=`` for mrclam_relay)                |
    """
    import coloc_env
    from coloc_env.bound_models import bound_problem

    if isinstance(episodes, bool) or not isinstance(episodes, (int, np.integer)) or not 1 <= episodes <= 100_000:
        raise ValueError(f"episodes must be an integer in [1, 100000], got {episodes!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    if isinstance(policy, (list, tuple)):
        if len(policy) != episodes or not all(callable(p) for p in policy):
            raise ValueError(f"policy as a sequence must hold one callable per episode ({episodes}), got {policy!r}")
    elif not callable(policy) and policy not in POLICIES:
        raise ValueError(f"policy must be one of {list(POLICIES)} or a callable act(observations) -> actions, "
                         f"got {policy!r}")
    if not 0.0 <= float(regularization) <= 1e-3:
        raise ValueError(f"regularization must be in [0, 1e-3], got {regularization!r}")
    spec = _resolve(spec_or_name)
    rng = np.random.default_rng(int(seed)) if policy == "random" else None
    problems = []
    for e in range(int(episodes)):
        # one copy per episode: the episode env.reset(seed=seed + e) plays, whatever a backend's batching
        core = coloc_env.make_core(spec, batch=1, **config)
        played = policy[e] if isinstance(policy, (list, tuple)) else policy
        record = _record_play(core, np.random.default_rng(int(seed) + e), played, rng)
        steps = record.steps
        problems.append(bound_problem(core, record))
    K, N = steps, core.num_agents
    if problems[0].per_episode:
        outs = [_bounds(p, K, N, regularization) for p in problems]
        out = dict(outs[0])
        for key in ("centralized", "local", "delivered"):
            if key in out:
                out[key] = np.mean([o[key] for o in outs], axis=0)
        return out
    return _bounds(_merge(problems), K, N, regularization)


def _bounds(problem: BoundProblem, K: int, N: int, regularization: float) -> dict:
    out = {"centralized": problem.centralized.run(regularization), "model_based": bool(problem.model_based)}
    out["local"] = _assemble(problem.local, problem.local_agents, K, N, regularization)
    if problem.delivered is not None:
        out["delivered"] = _assemble(problem.delivered, problem.delivered_agents, K, N, regularization)
    else:
        out["delivered_reason"] = problem.delivered_reason
    return out


def _collapse(arrays):
    """Per-episode F or Q (K-1, n, n) -> (K-1, n, n) where every episode has the same, else (K-1, E, n, n)."""
    if arrays[0] is None:
        return None
    first = np.asarray(arrays[0])
    if all(np.array_equal(first, a) for a in arrays[1:]):
        return first
    return np.stack([np.asarray(a) for a in arrays], axis=1)


def _merge_recursions(recursions: list[Recursion]) -> Recursion:
    first = recursions[0]
    return Recursion(first.P0, np.mean([r.info for r in recursions], axis=0), _collapse([r.F for r in recursions]),
                     _collapse([r.Q for r in recursions]), first.positions)


def _merge(problems: list[BoundProblem]) -> BoundProblem:
    """The D-terms of every episode averaged: the reading information's mean per step; F and Q kept per episode
    where they differ (estimators.bounds takes the expectations over them)."""
    first = problems[0]
    merged = BoundProblem(_merge_recursions([p.centralized for p in problems]),
                          [_merge_recursions([p.local[i] for p in problems]) for i in range(len(first.local))],
                          first.local_agents, model_based=first.model_based, delivered_reason=first.delivered_reason)
    if first.delivered is not None:
        merged.delivered = [_merge_recursions([p.delivered[i] for p in problems]) for i in range(len(first.delivered))]
        merged.delivered_agents = first.delivered_agents
    return merged


def _assemble(recursions, agents, K: int, N: int, regularization: float) -> np.ndarray:
    out = np.full((K, N), np.nan)
    for recursion, columns in zip(recursions, agents, strict=True):
        out[:, np.asarray(columns)] = recursion.run(regularization)
    return out
