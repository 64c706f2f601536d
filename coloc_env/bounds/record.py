"""Recording one episode's play for the bounds: what the world read and what the network delivered.

The core reports both through its observer (``ComposedScenario.observe``): ``readings(k, readings)`` for
every ``world.readings`` call, ``delivery(network, call, arguments, result)`` for every delivery call of
the network (``coloc_env.networks.base.DELIVERY_CALLS``, whatever network subclass makes it). ``Recorder``
is that observer; ``record_play`` resets a core, plays it to its horizon and returns the ``Record``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from coloc_env.scenarios.composed import ComposedScenario

POLICIES = ("always", "silent", "random")


@dataclass
class Record:
    """What one episode's play read and carried, by step (lists of length K).

    ``readings[k]`` the world's ``coloc_env.worlds.base.Readings`` of k (one copy); ``packets[k]`` the delay
    arrays (N, N) [t, s] of every ``Network.packets`` call stamped k; ``node_packets[k]`` the (N, J) delays of the
    ``Network.node_packets`` calls stamped k; ``broadcasts[k]`` each ``Network.broadcast`` call's delivered
    matrix (N, N) [t, s] by its slot (a ``Network.messages_to`` call's message j as the broadcast of its slot);
    ``deliveries[k]`` every delivery call stamped k, in the order made, as a dict (``Recorder.delivery``):
    ``call`` its name and, by call, ``delivered`` (N, N) [t, s] (``broadcast``), ``delay`` (N, N) [t, s]
    (``packets``) or (N, J) (``node_packets``), ``senders`` (J,), ``receiver`` and ``delivered`` (J,)
    (``messages_to``), ``chain`` (J, N), ``length`` (J,) and ``first`` (J,) (``relay``, ``relay_each``: one
    row per chain; ``first`` the first hop asked for, -1: the holder's choice).
    """

    steps: int
    readings: list = field(default_factory=list)
    packets: list = field(default_factory=list)
    node_packets: list = field(default_factory=list)
    broadcasts: list = field(default_factory=list)  # [k]: {slot: delivered (N, N) [t, s]} of Network.broadcast
    deliveries: list = field(default_factory=list)

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


class Recorder:
    """The observer of one play (copy 0 of the core): fills a ``Record`` from the core's reports."""

    def __init__(self, steps: int, num_agents: int):
        self.record = Record(steps)
        self.record.readings = [None] * steps
        self.record.packets = [[] for _ in range(steps)]
        self.record.node_packets = [[] for _ in range(steps)]
        self.record.broadcasts = [{} for _ in range(steps)]
        self.record.deliveries = [[] for _ in range(steps)]
        self.num_agents = int(num_agents)

    def _step(self, k) -> int | None:
        k = int(np.max(np.asarray(k)))
        return k if k < self.record.steps else None

    def readings(self, k, readings) -> None:
        k = self._step(k)
        if k is not None:
            self.record.readings[k] = readings

    def delivery(self, network, call: str, arguments: dict, result) -> None:
        k = self._step(network._k)
        if k is None:
            return
        record = self.record
        if call == "broadcast":
            delivered = np.array(result[0])
            record.broadcasts[k][int(arguments["slot"])] = delivered
            record.deliveries[k].append({"call": call, "delivered": delivered})
        elif call == "packets":
            delay = np.array(result[0])
            record.packets[k].append(delay)
            record.deliveries[k].append({"call": call, "delay": delay})
        elif call == "node_packets":
            delay = np.array(result[0])
            record.node_packets[k].append(delay)
            record.deliveries[k].append({"call": call, "delay": delay})
        elif call == "messages_to":
            # J one-off messages to one receiver, each the broadcast call of its slot (Network.messages_to): recorded
            # as that call's delivered matrix, [sender, receiver] the outcome
            receiver = int(arguments["receiver"])
            senders = np.asarray(arguments["senders"], int)[0]
            delivered = np.array(result[0], bool)
            for j, slot in enumerate(np.broadcast_to(np.asarray(arguments["slots"], int), senders.shape)):
                matrix = record.broadcasts[k].setdefault(int(slot), np.zeros((self.num_agents,) * 2, bool))
                if senders[j] >= 0:
                    matrix[senders[j], receiver] |= bool(delivered[j])
            record.deliveries[k].append({"call": call, "senders": senders, "receiver": receiver,
                                         "delivered": delivered})
        elif call in ("relay", "relay_each"):
            chain, length = np.asarray(result.chain)[0], np.asarray(result.length)
            first = np.broadcast_to(np.asarray(arguments["first"], int), length.shape)[0]
            length = length[0]
            if chain.ndim == 1:  # one chain per copy
                chain, length, first = chain[None], np.reshape(length, (1,)), np.reshape(first, (1,))
            record.deliveries[k].append({"call": call, "chain": np.array(chain), "length": np.array(length),
                                         "first": np.array(first)})


def record_play(core, episode_rng: np.random.Generator, policy, rng: np.random.Generator | None,
                stand_in=None) -> Record:
    """Reset ``core`` (one copy) with ``episode_rng`` and step it to its horizon under ``policy``, recording
    readings and deliveries through the core's observer (``ComposedScenario.observe``; the reset is recorded
    too: a backend that receives before deciding reads step 0 there). ``stand_in`` (a callable f(readings), or
    True for one that does nothing) runs in the backend's place; None: the backend runs."""
    recorder = Recorder(int(core.horizon), core.num_agents)
    if stand_in is True:
        def stand_in(readings):
            return None
    core.observe(recorder, stand_in)
    try:
        core.reset([episode_rng])
        _play(core, recorder.record.steps, policy, rng)
    finally:
        core.observe(None)
    return recorder.record


def reads_backend(core) -> bool:
    """Whether the scenario's own step reads the backend's result (a preset that overrides the core's step:
    ``gps_denied_nbp``), so that the backend must run even where the bound needs only readings."""
    return type(core).advance is not ComposedScenario.advance


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
