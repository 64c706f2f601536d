"""The building blocks worlds are assembled from: motion models and sensors.

Each block is a small validated config dataclass with batched numpy methods (leading batch axis B) that
draws only from the ``numpy.random.Generator`` it is handed. A block knows nothing of the worlds that use it:
it imports only ``coloc_env.config`` (the checks), other world blocks and ``estimators``.
"""

from coloc_env.worlds.blocks.motion import LinearMotion
from coloc_env.worlds.blocks.odometry import OdometrySensor, RangeSensor
from coloc_env.worlds.blocks.sensors import LinearSensor
from coloc_env.worlds.blocks.target import ConstantVelocityTarget
from coloc_env.worlds.blocks.unicycle import CircularTracks, UnicycleMotion

__all__ = ["CircularTracks", "ConstantVelocityTarget", "LinearMotion", "LinearSensor", "OdometrySensor",
           "RangeSensor", "UnicycleMotion"]
