"""Network ``gilbert_elliott``: ``broadcast``'s medium with bursty loss, a two-state Markov chain per directed link.

Gilbert (1960), Elliott (1963): each directed link t -> s (and each world node -> agent link) is in a
*good* or a *bad* state; a message over it is lost with ``loss_good`` in the good state and ``loss_bad``
in the bad one. Between steps the state moves good -> bad with p = ``p_good_to_bad`` and bad -> good with
r = ``p_bad_to_good``, every step, whether the link carries a message or not; at step 0 each link draws its
state from the chain's stationary distribution. Everything else is ``broadcast``'s (the range limit, the
``transmit`` decisions, the message kinds, the accounting of ``coloc_env.networks.base``).

| quantity   | value                                                                                     |
|------------|-------------------------------------------------------------------------------------------|
| carries    | ``broadcast``, ``central``, ``packets``, ``chain`` (chains relay nearest first, in range) |
| decisions  | ``transmit`` MultiDiscrete([2] * rounds) per agent: broadcast in each round or not         |
| always     | broadcast at every opportunity                                                            |
| silent     | never broadcast                                                                           |
| loss       | a message over link t -> s at step k is lost iff u < loss(state_k(t, s)), u the uniform   |
|            | ``broadcast`` draws for it (the same counters: with every link good it is ``broadcast``   |
|            | with ``loss = loss_good``, message for message)                                           |
| state      | hidden from the agents; a sender observes it only through its acknowledgements            |
| observation| ``ack`` (N,) per agent (``kind`` broadcast, central, packets, chain): 1 for each receiver  |
|            | that its message (a hop of a chain) reached in the last step, 0 otherwise (0 at reset)    |
| statistics | ``slot_probabilities``: (1 - L within range, 0) per link, what an estimator that assumes  |
|            | i.i.d. slots (fu2017's ``kalman``, ``centralized_lmmse``) is told: not the bursts         |

Closed forms (pi_B = p / (p + r), pi_G = 1 - pi_B, lambda = 1 - p - r, one message per link and step)

| quantity                         | value                                                                |
|----------------------------------|----------------------------------------------------------------------|
| stationary loss rate L           | pi_G loss_good + pi_B loss_bad                                       |
| mean bad-state sojourn (burst)   | 1 / r steps (geometric); the good state's 1 / p                     |
| P(lost at k and at k + 1) = P11  | L^2 + pi_G pi_B (loss_bad - loss_good)^2 lambda                      |
| lag-1 loss correlation rho       | pi_G pi_B (loss_bad - loss_good)^2 lambda / (L (1 - L))             |
| mean run of consecutive losses   | L / (L - P11) (a stationary 0/1 sequence has L - P11 run ends per   |
|                                  | step); = 1 / r when loss_good = 0 and loss_bad = 1 (Gilbert's model) |

Derivation: the state sequence is a stationary Markov chain with transition matrix T = [[1 - p, p],
[r, 1 - r]], whose eigenvalues are 1 and lambda, so P(bad at k + 1 | bad at k) - P(bad at k + 1 | good
at k) = lambda and Cov(bad_k, bad_{k+1}) = pi_G pi_B lambda; given the states, the losses are independent
with probabilities loss(state), so E[lost_k lost_{k+1}] = L^2 + (loss_bad - loss_good)^2 pi_G pi_B lambda.
With loss_good = loss_bad the losses are Bernoulli(L) (rho = 0). The forms are the per-link rates of
``link_deliveries / link_attempts`` (1 - L) when a link carries one message per step.

Draws (counter-based, ``coloc_env.draws``): link t -> s's state at step k is a function of the episode's
key, the link and k only: its stationary draw is the uniform of counters (0, ``CHAIN_STREAM``, 0) at cell
(t, s), and its move into step k >= 1 the uniform of (k, ``CHAIN_STREAM``, 0) (world node links:
``NODE_CHAIN_STREAM``, cell (agent, node)). The network keeps each copy's state at the last step asked for
and moves it forward from there, so no delivery call, round, receive-ahead pass, bound recording or
copy's reset moves a chain twice, and copies never share one: copy b of a batch is copy b run alone.

Arguments (``coloc_env.networks.GilbertElliott``)

| field         | default | allowed                                                                    |
|---------------|---------|----------------------------------------------------------------------------|
| comm_range    | 200     | (0, inf] m (as ``broadcast``)                                              |
| loss_good     | 0.0     | [0, 1] loss probability per message in the good state                      |
| loss_bad      | 0.9     | [0, 1] loss probability per message in the bad state                       |
| p_good_to_bad | 0.05    | [0, 1] per step; p_good_to_bad + p_bad_to_good > 0                         |
| p_bad_to_good | 0.2     | [0, 1] per step (mean burst 1 / p_bad_to_good steps); the sum > 0          |

The defaults: pi_B = 0.2, mean burst 5 steps, L = 0.18, P11 = 0.1296, rho = 0.66, mean loss run 3.57 steps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import BadInput, check_distance
from coloc_env.draws import uniforms
from coloc_env.networks.base import NODE_STREAM, Network
from coloc_env.networks.broadcast import Broadcast, BroadcastNetwork
from coloc_env.parts import NETWORKS, PartConfig, check_range

CHAIN_STREAM = 4  # counter stream of the agent links' states (broadcast 0, relay 1, packets 2, world nodes 3)
NODE_CHAIN_STREAM = 5  # counter stream of the world node -> agent links' states
ACK_KINDS = ("broadcast", "central", "packets", "chain")


@NETWORKS.register
@dataclass(frozen=True)
class GilbertElliott(PartConfig):
    """Config of the ``gilbert_elliott`` network (see the module table)."""

    name = "gilbert_elliott"
    carries = Broadcast.carries  # broadcast whose losses come in bursts: the same message kinds
    comm_range: float = 200.0
    loss_good: float = 0.0
    loss_bad: float = 0.9
    p_good_to_bad: float = 0.05
    p_bad_to_good: float = 0.2

    def check(self, prefix: str) -> None:
        check_distance(f"{prefix}comm_range", self.comm_range)
        check_range(f"{prefix}loss_good", self.loss_good, 0.0, 1.0)
        check_range(f"{prefix}loss_bad", self.loss_bad, 0.0, 1.0)
        check_range(f"{prefix}p_good_to_bad", self.p_good_to_bad, 0.0, 1.0)
        check_range(f"{prefix}p_bad_to_good", self.p_bad_to_good, 0.0, 1.0)
        if not float(self.p_good_to_bad) + float(self.p_bad_to_good) > 0.0:
            raise BadInput(f"{prefix}p_good_to_bad + {prefix}p_bad_to_good must be > 0 (the chain starts from its "
                           f"stationary distribution, which needs a transition), got {self.p_good_to_bad!r} and "
                           f"{self.p_bad_to_good!r}")

    @property
    def bad_probability(self) -> float:
        """pi_B = p_good_to_bad / (p_good_to_bad + p_bad_to_good), the stationary probability of the bad state."""
        return float(self.p_good_to_bad) / (float(self.p_good_to_bad) + float(self.p_bad_to_good))

    def closed_forms(self) -> dict[str, float]:
        """The module's closed forms: ``loss_rate`` L, ``burst`` 1 / r (inf for r = 0), ``both_lost`` P11,
        ``correlation`` rho (0 where L is 0 or 1) and ``loss_run`` L / (L - P11) (nan where L is 0)."""
        bad = self.bad_probability
        good = 1.0 - bad
        lg, lb = float(self.loss_good), float(self.loss_bad)
        lam = 1.0 - float(self.p_good_to_bad) - float(self.p_bad_to_good)
        rate = good * lg + bad * lb
        cov = good * bad * (lb - lg) ** 2 * lam
        both = rate * rate + cov
        r = float(self.p_bad_to_good)
        return {"loss_rate": rate, "burst": 1.0 / r if r > 0 else float("inf"), "both_lost": both,
                "correlation": cov / (rate * (1.0 - rate)) if 0.0 < rate < 1.0 else 0.0,
                "loss_run": rate / (rate - both) if rate > both else float("nan")}

    def build(self, num_agents: int, batch: int, message_kind: str, rounds: int = 1) -> Network:
        return GilbertElliottNetwork(self, num_agents, batch, message_kind, rounds)


class _Chains:
    """The link states (B, *shape) bool (True = bad) of every copy at step ``at`` (B,) (-1: none yet)."""

    def __init__(self, batch: int, shape: tuple[int, ...], stream: int):
        self.shape, self.stream = shape, stream
        self.bad = np.zeros((batch, *shape), dtype=bool)
        self.at = np.full(batch, -1, dtype=np.int64)

    def states(self, keys: np.ndarray, k: np.ndarray, bad_probability: float, p: float, r: float) -> np.ndarray:
        """The states at each copy's step k (B,): moved forward from the kept step (from the stationary draw at
        step 0 where none is kept or k is before it); a loop over the steps moved, never over copies."""
        back = k < self.at
        self.at[back] = -1
        start = np.flatnonzero(self.at < 0)
        if start.size:
            self.bad[start] = uniforms(keys[start], (0, self.stream, 0), self.shape) < bad_probability
            self.at[start] = 0
        while True:
            rows = np.flatnonzero(self.at < k)
            if not rows.size:
                return self.bad
            step = self.at[rows] + 1
            v = uniforms(keys[rows], (step, self.stream, 0), self.shape)
            self.bad[rows] = np.where(self.bad[rows], v >= r, v < p)
            self.at[rows] = step


class GilbertElliottNetwork(BroadcastNetwork):
    """``broadcast`` whose per-message loss probability is the link's state's at this step."""

    loss_reads_links = True

    def __init__(self, config: GilbertElliott, num_agents, batch, message_kind, rounds=1):
        super().__init__(config, num_agents, batch, message_kind, rounds)
        self._chains: dict[tuple, _Chains] = {}

    def reset(self, rngs, idx) -> None:
        super().reset(rngs, idx)
        for chains in self._chains.values():
            chains.at[idx] = -1  # a new key: the copies' chains start again at their stationary draw

    def link_bad(self, nodes: int | None = None) -> np.ndarray:
        """(B, N, N) bool [t, s]: link t -> s is bad at this step (``nodes`` = J: the (B, N, J) world node ->
        agent links instead). Hidden from the agents."""
        shape = (self.num_agents, self.num_agents) if nodes is None else (self.num_agents, int(nodes))
        stream = CHAIN_STREAM if nodes is None else NODE_CHAIN_STREAM
        chains = self._chains.get((stream, shape))
        if chains is None:
            chains = self._chains[(stream, shape)] = _Chains(self.batch, shape, stream)
        k = np.broadcast_to(np.asarray(self._k, dtype=np.int64), (self.batch,))
        c = self.config
        return chains.states(self.keys, k, c.bad_probability, float(c.p_good_to_bad), float(c.p_bad_to_good))

    def loss_probability(self, distance):
        """The loss probability of every link at this step by its state: ``distance`` (B, N, N) for the agents'
        links, (B, N, J) for the world nodes' (``node_packets``)."""
        shape = np.shape(distance)
        node = self._stream == NODE_STREAM
        if shape != ((self.batch, self.num_agents, shape[-1]) if node and len(shape) == 3
                     else (self.batch, self.num_agents, self.num_agents)):
            raise ValueError(f"gilbert_elliott: a link's loss depends on its state; ask with the (B, N, N) = "
                             f"{(self.batch, self.num_agents, self.num_agents)} distances, got shape {shape}")
        bad = self.link_bad(shape[-1] if node else None)
        return np.where(bad, float(self.config.loss_bad), float(self.config.loss_good))

    def slot_probabilities(self, distance) -> tuple[np.ndarray, np.ndarray]:
        """(alpha1, alpha2) per link at ``distance``, what an estimator that assumes i.i.d. slots (fu2017's)
        is told: the stationary delivery rate 1 - L within ``comm_range``, 0 beyond; no delays."""
        delivered = np.where(self.usable(distance), 1.0 - self.config.closed_forms()["loss_rate"], 0.0)
        return delivered, np.zeros(np.shape(distance))

    def observation_size(self) -> int:
        return self.num_agents if self.message_kind in ACK_KINDS else 0

    def observation_features(self) -> np.ndarray:
        """``ack``: (B, N, N) [t, s] 1 where t's message (or hop) of the last step reached s."""
        if not self.observation_size():
            return super().observation_features()
        return self.delivered.astype(float)

    def acknowledged(self) -> np.ndarray | None:
        """(B, N): its ``ack`` of this step names a receiver; None where the message kind has no ``ack``."""
        return self.delivered.any(axis=-1) if self.observation_size() else None
