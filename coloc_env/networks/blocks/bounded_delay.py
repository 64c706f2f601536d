"""Bounded random delay with a buffer of length D (gao2016 Assumption 3) [paper].

Each packet draws its own delay tau in {0..D} with P(tau = l) = q_l, independently of
everything else; with probability 1 - sum q_l it is later than the buffer and counts as lost
(encoded tau = D + 1). A packet arrives at most once, at s + tau; at time k the packets of
stamp s known to the receiver are those with tau <= k - s (Step 1's reorganisation). Packets
that were never sent (sender outside the RSA) carry ``NEVER``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import as_array, check_range

__all__ = ["BoundedRandomDelay", "NEVER"]

NEVER = np.iinfo(np.int16).max


@dataclass(frozen=True)
class BoundedRandomDelay:
    """Delay distribution ``probabilities`` = (q_0, ..., q_D) over a buffer of length D."""

    probabilities: tuple = (0.6, 0.2, 0.1, 0.05)
    buffer_length: int = 3

    def validate(self, probs_name: str = "delay_probs", buffer_name: str = "buffer_length") -> None:
        check_range(buffer_name, self.buffer_length, 0, 1000, integer=True)
        q = as_array(probs_name, self.probabilities, ndim=1)
        if len(q) != self.buffer_length + 1:
            raise ValueError(f"{probs_name} must have {buffer_name} + 1 = {self.buffer_length + 1} entries "
                             f"(q_0..q_D), got {len(q)}")
        if np.any(q < 0) or np.any(q > 1):
            raise ValueError(f"{probs_name} must be probabilities in [0, 1], got {self.probabilities}")
        if q.sum() > 1.0 + 1e-12:
            raise ValueError(f"{probs_name} must sum to at most 1 (the rest is lost), got sum {q.sum():.6g}")

    @property
    def lost(self) -> float:
        return max(0.0, 1.0 - float(np.sum(self.probabilities)))

    def sample(self, rng: np.random.Generator, size: tuple) -> np.ndarray:
        """Delays (int16) of shape ``size``: 0..D, or D + 1 for a lost packet; one uniform each."""
        return self.from_uniforms(rng.random(size))

    def from_uniforms(self, u: np.ndarray) -> np.ndarray:
        """Delays (int16) of uniforms ``u`` by the inverse CDF, tau = #{l : q_0 + ... + q_l <= u}: 0..D, or
        D + 1 for a lost packet."""
        edges = np.cumsum(np.asarray(self.probabilities, float))
        return np.searchsorted(edges, u, side="right").astype(np.int16)

    def arrivals(self, delays: np.ndarray, stamps: np.ndarray, k) -> np.ndarray:
        """Packets of ``stamps`` (broadcast against ``delays``) arriving exactly at time ``k``
        (a lost packet, tau > D, never arrives)."""
        delays = np.asarray(delays)
        return (delays == (np.asarray(k) - np.asarray(stamps))) & (delays <= self.buffer_length)
