"""Odometry motion model with the heading error in the state (the time-correlated part of dead reckoning).

Setting (wang2019's odometry, ``estimators.models.OdometryDisplacement``): a
platform measures its speed V_m = V + n_v and its turn rate omega_m = omega + n_omega
(white, variances sigma_v^2, sigma_omega^2) and integrates the heading it moves along,
phi_m(k+1) = phi_m(k) + dt omega_m(k), from a known phi(0). The heading error
e(k) = phi_m(k) - phi(k) is then a random walk, e(k+1) = e(k) + dt n_omega(k), and
every displacement dt V_m [cos phi_m; sin phi_m] carries the same slowly growing
error. A position-only filter can give each step's displacement the right marginal
variance (the ``heading_var`` term of ``estimators.ukf_relay.process_noise``) but
treats successive steps as independent; the true errors of successive steps are
correlated through e, so over K steps the lateral error grows like K^3 sigma_omega^2
while the white model's grows like K^2, and the filter becomes overconfident.

Model (``OdometryHeadingError``): per platform the state is
s = (x, y, e), the position and the error of the integrated heading reading; the
input is the same as the displacement model's, u = (V_m, phi_m, sigma_phi^2) (the
last entry is not used: the model carries the heading error itself):

    p(k+1) = p(k) + dt V_m t(k),   t(k) = [cos(phi_m - e); sin(phi_m - e)],
    e(k+1) = e(k) + dt n_omega,

with process noise Q = blockdiag(dt^2 sigma_v^2 t t^T, dt^2 sigma_omega^2) (the speed
noise along the track, the turn-rate noise driving the heading error; independent
of each other and of e(k)). The Jacobian is

    F = [[1, 0,  dt V_m sin(phi_m - e)],
         [0, 1, -dt V_m cos(phi_m - e)],
         [0, 0,  1]],

so the cross-covariance of position and heading error (and, through
``estimators.models.predict_joint``, between platforms) evolves; the filter's
time update is the EKF one (exact to first order in e). Range and fix updates see
the position, the first two entries of each block, unchanged.

Equivalently this is the heading-in-state unicycle driven by the turn-rate reading
(phi = phi_m - e); writing it as the reading's error keeps the input of the
position-only model, so one world's readings serve both.

Departure: the integrated heading is exact at k = 0 (e(0) = 0 with variance 0), and a
joint covariance with a zero block has no Cholesky factor for the sigma points; the
initial variance of e is one step's increment, dt^2 sigma_omega^2
(``OdometryHeadingError.initial_error_var``), which overstates the heading
error's variance at step k by that of one step ((k + 1) instead of k increments).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from estimators.models import symmetric_root_draw

__all__ = ["OdometryHeadingError"]


@dataclass(frozen=True)
class OdometryHeadingError:
    """State (x, y, e): position and heading-reading error; input (V_m, phi_m, unused). See the module docstring.

    | field          | meaning                                   | allowed   |
    |----------------|-------------------------------------------|-----------|
    | dt             | step [s]                                  | > 0       |
    | speed_var      | sigma_v^2 of the speed reading [m^2/s^2]  | >= 0      |
    | turn_rate_var  | sigma_omega^2 of the turn rate [rad^2/s^2] | > 0      |
    """

    dt: float
    speed_var: float
    turn_rate_var: float
    kind: ClassVar[str] = "odometry_heading_error"
    state_dim: ClassVar[int] = 3
    input_dim: ClassVar[int] = 3
    identity_jacobian: ClassVar[bool] = False

    def __post_init__(self):
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be > 0, got {self.dt!r}")
        if not (np.isfinite(self.speed_var) and self.speed_var >= 0):
            raise ValueError(f"speed_var must be >= 0, got {self.speed_var!r}")
        if not (np.isfinite(self.turn_rate_var) and self.turn_rate_var > 0):
            raise ValueError(f"turn_rate_var must be > 0 (with 0 the heading error is identically 0: use "
                             f"OdometryDisplacement), got {self.turn_rate_var!r}")

    def _track(self, state, inputs):
        heading = np.asarray(inputs, float)[..., 1] - np.asarray(state, float)[..., 2]
        return np.cos(heading), np.sin(heading)

    def function(self, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        state = np.asarray(state, float)
        c, s = self._track(state, inputs)
        step = self.dt * np.asarray(inputs, float)[..., 0]
        return np.stack([state[..., 0] + step * c, state[..., 1] + step * s, state[..., 2]], axis=-1)

    def jacobian(self, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        c, s = self._track(state, inputs)
        step = self.dt * np.asarray(inputs, float)[..., 0]
        F = np.zeros((*np.shape(state)[:-1], 3, 3))
        F[..., 0, 0] = F[..., 1, 1] = F[..., 2, 2] = 1.0
        F[..., 0, 2] = step * s
        F[..., 1, 2] = -step * c
        return F

    def covar(self, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        c, s = self._track(state, inputs)
        along = np.stack([c, s], axis=-1)
        Q = np.zeros((*np.shape(state)[:-1], 3, 3))
        Q[..., :2, :2] = self.dt**2 * self.speed_var * along[..., :, None] * along[..., None, :]
        Q[..., 2, 2] = self.initial_error_var()
        return Q

    def initial_error_var(self) -> float:
        """dt^2 sigma_omega^2: one step's increment of the heading error (the prior of e, module docstring)."""
        return self.dt**2 * self.turn_rate_var

    def augment(self, mean: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position beliefs (..., N, 2), (..., N, 2, 2) -> (..., N, 3), (..., N, 3, 3): e = 0, var(e) = the prior."""
        mean, cov = np.asarray(mean, float), np.asarray(cov, float)
        out_mean = np.concatenate([mean, np.zeros((*mean.shape[:-1], 1))], axis=-1)
        out_cov = np.zeros((*cov.shape[:-2], 3, 3))
        out_cov[..., :2, :2] = cov
        out_cov[..., 2, 2] = self.initial_error_var()
        return out_mean, out_cov

    def rvs(self, rng: np.random.Generator, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """One draw of the process noise per agent, shape like ``state`` (Q is rank 2: symmetric square root)."""
        return symmetric_root_draw(rng, self.covar(state, inputs), np.shape(state))

    @staticmethod
    def position(state: np.ndarray) -> np.ndarray:
        return state[..., :2]
