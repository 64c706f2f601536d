"""Network ``relay`` (wang2019 links): serial relay hops with a hop budget, a range limit and distance loss.

A hop of length d is lost with p_loss(d) = 1 - (1 - loss_at_zero) exp(-d / loss_length)
(:class:`coloc_env.world.relay.RelayChainLinks`); a hop beyond ``comm_range`` is not possible.

| quantity   | value                                                                                     |
|------------|-------------------------------------------------------------------------------------------|
| carries    | ``chain``, ``broadcast``, ``central``, ``packets`` (one hop, lost with p_loss(d))         |
| decisions  | ``chain``: ``next_hop`` Discrete(N + 2) per agent: a platform, N = stop,                 |
|            | N + 1 = the nearest not yet reached; ``broadcast``: ``transmit`` ([2] * rounds)          |
| always     | nearest-first relay, transmit in every round                                             |
| silent     | stop at once (the measured platform alone), transmit nothing                             |

Arguments (``coloc_env.networks.Relay``)

| field        | default | allowed                                         |
|--------------|---------|-------------------------------------------------|
| comm_range   | inf     | > 0 m                                           |
| max_hops     | None    | >= 1 hops per chain, None = no limit            |
| loss_at_zero | 0.1     | [0, 1]                                          |
| loss_length  | inf     | > 0 m                                           |
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.networks.base import Network
from coloc_env.parts import NETWORKS, Block, PartConfig, check_range
from coloc_env.world.relay import RelayChainLinks, check_distance


@NETWORKS.register
@dataclass(frozen=True)
class Relay(PartConfig):
    """Config of the ``relay`` network (see the module table)."""

    name = "relay"
    carries = frozenset({"broadcast", "chain", "central", "packets"})
    comm_range: float = float("inf")
    max_hops: int | None = None
    loss_at_zero: float = 0.1
    loss_length: float = float("inf")

    def check(self, prefix: str) -> None:
        check_distance(f"{prefix}comm_range", self.comm_range)
        if self.max_hops is not None:
            check_range(f"{prefix}max_hops", self.max_hops, 1, 1000, integer=True)
        check_range(f"{prefix}loss_at_zero", self.loss_at_zero, 0.0, 1.0)
        check_distance(f"{prefix}loss_length", self.loss_length)

    def build(self, num_agents: int, batch: int, message_kind: str, rounds: int = 1) -> Network:
        return RelayNetwork(self, num_agents, batch, message_kind, rounds)


class RelayNetwork(Network):
    def __init__(self, config: Relay, num_agents, batch, message_kind, rounds=1):
        super().__init__(config, num_agents, batch, message_kind, rounds)
        self.links = RelayChainLinks(config.comm_range, config.max_hops, config.loss_at_zero, config.loss_length)

    def transport_blocks(self) -> list[Block]:
        N = self.num_agents
        if self.message_kind == "chain":
            return [Block("next_hop", 1, N + 2, f"whom to relay to: a platform, {N} = stop, {N + 1} = nearest "
                          "not yet reached", default=N + 1, maximum=N + 1, minimum=N)]
        if self.message_kind in ("broadcast", "central", "packets"):
            return [Block("transmit", self.rounds, 2, "transmit in this round (1) or not (0)", default=1,
                          maximum=1, minimum=0)]
        return []

    def usable(self, distance):
        return np.asarray(distance) <= self.config.comm_range

    def loss_probability(self, distance):
        return self.links.loss_probability(distance)

    def max_hops(self) -> int:
        limit = self.num_agents - 1
        return limit if self.config.max_hops is None else min(self.config.max_hops, limit)

    def transmits(self, round_index: int) -> np.ndarray:
        if self.message_kind == "chain":
            return super().transmits(round_index)
        return self._decisions[:, :, min(round_index, self.rounds - 1)].astype(bool)

    def next_hop_choice(self):
        return self._decisions[:, :, 0] if self.message_kind == "chain" else None
