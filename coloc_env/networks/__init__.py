"""Networks: who can send what to whom, what arrives, and what it cost. ``coloc_env.NETWORKS`` lists them.

Every module of this package is imported (and so registers its network) when the package loads.
"""

from coloc_env.parts import NETWORKS
from coloc_env.parts_discovery import import_parts

import_parts(__name__, __path__, ("ideal", "bernoulli_delay", "bandwidth", "relay", "broadcast", "random_delay"))

from coloc_env.networks.bandwidth import Bandwidth  # noqa: E402
from coloc_env.networks.bernoulli_delay import BernoulliDelay  # noqa: E402
from coloc_env.networks.broadcast import Broadcast  # noqa: E402
from coloc_env.networks.contention import Contention  # noqa: E402
from coloc_env.networks.gilbert_elliott import GilbertElliott  # noqa: E402
from coloc_env.networks.ideal import Ideal  # noqa: E402
from coloc_env.networks.random_delay import RandomDelay  # noqa: E402
from coloc_env.networks.relay import Relay  # noqa: E402

__all__ = ["NETWORKS", "Bandwidth", "BernoulliDelay", "Broadcast", "Contention", "GilbertElliott", "Ideal",
           "RandomDelay", "Relay"]
