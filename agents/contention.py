"""Medium-access baselines for the ``contention`` network: ``round_robin`` (TDMA) and ``aloha:p`` (slotted ALOHA).

Both are realizable: each agent reads only its own observation (its index, the one-hot
``[0, N)``; the step fraction ``[3N + 1]``; its distances to the others ``[2N + 1, 3N + 1)``) and,
for ``aloha``, its own generator. What they know of the env they are built with is its
configuration (N, the horizon, the network's rounds, slots and ``comm_range``), never its state.
Every other entry of the action (sensing, backend decisions) is the composition's default, as
``always`` plays it.

| policy        | agent i transmits in slot s of round r at step k iff                                   |
|---------------|---------------------------------------------------------------------------------------|
| ``round_robin`` | t mod N = i, t = (k R + r) S + s the global slot (R rounds of S slots per step): TDMA, |
|               | no collision where every agent knows its index; with S = N slots each agent has one per |
|               | step                                                                                  |
| ``aloha:p``   | a uniform draw of its own generator is below p, independently per slot (p in (0, 1]); |
|               | ``aloha`` alone: p = 1 / (n_i + 1), n_i the agents its observation places within the   |
|               | network's ``comm_range`` (slotted ALOHA's throughput-optimal p for n_i + 1 contenders,|
|               | Bertsekas and Gallager, *Data Networks*, 2nd ed., section 4.2.1: n p (1 - p)^(n-1) is  |
|               | largest at p = 1 / n)                                                                 |
"""

from __future__ import annotations

import numpy as np

from agents.base import SeededPolicy
from coloc_env.config import BadInput, is_real
from coloc_env.scenarios.composed import DISTANCE_SCALE


def _medium(env):
    """(core, the transport entries' first index, rounds, slots) of an env over ``contention``."""
    core = env.unwrapped.scenario
    composition = getattr(core, "composition", None)
    if composition is None or composition.network.name != "contention" or not hasattr(core, "action_vector"):
        raise BadInput(f"this policy schedules the contention network's slots; {core.name} is not over "
                       "network contention")
    start = 0
    for blk, part in zip(core.blocks, core.block_parts, strict=True):
        if part == "network" and blk.name == "transmit":
            network = core.network
            return core, start, network.rounds, network.slots
        start += blk.size
    raise BadInput(f"{core.name}: its backend sends nothing over the contention network (no transmit block)")


class _SlotPolicy(SeededPolicy):
    batching = "per_copy"

    def __init__(self, env, seed: int | None = None):
        super().__init__(env, seed)
        core, self.start, self.rounds, self.slots = _medium(env)
        self.N = core.num_agents
        self.horizon = int(core.horizon)
        self.base = np.asarray(core.action_vector("maximum"))
        self.dtype = env.action_space(env.possible_agents[0]).dtype

    def own(self, observation) -> tuple[int, int]:
        """(the agent's index, the step k) from its own observation."""
        o = np.asarray(observation, float)
        return int(np.argmax(o[:self.N])), int(round(float(o[3 * self.N + 1]) * self.horizon))

    def transmit(self, observation) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def act(self, observations: dict) -> dict:
        actions = {}
        for agent, observation in observations.items():
            action = self.base.copy()
            action[self.start:self.start + self.rounds * self.slots] = self.transmit(observation)
            actions[agent] = action.astype(self.dtype)
        return actions


class RoundRobinPolicy(_SlotPolicy):
    """TDMA by index (the module table): deterministic, collision-free where every agent knows its index."""

    def transmit(self, observation) -> np.ndarray:
        i, k = self.own(observation)
        t = k * self.rounds * self.slots + np.arange(self.rounds * self.slots)  # entry r * S + s: the global slot
        return (t % self.N == i).astype(int)


class AlohaPolicy(_SlotPolicy):
    """Slotted ALOHA (the module table): each slot transmitted with probability p from the policy's own
    generator; ``p`` None: 1 / (neighbours within ``comm_range`` by the agent's observed distances + 1)."""

    def __init__(self, env, p: float | None = None, seed: int | None = None):
        super().__init__(env, seed)
        self.p = p
        self.comm_range = float(env.unwrapped.scenario.composition.network.comm_range)

    def probability(self, observation) -> float:
        if self.p is not None:
            return self.p
        o = np.asarray(observation, float)
        i, _ = self.own(o)
        distance = o[2 * self.N + 1:3 * self.N + 1] * DISTANCE_SCALE
        neighbours = int(np.sum(distance <= self.comm_range)) - 1  # itself at 0
        return 1.0 / (neighbours + 1)

    def transmit(self, observation) -> np.ndarray:
        return (self.rng.random(self.rounds * self.slots) < self.probability(observation)).astype(int)


