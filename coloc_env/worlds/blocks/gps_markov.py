"""GPS receivers whose health follows a two-state normal/fault Markov chain (wan2014, eqs. 2-3).

g(k) in {normal, fault} per UAV, independent across UAVs:
P(fault at k+1 | normal at k) = p_nf, P(normal at k+1 | fault at k) = p_fn;
g(0) from the stationary law P(normal) = p_fn / (p_nf + p_fn). A normal
receiver reports z = p + n, n ~ N(0, sigma_gps^2 I2); a faulty one reports
nothing. ``MarkovGPS.fixed_states`` is the "fixed proportion" mode of the
paper's Fig. 6(a): exactly ``n_normal`` randomly chosen UAVs normal for all k.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import check_range


@dataclass(frozen=True)
class MarkovGPS:
    """Per-UAV GPS with a normal/fault Markov chain.

    | field              | symbol    | meaning                             | wan2014 default |
    |--------------------|-----------|-------------------------------------|-----------------|
    | p_normal_to_fault  | p_nf      | P(normal -> fault) per step         | 0.02 [chosen]   |
    | p_fault_to_normal  | p_fn      | P(fault -> normal) per step         | 0.02 [chosen]   |
    | noise_std          | sigma_gps | fix noise std per axis [m]          | 3 [chosen]      |
    """

    p_normal_to_fault: float = 0.02
    p_fault_to_normal: float = 0.02
    noise_std: float = 3.0

    def validate(self, prefix: str = "") -> None:
        check_range(f"{prefix}p_normal_to_fault", self.p_normal_to_fault, 0.0, 1.0)
        check_range(f"{prefix}p_fault_to_normal", self.p_fault_to_normal, 0.0, 1.0)
        check_range(f"{prefix}noise_std", self.noise_std, 0.0, 1e4, low_open=True)

    @property
    def stationary_normal(self) -> float:
        """P(normal) of the stationary law; 1/2 when the chain never switches (p_nf = p_fn = 0)."""
        total = self.p_normal_to_fault + self.p_fault_to_normal
        return 0.5 if total == 0 else self.p_fault_to_normal / total

    def sample_states(self, rng: np.random.Generator, steps: int, count: int) -> np.ndarray:
        """Health (steps, count), True = normal; one uniform per (step, UAV) drawn as a block."""
        u = rng.random((steps, count))
        normal = np.empty((steps, count), dtype=bool)
        normal[0] = u[0] < self.stationary_normal
        for k in range(1, steps):
            stay_normal = u[k] >= self.p_normal_to_fault
            recover = u[k] < self.p_fault_to_normal
            normal[k] = np.where(normal[k - 1], stay_normal, recover)
        return normal

    @staticmethod
    def fixed_states(rng: np.random.Generator, steps: int, count: int, n_normal: int) -> np.ndarray:
        """Exactly ``n_normal`` randomly chosen UAVs normal at every step (no switching)."""
        if not 0 <= n_normal <= count:
            raise ValueError(f"n_normal must be in [0, {count}], got {n_normal}")
        normal = np.zeros(count, dtype=bool)
        normal[rng.permutation(count)[:n_normal]] = True
        return np.broadcast_to(normal, (steps, count)).copy()

    def sample_noise(self, rng: np.random.Generator, size: tuple[int, ...]) -> np.ndarray:
        return self.noise_std * rng.standard_normal((*size, 2))

    @staticmethod
    def measure(positions: np.ndarray, noise: np.ndarray, normal: np.ndarray) -> np.ndarray:
        """Fixes (..., 2): p + n where normal, NaN where faulty (no fix)."""
        z = np.asarray(positions, float) + noise
        return np.where(np.asarray(normal, bool)[..., None], z, np.nan)
