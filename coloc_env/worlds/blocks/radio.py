"""Radio for ``nlos_horizon``: the receive-search area (gao2016 Defs. 1-2) and RSS/AOA sensors.

Log-distance path loss (Def. 2) [reconstructed]:

    P_r(d) = P_T - PL(d0) - 10 n log10(d / d0) - eps,   PL(d0) = 20 log10(4 pi d0 f / c)
    r(P)   = d0 10^((P_T - PL(d0) - P) / (10 n)),  r_sup = r(P_min), r_inf = r(P_max).

A neighbour is in the RSA of the target when r_inf <= ||p_i - p_j|| <= r_sup (Def. 1), decided
on the true distance (the receiver either decodes or not).

Measurements of a packet (docs/gao2016.md, section 4) [reconstructed]: RSS = P_T - PL(d0) - 10 n log10(d/d0) - eps
with eps ~ N(0, s_db^2) in LOS and N(mu_db, s_db^2 + s_b,db^2) in NLOS (mu_db > 0 weakens the
signal); AOA theta = atan2(p_i - p_j) + n_theta, n_theta ~ N(0, s_th^2) in LOS and
N(mu_th, s_th^2 + s_b,th^2) in NLOS.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import check_range
from estimators.afge import SignalModel, range_from_power, reference_path_loss

__all__ = ["rsa_radii", "ReceiveSearchArea", "RssAoaSensor"]


def rsa_radii(tx_power_dbm: float, p_min_dbm: float, p_max_dbm: float, exponent: float, frequency_hz: float,
              d0: float = 1.0) -> tuple[float, float]:
    """(r_inf, r_sup) of the RSA from the power thresholds (Def. 2) [reconstructed].

    ``p_min_dbm``: weakest decodable signal -> r_sup; ``p_max_dbm``: saturation -> r_inf.
    """
    if p_max_dbm <= p_min_dbm:
        raise ValueError(f"p_max_dbm must exceed p_min_dbm (saturation above sensitivity), got "
                         f"{p_max_dbm} <= {p_min_dbm}")
    check_range("exponent", exponent, 0.0, 100.0, low_open=True)
    loss = reference_path_loss(frequency_hz, d0)
    r_inf = range_from_power(p_max_dbm, tx_power_dbm, loss, exponent, d0)
    r_sup = range_from_power(p_min_dbm, tx_power_dbm, loss, exponent, d0)
    return float(r_inf), float(r_sup)


@dataclass(frozen=True)
class ReceiveSearchArea:
    """The annulus r_inf <= d <= r_sup (Def. 1) [reconstructed]."""

    r_inf: float = 30.0
    r_sup: float = 1000.0

    def validate(self, inf_name: str = "r_inf", sup_name: str = "r_sup") -> None:
        check_range(inf_name, self.r_inf, 0.0, 1e9, low_open=True)
        check_range(sup_name, self.r_sup, 0.0, 1e9, low_open=True)
        if not self.r_inf < self.r_sup:
            raise ValueError(f"{inf_name} must be below {sup_name} (0 < r_inf < r_sup), got "
                             f"{self.r_inf} >= {self.r_sup}")

    def contains(self, distance: np.ndarray) -> np.ndarray:
        distance = np.asarray(distance, float)
        return (distance >= self.r_inf) & (distance <= self.r_sup)


@dataclass(frozen=True)
class RssAoaSensor:
    """RSS (log-distance path loss) and AOA with a LOS/NLOS-dependent error (docs/gao2016.md, section 4).

    The same fields as ``estimators.afge.SignalModel`` (the estimator's knowledge);
    ``sigma_nav``/``p_nlos`` are not used here.
    """

    signal: SignalModel

    def validate(self, prefix: str = "") -> None:
        s = self.signal
        check_range(f"{prefix}tx_power_dbm", s.tx_power_dbm, -200.0, 200.0)
        check_range(f"{prefix}frequency_hz", s.frequency_hz, 0.0, 1e13, low_open=True)
        check_range(f"{prefix}d0", s.d0, 0.0, 1e6, low_open=True)
        check_range(f"{prefix}path_loss_exponent", s.exponent, 0.0, 10.0, low_open=True)
        check_range(f"{prefix}sigma_db", s.sigma_db, 0.0, 100.0, low_open=True)
        # the angles are held in radians but named (and given) in degrees: checked and reported in degrees
        check_range(f"{prefix}sigma_theta_deg", float(np.degrees(s.sigma_theta)), 0.0, 180.0, low_open=True)
        check_range(f"{prefix}nlos_bias_db", s.nlos_bias_db, -100.0, 100.0)
        check_range(f"{prefix}nlos_sigma_db", s.nlos_sigma_db, 0.0, 100.0)
        check_range(f"{prefix}nlos_bias_deg", float(np.degrees(s.nlos_bias_theta)), -180.0, 180.0)
        check_range(f"{prefix}nlos_sigma_deg", float(np.degrees(s.nlos_sigma_theta)), 0.0, 180.0)

    def mean_rss(self, distance: np.ndarray) -> np.ndarray:
        """P_T - PL(d0) - 10 n log10(d / d0): the LOS mean in dBm."""
        s = self.signal
        return s.tx_power_dbm - s.reference_loss_db - 10.0 * s.exponent * np.log10(np.asarray(distance, float) / s.d0)

    def measure(self, target: np.ndarray, sender: np.ndarray, nlos: np.ndarray, white: np.ndarray):
        """RSS (dBm) and AOA (rad) of the target seen from the sender.

        ``target`` and ``sender`` (..., 2) true positions, ``nlos`` (...) 0/1, ``white`` (..., 2)
        standard normals (dB channel, angle channel).
        """
        s = self.signal
        nlos = np.asarray(nlos, bool)
        rel = np.asarray(target, float) - np.asarray(sender, float)
        distance = np.hypot(rel[..., 0], rel[..., 1])
        eps = np.where(nlos, s.nlos_bias_db + np.hypot(s.sigma_db, s.nlos_sigma_db) * white[..., 0],
                       s.sigma_db * white[..., 0])
        n_theta = np.where(nlos, s.nlos_bias_theta + np.hypot(s.sigma_theta, s.nlos_sigma_theta) * white[..., 1],
                           s.sigma_theta * white[..., 1])
        return self.mean_rss(distance) - eps, np.arctan2(rel[..., 1], rel[..., 0]) + n_theta