class PolledPolicy(_SlotPolicy):
    """A polled medium, not realizable over ``contention`` (it has no downlink to carry the polls, and the polls
    here cost nothing): in each of the step's R x S slots the centre lets one UAV transmit, the ones with the
    largest ``score``, one per slot in that order. Polled are the UAVs whose transmit is not masked (not the
    centre) and, where the centre only listens, that it can hear now (within ``comm_range`` of it by the
    observed link distances, which the centre's radio knows; none in range: every UAV that may send): a UAV
    out of its range would otherwise keep the largest score and hold every slot. No two frames share a slot,
    so nothing collides; each step gives a slot to min(R S, polled) UAVs.

    | ``score``   | the UAV polled first                                                          |
    |-------------|-------------------------------------------------------------------------------|
    | ``"trace"`` | the largest log tr P it observes (its block of the centre's covariance, which |
    |             | the centre holds: a schedule the centre could run with a downlink)            |
    | ``"error"`` | the largest current position error (the truth: a hindsight schedule)          |
    | ``"age"``   | the most steps since its last delivered frame (``steps_since``; the oldest    |
    |             | first: round robin over the UAVs that transmit, no slot left to the centre)    |
    """

    SCORES = ("trace", "error", "age")

    def __init__(self, env, score: str = "trace"):
        super().__init__(env)
        if score not in self.SCORES:
            raise BadInput(f"score must be one of {self.SCORES}, got {score!r}")
        self.score = score
        # "error" reads the env's truth, which no copy of the batched core hands a policy: the env loop only
        self.batching = None if score == "error" else "per_copy"
        self.core = env.unwrapped.scenario
        masks = self.core.network.transport_masks(None)
        can_send = np.ones(self.N, bool) if masks is None else masks[0][0, :, :, 1].all(axis=-1)
        self.candidates = np.flatnonzero(can_send)
        self.feature = {"trace": self.core.feature_index("log_trace"),
                        "age": self.core.feature_index("steps_since")}.get(score)
        listeners = np.flatnonzero(~can_send)
        self.centre = int(listeners[0]) if len(listeners) == 1 else None
        self.comm_range = float(self.core.composition.network.comm_range)

    def act(self, observations: dict) -> dict:
        agents = list(observations)
        index = {agent: self.own(observations[agent])[0] for agent in agents}
        if self.score == "error":
            value = np.asarray(self.core.position_error()[0], float)
        else:
            value = np.full(self.N, -np.inf)
            for agent in agents:
                value[index[agent]] = float(np.asarray(observations[agent], float)[self.feature])
        candidates = self.candidates
        if self.centre is not None:
            centre = next(a for a in agents if index[a] == self.centre)
            distance = np.asarray(observations[centre], float)[2 * self.N + 1:3 * self.N + 1] * DISTANCE_SCALE
            heard = candidates[distance[candidates] <= self.comm_range]
            candidates = heard if len(heard) else candidates
        # the largest first; equal scores by index (a stable sort of the negated values)
        order = candidates[np.argsort(-value[candidates], kind="stable")]
        slot_of = {int(i): s for s, i in enumerate(order[:self.rounds * self.slots])}
        actions = {}
        for agent in agents:
            action = self.base.copy()
            transmit = np.zeros(self.rounds * self.slots, int)
            if index[agent] in slot_of:
                transmit[slot_of[index[agent]]] = 1
            action[self.start:self.start + self.rounds * self.slots] = transmit
            actions[agent] = action.astype(self.dtype)
        return actions


def bound_polled(env) -> PolledPolicy:
    """The centre polls the UAV with the largest log tr P in each slot (``PolledPolicy``, score ``"trace"``)."""
    return PolledPolicy(env, "trace")


def bound_polled_error(env) -> PolledPolicy:
    """The centre polls the UAV with the largest current position error (``PolledPolicy``, score ``"error"``)."""
    return PolledPolicy(env, "error")


def bound_polled_age(env) -> PolledPolicy:
    """The centre polls the UAV whose last frame it received is the oldest (``PolledPolicy``, score ``"age"``)."""
    return PolledPolicy(env, "age")


def round_robin(env) -> RoundRobinPolicy:
    """Agent i transmits in global slot t iff t mod N = i (module table)."""
    return RoundRobinPolicy(env)


def aloha(env, variant: str | None = None, seed: int | None = None) -> AlohaPolicy:
    """Slotted ALOHA, ``aloha:p`` with p in (0, 1] (module table); ``aloha``: p = 1 / (neighbours + 1)."""
    p = None
    if variant is not None:
        try:
            p = float(variant)
        except ValueError:
            p = None
        if p is None or not is_real(p) or not 0.0 < p <= 1.0:
            raise BadInput(f"aloha's transmit probability (aloha:p) must be a number in (0, 1], got {variant!r}")
    return AlohaPolicy(env, p, seed=seed)


POLICIES = {"round_robin": round_robin, "aloha": aloha}
BASELINES = ("round_robin", "aloha")


def _preset_fixed(env, which: str):
    """``always`` / ``silent`` of the preset: every transmit entry at its maximum / minimum (the composition's
    ``action_vector``; the preset keeps the composition's action)."""
    from agents.base import FixedActionPolicy

    core, _, _, _ = _medium(env)
    return FixedActionPolicy(env, np.tile(core.action_vector(which), (core.num_agents, 1)))


def preset_always(env):
    """Transmit in every slot."""
    return _preset_fixed(env, "maximum")


def preset_silent(env):
    """Never transmit."""
    return _preset_fixed(env, "minimum")


# ``contention_localization``'s policies: ``paper`` is round_robin (the preset's module says why)
PRESET_POLICIES = {"paper": round_robin, "round_robin": round_robin, "aloha": aloha, "always": preset_always,
                   "silent": preset_silent}
