"""Primitives the worlds and networks are built from: motion models, sensors and links.

Each part is a small validated config dataclass with batched numpy methods
(leading batch axis B). Randomness only from ``numpy.random.Generator``
objects passed in.
"""

from coloc_env.primitives.delay_links import BernoulliDelayLink
from coloc_env.primitives.links import BandwidthBudget
from coloc_env.primitives.motion import LinearMotion
from coloc_env.primitives.odometry import OdometrySensor, RangeSensor
from coloc_env.primitives.relay import RelayChain, RelayChainLinks
from coloc_env.primitives.sensors import LinearSensor
from coloc_env.primitives.target import ConstantVelocityTarget
from coloc_env.primitives.unicycle import CircularTracks, UnicycleMotion

__all__ = ["BandwidthBudget", "BernoulliDelayLink", "CircularTracks", "ConstantVelocityTarget", "LinearMotion",
           "LinearSensor", "OdometrySensor", "RangeSensor", "RelayChain", "RelayChainLinks", "UnicycleMotion"]
