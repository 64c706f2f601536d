"""2-D constant-velocity UAVs driven by a noisy accelerometer (wan2014, eq. 1).

State x = [px, py, vx, vy]. With the true acceleration a ~ N(0, sigma_a^2 I2)
and the accelerometer reading a_hat = a + e, e ~ N(0, sigma_acc^2 I2):

    x(k+1) = F x(k) + G a(k),   F = [[I2, dt I2], [0, I2]],   G = [[dt^2/2 I2], [dt I2]]

An estimator that only knows a_hat sees x(k+1) = F x(k) + G a_hat(k) + w with
w = -G e ~ N(0, Q), Q = sigma_acc^2 G G^T: exact for this generator, because
the true acceleration enters the truth and the reading alike.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import check_range
from estimators.cv_models import ConstantVelocityAccel


@dataclass(frozen=True)
class ConstantVelocityUAVs:
    """Constant-velocity point UAVs in the plane with an accelerometer.

    | field            | symbol     | meaning                                  | wan2014 default      |
    |------------------|------------|------------------------------------------|----------------------|
    | dt               | Delta t    | period [s]                               | 1 [chosen]           |
    | accel_std        | sigma_a    | true acceleration std per axis [m/s^2]   | 0.5 [chosen]         |
    | accel_noise_std  | sigma_acc  | accelerometer noise std per axis [m/s^2] | 0.3 [chosen]         |
    """

    dt: float = 1.0
    accel_std: float = 0.5
    accel_noise_std: float = 0.3

    def validate(self, prefix: str = "") -> None:
        check_range(f"{prefix}dt", self.dt, 0.0, 1e3, low_open=True)
        check_range(f"{prefix}accel_std", self.accel_std, 0.0, 1e3)
        check_range(f"{prefix}accel_noise_std", self.accel_noise_std, 0.0, 1e3)

    @property
    def model(self) -> ConstantVelocityAccel:
        """The model an estimator driven by the readings assumes (``estimators.cv_models``)."""
        return ConstantVelocityAccel(self.dt, self.accel_noise_std**2)

    @property
    def transition(self) -> np.ndarray:
        """F (4, 4)."""
        return self.model.transition

    @property
    def input_matrix(self) -> np.ndarray:
        """G (4, 2)."""
        return self.model.input_matrix

    @property
    def process_noise(self) -> np.ndarray:
        """Q = sigma_acc^2 G G^T, the noise an estimator driven by the readings sees."""
        return self.model.process_noise

    def sample_accelerations(self, rng: np.random.Generator, size: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        """(true accelerations, accelerometer readings), each ``(*size, 2)``; truth drawn first."""
        true = self.accel_std * rng.standard_normal((*size, 2))
        reading = true + self.accel_noise_std * rng.standard_normal((*size, 2))
        return true, reading

    def step(self, state: np.ndarray, accel: np.ndarray) -> np.ndarray:
        """x(k+1) = F x + G a for states (..., 4) and accelerations (..., 2)."""
        state = np.asarray(state, float)
        pos, vel = state[..., :2], state[..., 2:]
        return np.concatenate([pos + self.dt * vel + 0.5 * self.dt**2 * accel, vel + self.dt * accel], axis=-1)

    def trajectory(self, initial: np.ndarray, accel: np.ndarray) -> np.ndarray:
        """States (T, ..., 4) for steps 0..T-1 from ``initial`` (..., 4) and accelerations (T-1, ..., 2)."""
        states = [np.asarray(initial, float)]
        for a in accel:
            states.append(self.step(states[-1], a))
        return np.stack(states)
