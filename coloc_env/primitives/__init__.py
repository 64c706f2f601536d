"""Deprecated: the building blocks moved to ``coloc_env.worlds.blocks`` and ``coloc_env.networks.blocks``.

``coloc_env.primitives`` and its modules stay importable for one release (user scripts and pickled objects
that name the old paths); importing them warns. ``MOVED`` maps each old module to its new one.
"""

import importlib
import sys
import warnings

MOVED = {
    **{name: f"coloc_env.worlds.blocks.{name}" for name in (
        "cv_uav", "flight", "gps_markov", "los_nlos", "motion", "noise", "odometry", "radio", "range_network",
        "sensors", "target", "unicycle")},
    **{name: f"coloc_env.networks.blocks.{name}" for name in ("broadcast_medium", "delay_links", "links")},
    "random_delay": "coloc_env.networks.blocks.bounded_delay",
    "relay": "coloc_env.networks.blocks.relay_chain",
}

warnings.warn("coloc_env.primitives is deprecated: import the blocks from coloc_env.worlds.blocks and "
              "coloc_env.networks.blocks (coloc_env.primitives.MOVED maps each module)", DeprecationWarning,
              stacklevel=2)

for _old, _new in MOVED.items():  # `import coloc_env.primitives.relay` finds the module and the attribute
    sys.modules[f"{__name__}.{_old}"] = globals()[_old] = importlib.import_module(_new)

from coloc_env.networks.blocks import BandwidthBudget, BernoulliDelayLink, RelayChain, RelayChainLinks  # noqa: E402
from coloc_env.worlds.blocks import (  # noqa: E402
    CircularTracks,
    ConstantVelocityTarget,
    LinearMotion,
    LinearSensor,
    OdometrySensor,
    RangeSensor,
    UnicycleMotion,
)

__all__ = ["MOVED", "BandwidthBudget", "BernoulliDelayLink", "CircularTracks", "ConstantVelocityTarget",
           "LinearMotion", "LinearSensor", "OdometrySensor", "RangeSensor", "RelayChain", "RelayChainLinks",
           "UnicycleMotion"]
