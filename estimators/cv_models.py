"""Constant-velocity motion driven by an accelerometer (wan2014, eq. 1), in the shape of ``estimators.models``.

| model                           | kind       | state x                | input u                      | paper   |
|---------------------------------|------------|------------------------|------------------------------|---------|
| ``ConstantVelocityAccel``  | ``cv_accel`` | [px, py, vx, vy] (4) | accelerometer reading (2)    | wan2014 |

x(k+1) = F x(k) + G a_hat(k) + w, F = [[I2, dt I2], [0, I2]], G = [[dt^2/2 I2], [dt I2]],
w ~ N(0, Q), Q = accel_noise_var G G^T: an estimator that only knows the reading
a_hat sees exactly this noise (``coloc_env.worlds.blocks.cv_uav.ConstantVelocityUAVs``).
The model is linear, so ``estimators.models.predict_joint`` is exact on it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

__all__ = ["ConstantVelocityAccel"]


@dataclass(frozen=True)
class ConstantVelocityAccel:
    """x(k+1) = F x + G u + w, u the accelerometer reading (m/s^2), w ~ N(0, accel_noise_var G G^T)."""

    dt: float
    accel_noise_var: float
    kind: ClassVar[str] = "cv_accel"
    state_dim: ClassVar[int] = 4
    input_dim: ClassVar[int] = 2
    identity_jacobian: ClassVar[bool] = False

    @property
    def transition(self) -> np.ndarray:
        """F (4, 4)."""
        F = np.eye(4)
        F[0, 2] = F[1, 3] = self.dt
        return F

    @property
    def input_matrix(self) -> np.ndarray:
        """G (4, 2)."""
        return np.vstack([0.5 * self.dt**2 * np.eye(2), self.dt * np.eye(2)])

    @property
    def process_noise(self) -> np.ndarray:
        """Q (4, 4) = accel_noise_var G G^T."""
        G = self.input_matrix
        return self.accel_noise_var * G @ G.T

    def function(self, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        state, inputs = np.asarray(state, float), np.asarray(inputs, float)
        return state @ self.transition.T + inputs @ self.input_matrix.T

    def jacobian(self, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.transition, (*np.shape(state)[:-1], 4, 4))

    def covar(self, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.process_noise, (*np.shape(state)[:-1], 4, 4))

    def rvs(self, rng: np.random.Generator, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """One draw of w per agent, shape like ``state`` (w = -G e, e ~ N(0, accel_noise_var I2))."""
        e = np.sqrt(self.accel_noise_var) * rng.standard_normal((*np.shape(state)[:-1], 2))
        return -e @ self.input_matrix.T

    @staticmethod
    def position(state: np.ndarray) -> np.ndarray:
        return state[..., :2]
