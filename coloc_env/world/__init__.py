"""World parts shared by the scenarios: motion models, sensors and links.

Each part is a small validated config dataclass with batched numpy methods
(leading batch axis B). Randomness only from ``numpy.random.Generator``
objects passed in.
"""

from coloc_env.world.links import BandwidthBudget
from coloc_env.world.motion import LinearMotion
from coloc_env.world.sensors import LinearSensor

__all__ = ["BandwidthBudget", "LinearMotion", "LinearSensor"]
