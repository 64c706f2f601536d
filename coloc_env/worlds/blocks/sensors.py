"""Linear noisy sensors y = C x + v, v ~ N(0, V)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from coloc_env.config import as_array, check_psd
from coloc_env.worlds.blocks.noise import covariance_factor, sample_gaussian


@dataclass(frozen=True)
class LinearSensor:
    """A linear sensor carried by each of ``count`` nodes, noise independent across nodes.

    | field         | symbol | shape  | meaning                           |
    |---------------|--------|--------|-----------------------------------|
    | measurement   | C      | (m, n) | observation matrix                |
    | noise         | V      | (m, m) | covariance of v(k), PD            |
    """

    measurement: np.ndarray
    noise: np.ndarray

    @property
    def dim(self) -> int:
        return np.asarray(self.measurement).shape[0]

    def validate(self, state_dim: int, matrix_name: str = "measurement", noise_name: str = "noise") -> None:
        """Check shapes and that the noise is positive definite; errors name the config fields given."""
        C = as_array(matrix_name, self.measurement, ndim=2)
        if C.shape[1] != state_dim:
            raise ValueError(f"{matrix_name} must have shape (m, {state_dim}), got {C.shape}")
        check_psd(noise_name, self.noise, C.shape[0], strict=True)

    @cached_property
    def noise_factor(self) -> np.ndarray:
        """F with F F^T = the noise covariance, computed once."""
        return covariance_factor(self.noise)

    def sample_noise(self, rng: np.random.Generator, size: tuple[int, ...]) -> np.ndarray:
        """Measurement noise of shape ``(*size, m)`` drawn from ``rng``."""
        return sample_gaussian(rng, self.noise_factor, size)

    def measure(self, state: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """y = C x + v; ``state`` (..., n) broadcast against ``noise`` (..., m)."""
        return np.einsum("mn,...n->...m", np.asarray(self.measurement, float), state) + noise
