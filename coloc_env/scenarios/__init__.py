"""Scenario registry: one module per paper setting.

Every module of this package is imported here, and each preset registers itself with
``coloc_env.scenarios.binding.register_preset``; ``REGISTRY`` is that registry (name -> scenario class).
A new preset is a new module: no list here is edited. The order of ``REGISTRY`` (and of
``coloc_env.SCENARIOS``) follows the tuple below, then the remaining presets alphabetically.
"""

from coloc_env.parts_discovery import import_parts
from coloc_env.scenarios.binding import PRESET_SCENARIOS

import_parts(__name__, __path__, ("bandwidth_fusion", "lossy_fusion", "relay_ukf", "gps_denied_nbp", "nlos_horizon",
                                   "mrclam_relay"))

REGISTRY = PRESET_SCENARIOS

__all__ = ["REGISTRY"]
