"""Backends: one adapter per estimator of :mod:`estimators`. ``coloc_env.BACKENDS`` lists them."""

from coloc_env.backends.dead_reckoning import DeadReckoning
from coloc_env.backends.particles import Dnbp, RangeLs  # noqa: F401 (registers them)
from coloc_env.backends.ukf import UkfCcl, UkfDcl
from coloc_env.parts import BACKENDS

__all__ = ["BACKENDS", "DeadReckoning", "UkfCcl", "UkfDcl"]
