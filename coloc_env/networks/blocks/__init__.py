"""The building blocks networks are assembled from: links, delays, budgets, the broadcast medium and relay chains.

Each block is a small validated config dataclass with batched numpy methods (leading batch axis B) that
draws only from the ``numpy.random.Generator`` it is handed. A block knows nothing of the networks that use
it: it imports only ``coloc_env.config`` (the checks), other network blocks and ``estimators``. Backends
read two of them, since they consume what a network delivers: a relay chain's record (``RelayChain``) and
the delay code of a packet never sent (``bounded_delay.NEVER``).
"""

from coloc_env.networks.blocks.delay_links import BernoulliDelayLink
from coloc_env.networks.blocks.links import BandwidthBudget
from coloc_env.networks.blocks.relay_chain import RelayChain, RelayChainLinks

__all__ = ["BandwidthBudget", "BernoulliDelayLink", "RelayChain", "RelayChainLinks"]
