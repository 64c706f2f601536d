"""Network ``bandwidth`` (zhao2020): each receiver takes a budget of state components from its neighbours.

Zhao et al. 2020, Sec. 1-2 (eqs. 5-7): receiver i takes, from each neighbour
j, t_ji of the n components of j's message (a diagonal 0/1 selection T_ji),
with ``min_per_link <= t_ji <= max_per_link`` and sum_j t_ji = ``budget``
(``<=`` when ``exact_budget`` is False); the rest it fills with its own
prediction (the backend's eq. 6). The network is fully connected and
lossless (the paper's); the constraint is the receiver's bandwidth
(``coloc_env.networks.blocks.links.BandwidthBudget``). n is the backend's message
size (the world's state dimension), known when the backend is built.

A receiver's transport decision is one index into the feasible selections
(``BandwidthBudget.feasible``, a fixed order; 108 of them in the paper's
setting N = 4, n = 3, budget 5, 1..3 per link); neighbours are indexed
relative to the receiver (neighbour k of agent i is agent (i + 1 + k) mod N).
Up to 4,096 selections (``TABLE_LIMIT``) the index is decoded by a lookup in
a table built once from ``BandwidthBudget.feasible``; beyond, by
``BandwidthBudget.selection_at`` (unranking by the completion table), so
nothing is listed; the Discrete's size is capped at 100,000 (``MAX_SELECTIONS``).
``ScoredBandwidth`` is the same network for a caller that decodes its own
action into selections (the ``bandwidth_fusion`` preset's scores): no cap.

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
from coloc_env.networks.blocks.links import BandwidthBudget
from coloc_env.parts import NETWORKS, Block, PartConfig, check_flag, check_range

MAX_SELECTIONS = 100_000
TABLE_LIMIT = 4096  # feasible selections up to which component_selection decodes by a lookup table


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


@dataclass(frozen=True)
class ScoredBandwidth(Bandwidth):
    """The ``bandwidth`` network with the same rules and delivery, but a budget is not refused beyond
    ``MAX_SELECTIONS`` feasible selections (the limit of a Discrete selection action): for a caller whose
    action decodes to selections itself (``BandwidthBudget.best_selection``) and hands them over with
    ``BandwidthNetwork.offer_selection``; the selection index only carries the result (int64, exact for
    the ~7e11 selections of N = 16)."""

    def budget_for(self, num_agents: int, dim: int, prefix: str = "network.") -> BandwidthBudget:
        links = BandwidthBudget(num_agents, dim, self.budget, self.min_per_link,
                                dim if self.max_per_link is None else self.max_per_link, self.exact_budget)
        links.validate(prefix)
        return links


class BandwidthNetwork(Network):
    """Lossless, fully connected; the receivers' selections are its transport decisions."""

    def __init__(self, config: Bandwidth, num_agents, batch, message_kind, rounds=1):
        super().__init__(config, num_agents, batch, message_kind, rounds)
        self.links: BandwidthBudget | None = None
        self._table: np.ndarray | None = None  # [i, f]: receiver i's row of full_selection(feasible[f])
        self._offered: tuple[np.ndarray, np.ndarray] | None = None  # (index, selection) from offer_selection

    def set_component_dim(self, dim: int) -> None:
        """Called by a ``components`` backend at build: n, the components of its message."""
        self.links = self.config.budget_for(self.num_agents, int(dim))
        # the first selection with the most (fewest) components: the best for scores +1 (-1) per component
        ones = np.ones((self.links.num_nodes - 1, self.links.dim))
        self._most = int(self.links.index_of(self.links.best_selection(ones)))
        self._fewest = int(self.links.index_of(self.links.best_selection(-ones)))
        # a lookup decodes a step's indices far faster than unranking them one link at a time
        if 0 < self.links.size <= TABLE_LIMIT:
            feasible, N = self.links.feasible, self.links.num_nodes  # (F, N-1, n)
            every = np.broadcast_to(feasible[:, None], (len(feasible), N, *feasible.shape[1:]))  # all receivers
            self._table = np.ascontiguousarray(self.links.full_selection(every).swapaxes(0, 1))

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
        index = np.asarray(self._decisions[:, :, 0], np.int64)
        table = self._table
        if table is not None and index.size and 0 <= index.min() and index.max() < table.shape[1]:
            return table[np.arange(self.num_agents), index]
        offered = self._offered
        if offered is not None and offered[0].shape == index.shape and np.array_equal(offered[0], index):
            relative = offered[1]
        else:
            relative = self.links.selection_at(index)  # also the ValueError for an index out of range
        return self.links.full_selection(relative)

    def offer_selection(self, index: np.ndarray, selection: np.ndarray) -> None:
        """Hand over the selections (B, N, N-1, n) that the indices (B, N) stand for, from a caller that
        decoded both (the ``bandwidth_fusion`` preset decodes scores): beyond ``TABLE_LIMIT`` selections
        ``component_selection`` takes them while the ``selection`` decisions are those indices, instead
        of unranking the indices again. ``selection`` must be ``links.selection_at(index)``; it is kept,
        not copied."""
        self._offered = (np.array(index, np.int64), selection)
