"""Deprecated: the bound models moved to ``coloc_env.bounds.models`` (this path imports them from there, with a
``DeprecationWarning``, for one release). What a backend's messages carry is its declaration
(``message_content``, ``shared_estimate``: ``coloc_env.backends.base``); the name sets below are read from it."""

from __future__ import annotations

import sys
import warnings

from coloc_env.bounds.models import MODELS as _MODELS
from coloc_env.bounds.models import (
    bound_problem,
    circles,
    gps_denied,
    mrclam,
    mrclam_slices,
    nlos_orbit,
    stand_in,
    target,
)
from coloc_env.bounds.problem import CENTRE, centre_received, with_delivered
from coloc_env.parts import BACKENDS

warnings.warn("coloc_env.bound_models is deprecated; use coloc_env.bounds.models", DeprecationWarning, stacklevel=2)

for _module in (circles, gps_denied, mrclam, mrclam_slices, nlos_orbit, target):
    sys.modules[f"{__name__}.{_module.__name__.rsplit('.', 1)[1]}"] = _module

MODULES = {world: module.__name__.rsplit(".", 1)[1] for world, module in _MODELS.items()}
READING_PACKETS = frozenset(name for name, cls in BACKENDS.items() if cls.message_content == "readings")
SHARED_AT_LEADER = frozenset(name for name, cls in BACKENDS.items() if cls.shared_estimate)
NOTHING_SENT = frozenset(name for name, cls in BACKENDS.items() if cls.message_content == "nothing")


def delivered_kind(backend_name: str) -> str:
    """The backend's declared ``message_content``: ``"readings"``, ``"nothing"`` or ``"estimates"``."""
    return BACKENDS[backend_name].message_content


__all__ = ["CENTRE", "MODULES", "NOTHING_SENT", "READING_PACKETS", "SHARED_AT_LEADER", "bound_problem",
           "centre_received", "delivered_kind", "stand_in", "with_delivered"]
