"""SE(2) odometry motion and range+bearing measurement models (MRCLAM robots), in the shape of ``estimators.models``.

The math is that of ``estimators.ukf_relay_se2`` (its module docstring
states the equations); these objects call its functions, so the simulated
truth, the dead-reckoning backend (``estimators.models.predict_joint``)
and the SE(2) UKF agree by construction.

| model                      | kind                       | state x / reading z   | input u / target                 |
|----------------------------|----------------------------|-----------------------|----------------------------------|
| ``SE2Odometry``       | ``se2_odometry``           | x = [x, y, theta] (3) | [v, omega, var_v, var_omega] (4) |
| ``RangeBearingModel`` | ``landmark_range_bearing`` | z = [range, bearing]  | a landmark or a robot's position |

Both are MRCLAM's (Leung et al., IJRR 2011: the robots' odometry and camera).

Noise is given as variances (the library's convention). The odometry
variances travel in the input, one pair per robot and step, because the
MRCLAM noise model is speed dependent (``estimators.ukf_relay_se2.odometry_variance``:
sigma_c^2 = r_c (a_c + b_c u_c^2)); a constant-noise user passes the same pair every step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

import estimators.ukf_relay_se2 as se2

__all__ = ["RangeBearingModel", "SE2Odometry"]


@dataclass(frozen=True)
class SE2Odometry:
    """Unicycle over one step dt driven by odometry (``estimators.ukf_relay_se2.motion``):

        x(k+1) = x + dt v cos theta,  y(k+1) = y + dt v sin theta,  theta(k+1) = wrap(theta + dt omega),

    with u = (v, omega, sigma_v^2, sigma_omega^2): the (corrected) measured speed and turn rate
    and the variances of their white errors. The process noise in state space is the
    first-order image of the input noise, Q = G diag(sigma_v^2, sigma_omega^2) G^T with
    G = dt [[cos theta, 0], [sin theta, 0], [0, 1]]; the Jacobian is
    F = [[1, 0, -dt v sin theta], [0, 1, dt v cos theta], [0, 0, 1]]
    (the EKF time update P <- F P F^T + Q of ``estimators.ukf_relay_se2.time_update``).
    """

    dt: float
    kind: ClassVar[str] = "se2_odometry"
    state_dim: ClassVar[int] = 3
    input_dim: ClassVar[int] = 4
    identity_jacobian: ClassVar[bool] = False

    def __post_init__(self):
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be > 0 seconds, got {self.dt!r}")

    @staticmethod
    def _split(inputs):
        u = np.asarray(inputs, float)
        if u.shape[-1] != 4:
            raise ValueError(f"se2_odometry inputs must end in 4 values (v, omega, var_v, var_omega), got {u.shape}")
        return u[..., :2], u[..., 2:]

    def function(self, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        odometry, _ = self._split(inputs)
        return se2.motion(state, odometry, self.dt)[0]

    def jacobian(self, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        odometry, _ = self._split(inputs)
        return se2.motion(state, odometry, self.dt)[1]

    def input_jacobian(self, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """G = df/du (..., 3, 2)."""
        odometry, _ = self._split(inputs)
        return se2.motion(state, odometry, self.dt)[2]

    def covar(self, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """Q = G diag(var_v, var_omega) G^T (..., 3, 3); variances must be >= 0."""
        _, var = self._split(inputs)
        if np.any(var < 0):
            raise ValueError("se2_odometry input variances (var_v, var_omega) must be >= 0")
        G = self.input_jacobian(state, inputs)
        return np.einsum("...ab,...b,...cb->...ac", G, var, G)

    def rvs(self, rng: np.random.Generator, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """One draw of the state noise w = G e, e ~ N(0, diag(var_v, var_omega)) per state (the leading axes
        of ``state`` and ``inputs`` broadcast: one draw per particle), shape like ``state`` broadcast."""
        _, var = self._split(inputs)
        G = self.input_jacobian(state, inputs)  # (..., 3, 2)
        e = np.sqrt(var) * rng.standard_normal(G.shape[:-2] + (2,))
        return np.einsum("...ab,...b->...a", G, e)

    @staticmethod
    def position(state: np.ndarray) -> np.ndarray:
        return state[..., :2]


@dataclass(frozen=True)
class RangeBearingModel:
    """z = [||t - p||, wrap(atan2(t_y - y, t_x - x) - theta)] + v from pose (x, y, theta) to point t.

    (``estimators.ukf_relay_se2.observe``), v ~ N(0, R), R = diag(range_var + range_var_gain r^2,
    bearing_var) with r the measured range (the MRCLAM calibration's range-dependent sigma_r,
    ``coloc_env.data.mrclam_noise.NoiseModel.measurement_cov``; gain 0 = constant noise). The target t is
    a known landmark or another robot's position.
    """

    range_var: float
    bearing_var: float
    range_var_gain: float = 0.0
    kind: ClassVar[str] = "landmark_range_bearing"

    def __post_init__(self):
        for name in ("range_var", "bearing_var", "range_var_gain"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite variance >= 0, got {value!r}")

    @staticmethod
    def function(observer_state: np.ndarray, target: np.ndarray) -> np.ndarray:
        return se2.observe(observer_state, target)

    @staticmethod
    def jacobian(observer_state: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(dh/dx_observer (..., 2, 3), dh/dt (..., 2, 2)); with d = t - p, r = ||d||:
        dr/dp = -d^T / r, dr/dt = d^T / r, db/dp = [d_y, -d_x] / r^2, db/dt = [-d_y, d_x] / r^2, db/dtheta = -1."""
        s, t = np.asarray(observer_state, float), np.asarray(target, float)
        d = t - s[..., :2]
        r2 = np.sum(d * d, axis=-1)
        r = np.sqrt(r2)
        dx, dy = d[..., 0], d[..., 1]
        H_t = np.stack([np.stack([dx / r, dy / r], axis=-1), np.stack([-dy / r2, dx / r2], axis=-1)], axis=-2)
        H_s = np.zeros((*H_t.shape[:-1], 3))
        H_s[..., :2] = -H_t
        H_s[..., 1, 2] = -1.0
        return H_s, H_t

    def covar(self, measured_range=None) -> np.ndarray:
        """R (..., 2, 2) at the measured range(s) (None: the range term without the gain)."""
        r = np.zeros(()) if measured_range is None else np.asarray(measured_range, float)
        R = np.zeros((*r.shape, 2, 2))
        R[..., 0, 0] = self.range_var + self.range_var_gain * r * r
        R[..., 1, 1] = self.bearing_var
        return R

    def rvs(self, rng: np.random.Generator, size, true_range=None) -> np.ndarray:
        """Noise draws (*size, 2) (range at ``true_range``, broadcast to ``size``)."""
        size = tuple(np.atleast_1d(size)) if np.ndim(size) else (int(size),)
        R = np.broadcast_to(self.covar(true_range), (*size, 2, 2))
        std = np.sqrt(np.stack([R[..., 0, 0], R[..., 1, 1]], axis=-1))
        return std * rng.standard_normal((*size, 2))
