"""Network ``random_delay`` (gao2016 Assumption 3): each packet arrives after 0..D steps, or is lost.

Each packet draws its own delay tau in {0..D}, P(tau = l) = q_l (``delay_probs``),
independently of everything else; with probability 1 - sum q_l it is later than the
receiver's buffer of length D (``buffer_length``) and counts as lost [paper]. The draw is
the inverse CDF of one counter-based uniform u per packet (``coloc_env.draws``):
``tau = #{l : q_0 + ... + q_l <= u}``, lost when tau > D, the rule of
``coloc_env.networks.blocks.bounded_delay.BoundedRandomDelay.sample``. The receiver (the backend)
buffers what arrives late; the network only says when.

| quantity   | value                                                                                  |
|------------|----------------------------------------------------------------------------------------|
| carries    | ``packets`` only (a broadcast, chain or central message has no buffer; a "late = lost" |
|            | reading of them would be a different network, so they are not offered)                 |
| packets    | agent -> agent by ``coloc_env.networks.base.Network.packets``, world node -> agent by |
|            | ``coloc_env.networks.base.Network.node_packets`` (the delays of both overridden here) |
| delay      | 0..D steps with q_0..q_D; lost with 1 - sum q_l; a link beyond ``comm_range`` carries   |
|            | nothing                                                                                |
| decisions  | none by default (gao2016's senders always transmit); with ``transmit_decision`` a      |
|            | ``transmit`` block MultiDiscrete([2] * rounds) for agent senders                       |
| always     | every packet transmitted                                                               |
| silent     | with ``transmit_decision``: no agent transmits (world nodes still do)                  |
| accounting | agent senders: ``messages_sent`` / ``floats_sent`` as in the base (one message per     |
|            | sender and step, counted when transmitted); world nodes: ``node_messages`` /           |
|            | ``node_floats`` (B, N) per receiving agent (world nodes are no agents)                 |

In gao2016 the senders are the target's orbiting neighbours, which are part of the world,
not agents: their packets go through the base's ``node_packets``, whose uniforms this
network's ``packet_delays`` turns into delays.

Arguments (``coloc_env.networks.RandomDelay``; defaults = ``nlos_horizon``'s)

| field             | default               | allowed                                          |
|-------------------|-----------------------|--------------------------------------------------|
| delay_probs       | (0.6, 0.2, 0.1, 0.05) | buffer_length + 1 entries in [0, 1], sum <= 1    |
| buffer_length     | 3                     | D, 0..1000 steps                                 |
| comm_range        | inf                   | (0, inf] m (gao2016 has none: the RSA is the world's) |
| transmit_decision | False                 | True: agent senders get a ``transmit`` block     |
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import as_array, check_distance
from coloc_env.networks.base import Network
from coloc_env.networks.blocks.bounded_delay import BoundedRandomDelay
from coloc_env.parts import NETWORKS, Block, PartConfig, check_flag


@NETWORKS.register
@dataclass(frozen=True)
class RandomDelay(PartConfig):
    """Config of the ``random_delay`` network (see the module table)."""

    name = "random_delay"
    carries = frozenset({"packets"})
    delay_probs: tuple = (0.6, 0.2, 0.1, 0.05)
    buffer_length: int = 3
    comm_range: float = float("inf")
    transmit_decision: bool = False

    @property
    def delay(self) -> BoundedRandomDelay:
        return BoundedRandomDelay(tuple(self.delay_probs), self.buffer_length)

    def check(self, prefix: str) -> None:
        as_array(f"{prefix}delay_probs", self.delay_probs, ndim=1)  # before ``delay`` iterates over it
        self.delay.validate(f"{prefix}delay_probs", f"{prefix}buffer_length")
        check_distance(f"{prefix}comm_range", self.comm_range)
        check_flag(f"{prefix}transmit_decision", self.transmit_decision)

    def build(self, num_agents: int, batch: int, message_kind: str, rounds: int = 1) -> Network:
        return RandomDelayNetwork(self, num_agents, batch, message_kind, rounds)


def delays_from_uniforms(probabilities, buffer_length: int, u: np.ndarray) -> np.ndarray:
    """tau = #{l : q_0 + ... + q_l <= u} (Assumption 3's inverse CDF), -1 where tau > D (lost)."""
    tau = np.searchsorted(np.cumsum(np.asarray(probabilities, float)), u, side="right")
    return np.where(tau > buffer_length, -1, tau).astype(np.int64)


class RandomDelayNetwork(Network):
    def transport_blocks(self) -> list[Block]:
        if self.config.transmit_decision and self.message_kind == "packets":
            return [Block("transmit", self.rounds, 2, "transmit this step's packet (1) or not (0)", default=1,
                          maximum=1, minimum=0)]
        return []

    def usable(self, distance):
        return np.asarray(distance) <= self.config.comm_range

    def packet_delays(self, distance, u):
        return delays_from_uniforms(self.config.delay_probs, self.config.buffer_length, u)

    def max_delay(self) -> int:
        return int(self.config.buffer_length)

    def transmits(self, round_index: int) -> np.ndarray:
        if not (self.config.transmit_decision and self.message_kind == "packets"):
            return super().transmits(round_index)
        return self._decisions[:, :, min(round_index, self.rounds - 1)].astype(bool)
