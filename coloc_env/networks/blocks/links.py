"""Links with a per-receiver bandwidth budget counted in state components.

Every receiver i of a fully connected network takes, from each neighbour j,
t_ji of the n components of j's message (a diagonal 0/1 selection T_ji), with
``min_per_link <= t_ji <= max_per_link`` and ``sum_j t_ji = budget`` (or
``<= budget`` when ``exact_budget`` is False). Neighbours are indexed
relative to the receiver: neighbour k of node i is node (i + 1 + k) mod N, so
every receiver sees the same layout (a shared action space).

Why nothing here enumerates the product of all links: a receiver has
``S^(N-1)`` candidate selections (S = the per-link subsets allowed), 7^15 ~
5e12 at N = 16 with the paper's n = 3. The feasible set is instead described
by a table of completions (a dynamic programme over links and the components
still to spend), which counts it, ranks and unranks it in the fixed order of
``BandwidthBudget.feasible``, and finds the best selection for additive
scores (``BandwidthBudget.best_selection``) in O(N S budget) per receiver.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from coloc_env.config import check_range

MAX_ENUMERATED = 2_000_000  # feasible selections ``BandwidthBudget.feasible`` lists at most
_INT64_LIMIT = 2**62


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

    The feasible selections of one receiver have a fixed order: the product
    order of the per-link subsets (link 0 outermost; a link's subsets in the
    order of ``itertools.product((0, 1), repeat=n)``, i.e. by the binary
    number with component 0 as the most significant bit), keeping those that
    meet the budget. ``index_of`` and ``selection_at`` are that order's
    codec; ``feasible`` lists it.
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
        if not isinstance(self.exact_budget, (bool, np.bool_)):
            raise ValueError(f"{prefix}exact_budget must be True or False, got {self.exact_budget!r}")

    @cached_property
    def neighbours(self) -> np.ndarray:
        """``neighbours[i, k]`` = node index of receiver i's k-th neighbour, shape (N, N-1)."""
        N = self.num_nodes
        return (np.arange(N)[:, None] + 1 + np.arange(N - 1)[None, :]) % N

    # --- the per-link subsets and the completion table ---------------------------------------------
    @cached_property
    def subsets(self) -> np.ndarray:
        """The components one link may carry, shape (S, n) bool, in ``itertools.product`` order."""
        n = self.dim
        bits = (np.arange(2**n)[:, None] >> np.arange(n - 1, -1, -1)[None, :]) & 1
        sizes = bits.sum(axis=1)
        return bits[(sizes >= self.min_per_link) & (sizes <= self.max_per_link)].astype(bool)

    @cached_property
    def _subset_sizes(self) -> np.ndarray:
        return self.subsets.sum(axis=1)

    @cached_property
    def _subset_lookup(self) -> np.ndarray:
        """``lookup[code]`` = position in ``subsets`` of the subset with binary code ``code``, -1 if not allowed."""
        n = self.dim
        codes = self.subsets.astype(np.int64) @ (1 << np.arange(n - 1, -1, -1))
        lookup = np.full(2**n, -1, dtype=np.int64)
        lookup[codes] = np.arange(len(codes))
        return lookup

    @property
    def _capacity(self) -> int:
        """Components a receiver can spend at most (the budget, capped by what the links can carry)."""
        return int(min(self.budget, (self.num_nodes - 1) * self.max_per_link))

    @cached_property
    def _completions(self) -> list[list[int]]:
        """``C[k][r]``: selections of links k..N-2 that spend r more components and meet the budget (exact ints).

        C[N-1][r] = 1 for r = 0 (or every r >= 0 without ``exact_budget``);
        C[k][r] = sum over allowed subsets s of C[k+1][r - |s|].
        """
        L, R = self.num_nodes - 1, self._capacity
        per_size = np.bincount(self._subset_sizes, minlength=self.dim + 1)
        table = [[0] * (R + 1) for _ in range(L + 1)]
        table[L] = [1 if (r == 0 or not self.exact_budget) else 0 for r in range(R + 1)]
        for k in range(L - 1, -1, -1):
            table[k] = [sum(int(per_size[t]) * table[k + 1][r - t] for t in range(min(r, self.dim) + 1))
                        for r in range(R + 1)]
        return table

    @property
    def size(self) -> int:
        """F, the number of feasible selections of one receiver (108 in the paper's setting), counted exactly."""
        return self._completions[0][self._capacity]

    @cached_property
    def _completions_int64(self) -> np.ndarray:
        if self.size > _INT64_LIMIT:
            raise ValueError(f"budget: {self.size} feasible selections are too many to index with int64 "
                             "(use fewer agents or components)")
        return np.array(self._completions, dtype=np.int64)

    def _completion_counts(self, link: int, remaining: np.ndarray) -> np.ndarray:
        """C[link+1][remaining - |s|] for every subset s, shape (..., S); 0 where |s| > remaining."""
        table = self._completions_int64[link + 1]
        after = remaining[..., None] - self._subset_sizes
        return np.where(after >= 0, table[np.clip(after, 0, None)], 0)

    # --- the codec of the fixed order ----------------------------------------------------------------
    def index_of(self, neighbour_selection: np.ndarray) -> np.ndarray:
        """Index in the fixed order (``feasible``) of each receiver's selection (..., N-1, n); -1 if infeasible.

        The rank: sum over links k of the feasible selections that agree on
        links 0..k-1 and take an earlier subset at link k (the completion table).
        """
        sel = np.asarray(neighbour_selection, bool)
        L, n = self.num_nodes - 1, self.dim
        if sel.shape[-2:] != (L, n):
            raise ValueError(f"selection must end in shape ({L}, {n}), got {sel.shape}")
        position = self._subset_lookup[sel.astype(np.int64) @ (1 << np.arange(n - 1, -1, -1))]  # (..., L)
        allowed = np.all(position >= 0, axis=-1)
        total = sel.sum(axis=(-1, -2))
        allowed &= (total == self.budget) if self.exact_budget else (total <= self.budget)
        position = np.where(allowed[..., None], position, 0)
        remaining = np.full(sel.shape[:-2], self._capacity, dtype=np.int64)
        rank = np.zeros(sel.shape[:-2], dtype=np.int64)
        for k in range(L):
            counts = self._completion_counts(k, remaining)
            before = np.cumsum(counts, axis=-1) - counts  # selections with an earlier subset at link k
            rank += np.take_along_axis(before, position[..., k : k + 1], axis=-1)[..., 0]
            remaining = remaining - self._subset_sizes[position[..., k]]
        return np.where(allowed, rank, -1)

    def selection_at(self, index: np.ndarray) -> np.ndarray:
        """The selection (..., N-1, n) at ``index`` of the fixed order (the inverse of ``index_of``)."""
        index = np.asarray(index, dtype=np.int64)
        if np.any(index < 0) or np.any(index >= self.size):
            raise ValueError(f"selection index must be in [0, {self.size - 1}], got "
                             f"{index.min() if np.any(index < 0) else index.max()}")
        L = self.num_nodes - 1
        remaining = np.full(index.shape, self._capacity, dtype=np.int64)
        left = index.copy()
        chosen = np.zeros((*index.shape, L), dtype=np.int64)
        for k in range(L):
            counts = self._completion_counts(k, remaining)
            upto = np.cumsum(counts, axis=-1)
            position = np.sum(upto <= left[..., None], axis=-1)
            left = left - np.take_along_axis(upto - counts, position[..., None], axis=-1)[..., 0]
            remaining = remaining - self._subset_sizes[position]
            chosen[..., k] = position
        return self.subsets[chosen]

    @cached_property
    def feasible(self) -> np.ndarray:
        """Every feasible selection of one receiver, shape (F, N-1, n), bool, in the fixed order.

        For the paper's setting (N=4, n=3, budget 5, 1..3 per link) F = 108.
        Listed by ``selection_at``; refused beyond ``MAX_ENUMERATED``
        (2,000,000) selections, where the codec and ``best_selection`` still work.
        """
        if self.size == 0:
            raise ValueError(f"budget={self.budget}: no selection meets it with "
                             f"{self.min_per_link}..{self.max_per_link} components per link")
        if self.size > MAX_ENUMERATED:
            raise ValueError(f"budget: {self.size} feasible selections, more than {MAX_ENUMERATED} to list; "
                             "use index_of / selection_at / best_selection")
        return self.selection_at(np.arange(self.size))

    # --- the best selection for additive scores ------------------------------------------------------
    def best_selection(self, scores: np.ndarray) -> np.ndarray:
        """The feasible selection with the highest total score, per receiver: (..., N-1, n) -> (..., N-1, n) bool.

        ``scores[..., k, c]`` is the value of taking component c from
        neighbour k; a selection's score is the sum over what it takes. Ties go
        to the first in the fixed order, as ``feasible[argmax(scores . feasible)]``
        would, but without listing F selections: a dynamic programme over links,

            V_k(r) = max_s [ v_k(s) + V_{k+1}(r - |s|) ],   V_{N-1}(r) = 0 if r = 0 (or r >= 0 when not exact),

        with v_k(s) the score of subset s on link k and r the components still
        to spend; then, link by link, the first subset (in order) that attains
        the maximum. Float addition is monotone, so the maximum taken over
        subsets equals the one the table holds and the first attaining subset
        is the lexicographically first optimal selection.
        """
        scores = np.asarray(scores, float)
        L, R = self.num_nodes - 1, self._capacity
        if scores.shape[-2:] != (L, self.dim):
            raise ValueError(f"scores must end in shape ({L}, {self.dim}), got {scores.shape}")
        batch = scores.shape[:-2]
        sizes = self._subset_sizes
        # receivers last, so that every slice over r below is contiguous
        value = np.moveaxis(scores.reshape(-1, L, self.dim) @ self.subsets.T.astype(float), 0, -1)  # (L, S, M): v_k(s)
        size_values = np.unique(sizes)
        best_of_size = np.stack([value[:, sizes == t].max(axis=1) for t in size_values], axis=1)  # (L, T, M)
        M = value.shape[-1]
        future = np.full((R + 1, M), -np.inf)  # V_{L}(r), then V_{L-1}, ... down to V_1
        if self.exact_budget:
            future[0] = 0.0
        else:
            future[:] = 0.0
        tables = [future]
        for k in range(L - 1, 0, -1):
            # r only where link k can be reached with it: spent by links 0..k-1 within their limits
            low = max(0, R - k * self.max_per_link) if self.exact_budget else 0
            current = np.full((R + 1, M), -np.inf)
            for position, t in enumerate(size_values):
                start = max(low, t)
                if start > R:
                    continue
                np.maximum(current[start:], best_of_size[k, position] + future[start - t : R + 1 - t],
                           out=current[start:])
            future = current
            tables.append(current)
        tables = tables[::-1]  # tables[k] = V_{k+1}
        remaining = np.full(M, R, dtype=np.int64)
        chosen = np.zeros((L, M), dtype=np.int64)
        receivers = np.arange(M)
        for k in range(L):
            after = remaining[None, :] - sizes[:, None]  # (S, M)
            reachable = tables[k][np.clip(after, 0, None), receivers]
            candidate = np.where(after >= 0, value[k] + reachable, -np.inf)
            position = np.argmax(candidate, axis=0)
            chosen[k] = position
            remaining = remaining - sizes[position]
        return self.subsets[chosen.T].reshape(*batch, L, self.dim)

    def is_feasible(self, neighbour_selection: np.ndarray) -> np.ndarray:
        """Whether each receiver's selection (..., N-1, n) meets the budget."""
        sel = np.asarray(neighbour_selection, bool)
        per_link = sel.sum(axis=-1)
        total = per_link.sum(axis=-1)
        within = np.all((per_link >= self.min_per_link) & (per_link <= self.max_per_link), axis=-1)
        return within & ((total == self.budget) if self.exact_budget else (total <= self.budget))

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
