"""Models of gao2016 (``nlos_orbit`` / ``afge`` / ``dfir``) in the shape of ``estimators.models``.

| model                               | kind             | state x              | input u | paper   |
|-------------------------------------|------------------|----------------------|---------|---------|
| ``ConstantVelocityWhiteAccel`` | ``cv_white_accel`` | [px, py, vx, vy] (4) | none (0) | gao2016 |
| ``RssAoaModel``                | ``rss_aoa``      | target position (2), seen from a sender | - | gao2016 |

Motion (docs/gao2016.md §2) [reconstructed]: ``x(k+1) = A x(k) + B w(k)``, ``w ~ N(0, accel_var I_2)``,
``A = [[I, T I], [0, I]]``, ``B = [[T^2/2 I], [T I]]``; the matrices are those of
``estimators.afge.MotionModel`` (this class wraps it; no second copy). Unlike
``estimators.cv_models.ConstantVelocityAccel`` there is no accelerometer: the target's
acceleration is an unknown white input, so the model takes an empty input ``u`` (..., 0).
Noise is a variance here (the library's convention); ``ConstantVelocityWhiteAccel.afge``
converts to the estimator's ``accel_sigma`` at the boundary.

Measurement (§4) [reconstructed]: what neighbour j measures of the target, the RSS
``P_T - PL(d0) - 10 n log10(d / d0) - eps`` (dBm) and the AOA ``atan2(p - p_j) + n_theta``
(rad), with ``(eps, n_theta) ~ N(0, diag(s_db^2, s_th^2))`` in LOS and
``N((mu_db, mu_th), diag(s_db^2 + s_b,db^2, s_th^2 + s_b,th^2))`` in NLOS, as
``coloc_env.worlds.blocks.radio.RssAoaSensor`` draws them; the parameters are an
``estimators.afge.SignalModel``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import ClassVar

import numpy as np

from estimators.afge import MotionModel, SignalModel

__all__ = ["ConstantVelocityWhiteAccel", "RssAoaModel"]


@dataclass(frozen=True)
class ConstantVelocityWhiteAccel:
    """x(k+1) = A x + w, w ~ N(0, Gam), Gam = accel_var B B^T (§2) [reconstructed]; no input."""

    period: float
    accel_var: float
    kind: ClassVar[str] = "cv_white_accel"
    state_dim: ClassVar[int] = 4
    input_dim: ClassVar[int] = 0
    identity_jacobian: ClassVar[bool] = False

    @cached_property
    def afge(self) -> MotionModel:
        """The same model as ``estimators.afge`` takes it (``accel_sigma`` = sqrt(accel_var))."""
        return MotionModel(float(self.period), float(np.sqrt(self.accel_var)))

    @property
    def dt(self) -> float:
        return float(self.period)

    @property
    def transition(self) -> np.ndarray:
        """A (4, 4)."""
        return self.afge.transition

    @property
    def process_noise(self) -> np.ndarray:
        """Gam = B Q B^T (4, 4), Q = accel_var I_2."""
        return self.afge.process_cov

    def function(self, state: np.ndarray, inputs: np.ndarray | None = None) -> np.ndarray:
        return np.asarray(state, float) @ self.transition.T

    def jacobian(self, state: np.ndarray, inputs: np.ndarray | None = None) -> np.ndarray:
        return np.broadcast_to(self.transition, (*np.shape(state)[:-1], 4, 4))

    def covar(self, state: np.ndarray, inputs: np.ndarray | None = None) -> np.ndarray:
        return np.broadcast_to(self.process_noise, (*np.shape(state)[:-1], 4, 4))

    def rvs(self, rng: np.random.Generator, state: np.ndarray, inputs: np.ndarray | None = None) -> np.ndarray:
        """One draw of B w per agent, shape like ``state``."""
        w = np.sqrt(self.accel_var) * rng.standard_normal((*np.shape(state)[:-1], 2))
        return w @ self.afge.noise_input.T

    @staticmethod
    def position(state: np.ndarray) -> np.ndarray:
        return state[..., :2]


@dataclass(frozen=True)
class RssAoaModel:
    """RSS (dBm) and AOA (rad) of a target at ``position`` seen from a sender at ``sender`` (§4).

    ``function`` is the noiseless (LOS, bias-free) reading, ``jacobian`` its derivative with
    respect to the target position (2, 2), ``covar(nlos)`` the reading's covariance in each
    mode, ``mean_error(nlos)`` the NLOS bias, ``rvs`` a draw of (eps, n_theta) added as the
    sensor adds it (RSS minus eps, AOA plus n_theta).
    """

    signal: SignalModel
    kind: ClassVar[str] = "rss_aoa"

    def function(self, position: np.ndarray, sender: np.ndarray) -> np.ndarray:
        s = self.signal
        rel = np.asarray(position, float) - np.asarray(sender, float)
        d = np.hypot(rel[..., 0], rel[..., 1])
        rss = s.tx_power_dbm - s.reference_loss_db - 10.0 * s.exponent * np.log10(d / s.d0)
        return np.stack([rss, np.arctan2(rel[..., 1], rel[..., 0])], axis=-1)

    def jacobian(self, position: np.ndarray, sender: np.ndarray) -> np.ndarray:
        rel = np.asarray(position, float) - np.asarray(sender, float)
        d2 = np.sum(rel**2, axis=-1)
        c = -10.0 * self.signal.exponent / np.log(10.0)
        rows = [c * rel[..., 0] / d2, c * rel[..., 1] / d2, -rel[..., 1] / d2, rel[..., 0] / d2]
        return np.stack(rows, axis=-1).reshape(*rel.shape[:-1], 2, 2)

    def mean_error(self, nlos: np.ndarray) -> np.ndarray:
        """E[(eps, n_theta)]: 0 in LOS, (mu_db, mu_theta) in NLOS, (..., 2)."""
        s = self.signal
        n = np.asarray(nlos, float)[..., None]
        return n * np.array([s.nlos_bias_db, s.nlos_bias_theta])

    def covar(self, nlos: np.ndarray) -> np.ndarray:
        """Cov[(eps, n_theta)] (..., 2, 2): diag(s_db^2, s_th^2), plus the NLOS spreads in NLOS."""
        s = self.signal
        n = np.asarray(nlos, float)
        var = np.stack([s.sigma_db**2 + n * s.nlos_sigma_db**2, s.sigma_theta**2 + n * s.nlos_sigma_theta**2], -1)
        return var[..., :, None] * np.eye(2)

    def rvs(self, rng: np.random.Generator, nlos: np.ndarray) -> np.ndarray:
        """One draw of (eps, n_theta) per reading, (..., 2)."""
        nlos = np.asarray(nlos)
        white = rng.standard_normal((*nlos.shape, 2))
        return self.mean_error(nlos) + np.sqrt(np.diagonal(self.covar(nlos), axis1=-2, axis2=-1)) * white
