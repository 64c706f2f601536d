"""Odometry (measured speed and turn rate) and range sensors between platforms."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import check_distance, check_range


@dataclass(frozen=True)
class OdometrySensor:
    """Measured speed V_m = v + n_v and turn rate omega_m = omega + n_omega, white Gaussian noise.

    | field                | meaning                          | wang2019 (Table 1) |
    |----------------------|----------------------------------|--------------------|
    | speed_noise_std      | sigma_v [m/s]                    | 0.5                |
    | turn_rate_noise_std  | sigma_omega [rad/s]              | 1e-3               |

    The heading a platform integrates from omega_m drifts as a random walk:
    after k steps of length dt its variance is k dt^2 sigma_omega^2
    (``heading_variance``).
    """

    speed_noise_std: float = 0.5
    turn_rate_noise_std: float = 1e-3

    def validate(self, prefix: str = "") -> None:
        check_range(f"{prefix}speed_noise_std", self.speed_noise_std, 0.0, 1e3)
        check_range(f"{prefix}turn_rate_noise_std", self.turn_rate_noise_std, 0.0, 10.0)

    def sample_noise(self, rng: np.random.Generator, size: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        """(speed noise, turn-rate noise), each of shape ``size``: speed first, then turn rate."""
        speed = self.speed_noise_std * rng.standard_normal(size)
        turn = self.turn_rate_noise_std * rng.standard_normal(size)
        return speed, turn

    def measure(self, speed: np.ndarray, turn_rate: np.ndarray, speed_noise: np.ndarray,
                turn_noise: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(speed, float) + speed_noise, np.asarray(turn_rate, float) + turn_noise

    def heading_variance(self, steps: np.ndarray, dt: float) -> np.ndarray:
        """Variance of a heading integrated over ``steps`` steps from a known start."""
        return np.asarray(steps, float) * dt**2 * self.turn_rate_noise_std**2


@dataclass(frozen=True)
class RangeSensor:
    """z = ||x_a - x_b|| + n, n ~ N(0, noise_var), available up to ``max_range`` metres.

    | field      | meaning                          | wang2019 |
    |------------|----------------------------------|----------|
    | noise_var  | sigma_r^2 [m^2]                  | 1        |
    | max_range  | sensing range [m] (inf: any)     | inf      |
    """

    noise_var: float = 1.0
    max_range: float = float("inf")

    def validate(self, prefix: str = "") -> None:
        check_range(f"{prefix}noise_var", self.noise_var, 0.0, 1e6, low_open=True)
        check_distance(f"{prefix}max_range", self.max_range)

    def sample_noise(self, rng: np.random.Generator, size: tuple[int, ...]) -> np.ndarray:
        return np.sqrt(self.noise_var) * rng.standard_normal(size)

    @staticmethod
    def true_range(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.sqrt(np.sum((np.asarray(a, float) - np.asarray(b, float)) ** 2, axis=-1))

    def in_range(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return self.true_range(a, b) <= self.max_range

    def measure(self, a: np.ndarray, b: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """Ranges between positions ``a`` and ``b`` (..., 2) plus ``noise`` (...)."""
        return self.true_range(a, b) + noise
