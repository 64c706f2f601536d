"""The MRCLAM robots' own navigation: one UKF per robot on (x, y, theta) from its odometry and its own landmark
sightings, no robot-robot data (the ``mrclam_slices`` world's source of each robot's pose belief), and the
landmark pseudo-fix of one sighting. ``cached_own_navigation`` reads a whole run's filters from the on-disk
cache of ``coloc_env.data.fit_cache`` where an earlier process computed them.
"""

from __future__ import annotations

import sys

import numpy as np

from coloc_env.data.mrclam import NUM_ROBOTS, MrclamData
from coloc_env.data.mrclam_noise import GATE_999, NoiseModel

__all__ = ["OWN_NAV_INITIAL_STD", "cached_own_navigation", "fix_std", "own_nav_predict", "own_nav_update",
           "own_navigation", "pseudo_fix"]

OWN_NAV_INITIAL_STD = 0.01  # m and rad: the own-navigation filter's start (Vicon pose), as coloc reproduce mrclam


def pseudo_fix(landmark, measured_range, bearing, heading, offset=0.0) -> np.ndarray:
    """Position of the observer from a sighting of a known landmark: l - r [cos(theta + b), sin(theta + b)] + offset."""
    angle = np.asarray(heading, float) + np.asarray(bearing, float)
    r = np.asarray(measured_range, float)[..., None]
    return (np.asarray(landmark, float) - r * np.stack([np.cos(angle), np.sin(angle)], axis=-1)
            + np.asarray(offset, float))


def fix_std(measured_range, range_var, bearing_var, heading_var, landmark_var=0.0) -> np.ndarray:
    """Isotropic std of a pseudo-fix: sqrt(max(sigma_r^2, r^2 (sigma_b^2 + sigma_theta^2)) + sigma_landmark^2)."""
    r = np.asarray(measured_range, float)
    return np.sqrt(np.maximum(range_var, r * r * (bearing_var + heading_var)) + landmark_var)


def own_nav_update(d: MrclamData, model: NoiseModel, k: int, x: np.ndarray, P: np.ndarray,
                   accepted: np.ndarray | None = None, robots: int = NUM_ROBOTS) -> None:
    """The own-navigation filters' landmark updates of step k, in file order, in place on ``x`` (N, 3), ``P`` (N, 3, 3).

    Each robot r < ``robots`` updates its own UKF on (x, y, theta) with its own landmark sightings
    (``estimators.ukf_relay_se2.ccl_update`` with N = 1, R from the measured range, the
    chi-square(2) 99.9 % gate); robot-robot lines are skipped. ``accepted`` (M,) bool, if given,
    records which lines the gate let in.
    """
    import estimators.ukf_relay_se2 as se2

    s = d.measurements_at(k)
    for i in range(s.start, s.stop):
        sub = int(d.meas_subject[i])
        r = int(d.meas_robot[i])
        if sub <= NUM_ROBOTS or r >= robots:
            continue
        z = np.array([d.meas_range[i], d.meas_bearing[i]])
        xr, Pr, ok = se2.ccl_update(x[r:r + 1], P[r], 0, z, model.measurement_cov(float(z[0])),
                                    landmark=d.landmarks[sub - NUM_ROBOTS - 1], gate=GATE_999)
        x[r], P[r] = xr[0], Pr
        if accepted is not None:
            accepted[i] = ok


def own_nav_predict(x: np.ndarray, P: np.ndarray, u: np.ndarray, q: np.ndarray, dt: float):
    """The own-navigation filters' time update: new ``(x, P)`` from odometry ``u`` (N, 2) and variances ``q`` (N, 2)."""
    import estimators.ukf_relay_se2 as se2

    new, F, G = se2.motion(x, u, dt)
    P = F @ P @ np.swapaxes(F, -1, -2) + np.einsum("nab,nb,ncb->nac", G, q, G)
    return new, 0.5 * (P + np.swapaxes(P, -1, -2))


def own_navigation(d: MrclamData, model: NoiseModel, x0: np.ndarray, initial_std: float = OWN_NAV_INITIAL_STD):
    """Per-robot UKF on (x, y, theta), odometry + its own landmark sightings only (no robot-robot data).

    Returns poses (T, N, 3) and covariances (T, N, 3, 3) after the step's updates, and
    ``accepted`` (n_meas,) bool: landmark sightings the gate let in (robot-robot entries False).
    """
    u = model.odometry(d, np.arange(d.steps))
    q = model.odometry_var(u)
    x = np.array(x0, float)
    N = len(x)
    P = np.broadcast_to(np.eye(3) * initial_std**2, (N, 3, 3)).copy()
    poses, covs = np.empty((d.steps, N, 3)), np.empty((d.steps, N, 3, 3))
    accepted = np.zeros(len(d.meas_step), bool)
    for k in range(d.steps):
        own_nav_update(d, model, k, x, P, accepted)
        poses[k], covs[k] = x, P
        x, P = own_nav_predict(x, P, u[k], q[k], d.dt)
    return poses, covs, accepted


def _navigation_key(d: MrclamData, model: NoiseModel, x0: np.ndarray, initial_std: float) -> str:
    """Digest of what ``own_navigation`` reads (the run's odometry and sightings, the noise model, the start) and
    of its code (this module's source and the SE(2) filter's, ``estimators.ukf_relay_se2``)."""
    import dataclasses
    import hashlib
    import inspect

    import estimators.ukf_relay_se2 as se2
    from coloc_env.data import mrclam_noise

    h = hashlib.sha256()
    for array in (d.odometry, d.landmarks, d.meas_step, d.meas_robot, d.meas_subject, d.meas_range,
                  d.meas_bearing, np.asarray(x0, float)):
        h.update(np.ascontiguousarray(array).tobytes())
    fields = [(f.name, getattr(model, f.name)) for f in dataclasses.fields(model) if f.compare]
    h.update(repr((fields, d.dt, d.steps, float(initial_std))).encode())
    for module in (sys.modules[__name__], se2, mrclam_noise):
        try:
            h.update(inspect.getsource(module).encode())
        except (OSError, TypeError):  # an installation without sources: the module's name alone
            h.update(module.__name__.encode())
    return h.hexdigest()


def cached_own_navigation(d: MrclamData, model: NoiseModel, x0: np.ndarray,
                          initial_std: float = OWN_NAV_INITIAL_STD, cache_dir=None):
    """``own_navigation``, read from the on-disk cache (``coloc_env.data.fit_cache.cached_arrays``, keyed by a
    digest of its inputs and code) where an earlier process stored it: the same arrays, bit for bit."""
    from coloc_env.data import fit_cache

    steps, robots = d.steps, len(np.asarray(x0))

    def compute() -> dict:
        poses, covs, accepted = own_navigation(d, model, x0, initial_std)
        return {"poses": poses, "covs": covs, "accepted": accepted}

    def sound(arrays: dict) -> bool:
        return (set(arrays) == {"poses", "covs", "accepted"} and arrays["poses"].shape == (steps, robots, 3)
                and arrays["covs"].shape == (steps, robots, 3, 3) and arrays["accepted"].shape == d.meas_step.shape
                and bool(np.all(np.isfinite(arrays["poses"])) and np.all(np.isfinite(arrays["covs"]))))

    arrays = fit_cache.cached_arrays("mrclam-navigation", _navigation_key(d, model, x0, initial_std), compute,
                                     sound, cache_dir)
    return arrays["poses"], arrays["covs"], arrays["accepted"]
