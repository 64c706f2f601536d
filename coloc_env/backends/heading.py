"""The motion model a joint UKF backend (``ukf_ccl`` / ``ukf_dcl``) runs on a world's odometry.

``motion="heading"`` (the default): on a world whose motion kind is
``odometry_displacement`` and whose turn-rate readings are noisy
(``world.turn_rate_noise_var()`` > 0), the filter carries each platform's heading
error in its state (``estimators.heading_models.OdometryHeadingError``), so the
time-correlated displacement errors of an integrated heading are modelled.
``motion="displacement"``: the world's position-only model
(``estimators.models.OdometryDisplacement``, wang2019's). Where the heading
error is identically zero (no turn-rate noise, or a world that declares none, or
the world's model deliberately omits it: ``circles`` with ``heading_noise=False``)
both choices are the same filter and the position-only one runs. Other motion kinds
are used as the world gives them.
"""

from __future__ import annotations

from estimators.heading_models import OdometryHeadingError

MOTIONS = ("heading", "displacement")


def ukf_motion_model(motion: str, world):
    """The model the joint UKF predicts with (see the module docstring)."""
    base = world.motion_model
    if motion == "displacement" or base.kind != "odometry_displacement":
        return base
    turn_rate_var = float(world.turn_rate_noise_var()) if hasattr(world, "turn_rate_noise_var") else 0.0
    if turn_rate_var <= 0.0:
        return base
    return OdometryHeadingError(base.dt, base.speed_var, turn_rate_var)
