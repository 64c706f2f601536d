"""Network ``contention``: a shared slotted medium, where simultaneous transmissions collide.

Each step has ``rounds`` (the backend's rounds: dNBP's iterations, 1 elsewhere) x ``slots`` transmission
slots in air time. In each slot every agent either transmits one frame or stays silent; the medium, not a
random draw, decides what is heard (the *protocol model* of interference, Gupta and Kumar, "The capacity of
wireless networks", IEEE Trans. Inf. Theory 46(2), 2000, eq. 1): the frame of t reaches r in a slot iff

    d(t, r) <= comm_range,  r does not transmit in the slot (half duplex),  and no other transmitter u of
    the slot has d(u, r) <= interference_range.

With ``capture`` = c > 0 a frame also gets through a collision when its power beats the sum of the others by
that factor (the SINR rule without noise: P_t > c * sum_u P_u over the other transmitters u within
``interference_range`` of r, P = max(d, 0.1 m)^-alpha, alpha = ``path_loss_exponent``). The medium is a
function of the decisions and the positions only: no draw, so the same actions give the same deliveries.

| quantity   | value                                                                                 |
|------------|---------------------------------------------------------------------------------------|
| carries    | ``broadcast``, ``central``, ``packets`` (``chain`` refused: the relay kernel has no     |
|            | notion of simultaneous transmissions)                                                 |
| decisions  | ``transmit`` MultiDiscrete([2] * rounds * slots) per agent: entry r * slots + s, transmit |
|            | in slot s of round r (1) or stay silent (0); ``central``: the centre (agent 0) only  |
|            | listens, its transmit choices are masked (they do what silent does)                  |
| always     | transmit in every slot (every agent in range of another collides)                    |
| silent     | never transmit                                                                        |
| features   | ``ack`` (rounds * slots per agent, in [0, 1]): what the agent's frame of each slot of  |
|            | the step before achieved (below); 0 where it did not transmit                         |

Rounds onto slots. A backend's round r (the ``slot`` argument of its ``broadcast`` / ``packets`` /
``messages_to`` call, clipped to ``rounds - 1``, as ``broadcast`` reads its transmit decisions) uses the r-th
group of ``slots`` slots. An agent's frame in round r carries everything its backend sends in that round (its
broadcast, its packets, each of its readings to the centre); a message of round r from t reaches x iff at least
one of t's slots of round r reached x. A frame is sent whenever the agent decides to transmit, whether its
backend had anything for it or not (the radio's decision; an empty frame occupies the medium all the same).

Accounting, per agent and step (the infos report each under its name):

| name              | counts                                                                            |
|-------------------|-----------------------------------------------------------------------------------|
| ``transmissions`` | frames the agent sent (one per slot it transmitted in)                            |
| ``messages_sent`` | = ``transmissions``: the composition's ``communication_cost`` charges every frame sent, |
|                   | heard or not (the air time is spent)                                              |
| ``link_attempts`` | (frame, in-range receiver) pairs: a frame with k agents within ``comm_range`` counts k; |
|                   | ``central``: 1 where the centre is within ``comm_range`` (it is the only receiver)  |
| ``link_deliveries`` | those that were received                                                        |
| ``collisions``    | those lost to another transmitter within ``interference_range`` of the receiver or to |
|                   | the receiver transmitting (= link_attempts - link_deliveries: the medium loses no other way) |
| ``floats_sent``   | the floats of the backend's messages times the frames that carried them           |

``ack``: one step later the sender observes, per round x slot, the fraction of its in-range neighbours that
received its frame (``central``: 1 if the centre received it, else 0). A receiver's acknowledgement is its own
observation of its own reception; the sender learns it, as a link layer's ACK, before its next decision.

World-node packets (``nlos_orbit``'s neighbours) are not on the agents' medium: they arrive within
``comm_range``, as on ``broadcast``.

Arguments (``coloc_env.networks.Contention``)

| field              | default | allowed                                                                  |
|--------------------|---------|--------------------------------------------------------------------------|
| comm_range         | 200     | (0, inf] m: a frame is heard within this distance                        |
| slots              | 1       | 1..64 transmission slots per round                                        |
| interference_range | None    | [comm_range, inf] m, None = comm_range; a smaller one is refused (a signal |
|                    |         | that can be decoded at d interferes at d)                                |
| capture            | 0.0     | 0 (off) or [1, 1e6]: the power ratio over the sum of the others that wins |
| path_loss_exponent | 2.0     | [1, 10]: alpha of P ~ d^-alpha (read only with capture)                   |
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from coloc_env.config import BadInput, check_distance, is_real
from coloc_env.networks.base import CENTRE, Network, _self_links
from coloc_env.parts import NETWORKS, Block, PartConfig, check_range

MIN_DISTANCE = 0.1  # m: the capture rule's powers are of max(d, MIN_DISTANCE) (two agents at one place)
MEDIUM_KINDS = ("broadcast", "central", "packets")


@NETWORKS.register
@dataclass(frozen=True)
class Contention(PartConfig):
    """Config of the ``contention`` network (see the module table)."""

    name = "contention"
    carries = frozenset(MEDIUM_KINDS)
    refuses: ClassVar[dict[str, str]] = {
        "chain": "the relay kernel has no notion of simultaneous transmissions"}
    comm_range: float = 200.0
    slots: int = 1
    interference_range: float | None = None
    capture: float = 0.0
    path_loss_exponent: float = 2.0

    def check(self, prefix: str) -> None:
        check_distance(f"{prefix}comm_range", self.comm_range)
        check_range(f"{prefix}slots", self.slots, 1, 64, integer=True)
        if self.interference_range is not None:
            check_range(f"{prefix}interference_range", self.interference_range, float(self.comm_range), np.inf,
                        low_label="comm_range")
        if not (is_real(self.capture) and float(self.capture) == 0.0):  # 0: off
            if not is_real(self.capture) or not 1.0 <= float(self.capture) <= 1e6:
                raise BadInput(f"{prefix}capture must be 0 (off) or in [1.0, 1000000.0], got {self.capture!r}")
        check_range(f"{prefix}path_loss_exponent", self.path_loss_exponent, 1.0, 10.0)

    @property
    def interference(self) -> float:
        """The interference range in use (m): ``interference_range``, or ``comm_range`` where it is None."""
        return float(self.comm_range if self.interference_range is None else self.interference_range)

    def build(self, num_agents: int, batch: int, message_kind: str, rounds: int = 1) -> Network:
        return ContentionNetwork(self, num_agents, batch, message_kind, rounds)


class ContentionNetwork(Network):
    """The shared medium: ``begin`` resolves every slot of the step at once (batched over copies, rounds and
    slots: two matrix products per step, none over agents); the delivery calls read the result."""

    def __init__(self, config, num_agents: int, batch: int, message_kind: str, rounds: int = 1):
        super().__init__(config, num_agents, batch, message_kind, rounds)
        B, N = self.batch, self.num_agents
        self.slots = int(config.slots)
        self.on_medium = message_kind in MEDIUM_KINDS
        Q = self.rounds * self.slots if self.on_medium else 0
        self.ack = np.zeros((B, N, Q))
        self._heard = np.zeros((B, self.rounds, N, N), dtype=bool)  # [b, r, t, x]: t's round-r frame reached x
        self._frames = np.zeros((B, self.rounds, N))  # [b, r, t]: t's frames in round r
        self._zero_accounting()

    def _zero_accounting(self) -> None:
        B, N = self.batch, self.num_agents
        self.transmissions = np.zeros((B, N))
        self.link_attempts = np.zeros((B, N))
        self.link_deliveries = np.zeros((B, N))
        self.collisions = np.zeros((B, N))

    # --- description ---------------------------------------------------------------------------------
    def transport_blocks(self) -> list[Block]:
        if not self.on_medium:
            return []
        return [Block("transmit", self.rounds * self.slots, 2,
                      "transmit in this slot (1) or stay silent (0); entry round * slots + slot",
                      default=1, maximum=1, minimum=0)]

    def transport_masks(self, distances) -> list[np.ndarray] | None:
        """``central``: the centre's transmit choice does what silent does (it only listens): masked."""
        if self.message_kind != "central":
            return None
        mask = np.ones((self.batch, self.num_agents, self.rounds * self.slots, 2), dtype=bool)
        mask[:, CENTRE, :, 1] = False
        return [mask]

    def observation_size(self) -> int:
        return self.ack.shape[-1]

    def observation_features(self) -> np.ndarray:
        return self.ack.copy()

    def acknowledged(self) -> np.ndarray | None:
        """(B, N): some slot's ``ack`` of this step is positive; None off the medium (no ``ack``)."""
        return (self.ack > 0).any(axis=-1) if self.observation_size() else None

    def usable(self, distance):
        return np.asarray(distance) <= self.config.comm_range

    # --- the medium ------------------------------------------------------------------------------------
    def reset(self, rngs, idx) -> None:
        super().reset(rngs, idx)
        self.ack[idx] = 0.0

    def begin(self, k, positions, decisions) -> None:
        super().begin(k, positions, decisions)
        self._zero_accounting()
        B, N, R, S = self.batch, self.num_agents, self.rounds, self.slots
        self._heard = np.zeros((B, R, N, N), dtype=bool)
        self._frames = np.zeros((B, R, N))
        self.ack = np.zeros_like(self.ack)
        decisions = np.asarray(decisions)
        if not self.on_medium or decisions.shape[-1] != R * S:  # no transport decisions (a receive-ahead call)
            return
        sending = decisions.reshape(B, N, R * S).astype(bool)
        if self.message_kind == "central":
            sending = sending.copy()
            sending[:, CENTRE] = False
        if not sending.any():
            return
        T = sending.transpose(0, 2, 1).astype(float)  # (B, Q, N) [b, q, t]: t transmits in slot q
        distance = self.distances()
        shared = distance.strides[0] == 0
        d = distance[:1] if shared else distance  # copies at one place share the link geometry
        others = ~_self_links(N)
        in_range = (d <= self.config.comm_range) & others  # [t, x]
        near = (d <= self.config.interference) & others  # [u, x]: u's transmission interferes at x
        idle = T == 0.0
        if self.config.capture > 0:
            c = float(self.config.capture)
            power = np.where(near, np.maximum(d, MIN_DISTANCE) ** -float(self.config.path_loss_exponent), 0.0)
            total = T @ power  # (B, Q, N) [q, x]: the power of every transmitter within interference range of x
            # [b, q, t, x]: P_t > c (total - P_t), i.e. P_t (1 + c) > c total; alone (total = P_t) it holds
            got = (T[..., :, None] > 0) & in_range[:, None] & idle[..., None, :] \
                & (power[:, None] * (1.0 + c) > c * total[..., None, :])
            per_slot = got.astype(float)
            heard_slots = per_slot.reshape(B, R, S, N, N).sum(axis=2)  # [b, r, t, x]
            received = per_slot  # (B, Q, N, N)
        else:
            # protocol model: x hears in slot q iff exactly one transmitter is within interference range of x and
            # x is silent; that one is t whenever t is within comm_range <= interference_range of x
            count = T @ near.astype(float)  # (B, Q, N) [q, x]
            clear = ((count == 1.0) & idle).astype(float)
            # [b, r, t, x]: the slots of round r in which t transmitted and x heard only it
            heard_slots = T.reshape(B, R, S, N).transpose(0, 1, 3, 2) @ clear.reshape(B, R, S, N)
            heard_slots = heard_slots * in_range[:, None]
            received = None
        self._heard = heard_slots > 0
        self._frames = T.reshape(B, R, S, N).sum(axis=2)
        frames = T.sum(axis=1)  # (B, N)
        self.transmissions = frames
        self.messages_sent = frames.copy()
        if self.message_kind == "central":
            reach = np.broadcast_to(in_range[:, :, CENTRE], (B, N)).astype(float)  # the centre alone listens
            if received is None:
                got_slot = T * clear[:, :, CENTRE:CENTRE + 1] * reach[:, None, :]  # (B, Q, N) [q, t]
            else:
                got_slot = received[..., CENTRE]
            ack = got_slot
        else:
            reach = np.broadcast_to(in_range.sum(axis=-1), (B, N)).astype(float)  # in-range receivers of t
            if received is None:
                got_count = T * (clear @ in_range.transpose(0, 2, 1).astype(float))  # (B, Q, N) [q, t]
            else:
                got_count = received.sum(axis=-1)
            got_slot = got_count
            ack = np.divide(got_count, reach[:, None, :], out=np.zeros_like(got_count), where=reach[:, None, :] > 0)
        self.link_attempts = frames * reach
        self.link_deliveries = got_slot.sum(axis=1)
        self.collisions = self.link_attempts - self.link_deliveries
        self.ack = ack.transpose(0, 2, 1).copy()  # (B, N, Q)

    def _round(self, slot) -> np.ndarray:
        return np.minimum(np.asarray(slot, int), self.rounds - 1)

    def _wanted(self, senders, listening) -> np.ndarray:
        """(B, N, N) [t, x]: t has a message for x, x within range."""
        want = np.asarray(senders, bool)[:, :, None] & np.asarray(listening, bool) & ~_self_links(self.num_agents)
        return want & self.usable(self.distances())

    def broadcast(self, senders, listening, floats: float, slot: int = 0) -> np.ndarray:
        """One round's broadcast (``Network.broadcast``'s arguments): delivered (B, N, N) [t, x] where t's frame of
        round ``slot`` reached x (module docstring); the floats count once per frame that carried them."""
        r = int(self._round(slot))
        want = self._wanted(senders, listening)
        delivered = want & self._heard[:, r]
        self.floats_sent += floats * want.any(axis=-1) * self._frames[:, r]
        self.delivered |= delivered
        return delivered

    def packets(self, senders, listening, floats, slot: int = 0) -> np.ndarray:
        """One stamped packet per sender in round ``slot`` (``Network.packets``' arguments): delay (B, N, N) 0 where
        t's frame of that round reached x, else -1 (never late: the medium loses, it does not delay)."""
        r = int(self._round(slot))
        want = self._wanted(senders, listening)
        delay = np.where(want & self._heard[:, r], 0, -1).astype(np.int64)
        if isinstance(floats, np.ndarray) and floats.ndim == 3:
            payload = np.where(want, floats, 0.0).sum(axis=-1)
        else:
            payload = np.asarray(floats, float) * want.any(axis=-1)
        self.floats_sent += payload * self._frames[:, r]
        self.delivered |= delay == 0
        return delay

    def messages_to(self, senders, receiver: int, floats: float, slots) -> np.ndarray:
        """J messages per copy to ``receiver`` (``Network.messages_to``' arguments): message j of sender t in round
        ``slots[j]`` arrives iff t's frame of that round reached the receiver."""
        senders = np.asarray(senders, int)
        B, J = senders.shape
        N = self.num_agents
        rounds = np.broadcast_to(self._round(slots), (J,))
        rows = np.arange(B)[:, None]
        sender = np.maximum(senders, 0)
        want = (senders >= 0) & (senders != receiver) \
            & self.usable(self.distances()[rows, sender, receiver])
        ok = want & self._heard[rows, rounds[None, :], sender, receiver]
        carried = np.where(want, self._frames[rows, rounds[None, :], sender], 0.0)
        self.floats_sent += floats * np.bincount((rows * N + sender).reshape(-1), carried.reshape(-1),
                                                 minlength=B * N).reshape(B, N)
        b, j = np.nonzero(ok)
        self.delivered[b, sender[b, j], receiver] = True
        return ok

    def relay(self, *args, **kwargs):  # pragma: no cover - refused by the composition (``Contention.refuses``)
        raise NotImplementedError("contention carries no relay chains: the relay kernel has no notion of "
                                  "simultaneous transmissions")
