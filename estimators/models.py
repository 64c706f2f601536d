"""Motion and measurement models shared by the simulated truth and the filters (Stone Soup's shape).

A motion model maps one agent's state x (..., d) and input u (..., u_dim) to
the next state; it gives what an estimator needs: the noiseless
``function(x, u)``, its ``jacobian(x, u)`` = df/dx (..., d, d), the process
noise ``covar(x, u)`` (..., d, d) in state space, and ``rvs`` to sample that
noise. A measurement model does the same for a reading z = h(x) + v. Every
array carries arbitrary leading batch axes (the library's convention:
copies first, then agents).

The models take their noise as variances (``*_var`` fields, m^2, rad^2) or
covariances, the package's convention (``estimators``).

| model                         | kind                      | state x      | input u                     | paper  |
|-------------------------------|---------------------------|--------------|-----------------------------|--------|
| ``OdometryDisplacement`` | ``odometry_displacement`` | position (2) | speed, heading, heading var | wang2019 |

``predict_joint`` is the time update of a joint Gaussian over N agents
(the EKF form P <- F P F^T + Q, exact for the linear models); it is shared by
every Kalman-type backend. ``per_copy`` reads a noise parameter given as one
value for every copy or one per copy.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

__all__ = ["OdometryDisplacement", "RangeModel", "PositionFixModel", "predict_joint"]


@dataclass(frozen=True)
class OdometryDisplacement:
    """x(k+1) = x(k) + dt V_m [cos phi_m; sin phi_m] + w (wang2019 eq. 1), w ~ N(0, Q).

    u = (V_m, phi_m, sigma_phi^2): the measured speed, the heading integrated
    from the measured turn rate and that heading's variance. Q = dt^2
    speed_var u u^T + dt^2 V_m^2 sigma_phi^2 n n^T (``estimators.ukf_relay.process_noise``:
    the speed noise along the track, the heading's first-order effect across it).
    The Jacobian is the identity, so cross-covariances do not change.
    """

    dt: float
    speed_var: float
    kind: ClassVar[str] = "odometry_displacement"
    state_dim: ClassVar[int] = 2
    input_dim: ClassVar[int] = 3
    identity_jacobian: ClassVar[bool] = True

    def function(self, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        speed, heading = inputs[..., 0], inputs[..., 1]
        return state + self.dt * speed[..., None] * np.stack([np.cos(heading), np.sin(heading)], axis=-1)

    def jacobian(self, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        return np.broadcast_to(np.eye(2), (*np.shape(state)[:-1], 2, 2))

    def covar(self, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        from estimators.ukf_relay import process_noise

        return process_noise(inputs[..., 0], inputs[..., 1], self.dt, self.speed_var, inputs[..., 2])

    def rvs(self, rng: np.random.Generator, state: np.ndarray, inputs: np.ndarray) -> np.ndarray:
        """One draw of w per agent, shape like ``state``.

        Q is often singular (rank 1 at k = 0, where the heading is known exactly), so the square root
        is the symmetric one from the eigendecomposition, not a Cholesky factor."""
        return symmetric_root_draw(rng, self.covar(state, inputs), np.shape(state))

    @staticmethod
    def position(state: np.ndarray) -> np.ndarray:
        return state[..., :2]


def per_copy(name: str, value, batch: int) -> np.ndarray:
    """A parameter given as a float (every copy) or as (B,) floats (one per copy), as (B,) floats; ValueError
    naming ``name`` for any other shape."""
    arr = np.asarray(value, float)
    if arr.ndim == 0:
        return np.full(batch, float(arr))
    if arr.shape != (batch,):
        raise ValueError(f"{name} must be a float or have shape ({batch},), got shape {arr.shape}")
    return arr


def symmetric_root_draw(rng: np.random.Generator, cov: np.ndarray, shape) -> np.ndarray:
    """One N(0, cov) draw per leading index, ``shape`` = cov's (..., n): S z with S the symmetric square root of
    ``cov`` from its eigendecomposition (defined for a singular, PSD ``cov``, where a Cholesky factor is not)."""
    values, vectors = np.linalg.eigh(cov)
    factor = vectors * np.sqrt(np.maximum(values, 0.0))[..., None, :]
    return np.einsum("...ij,...j->...i", factor, rng.standard_normal(shape))


@dataclass(frozen=True)
class RangeModel:
    """z = ||p_a - p_b|| + v, v ~ N(0, noise_var) (every paper's range sensor)."""

    noise_var: float
    kind: ClassVar[str] = "range"

    @staticmethod
    def function(position_a: np.ndarray, position_b: np.ndarray) -> np.ndarray:
        return np.sqrt(np.sum((np.asarray(position_a) - np.asarray(position_b)) ** 2, axis=-1))

    def covar(self) -> float:
        return self.noise_var

    def rvs(self, rng: np.random.Generator, size) -> np.ndarray:
        return np.sqrt(self.noise_var) * rng.standard_normal(size)


@dataclass(frozen=True)
class PositionFixModel:
    """z = p + v, v ~ N(0, noise_var I2): a GPS fix or an anchor's known position (H = [I2 0])."""

    noise_var: float
    kind: ClassVar[str] = "position_fix"

    @staticmethod
    def function(position: np.ndarray) -> np.ndarray:
        return np.asarray(position)

    def covar(self) -> np.ndarray:
        return self.noise_var * np.eye(2)

    def rvs(self, rng: np.random.Generator, size) -> np.ndarray:
        return np.sqrt(self.noise_var) * rng.standard_normal((*size, 2))


def predict_joint(model, mean: np.ndarray, cov: np.ndarray | None, inputs: np.ndarray):
    """Time update of N agents' joint Gaussian: x_i <- f(x_i, u_i), P <- F P F^T + blockdiag(Q_i).

    ``mean`` (..., N, d), ``cov`` (..., N d, N d) or None (dead reckoning without a
    covariance), ``inputs`` (..., N, u). F = blockdiag(df/dx_i): exact for a linear
    model, the EKF linearization otherwise. With an identity Jacobian only the
    diagonal blocks change (P_ii + Q_i), the arithmetic of wang2019's eq. (1).
    Returns new ``(mean, cov)``.
    """
    new_mean = model.function(mean, inputs)
    if cov is None:
        return new_mean, None
    N, d = mean.shape[-2:]
    Q = model.covar(mean, inputs)
    cov = np.array(cov, dtype=float, copy=True)
    if not model.identity_jacobian:
        F = model.jacobian(mean, inputs)  # (..., N, d, d)
        blocks = cov.reshape(*cov.shape[:-2], N, d, N, d)
        blocks = np.einsum("...iab,...ibjc,...jdc->...iajd", F, blocks, F)
        cov = blocks.reshape(cov.shape)
    for i in range(N):  # N diagonal blocks, each batched over copies
        cov[..., d * i:d * i + d, d * i:d * i + d] += Q[..., i, :, :]
    return new_mean, cov
