"""World parts shared by the scenarios: motion models, sensors and links.

Each part is a small validated config dataclass with batched numpy methods
(leading batch axis B). Randomness only from ``numpy.random.Generator``
objects passed in.
"""

from coloc_env.world.delay_links import BernoulliDelayLink
from coloc_env.world.links import BandwidthBudget
from coloc_env.world.motion import LinearMotion
from coloc_env.world.odometry import OdometrySensor, RangeSensor
from coloc_env.world.relay import RelayChain, RelayChainLinks
from coloc_env.world.sensors import LinearSensor
from coloc_env.world.target import ConstantVelocityTarget
from coloc_env.world.unicycle import CircularTracks, UnicycleMotion

__all__ = ["BandwidthBudget", "BernoulliDelayLink", "CircularTracks", "ConstantVelocityTarget", "LinearMotion",
           "LinearSensor", "OdometrySensor", "RangeSensor", "RelayChain", "RelayChainLinks", "UnicycleMotion"]
