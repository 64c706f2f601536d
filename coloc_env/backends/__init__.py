"""Backends: one adapter per estimator of ``estimators``. ``coloc_env.BACKENDS`` lists them.

Every module of this package is imported (and so registers its backends) when the package loads.
"""

from coloc_env.parts import BACKENDS
from coloc_env.parts_discovery import import_parts

import_parts(__name__, __path__, ("fusion", "kalman", "ukf", "ukf_se2", "particles", "nlos", "dead_reckoning"))

from coloc_env.backends.dead_reckoning import DeadReckoning  # noqa: E402
from coloc_env.backends.fusion import BandwidthFusion, CentralizedLmmse, PredictionCompensation  # noqa: E402
from coloc_env.backends.kalman import Kalman  # noqa: E402
from coloc_env.backends.nlos import Afge, DelayKalman, Dfir  # noqa: E402
from coloc_env.backends.particles import Dnbp, RangeLs  # noqa: E402
from coloc_env.backends.ukf import UkfCcl, UkfDcl  # noqa: E402
from coloc_env.backends.ukf_se2 import UkfSe2  # noqa: E402

__all__ = ["BACKENDS", "Afge", "BandwidthFusion", "CentralizedLmmse", "DeadReckoning", "DelayKalman", "Dfir", "Dnbp",
           "Kalman", "PredictionCompensation", "RangeLs", "UkfCcl", "UkfDcl", "UkfSe2"]
