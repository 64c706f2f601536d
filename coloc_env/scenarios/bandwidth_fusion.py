"""``bandwidth_fusion``: bandwidth-limited distributed fusion (Zhao et al. 2020).

Paper: Zhao, Liu, Zhao, Gao, "A distributed fusion estimator with bandwidth
limitation for clustered UAVs' position and attitude estimation", Electronics
Optics & Control 27(4), 2020 (seed ``001_c743ba0d1c0e3ecf.txt``); estimator in
``estimators.bandwidth_fusion``.

N UAVs (the fusion nodes) estimate one position x in R^3 that moves with a
constant drift, x(k+1) = A x(k) + B + w(k), each from its own linear
measurement y_j(k) = C x(k) + v_j(k) (the paper linearizes UWB ranges to four
anchors into C = I). Every step each node forms an intermediate estimate
lambda_j; receiver i may take only ``budget`` components in total from its
neighbours' intermediate estimates (at least ``min_per_link`` and at most
``max_per_link`` from each), fills the rest with its own prediction and fuses
with weights p_ij. The agents choose what the paper fixes by hand: the
component selection T and the fusion weights p.

The preset is the composition ``drift`` / ``bandwidth`` / ``bandwidth_fusion``
(``BandwidthFusionConfig.parts``: each keyword sets the part field named in
the Arguments table) with this action codec, observation, reward and info.
The world draws the episode (x(0), w, v_j) from the episode's generator
itself (``coloc_env.worlds.drift.draw_episode``); the bandwidth network
delivers every selected component on time and draws nothing. The paper's
tables T1..T3 and P1..P3 are ``estimators.bandwidth_fusion.paper_selection``
and ``paper_weights`` (also importable from here).

Timing: the backend reports xhat_i(k) at step k (the composition's pairing
of J_K); the preset reports, after step k, the estimate xhat_i(k+1) it has
just formed with y(k), against x(k+1), so that the reward credits a step's
selection and weights at once (the same sequence of estimates, one step
earlier than the composition's).

Action (one per receiver, the same Box for all agents)
------------------------------------------------------
``Box(-1, 1, shape=((N-1)*n + N,), float64)``; neighbours are indexed relative
to the receiver (neighbour k of ``uav_i`` is ``uav_{(i+1+k) mod N}``).

| slice                   | meaning                                                                 |
|-------------------------|-------------------------------------------------------------------------|
| ``[0, (N-1)*n)``        | score of (neighbour k, component c) at ``k*n + c``. Decoded to the      |
|                         | feasible selection with the highest total score (argmax over the 108    |
|                         | feasible selections of the paper's setting; ties go to the first in     |
|                         | ``BandwidthBudget.feasible`` order). Every feasible selection is    |
|                         | reachable: scores +1 selected / -1 not decode back to it exactly.       |
|                         | Beyond 2,048 selections found by ``BandwidthBudget.best_selection``,|
|                         | a dynamic programme over links (the same argmax, ties included, without |
|                         | listing the ~7e11 selections of N = 16), so every N in 2..16 decodes    |
|                         | the same way.                                                           |
| ``[(N-1)*n, (N-1)*n+N)``| fusion-weight logits for [self, neighbour 0, ..., neighbour N-2];       |
|                         | p_i = softmax(``weight_logit_scale`` * a). A weight is never exactly 0. |

Out-of-range actions are clipped to [-1, 1]; a NaN or inf is a ``ValueError``.

Observation (per agent, ``Box(shape=(n + (N-1)*n + 1 + N + 1,), float32)``)
--------------------------------------------------------------------------
| index                    | meaning                                                      | bounds    |
|--------------------------|--------------------------------------------------------------|-----------|
| ``[0, n)``               | log of the diagonal of the node's own bound matrix M_i(k)    | unbounded |
|                          | (eq. 19; local: it needs only the neighbours' M, which the   |           |
|                          | paper assumes known). Log because M can grow like 1.5^k.     |           |
| ``[n, n + (N-1)*n)``     | steps since each (neighbour, component) was last received,   | [0, 1]    |
|                          | divided by the horizon (0 at reset: all nodes start equal)   |           |
| ``[n + (N-1)*n]``        | step fraction k / horizon                                    | [0, 1]    |
| then ``N`` entries       | ``index``: one-hot of the node's own index                   | [0, 1]    |
| ``[-1]``                 | ``communication_cost``: its copy's cost per message this     | [0, inf)  |
|                          | episode (``communication_cost``, or the draw from            |           |
|                          | ``cost_range``), m^2                                         |           |

The log-diagonal is unbounded: a selection that starves a component lets M_i grow without limit
(like 1.5^k), and a well-fed one shrinks it towards 0.

``state()`` (centralized critic): every agent's observation, then
log diag Sigma_i(k) of the exact error covariance of every node.

Reward (per agent: each node has its own estimate)
--------------------------------------------------
| ``reward=``  | value after step k -> k+1 (m^2, the unit of ``error``)                   |
|--------------|--------------------------------------------------------------------------|
| ``"error"``  | -||xhat_i(k+1) - x(k+1)||^2 (m^2): minus the ``error`` info key          |
| ``"trace"``  | -tr Sigma_i(k+1) (m^2): the exact covariance of that error (noise-free,  |
|              | its expectation), minus the ``trace`` info key                           |

both minus ``component_cost`` per component the node received this step
(``components_received``; the receiver chooses them) and minus
``communication_cost`` (under ``cost_range``, its copy's draw of the episode)
per message it sent (``messages_sent``: one per receiver that took a component
of it), each in m^2.

Minus the sum over agents of an episode's return (k = 1..50) plus the k = 0
term sum_i tr M(0) = 1.44 is the paper's J_50 (eq. 12) for one realization.

Termination: none; truncation after ``horizon`` steps (the paper's 50).

``infos[agent]`` (after step k: time k+1; at reset: time 0)
-------------------------------------------------------------
| key                    | meaning                                                                 |
|------------------------|-------------------------------------------------------------------------|
| ``true_position``      | x(k+1) (n,), m (the paper's state is the 3-D position); the same for all|
| ``estimated_position`` | the node's xhat_i(k+1) (n,), m                                          |
| ``position_error``     | ||xhat_i(k+1) - x(k+1)|| (m), the distance of the estimate              |
| ``error``              | its square (m^2), the summand of J_K (eq. 12); the episode metric sums  |
|                        | it over the steps and nodes                                             |
| ``trace``              | tr Sigma_i(k+1) (m^2): the node's exact error covariance (the paper's   |
|                        | (10); the state is the position), the same as ``trace_error``           |
| ``trace_error``        | tr Sigma_i(k+1) (m^2)                                                   |
| ``bound_trace``        | tr M_i(k+1) (m^2), the node's own bound (eq. 19)                        |
| ``components_received``| components the node took from its neighbours this step (0 at reset)    |
| ``communication``      | the same count as a float (what ``coloc evaluate`` reports)             |
| ``messages_sent``      | messages the node sent this step, as the network counts them: one per   |
|                        | receiver that takes a component of it                                   |
| ``floats_sent``        | their floats: the components its receivers took from it                 |
| ``weights``            | the node's row p_i. of fusion weights (N,), absolute order              |
| ``transmissions``,     | the network's per-link counts (``coloc_env.networks.base``'s table):    |
| ``link_attempts``,     | each link carrying a component is one transmission, attempt and         |
| ``link_deliveries``,   | delivery; ``collisions`` 0)                                             |
| ``collisions``         |                                                                         |
| ``step``               | k + 1 (0 at reset)                                                      |

Batching: every step of B copies is one set of numpy calls (stacked matmul
and solve; a single network call for all links); the only per-copy loop is at
reset, where each copy draws its whole episode's noise from its own generator.

Arguments (fields of ``BandwidthFusionConfig``, defaults = the paper)
------------------------------------------------------------------------
Each keyword sets the field of the same name of the part in ``sets``, whose
check is the one that runs (a refused value is reported as
``bandwidth_fusion: <keyword> must be ...``); ``preset``: read by this module
only.

| field              | default                | allowed                                      | sets                |
|--------------------|------------------------|----------------------------------------------|---------------------|
| num_agents         | 4                      | 2..16 (older name: ``num_uavs``)             | world               |
| transition         | I_3                    | (n, n), n in 2..16, entries in [-1e6, 1e6],  | world               |
|                    |                        | spectral radius <= 1.001                     |                     |
| drift              | (0.5, 0.5, 0.5)        | (n,), entries in [-1e6, 1e6] (m per step)    | world               |
| measurement        | I_3                    | (m, n), m in 1..16, entries in [-1e6, 1e6]   | world               |
| process_noise      | diag(0.02, 0.05, 0.03) | (n, n) PSD, entries <= 1e12 (m^2)            | world               |
| measurement_noise  | diag(0.03, 0.04, 0.02) | (m, m) or (N, m, m) PD, entries <= 1e12      | world               |
| initial_state      | (10, 10, 10)           | (n,) in [-1e6, 1e6]: xhat_i(0); x(0) ~ N(.,  | world               |
|                    |                        | M(0))                                        |                     |
| initial_cov        | diag(0.19, 0.09, 0.08) | (n, n) positive definite, entries <= 1e12:   | world (positive     |
|                    |                        | M_i(0) = Sigma_i(0) (the observation takes   | definite: preset)   |
|                    |                        | the log of its diagonal)                     |                     |
| budget             | 5                      | (N-1)*min_per_link .. (N-1)*max_per_link;    | network             |
|                    |                        | without exact_budget up to 10000             |                     |
| min_per_link       | 1                      | 0..max_per_link                              | network             |
| max_per_link       | 3                      | 0..n                                         | network             |
| exact_budget       | True                   | False: sum_j t_ji <= budget                  | network             |
| horizon            | 50                     | 1..100000                                    | world, composition  |
| reward             | "error"                | "error", "trace" (both m^2)                  | composition         |
| component_cost     | 0.0                    | [0, 1e12], m^2 per component received        | preset              |
| communication_cost | 0.0                    | [0, 1e12], m^2 per message sent              | composition         |
| cost_range         | None                   | None, or (lo, hi) with 0 <= lo <= hi <= 1e12: | composition         |
|                    |                        | each copy draws its cost per episode at reset |                     |
|                    |                        | (``coloc_env.composition``'s law), replacing |                     |
|                    |                        | ``communication_cost``                       |                     |
| weight_logit_scale | 4.0                    | (0, 1000]                                    | backend             |
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np

import estimators.bandwidth_fusion as bf
from coloc_env.backends.fusion import BandwidthFusion, fusion_model
from coloc_env.config import check_psd, check_range
from coloc_env.networks.bandwidth import ScoredBandwidth
from coloc_env.networks.blocks import BandwidthBudget
from coloc_env.rendering import Link, Scene, ring_layout
from coloc_env.scenarios.base import Scenario
from coloc_env.scenarios.binding import PresetConfig, PresetScenario, keyword, register_preset
from coloc_env.worlds.drift import Drift
from estimators.bandwidth_fusion import paper_selection, paper_weights  # noqa: F401 - the paper's tables, here too

_COMPONENT_NAMES = "xyzabcdefghijklmnop"
ENUMERATED_DECODE_LIMIT = 2048  # feasible selections up to which decoding lists them (108 in the paper's setting)


@dataclass(frozen=True)
class BandwidthFusionConfig(PresetConfig):
    """Configuration of ``bandwidth_fusion``; defaults are the paper's simulation (Sec. 2), which are the
    ``drift`` world's."""

    preset = "bandwidth_fusion"
    World, Network, Backend = Drift, ScoredBandwidth, BandwidthFusion
    aliases = {"num_uavs": "num_agents"}

    num_agents: int = keyword(4, "world.num_agents")
    transition: tuple = keyword(Drift.transition, "world.transition")
    drift: tuple = keyword(Drift.drift, "world.drift")
    measurement: tuple = keyword(Drift.measurement, "world.measurement")
    process_noise: tuple = keyword(Drift.process_noise, "world.process_noise")
    measurement_noise: tuple = keyword(Drift.measurement_noise, "world.measurement_noise")
    initial_state: tuple = keyword(Drift.initial_state, "world.initial_state")
    initial_cov: tuple = keyword(Drift.initial_cov, "world.initial_cov")
    budget: int = keyword(5, "network.budget")
    min_per_link: int = keyword(1, "network.min_per_link")
    max_per_link: int = keyword(3, "network.max_per_link")
    exact_budget: bool = keyword(True, "network.exact_budget")
    horizon: int = keyword(50, "world.horizon", "composition.horizon")
    reward: str = keyword("error", "composition.reward")
    component_cost: float = keyword(0.0, "preset")
    communication_cost: float = keyword(0.0, "composition.communication_cost")
    cost_range: tuple | None = keyword(None, "composition.cost_range")
    weight_logit_scale: float = keyword(4.0, "backend.weight_logit_scale")

    def check_preset(self) -> None:
        """What only the preset asks: M(0) positive definite (the observation takes the log of its diagonal),
        ``component_cost``, and the budget feasible for ``num_agents`` agents and n components (the network's
        own check, ``ScoredBandwidth.budget_for``, which the parts' checks cannot run without n)."""
        n = np.asarray(self.transition).shape[0]
        check_psd("initial_cov", self.initial_cov, n, strict=True)
        check_range("component_cost", self.component_cost, 0.0, 1e12)
        try:
            self.parts()[1].budget_for(self.num_agents, n, prefix="")
        except ValueError as exc:  # a range the other keywords set: name them
            raise ValueError(f"{exc} (with num_agents={self.num_agents}, min_per_link={self.min_per_link}, "
                             f"max_per_link={self.max_per_link})") from exc

    def fusion_model(self) -> bf.FusionModel:
        """The estimator's model of this system, as the backend builds it from the world's models."""
        return fusion_model(*self.parts()[0].models(), self.num_agents)


