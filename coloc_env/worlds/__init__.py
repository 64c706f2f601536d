"""Worlds: truth and sensors, batched. ``coloc_env.WORLDS`` lists the registered names.

Every module of this package is imported (and so registers its world) when the package loads.
"""

from coloc_env.parts import WORLDS
from coloc_env.parts_discovery import import_parts

import_parts(__name__, __path__, ("drift", "target_cv", "circles", "gps_denied", "nlos_orbit", "mrclam",
                                   "mrclam_slices"))

from coloc_env.worlds.circles import Circles  # noqa: E402
from coloc_env.worlds.drift import Drift  # noqa: E402
from coloc_env.worlds.gps_denied import GpsDenied  # noqa: E402
from coloc_env.worlds.mrclam import Mrclam  # noqa: E402
from coloc_env.worlds.mrclam_slices import MrclamSlices  # noqa: E402
from coloc_env.worlds.nlos_orbit import NlosOrbit  # noqa: E402
from coloc_env.worlds.target_cv import TargetCv  # noqa: E402

__all__ = ["WORLDS", "Circles", "Drift", "GpsDenied", "Mrclam", "MrclamSlices", "NlosOrbit", "TargetCv"]
