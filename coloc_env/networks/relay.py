"""Network ``relay`` (wang2019 links): serial relay hops with a hop budget, a range limit and distance loss.

A hop of length d is lost with p_loss(d) = 1 - (1 - loss_at_zero) exp(-d / loss_length)
(``coloc_env.networks.blocks.relay_chain.RelayChainLinks``); a hop beyond ``comm_range`` is not possible.

| quantity   | value                                                                                     |
|------------|-------------------------------------------------------------------------------------------|
| carries    | ``chain``, ``broadcast``, ``central``, ``packets`` (one hop, lost with p_loss(d))         |
| decisions  | ``chain``: ``next_hop``, Discrete(N + 2) entries per agent: a platform, N = stop,        |
|            | N + 1 = the nearest not yet reached; one entry (``routing="per_holder"``) or N entries,  |
|            | entry m for the chain whose source is platform m (``routing="per_source"``);             |
|            | ``broadcast``: ``transmit`` ([2] * rounds)                                                |
| mask       | ``next_hop``: itself, a platform beyond ``comm_range`` and (``per_source``) entry m's    |
|            | source m end the chain as N = stop does; N + 1 where no other platform is in range       |
| always     | nearest-first relay, transmit in every round                                             |
| silent     | stop at once (the measured platform alone), transmit nothing                             |
| accounting | one message per delivered hop, at its holder (``coloc_env.networks.base``); the hop's    |
|            | energy cost ``hop_cost_per_m2 d^2`` of every delivered hop at its holder, in             |
|            | ``RelayNetwork.cost_sent`` (B, N), per step                                              |

Routing. ``per_holder`` (wang2019's ``relay_ukf``: one platform measures per
step): a holder passes every chain it holds to the same next hop.
``per_source`` (``mrclam_relay``: several robots measure in one step, each
starting a chain): each holder keeps a routing table, one next hop per source,
so two chains that pass the same holder can take different routes (with one
next hop per holder they could not both be complete).

Hop cost. A delivered hop is one message, so its flat price is the
composition's ``communication_cost`` (per message, subtracted from the
reward by ``coloc_env.scenarios.composed``); the network itself prices only
what depends on the hop's length, its radio energy ``hop_cost_per_m2 d^2``
(free-space energy grows like d^2), accounted at the sender in ``cost_sent``
and subtracted beside it, in the reward's unit. ``hop_cost``, the network's
older name of the flat price, is read as the composition's
``communication_cost`` (a price per message the network counts: for a chain,
per delivered hop) where a relay network is given as a dict
(``compose(network={"name": "relay", "hop_cost": c})``, ``coloc study
--sweep network.hop_cost=...``; ``Relay.aliases``); giving both
is refused, and a refused value is named ``network.hop_cost``. Neither cost
changes an estimate or a delivery.

Arguments (``coloc_env.networks.Relay``)

| field           | default      | allowed                                                     |
|-----------------|--------------|-------------------------------------------------------------|
| comm_range      | inf          | (0, inf] m                                                  |
| max_hops        | None         | 1..N-1 hops per chain (N the world's agents, checked at build), None = no limit |
| loss_at_zero    | 0.1          | [0, 1]                                                      |
| loss_length     | inf          | (0, inf] m                                                  |
| routing         | "per_holder" | "per_holder", "per_source" (see Routing)                    |
| hop_cost_per_m2 | 0.0          | [0, 1e12] per delivered hop and squared metre of its length |
| hop_cost        | (no field)   | older name of the composition's ``communication_cost`` (Hop cost) |
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.networks.base import Network
from coloc_env.networks.blocks.relay_chain import RelayChainLinks
from coloc_env.parts import NETWORKS, Block, PartConfig, check_choice

ROUTINGS = ("per_holder", "per_source")


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
    routing: str = "per_holder"
    hop_cost_per_m2: float = 0.0
    aliases = {"hop_cost": "composition.communication_cost"}  # a hop is one message: its flat price

    def check(self, prefix: str) -> None:
        """The hop rules' fields (``RelayChainLinks.validate``, before the team is known) and the routing."""
        self.links.validate(None, prefix)
        check_choice(f"{prefix}routing", self.routing, ROUTINGS)

    def check_hop_budget(self, num_agents: int, prefix: str, agents: str) -> None:
        """``max_hops`` against the team: at most N - 1 hops (``agents`` names N in the message)."""
        self.links.check_hop_budget(num_agents, prefix, agents)

    @property
    def links(self) -> RelayChainLinks:
        """The hop rules: range limit, hop budget, distance loss and a hop's energy cost."""
        return RelayChainLinks(self.comm_range, self.max_hops, self.loss_at_zero, self.loss_length,
                               self.hop_cost_per_m2)

    def build(self, num_agents: int, batch: int, message_kind: str, rounds: int = 1) -> Network:
        return RelayNetwork(self, num_agents, batch, message_kind, rounds)


