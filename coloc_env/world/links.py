"""Links with a per-receiver bandwidth budget counted in state components.

Every receiver i of a fully connected network takes, from each neighbour j,
t_ji of the n components of j's message (a diagonal 0/1 selection T_ji), with
``min_per_link <= t_ji <= max_per_link`` and ``sum_j t_ji = budget`` (or
``<= budget`` when ``exact_budget`` is False). Neighbours are indexed
relative to the receiver: neighbour k of node i is node (i + 1 + k) mod N, so
every receiver sees the same layout (a shared action space).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from coloc_env.config import check_range


@dataclass(frozen=True)
class BandwidthBudget:
    """Per-receiver budget on received state components.

    | field         | meaning                                                   | paper (zhao2020)  |
    |---------------|-----------------------------------------------------------|-------------------|
    | num_nodes     | N, nodes in the fully connected network                   | 4                 |
    | dim           | n, components of each message                             | 3                 |
    | budget        | t_i, components a receiver takes from all neighbours      | 5                 |
    | min_per_link  | least components taken from each neighbour                | 1                 |
    | max_per_link  | most components taken from each neighbour                 | 3 (= n)           |
    | exact_budget  | ``sum_j t_ji == budget`` (True) or ``<= budget`` (False) | True              |
    """

    num_nodes: int = 4
    dim: int = 3
    budget: int = 5
    min_per_link: int = 1
    max_per_link: int = 3
    exact_budget: bool = True

    def validate(self, prefix: str = "") -> None:
        check_range(f"{prefix}num_nodes", self.num_nodes, 2, 64, integer=True)
        check_range(f"{prefix}dim", self.dim, 1, 16, integer=True)
        check_range(f"{prefix}max_per_link", self.max_per_link, 0, self.dim, integer=True)
        check_range(f"{prefix}min_per_link", self.min_per_link, 0, self.max_per_link, integer=True)
        neighbours = self.num_nodes - 1
        high = neighbours * self.max_per_link if self.exact_budget else np.inf
        check_range(f"{prefix}budget", self.budget, neighbours * self.min_per_link, high, integer=True)
        if not isinstance(self.exact_budget, bool):
            raise ValueError(f"{prefix}exact_budget must be True or False, got {self.exact_budget!r}")

    @cached_property
    def neighbours(self) -> np.ndarray:
        """``neighbours[i, k]`` = node index of receiver i's k-th neighbour, shape (N, N-1)."""
        N = self.num_nodes
        return (np.arange(N)[:, None] + 1 + np.arange(N - 1)[None, :]) % N

    @cached_property
    def feasible(self) -> np.ndarray:
        """Every feasible selection of one receiver, shape (F, N-1, n), bool, in a fixed order.

        For the paper's setting (N=4, n=3, budget 5, 1..3 per link) F = 108.
        """
        subsets = [np.array(bits, dtype=bool) for bits in itertools.product((0, 1), repeat=self.dim)]
        subsets = [s for s in subsets if self.min_per_link <= s.sum() <= self.max_per_link]
        options = []
        for combo in itertools.product(subsets, repeat=self.num_nodes - 1):
            total = sum(int(s.sum()) for s in combo)
            if total == self.budget or (not self.exact_budget and total <= self.budget):
                options.append(np.stack(combo))
        if not options:
            raise ValueError(f"budget={self.budget}: no selection meets it with "
                             f"{self.min_per_link}..{self.max_per_link} components per link")
        return np.stack(options)

    def index_of(self, neighbour_selection: np.ndarray) -> np.ndarray:
        """Index into :attr:`feasible` of each receiver's selection (..., N-1, n); -1 if infeasible."""
        flat = self.feasible.reshape(len(self.feasible), -1)
        sel = np.asarray(neighbour_selection, bool).reshape(*np.shape(neighbour_selection)[:-2], 1, -1)
        match = np.all(sel == flat, axis=-1)
        return np.where(match.any(axis=-1), match.argmax(axis=-1), -1)

    def is_feasible(self, neighbour_selection: np.ndarray) -> np.ndarray:
        """Whether each receiver's selection (..., N-1, n) meets the budget."""
        return self.index_of(neighbour_selection) >= 0

    def full_selection(self, neighbour_selection: np.ndarray) -> np.ndarray:
        """Receiver-relative selections (..., N, N-1, n) -> absolute T (..., N, N, n), T_ii = I.

        ``result[..., i, j, c]`` is True when receiver i takes component c from node j.
        """
        neighbour_selection = np.asarray(neighbour_selection, bool)
        N = self.num_nodes
        full = np.ones((*neighbour_selection.shape[:-3], N, N, self.dim), dtype=bool)
        rows = np.arange(N)[:, None]
        full[..., rows, self.neighbours, :] = neighbour_selection
        return full

    def relative_selection(self, full_selection: np.ndarray) -> np.ndarray:
        """Absolute T (..., N, N, n) -> receiver-relative (..., N, N-1, n)."""
        rows = np.arange(self.num_nodes)[:, None]
        return np.asarray(full_selection, bool)[..., rows, self.neighbours, :]

    def components_received(self, neighbour_selection: np.ndarray) -> np.ndarray:
        """Components each receiver takes from its neighbours, shape (..., N)."""
        return np.asarray(neighbour_selection, bool).sum(axis=(-1, -2))
