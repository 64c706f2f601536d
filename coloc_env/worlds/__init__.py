"""Worlds: truth and sensors, batched. ``coloc_env.WORLDS`` lists the registered names."""

from coloc_env.parts import WORLDS
from coloc_env.worlds.circles import Circles
from coloc_env.worlds.gps_denied import GpsDenied as GpsDenied

__all__ = ["WORLDS", "Circles"]
