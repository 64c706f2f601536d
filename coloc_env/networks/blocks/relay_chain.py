"""Relay chains: location information passed platform to platform, one hop at a time.

A chain starts at a source (the measuring platform m), goes to ``first``
(the measured platform n), then each holder passes the message to the
platform it chose, until a stop. A chain never revisits a platform. A hop
from holder h to target t fails, and the chain stops at h, when

| reason          | condition                                                       |
|-----------------|-----------------------------------------------------------------|
| ``hop_budget``  | the chain already used ``max_hops`` hops                        |
| ``stopped``     | h chose to stop (a value outside [0, N), or itself)            |
| ``revisit``     | t already holds the message                                     |
| ``out_of_range``| ||x_h - x_t|| > ``comm_range``                                  |
| ``lost``        | the packet is lost: u < p_loss(d), u ~ U(0, 1) drawn per hop    |
| ``complete``    | (not a failure) every platform was reached                     |

checked in that order. The loss probability grows with the hop length d:
p_loss(d) = 1 - (1 - loss_at_zero) exp(-d / loss_length) (loss_length = inf:
a constant loss_at_zero). Each delivered hop costs ``hop_cost_per_m2 * d^2``
(a radio's energy grows like d^2 in free space); a price per hop regardless of
its length is a price per message, which a composition charges once
(``communication_cost``), not here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import check_distance, check_range

STOP_REASONS = ("complete", "hop_budget", "stopped", "revisit", "out_of_range", "lost")


@dataclass
class RelayChain:
    """A resolved chain per copy: ``chain`` (B, N) platforms in order, -1 padded; ``length`` (B,);
    ``hop_distance`` (B, N-1) metres of each delivered hop (nan after the end); ``stop`` (B,)
    index into ``STOP_REASONS``."""

    chain: np.ndarray
    length: np.ndarray
    hop_distance: np.ndarray
    stop: np.ndarray

    @property
    def hops(self) -> np.ndarray:
        return np.maximum(self.length - 1, 0)

    def next_hop(self, num_platforms: int) -> np.ndarray:
        """(B, N): the platform each one passed the message to, -1 if none."""
        B, N = self.chain.shape[0], num_platforms
        target = np.full((B, N), -1)
        copy, position = np.nonzero(self.chain[:, 1:] >= 0)
        target[copy, self.chain[copy, position]] = self.chain[copy, position + 1]
        return target

    def clear(self, idx: np.ndarray) -> None:
        """No chain in the copies ``idx`` (a copy that starts anew reports none)."""
        self.chain[idx] = -1
        self.length[idx] = 0
        self.hop_distance[idx] = np.nan
        self.stop[idx] = -1

    def position_of(self, num_platforms: int) -> np.ndarray:
        """(B, N): each platform's place in the chain (0 = source), -1 if not reached."""
        B = self.chain.shape[0]
        place = np.full((B, num_platforms), -1)
        copy, position = np.nonzero(self.chain >= 0)
        place[copy, self.chain[copy, position]] = position
        return place