@register_preset
class BandwidthFusionScenario(PresetScenario):
    """Batched core of ``bandwidth_fusion``: the binding of ``BandwidthFusionConfig`` on the composable core
    (``drift`` / ``bandwidth`` / ``bandwidth_fusion``); the module docstring has the table."""

    name = "bandwidth_fusion"
    paper = "zhao2020"
    Config = BandwidthFusionConfig
    version = 2
    metric = "J_K: squared estimation error summed over the steps and receivers"
    metric_unit = "m^2"
    communication = "components received"
    policy_module = "agents.bandwidth_fusion"
    appended_features = ("index", "communication_cost")

    def __init__(self, config: BandwidthFusionConfig, batch: int = 1):
        super().__init__(config, batch)
        self.n = self.world.state_dim
        links = self.links
        # Up to a few thousand selections one matmul + argmax over the list is the faster decoder; beyond,
        # the dynamic programme (BandwidthBudget.best_selection). Both give the same selection (a test holds it).
        self._feasible = links.feasible if links.size <= ENUMERATED_DECODE_LIMIT else None
        self._feasible_flat = (None if self._feasible is None
                               else self._feasible.reshape(links.size, -1).astype(float))
        # built once (check_actions reads it every step); float64: the paper's weight tables must survive
        # the softmax encoding exactly (float32 loses 1e-9)
        self._preset_action_space = gymnasium.spaces.Box(-1.0, 1.0, shape=(self.action_dim,), dtype=np.float64)
        B, N, n = self.batch, self.num_agents, self.n
        self.ages = np.zeros((B, N, N - 1, n))
        self.selection = np.zeros((B, N, N - 1, n), dtype=bool)

    # --- the parts' state, by the paper's names ------------------------------------------
    @property
    def fusion(self) -> bf.FusionState:
        """Every node's xhat_i, M_i and the exact joint error covariance (``estimators.bandwidth_fusion``)."""
        return self.backend.fusion

    @property
    def links(self) -> BandwidthBudget:
        """The receivers' budget (the network's)."""
        return self.network.links

    # --- description ------------------------------------------------------------
    @property
    def action_dim(self) -> int:
        return (self.num_agents - 1) * self.n + self.num_agents

    @property
    def obs_dim(self) -> int:
        return self.n + (self.num_agents - 1) * self.n + 1 + self.appended_size()

    def observation_space(self):
        fractions = (self.num_agents - 1) * self.n + 1  # after the n unbounded log-diagonal entries
        low = np.r_[np.full(self.n, -np.inf), np.zeros(fractions)]
        high = np.r_[np.full(self.n, np.inf), np.ones(fractions)]
        return self.extend_space(gymnasium.spaces.Box(low.astype(np.float32), high.astype(np.float32),
                                                      dtype=np.float32))

    def preset_feature_positions(self) -> dict[str, int]:
        """The composed table's features among this observation's own entries: ``step_fraction``."""
        return {"step_fraction": self.n + (self.num_agents - 1) * self.n}

    def action_space(self):
        return self._preset_action_space

    def state_space(self):
        dim = self.num_agents * (self.obs_dim + self.n)
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(dim,), dtype=np.float32)

    # --- action encoding --------------------------------------------------------
    def _decode(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Actions (B, N, A) -> relative selections (B, N, N-1, n), their indices in the feasible order (B, N)
        and the weight logits (B, N, N), clipped."""
        N, n = self.num_agents, self.n
        actions = np.clip(actions, -1.0, 1.0)
        scores = actions[..., : (N - 1) * n]
        if self._feasible is not None:  # argmax over the listed feasible selections (ties: the first)
            index = np.argmax(scores @ self._feasible_flat.T, axis=-1)
            selection = self._feasible[index]
        else:  # the same argmax by dynamic programming over links, nothing listed
            selection = self.links.best_selection(scores.reshape(*actions.shape[:-1], N - 1, n))
            index = self.links.index_of(selection)
        return selection, index, actions[..., (N - 1) * n :]

    def decode_actions(self, actions: np.ndarray) -> np.ndarray:
        """Actions (B, N, A), checked, -> the parts' blocks (``part_decisions``); the decoded selections go to the
        network with their indices (``offer_selection``: it need not decode an index again)."""
        selection, index, logits = self._decode(self.check_actions(actions))
        self.network.offer_selection(index, selection)
        return self.part_decisions(index, logits)

    def part_decisions(self, index: np.ndarray, logits: np.ndarray) -> np.ndarray:
        """The parts' blocks (B, N, 1 + N): the network's ``selection`` (an index in the feasible order) and
        the backend's ``fusion_weights`` logits (relative order)."""
        return np.concatenate([np.asarray(index, float)[..., None], logits], axis=-1)

    def encode_actions(self, selection: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """The action that decodes exactly to ``selection`` and ``weights``.

        ``selection`` is either absolute (N, N, n) or receiver-relative
        (N, N-1, n); ``weights`` absolute (N, N) with p_ij > 0. Returns (N, A)
        float64. Raises ``ValueError`` for an infeasible selection or weights
        the encoding cannot reach (a zero weight, or a ratio beyond
        exp(2 * weight_logit_scale)).
        """
        N, n = self.num_agents, self.n
        selection = np.asarray(selection, bool)
        if selection.shape == (N, N, n):
            selection = self.links.relative_selection(selection)
        if selection.shape != (N, N - 1, n):
            raise ValueError(f"selection must have shape ({N}, {N}, {n}) or ({N}, {N - 1}, {n}), got {selection.shape}")
        if not self.links.is_feasible(selection).all():
            raise ValueError("selection does not meet the bandwidth budget for every receiver")
        weights = bf.check_weights(np.asarray(weights, float))
        if np.any(weights <= 0):
            raise ValueError("weights: the softmax encoding cannot reach a zero weight p_ij")
        log_rel = np.log(np.take_along_axis(weights, self.backend.weight_order, axis=-1))
        logit_action = (log_rel - log_rel.mean(axis=-1, keepdims=True)) / self.config.weight_logit_scale
        if np.any(np.abs(logit_action) > 1.0):
            raise ValueError("weights too uneven for the action encoding; raise weight_logit_scale")
        scores = np.where(selection, 1.0, -1.0).reshape(N, (N - 1) * n)
        return np.concatenate([scores, logit_action], axis=-1)

    # --- dynamics ----------------------------------------------------------------
    def reset(self, rngs, env_index=None) -> None:
        super().reset(rngs, env_index)
        idx = self._indices(env_index)
        self.ages[idx] = 0.0
        self.selection[idx] = False  # nothing received before the first step

    def advance(self, decoded: np.ndarray) -> None:
        """One step of every copy under the parts' blocks (B, N, 1 + N) (``part_decisions``)."""
        super().advance(decoded)
        self.selection = self.links.relative_selection(self.backend.delivered_selection)
        self.ages = np.where(self.selection, 0.0, self.ages + 1.0)

    def compute_reward(self) -> np.ndarray:
        """The reward table of the module docstring, after ``advance``: xhat_i(k+1) against x(k+1)."""
        if self.config.reward == "error":
            loss = self._squared_error()
        else:
            loss = bf.node_traces(self.fusion.error_cov, self.num_agents)
        cost = self.config.component_cost, self.costs[:, None]  # each copy's communication cost this episode
        if cost[0] == 0 and not np.any(cost[1]):  # -loss - 0 * count is -loss exactly: no count needed
            return -loss
        return -loss - cost[0] * self.links.components_received(self.selection) - cost[1] * self.network.messages_sent

    def initial_cost(self) -> float:
        """The k = 0 term of J_K: sum_i tr M_i(0) = N tr M(0) (1.44 m^2 with the paper's values)."""
        return float(self.num_agents * np.trace(np.asarray(self.config.initial_cov, float)))

    def episode_error(self, errors: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """The paper's J_K without its k = 0 term: the squared errors summed over the steps and nodes."""
        return Scenario.episode_error(self, errors, weights)

    # --- views -------------------------------------------------------------------
    def true_position(self) -> np.ndarray:
        """The whole true state now, once per node (B, N, n): x(k+1) after step k, x(0) at reset (the
        episode's x(0..K) is ``world.truth``)."""
        return np.broadcast_to(self.world.target_state()[:, None, :], (self.batch, self.num_agents, self.n)).copy()

    def _squared_error(self) -> np.ndarray:
        """||xhat_i(k+1) - x(k+1)||^2 (B, N) (x(0) and xhat(0) at reset)."""
        return np.sum((self.fusion.estimate - self.world.target_state()[:, None, :]) ** 2, axis=-1)

    def observation(self) -> np.ndarray:
        B, N = self.batch, self.num_agents
        log_bound = np.log(np.diagonal(self.fusion.bound, axis1=-2, axis2=-1))
        ages = self.ages.reshape(B, N, -1) / self.horizon
        frac = np.broadcast_to((self.k / self.horizon)[:, None, None], (B, N, 1))
        return self.extend_observation(np.concatenate([log_bound, ages, frac], axis=-1))

    def state(self) -> np.ndarray:
        node_cov = bf.node_covariances(self.fusion.error_cov, self.num_agents)
        log_exact = np.log(np.diagonal(node_cov, axis1=-2, axis2=-1)).reshape(self.batch, -1)
        return np.concatenate([self.observation().reshape(self.batch, -1), log_exact], axis=-1).astype(np.float32)

    def info(self) -> dict[str, np.ndarray]:
        B, N = self.batch, self.num_agents
        error = self._squared_error()
        exact = bf.node_traces(self.fusion.error_cov, N)
        received = self.links.components_received(self.selection)
        return {
            "true_position": self.true_position(),
            "estimated_position": self.fusion.estimate.copy(),
            "position_error": np.sqrt(error),
            "error": error,
            "trace": exact.copy(),
            "trace_error": exact,
            "bound_trace": np.trace(self.fusion.bound, axis1=-2, axis2=-1),
            "components_received": received,
            "communication": received.astype(float),
            "messages_sent": self.network.messages_sent.copy(),
            **self.link_counts(),
            "floats_sent": self.network.floats_sent.copy(),
            "weights": self.backend.weights.copy(),
            "step": np.broadcast_to(self.k[:, None], (B, N)).copy(),
        }

    def scene(self, b: int) -> Scene:
        N, k, truth = self.num_agents, int(self.k[b]), self.world.target_state()[b, :2]
        node_cov = bf.node_covariances(self.fusion.error_cov[b], N)[:, :2, :2]
        spread = max(1.0, 3.0 * float(np.sqrt(node_cov.diagonal(axis1=-2, axis2=-1).max())))
        received = self.selection[b]  # [i, kk]: what receiver i took from its neighbour kk
        links = [Link(source=int(j), target=i, value=float(received[i, kk].sum()),
                      label="".join(_COMPONENT_NAMES[c] for c in np.flatnonzero(received[i, kk])))
                 for i in range(N) for kk, j in enumerate(self.links.neighbours[i])]
        return Scene(
            title=f"bandwidth_fusion (zhao2020)  k = {k}/{self.horizon}", truth=truth[None],
            estimates=self.fusion.estimate[b, :, :2], covariances=node_cov,
            trails=self.world.truth[b, max(0, k - 10) : k + 1, :2][None], node_positions=ring_layout(N),
            node_labels=self.agent_names, links=links, link_value_max=float(self.n),
            link_value_name="components received",
            extent=(truth[0] - spread, truth[0] + spread, truth[1] - spread, truth[1] + spread),
            notes=[f"mean tr Sigma_i = {bf.node_traces(self.fusion.error_cov[b], N).mean():.3f} m^2"],
        )
