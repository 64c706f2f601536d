"""Linear stochastic motion x(k+1) = A x(k) + B + w(k), w ~ N(0, W)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from coloc_env.config import as_array, check_psd
from coloc_env.worlds.blocks.noise import covariance_factor, sample_gaussian


@dataclass(frozen=True)
class LinearMotion:
    """Linear motion with a constant known drift and Gaussian process noise.

    | field          | symbol | shape  | meaning                                   |
    |----------------|--------|--------|-------------------------------------------|
    | transition     | A      | (n, n) | state transition per step                 |
    | drift          | B      | (n,)   | known constant input per step (e.g. v*dt) |
    | process_noise  | W      | (n, n) | covariance of w(k), PSD                   |
    """

    transition: np.ndarray
    drift: np.ndarray
    process_noise: np.ndarray

    @property
    def dim(self) -> int:
        return np.asarray(self.transition).shape[0]

    def validate(self, prefix: str = "") -> None:
        A = as_array(f"{prefix}transition", self.transition, ndim=2)
        if A.shape[0] != A.shape[1]:
            raise ValueError(f"{prefix}transition must be square, got shape {A.shape}")
        as_array(f"{prefix}drift", self.drift, shape=(A.shape[0],))
        check_psd(f"{prefix}process_noise", self.process_noise, A.shape[0])

    @cached_property
    def noise_factor(self) -> np.ndarray:
        """F with F F^T = the noise covariance, computed once."""
        return covariance_factor(self.process_noise)

    def sample_noise(self, rng: np.random.Generator, size: tuple[int, ...]) -> np.ndarray:
        """Process noise of shape ``(*size, n)`` drawn from ``rng``."""
        return sample_gaussian(rng, self.noise_factor, size)

    def step(self, state: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """x(k+1) for a batch ``state`` of shape (..., n)."""
        return np.einsum("ab,...b->...a", np.asarray(self.transition, float), state) + self.drift + noise
