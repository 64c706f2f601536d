"""Networks: who can send what to whom, what arrives, and what it cost. ``coloc_env.NETWORKS`` lists them."""

from coloc_env.networks.broadcast import Broadcast
from coloc_env.networks.ideal import Ideal
from coloc_env.networks.relay import Relay
from coloc_env.parts import NETWORKS

__all__ = ["NETWORKS", "Broadcast", "Ideal", "Relay"]
