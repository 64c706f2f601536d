"""Network ``bernoulli_delay`` (fu2017 eq. 3): each slot a link delivers on time, one slot late, or nothing.

Fu, Bi, Gao 2017, eq. (3): at slot k the receiver holds y_i(k) = xi1 z_i(k) +
xi2 z_i(k-1) + (1 - xi1 - xi2) y_i(k-1): one outcome per link and slot, on time
(probability alpha1 = ``on_time_probability``), late (alpha2 =
``late_probability``: the previous slot's packet arrives now) or lost; the
outcomes are i.i.d. over slots and links and exclusive (the paper's xi1, xi2;
see ``coloc_env.networks.blocks.delay_links.BernoulliDelayLink``).

Reading built (the paper's per-slot outcome, exactly): the outcome of slot k
on link t -> s is one uniform u_k (the base's counter-based draw of step k);
packet k is on time (delay 0) if u_k < alpha1; otherwise it arrives one step
late (delay 1) if the *next* slot's outcome is "late", alpha1 <= u_{k+1} <
alpha1 + alpha2 (u_{k+1} is the same counter-based draw the next step makes;
it is drawn once and kept for that step), else it is lost (-1). So at most
one packet per link arrives in a slot and the held sequence is eq. (3)'s.
The one difference from (3) as printed: a late outcome after an on-time
packet would re-deliver the packet already held (a duplicate); a packet has
one delay, so it is not delivered again. The held value and its age are the
same either way. Per packet, P(delay 0) = alpha1, P(delay 1) =
(1 - alpha1) alpha2.

| quantity   | value                                                                                     |
|------------|-------------------------------------------------------------------------------------------|
| carries    | ``packets`` (delays 0 or 1, or lost), ``components`` (a component message is one packet:  |
|            | on time, or late / lost; a backend that cannot use a late one drops it)                   |
| decisions  | ``transmit`` MultiDiscrete([2] * rounds) per agent: send this slot (1) or not (0)         |
| always     | transmit every slot                                                                       |
| silent     | transmit nothing                                                                          |
| accounting | at the sender when transmitted, delivered or not (the base's ``packets``)                 |
| statistics | ``BernoulliDelayNetwork.slot_probabilities``: (alpha1, alpha2) per link, what fu2017's |
|            | estimators assume                                                                          |

Arguments (``coloc_env.networks.BernoulliDelay``; defaults = the paper's)

| field                | default | allowed                                              |
|----------------------|---------|------------------------------------------------------|
| on_time_probability  | 0.4     | [0, 1] (alpha1)                                      |
| late_probability     | 0.3     | [0, 1] (alpha2); alpha1 + alpha2 in (0, 1]           |
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.draws import uniforms
from coloc_env.networks.base import Network
from coloc_env.parts import NETWORKS, Block, PartConfig, check_range


@NETWORKS.register
@dataclass(frozen=True)
class BernoulliDelay(PartConfig):
    """Config of the ``bernoulli_delay`` network (see the module table)."""

    name = "bernoulli_delay"
    carries = frozenset({"packets", "components"})
    on_time_probability: float = 0.4
    late_probability: float = 0.3

    def check(self, prefix: str) -> None:
        check_range(f"{prefix}on_time_probability", self.on_time_probability, 0.0, 1.0)
        check_range(f"{prefix}late_probability", self.late_probability, 0.0, 1.0)
        total = float(self.on_time_probability) + float(self.late_probability)
        if not 0.0 < total <= 1.0 + 1e-12:
            raise ValueError(f"{prefix}on_time_probability + {prefix}late_probability must be in (0, 1] "
                             f"(a link must deliver sometimes), got {total!r}")

    def build(self, num_agents: int, batch: int, message_kind: str, rounds: int = 1) -> Network:
        return BernoulliDelayNetwork(self, num_agents, batch, message_kind, rounds)


BLOCK_STEPS = 32  # steps of packet delays drawn at once (see BernoulliDelayNetwork._link_delays)


class BernoulliDelayNetwork(Network):
    """The base's ``packets`` with fu2017's per-slot outcomes as packet delays."""

    @property
    def _delays_read_distance(self) -> bool:
        # this packet_delays reads the uniforms only, so packets computes no distances; a subclass's may read them
        return type(self).packet_delays is not BernoulliDelayNetwork.packet_delays

    def __init__(self, config: BernoulliDelay, num_agents, batch, message_kind, rounds=1):
        super().__init__(config, num_agents, batch, message_kind, rounds)
        self._slot = 0
        # slot -> (first step (B,), delays (B, BLOCK_STEPS, N, N)): every link's packet delays over the next
        # BLOCK_STEPS steps, drawn in one call (a delay reads this step's uniform and the next one's)
        self._blocks: dict[int, tuple] = {}
        self._rows = np.arange(self.batch)
        # a subclass with a delay rule of its own draws per step through the base
        self._draws_blocks = type(self).packet_delays is BernoulliDelayNetwork.packet_delays

    def transport_blocks(self) -> list[Block]:
        if self.message_kind in ("packets", "components"):
            return [Block("transmit", self.rounds, 2, "transmit this slot (1) or not (0)", default=1, maximum=1,
                          minimum=0)]
        return []

    def transmits(self, round_index: int) -> np.ndarray:
        if self.message_kind not in ("packets", "components"):
            return super().transmits(round_index)
        return self._decisions[:, :, min(round_index, self.rounds - 1)].astype(bool)

    def packets(self, senders, listening, floats, slot: int = 0):
        self._slot = slot  # packet_delays reads the next slot's draw of the same (round) slot
        return super().packets(senders, listening, floats, slot)

    def max_delay(self) -> int:
        return 1

    def _delay_codes(self, u: np.ndarray, u_next: np.ndarray) -> np.ndarray:
        """The module's rule: on time if u_k < alpha1, one step late if the next slot's outcome is late."""
        a1 = float(self.config.on_time_probability)
        a2 = float(self.config.late_probability)
        late = (u_next >= a1) & (u_next < a1 + a2)
        return np.where(u < a1, 0, np.where(late, 1, -1))

    def packet_delays(self, distance: np.ndarray, u: np.ndarray) -> np.ndarray:
        u_next = uniforms(self.keys, (self._k + 1, self._stream, self._slot), np.shape(u)[-2:])
        return self._delay_codes(u, u_next)

    def _link_delays(self, distance, slot: int) -> np.ndarray:
        if not self._draws_blocks:
            return super()._link_delays(distance, slot)
        # one counter-based draw of BLOCK_STEPS + 1 steps instead of two per step: the values depend on the
        # counters only, so they equal the per-step draws bit for bit (tests/coloc_env/test_fast_paths.py)
        k = self._k if np.shape(self._k) == (self.batch,) else np.broadcast_to(self._k, (self.batch,))
        block = self._blocks.get(slot)  # the keys change only at reset, which drops the blocks
        if block is not None:
            first, delays = block
            row = k - first
            if row.min() >= 0 and row.max() < delays.shape[1]:
                return delays[self._rows, row]
        B, N, W = self.batch, self.num_agents, BLOCK_STEPS
        steps = (k[:, None] + np.arange(W + 1)).reshape(-1)
        u = uniforms(np.repeat(self.keys, W + 1), (steps, 2, slot), (N, N)).reshape(B, W + 1, N, N)
        delays = self._delay_codes(u[:, :-1], u[:, 1:])
        self._blocks[slot] = (np.array(k, dtype=np.int64), delays)
        return delays[:, 0]

    def reset(self, rngs, idx) -> None:
        super().reset(rngs, idx)
        self._blocks.clear()

    def slot_outcomes(self, steps, slot: int = 0) -> np.ndarray:
        """(B, len(steps), N, N) [t, s] eq. (3)'s outcome code of link t -> s at each of ``steps``: 0 on time
        (u_k < alpha1), 1 late (alpha1 <= u_k < alpha1 + alpha2), 2 lost (the codes of
        ``estimators.lossy_fusion``), from the same counter-based uniforms ``packets`` draws; known
        from reset, whatever the agents decide. A "late" code after an on-time packet delivers nothing new
        (see the module table)."""
        a1 = float(self.config.on_time_probability)
        a2 = float(self.config.late_probability)
        N, B = self.num_agents, self.batch
        steps = np.asarray(list(steps), dtype=np.int64)
        # one call for every (copy, step): the keys repeated per step, the step as that row's counter
        u = uniforms(np.repeat(self.keys, len(steps)), (np.tile(steps, B), 2, slot), (N, N))
        u = u.reshape(B, len(steps), N, N)
        return np.where(u < a1, 0, np.where(u < a1 + a2, 1, 2)).astype(np.int8)

    def slot_probabilities(self, distance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(alpha1, alpha2) per link at ``distance``: the per-slot outcome probabilities of eq. (3)."""
        shape = np.shape(distance)
        return (np.full(shape, float(self.config.on_time_probability)),
                np.full(shape, float(self.config.late_probability)))
