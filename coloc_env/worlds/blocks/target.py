"""A target moving with nearly constant velocity (white-noise acceleration).

State order per axis: position then velocity, ``[x, vx, y, vy, z, vz]`` for
three axes. With period T,

    x(k+1) = Phi x(k) + G w(k),   Phi = blockdiag([[1, T], [0, 1]] x axes),
                                  G   = blockdiag([T^2/2; T] x axes),
                                  w ~ N(0, q I_axes),

so the process noise covariance is Q = q G G^T (the discretized model of
Bar-Shalom, "Estimation with Applications to Tracking", Sec. 6.3.2).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from coloc_env.config import check_range


@dataclass(frozen=True)
class ConstantVelocityTarget:
    """Constant-velocity target in ``axes`` dimensions.

    | field        | symbol | meaning                                              | fu2017 |
    |--------------|--------|------------------------------------------------------|--------|
    | axes         |        | spatial dimensions                                   | 3      |
    | period       | T      | time step in seconds, > 0                            | 1.0    |
    | accel_noise  | q      | variance of each acceleration component w, >= 0     | 5.0    |
    """

    axes: int = 3
    period: float = 1.0
    accel_noise: float = 5.0

    def validate(self, prefix: str = "", period_name: str = "period", noise_name: str = "accel_noise") -> None:
        check_range(f"{prefix}axes", self.axes, 1, 16, integer=True)
        check_range(f"{prefix}{period_name}", self.period, 0.0, 1e4, low_open=True)
        check_range(f"{prefix}{noise_name}", self.accel_noise, 0.0, 1e12)

    @property
    def dim(self) -> int:
        return 2 * self.axes

    @cached_property
    def transition(self) -> np.ndarray:
        """Phi, shape (2 axes, 2 axes)."""
        block = np.array([[1.0, self.period], [0.0, 1.0]])
        return np.kron(np.eye(self.axes), block)

    @cached_property
    def noise_gain(self) -> np.ndarray:
        """G, shape (2 axes, axes)."""
        column = np.array([[self.period**2 / 2.0], [self.period]])
        return np.kron(np.eye(self.axes), column)

    @cached_property
    def process_noise(self) -> np.ndarray:
        """Q = q G G^T, the covariance of G w."""
        G = self.noise_gain
        return float(self.accel_noise) * G @ G.T

    @cached_property
    def position_matrix(self) -> np.ndarray:
        """H that picks the positions out of the state, shape (axes, 2 axes)."""
        return np.kron(np.eye(self.axes), np.array([[1.0, 0.0]]))

    def sample_noise(self, rng: np.random.Generator, size: tuple[int, ...]) -> np.ndarray:
        """Accelerations w of shape ``(*size, axes)`` drawn from ``rng``."""
        return np.sqrt(float(self.accel_noise)) * rng.standard_normal((*size, self.axes))

    def step(self, state: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """x(k+1) = Phi x(k) + G w(k) for a batch ``state`` (..., 2 axes) and ``noise`` (..., axes).

        Written per axis (position + T velocity + T^2/2 w, velocity + T w), not as the two matrix products:
        BLAS rounds a product of many rows differently from a product of one row, so with the products copy b
        of a batch differed from the same copy drawn alone by ~1e-12 at T = 0.1; per axis, every batch size
        gives the same numbers. Where multiplying by T and T^2/2 is exact (T a power of 2; the presets' T = 1)
        these are also the numbers the products gave."""
        state = np.asarray(state, float)
        noise = np.asarray(noise, float)
        T, half = float(self.period), self.period**2 / 2.0
        out = np.empty(np.broadcast_shapes(state.shape, (*noise.shape[:-1], self.dim)))
        position, velocity = state[..., 0::2], state[..., 1::2]
        out[..., 0::2] = position + velocity * T + noise * half
        out[..., 1::2] = velocity + noise * T
        return out

    def trajectory(self, initial: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """States x(0..K-1), shape (..., K, 2 axes), from x(0) (..., 2 axes) and w(0..K-2) (..., K-1, axes)."""
        initial = np.asarray(initial, float)
        steps = noise.shape[-2]
        out = np.empty((*np.broadcast_shapes(initial.shape[:-1], noise.shape[:-2]), steps + 1, self.dim))
        out[..., 0, :] = initial
        for k in range(steps):
            out[..., k + 1, :] = self.step(out[..., k, :], noise[..., k, :])
        return out
