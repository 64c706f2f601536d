"""Network ``bandwidth`` (zhao2020): each receiver takes a budget of state components from its neighbours.

Zhao et al. 2020, Sec. 1-2 (eqs. 5-7): receiver i takes, from each neighbour
j, t_ji of the n components of j's message (a diagonal 0/1 selection T_ji),
with ``min_per_link <= t_ji <= max_per_link`` and sum_j t_ji = ``budget``
(``<=`` when ``exact_budget`` is False); the rest it fills with its own
prediction (the backend's eq. 6). The network is fully connected and
lossless (the paper's); the constraint is the receiver's bandwidth
(:class:`coloc_env.world.links.BandwidthBudget`). n is the backend's message
size (the world's state dimension), known when the backend is built.

A receiver's transport decision is one index into the feasible selections
(:attr:`BandwidthBudget.feasible`, a fixed order; 108 of them in the paper's
setting N = 4, n = 3, budget 5, 1..3 per link); neighbours are indexed
relative to the receiver (neighbour k of agent i is agent (i + 1 + k) mod N).
The index is decoded by :meth:`BandwidthBudget.selection_at` (unranking by
the completion table), so nothing is listed; the Discrete's size is capped
at 100,000 (``MAX_SELECTIONS``).

| quantity   | value                                                                                    |
|------------|------------------------------------------------------------------------------------------|
| carries    | ``components``                                                                           |
| decisions  | ``selection`` Discrete(F) per agent (as receiver): which feasible selection it takes     |
| always     | the first feasible selection with the most components                                     |
| silent     | the first feasible selection with the fewest (with ``exact_budget`` every selection      |
|            | takes exactly ``budget``: silent cannot send less)                                        |
| delivery   | every selected component, on time                                                         |
| accounting | at the sender: one message per (sender, receiver) link with a component selected,        |
|            | t_ji floats                                                                               |

Arguments (``coloc_env.networks.Bandwidth``; defaults = the paper's)

| field         | default | allowed                                                                     |
|---------------|---------|-----------------------------------------------------------------------------|
| budget        | 5       | 0..10000; with the world: (N-1) min_per_link .. (N-1) max_per_link          |
| min_per_link  | 1       | 0..max_per_link                                                             |
| max_per_link  | None    | None (= n) or 0..16; with the world: <= n                                   |
| exact_budget  | True    | False: sum_j t_ji <= budget                                                 |
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.networks.base import Network
from coloc_env.parts import NETWORKS, Block, PartConfig, check_flag, check_range
from coloc_env.world.links import BandwidthBudget

MAX_SELECTIONS = 100_000


@NETWORKS.register
@dataclass(frozen=True)
class Bandwidth(PartConfig):
    """Config of the ``bandwidth`` network (see the module table)."""

    name = "bandwidth"
    carries = frozenset({"components"})
    budget: int = 5
    min_per_link: int = 1
    max_per_link: int | None = None
    exact_budget: bool = True

    def check(self, prefix: str) -> None:
        check_range(f"{prefix}budget", self.budget, 0, 10_000, integer=True)
        high = 16 if self.max_per_link is None else self.max_per_link
        if self.max_per_link is not None:
            check_range(f"{prefix}max_per_link", self.max_per_link, 0, 16, integer=True)
        check_range(f"{prefix}min_per_link (at most {prefix}max_per_link)", self.min_per_link, 0, high, integer=True)
        check_flag(f"{prefix}exact_budget", self.exact_budget)

    def budget_for(self, num_agents: int, dim: int, prefix: str = "network.") -> BandwidthBudget:
        """The validated budget for N agents and n components (ValueError naming the field otherwise)."""
        if self.max_per_link is not None and self.max_per_link > dim:
            raise ValueError(f"{prefix}max_per_link must be in [0, {dim}] (the message has {dim} components), "
                             f"got {self.max_per_link!r}")
        links = BandwidthBudget(num_agents, dim, self.budget, self.min_per_link,
                                dim if self.max_per_link is None else self.max_per_link, self.exact_budget)
        if self.min_per_link > links.max_per_link:
            raise ValueError(f"{prefix}min_per_link must be in [0, {links.max_per_link}], got {self.min_per_link!r}")
        links.validate(prefix)
        # counted by the completion table (BandwidthBudget.size), never listed: the limit is the Discrete's size
        if links.size > MAX_SELECTIONS:
            raise ValueError(f"{prefix}budget: {num_agents} agents x {dim} components give {links.size} feasible "
                             f"selections, more than {MAX_SELECTIONS} (a Discrete action); use fewer agents or "
                             "components, or the bandwidth_fusion scenario's score action")
        return links

    def build(self, num_agents: int, batch: int, message_kind: str, rounds: int = 1) -> Network:
        return BandwidthNetwork(self, num_agents, batch, message_kind, rounds)


class BandwidthNetwork(Network):
    """Lossless, fully connected; the receivers' selections are its transport decisions."""

    def __init__(self, config: Bandwidth, num_agents, batch, message_kind, rounds=1):
        super().__init__(config, num_agents, batch, message_kind, rounds)
        self.links: BandwidthBudget | None = None

    def set_component_dim(self, dim: int) -> None:
        """Called by a ``components`` backend at build: n, the components of its message."""
        self.links = self.config.budget_for(self.num_agents, int(dim))
        # the first selection with the most (fewest) components: the best for scores +1 (-1) per component
        ones = np.ones((self.links.num_nodes - 1, self.links.dim))
        self._most = int(self.links.index_of(self.links.best_selection(ones)))
        self._fewest = int(self.links.index_of(self.links.best_selection(-ones)))

    def transport_blocks(self) -> list[Block]:
        if self.message_kind != "components" or self.links is None:
            return []
        F = self.links.size
        return [Block("selection", 1, F, f"which of the {F} feasible component selections this agent receives "
                      "(BandwidthBudget.feasible order)", default=self._most, maximum=self._most,
                      minimum=self._fewest)]

    def component_selection(self) -> np.ndarray:
        """(B, N, N, n) bool [i, j, c]: receiver i takes component c of agent j (the diagonal all True)."""
        if self.links is None:
            raise RuntimeError("bandwidth network: set_component_dim was not called by the backend")
        index = np.asarray(self._decisions[:, :, 0], int)
        return self.links.full_selection(self.links.selection_at(index))
