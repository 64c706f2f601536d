"""Range measurements between UAVs within a communication range (wan2014, eq. 4).

Edge set E = {(s, t): ||p_s - p_t|| <= R}; one measurement per unordered pair,
d_st = d_ts = ||p_s - p_t|| + nu, nu ~ N(0, sigma_d^2), seen by both ends.
Ranges come from the same radio as messages, so "can range" = "can talk".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import check_range


@dataclass(frozen=True)
class RangeNetwork:
    """Symmetric noisy ranges on the disc graph of radius ``comm_range``.

    | field       | symbol  | meaning                               | wan2014 default |
    |-------------|---------|---------------------------------------|-----------------|
    | comm_range  | R       | communication / ranging range [m]     | 300 [chosen]    |
    | noise_std   | sigma_d | range noise std [m]                   | 2 [chosen]      |
    """

    comm_range: float = 300.0
    noise_std: float = 2.0

    def validate(self, prefix: str = "") -> None:
        check_range(f"{prefix}comm_range", self.comm_range, 0.0, 1e7, low_open=True)
        check_range(f"{prefix}noise_std", self.noise_std, 0.0, 1e4, low_open=True)

    @staticmethod
    def distances(positions: np.ndarray) -> np.ndarray:
        """True pairwise distances (..., N, N) of positions (..., N, 2): sqrt(dx^2 + dy^2), the same float
        operations as the sum of squares over the last axis, on (..., N, N) planes (no (..., N, N, 2) array)."""
        x, y = positions[..., 0], positions[..., 1]
        dx = x[..., :, None] - x[..., None, :]
        dy = y[..., :, None] - y[..., None, :]
        dx *= dx
        dy *= dy
        dx += dy
        return np.sqrt(dx, out=dx)

    def adjacency(self, positions: np.ndarray, distances: np.ndarray | None = None) -> np.ndarray:
        """Bool (..., N, N): within range, no self-loops (``distances`` if already computed)."""
        d = self.distances(positions) if distances is None else distances
        n = d.shape[-1]
        return (d <= self.comm_range) & ~np.eye(n, dtype=bool)

    def sample_noise(self, rng: np.random.Generator, size: tuple[int, ...], count: int) -> np.ndarray:
        """Symmetric noise (*size, N, N): one draw per unordered pair, zero diagonal."""
        iu = np.triu_indices(count, 1)
        upper = self.noise_std * rng.standard_normal((*size, len(iu[0])))
        noise = np.zeros((*size, count, count))
        noise[..., iu[0], iu[1]] = upper
        return noise + np.swapaxes(noise, -1, -2)

    def measure(self, positions: np.ndarray, noise: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(adjacency, ranges): ranges (..., N, N) are true + noise on edges, 0 elsewhere."""
        distances = self.distances(positions)
        adjacency = self.adjacency(positions, distances)
        return adjacency, np.where(adjacency, distances + noise, 0.0)