@dataclass(frozen=True)
class RelayChainLinks:
    """Serial relay links with a hop budget, range limit, distance-dependent loss and a hop's energy cost.

    | field            | meaning                                                  | wang2019 |
    |------------------|----------------------------------------------------------|----------|
    | comm_range       | longest hop [m]                                          | inf      |
    | max_hops         | hops per chain; None = no limit (N-1)                    | None     |
    | loss_at_zero     | packet loss probability of a zero-length hop             | 0        |
    | loss_length      | metres over which survival falls by e; inf = no growth   | inf      |
    | hop_cost_per_m2  | cost of a delivered hop per squared metre of its length  | 0        |
    """

    comm_range: float = float("inf")
    max_hops: int | None = None
    loss_at_zero: float = 0.0
    loss_length: float = float("inf")
    hop_cost_per_m2: float = 0.0

    def validate(self, num_platforms: int | None = None, prefix: str = "") -> None:
        """Every field; ``max_hops`` in [1, N - 1] for a team of ``num_platforms`` (``check_hop_budget``), in
        [1, 1000] where the team is not known yet."""
        check_distance(f"{prefix}comm_range", self.comm_range)
        if self.max_hops is not None:
            check_range(f"{prefix}max_hops", self.max_hops, 1, 1000, integer=True)
        if num_platforms is not None:
            self.check_hop_budget(num_platforms, prefix, "N")
        check_range(f"{prefix}loss_at_zero", self.loss_at_zero, 0.0, 1.0)
        check_distance(f"{prefix}loss_length", self.loss_length)
        check_range(f"{prefix}hop_cost_per_m2", self.hop_cost_per_m2, 0.0, 1e12)

    def check_hop_budget(self, num_platforms: int, prefix: str, agents: str) -> None:
        """``max_hops`` against the team: at most N - 1 hops (``agents`` names N in the message)."""
        if self.max_hops is not None:
            check_range(f"{prefix}max_hops", self.max_hops, 1, max(1, num_platforms - 1), integer=True,
                        high_label=f"{agents} - 1")

    def loss_probability(self, distance: np.ndarray) -> np.ndarray:
        survival = (1.0 - self.loss_at_zero) * np.exp(-np.asarray(distance, float) / self.loss_length)
        return 1.0 - survival

    def cost(self, distance: np.ndarray) -> np.ndarray:
        """``hop_cost_per_m2 * d^2`` of delivered hops of length ``distance``; nan (no hop) costs 0."""
        distance = np.asarray(distance, float)
        return np.where(np.isnan(distance), 0.0, self.hop_cost_per_m2 * np.nan_to_num(distance) ** 2)

    def resolve(self, positions: np.ndarray, source: np.ndarray, first: np.ndarray, choice: np.ndarray,
                uniforms: np.ndarray) -> RelayChain:
        """Follow the choices from ``source`` -> ``first`` -> ``choice[holder]`` -> ...

        ``positions`` (B, N, 2), ``source``/``first`` (B,) int, ``choice`` (B, N) int
        (the platform each one would pass to; outside [0, N) or itself = stop),
        ``uniforms`` (B, N-1) in [0, 1), one per potential hop. Vectorized over
        copies; the loop runs over the at most N-1 hops.
        """
        positions = np.asarray(positions, float)
        B, N = positions.shape[:2]
        rows = np.arange(B)
        source, first, choice = np.asarray(source, int), np.asarray(first, int), np.asarray(choice, int)
        limit = N - 1 if self.max_hops is None else min(self.max_hops, N - 1)
        chain = np.full((B, N), -1)
        chain[:, 0] = source
        reached = np.zeros((B, N), dtype=bool)
        reached[rows, source] = True
        length = np.ones(B, dtype=int)
        hop_distance = np.full((B, N - 1), np.nan)
        stop = np.zeros(B, dtype=int)
        holder, going = source.copy(), np.ones(B, dtype=bool)
        for hop in range(N - 1):
            target = first if hop == 0 else choice[rows, holder]
            valid_target = (target >= 0) & (target < N) & (target != holder)
            safe = np.where(valid_target, target, 0)
            distance = np.sqrt(np.sum((positions[rows, safe] - positions[rows, holder]) ** 2, axis=-1))
            reasons = [
                hop >= limit,
                ~valid_target,
                valid_target & reached[rows, safe],
                distance > self.comm_range,
                uniforms[:, hop] < self.loss_probability(distance),
            ]
            failed = np.zeros(B, dtype=bool)
            for code, condition in enumerate(reasons, start=1):
                new = going & ~failed & condition
                stop[new] = code
                failed |= new
            delivered = going & ~failed
            chain[delivered, hop + 1] = target[delivered]
            reached[rows[delivered], target[delivered]] = True
            hop_distance[delivered, hop] = distance[delivered]
            length += delivered
            holder = np.where(delivered, target, holder)
            going = delivered
        stop[length == N] = 0
        return RelayChain(chain=chain, length=length, hop_distance=hop_distance, stop=stop)