class RelayNetwork(Network):
    STEP_RECORD = (*Network.STEP_RECORD, "cost_sent")

    def __init__(self, config: Relay, num_agents, batch, message_kind, rounds=1):
        super().__init__(config, num_agents, batch, message_kind, rounds)
        config.check_hop_budget(num_agents, "network.", "world.num_agents")
        self.links = config.links
        self.cost_sent = np.zeros((self.batch, self.num_agents))
        self._source = np.zeros(self.batch, dtype=int)

    def transport_blocks(self) -> list[Block]:
        N = self.num_agents
        if self.message_kind == "chain":
            if self.config.routing == "per_source":
                return [Block("next_hop", N, N + 2, f"entry m: whom to relay the chain of source m to: a platform, "
                              f"{N} = stop, {N + 1} = nearest not yet reached", default=N + 1, maximum=N + 1,
                              minimum=N)]
            return [Block("next_hop", 1, N + 2, f"whom to relay to: a platform, {N} = stop, {N + 1} = nearest "
                          "not yet reached", default=N + 1, maximum=N + 1, minimum=N)]
        if self.message_kind in ("broadcast", "central", "packets"):
            return [Block("transmit", self.rounds, 2, "transmit in this round (1) or not (0)", default=1,
                          maximum=1, minimum=0)]
        return []

    def transport_masks(self, distances) -> list[np.ndarray] | None:
        """``next_hop``: itself and a platform beyond ``comm_range`` end the chain, as N = stop does; with
        ``per_source`` routing, entry m's source m too (every chain of m has reached it); N + 1 (the nearest
        not yet reached) only where another platform is within ``comm_range``. Stop is always valid."""
        if self.message_kind != "chain":
            return None
        N = self.num_agents
        others = ~np.eye(N, dtype=bool)
        reach = np.asarray(self.usable(distances()), bool) & others  # [holder, j]
        if self.config.routing == "per_source":  # entry m for the chain whose source is m
            allowed = reach[:, :, None, :] & others[None, None, :, :]  # [holder, m, j]
        else:  # per_holder: one next hop for whatever chain the holder holds
            allowed = reach[:, :, None, :]
        mask = np.ones((self.batch, N, allowed.shape[2], N + 2), dtype=bool)
        mask[..., :N] = allowed
        mask[..., N + 1] = allowed.any(axis=-1)
        return [mask]

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

    def begin(self, k, positions, decisions) -> None:
        super().begin(k, positions, decisions)
        self.cost_sent = np.zeros_like(self.cost_sent)

    def sending_cost(self) -> np.ndarray:
        """The hops' energy each holder spent this step (``cost_sent``: the module table)."""
        return self.cost_sent

    def next_hop_choice(self):
        """(B, N) each holder's next hop for the chain being resolved: its only entry (``per_holder``), or its
        entry for that chain's source (``per_source``)."""
        if self.message_kind != "chain":
            return None
        if self.config.routing == "per_source":
            return self._decisions[np.arange(self.batch), :, self._source]
        return self._decisions[:, :, 0]

    def relay(self, source, first, floats_per_hop, slot: int = 0):
        """``Network.relay`` with the routing entry of each copy's source, and the hops' energy costs accounted."""
        self._source = np.maximum(np.asarray(source, int), 0)
        chain = super().relay(source, first, floats_per_hop, slot)
        if self.config.hop_cost_per_m2 == 0:
            return chain  # free hops: cost_sent stays 0
        cost = self.links.cost(chain.hop_distance)  # (B, N - 1); 0 where no hop was delivered
        rows = np.arange(self.batch)
        for hop in range(cost.shape[1]):
            holder = chain.chain[:, hop]
            done = ~np.isnan(chain.hop_distance[:, hop])
            self.cost_sent[rows[done], holder[done]] += cost[done, hop]
        return chain
