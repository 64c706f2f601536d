"""Network ``broadcast`` (wan2014's medium): one transmission heard by every neighbour within range.

| quantity   | value                                                                                |
|------------|--------------------------------------------------------------------------------------|
| carries    | ``broadcast``, ``central``, ``packets``, ``chain`` (chains relay nearest first, in range) |
| decisions  | ``transmit`` MultiDiscrete([2] * rounds) per agent: broadcast in each round or not    |
| always     | broadcast at every opportunity                                                       |
| silent     | never broadcast                                                                      |

Arguments (``coloc_env.networks.Broadcast``)

| field        | default | allowed                                   |
|--------------|---------|-------------------------------------------|
| comm_range   | 200     | (0, inf] m (wan2014's communication radius) |
| loss         | 0.0     | [0, 1] loss probability per message       |
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import check_distance
from coloc_env.networks.base import Network
from coloc_env.parts import NETWORKS, Block, PartConfig, check_range


@NETWORKS.register
@dataclass(frozen=True)
class Broadcast(PartConfig):
    """Config of the ``broadcast`` network (see the module table)."""

    name = "broadcast"
    carries = frozenset({"broadcast", "chain", "central", "packets"})
    comm_range: float = 200.0
    loss: float = 0.0

    def check(self, prefix: str) -> None:
        check_distance(f"{prefix}comm_range", self.comm_range)
        check_range(f"{prefix}loss", self.loss, 0.0, 1.0)

    def build(self, num_agents: int, batch: int, message_kind: str, rounds: int = 1) -> Network:
        return BroadcastNetwork(self, num_agents, batch, message_kind, rounds)


class BroadcastNetwork(Network):
    def transport_blocks(self) -> list[Block]:
        if self.message_kind in ("broadcast", "central", "packets"):
            return [Block("transmit", self.rounds, 2, "broadcast in this round (1) or not (0)", default=1,
                          maximum=1, minimum=0)]
        return []

    def usable(self, distance):
        return np.asarray(distance) <= self.config.comm_range

    def loss_probability(self, distance):
        return np.full(np.shape(distance), float(self.config.loss))

    def transmits(self, round_index: int) -> np.ndarray:
        if self.message_kind not in ("broadcast", "central", "packets"):
            return super().transmits(round_index)
        return self._decisions[:, :, min(round_index, self.rounds - 1)].astype(bool)
