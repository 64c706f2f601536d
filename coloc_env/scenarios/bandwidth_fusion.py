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
(``BandwidthFusionConfig.parts``) with this action codec, observation,
reward and info. The world draws the episode (x(0), w, v_j) from the
episode's generator itself, in the order of ``draw_episode``; the
bandwidth network delivers every selected component on time and draws
nothing. Timing: the backend reports xhat_i(k) at step k (the composition's
pairing of J_K); the preset reports, after step k, the estimate xhat_i(k+1)
it has just formed with y(k), against x(k+1), so that the reward credits a
step's selection and weights at once (the same sequence of estimates, one
step earlier than the composition's).

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

Observation (per agent, ``Box(shape=(n + (N-1)*n + 1,), float32)``)
---------------------------------------------------------------
| index                    | meaning                                                      | bounds    |
|--------------------------|--------------------------------------------------------------|-----------|
| ``[0, n)``               | log of the diagonal of the node's own bound matrix M_i(k)    | unbounded |
|                          | (eq. 19; local: it needs only the neighbours' M, which the   |           |
|                          | paper assumes known). Log because M can grow like 1.5^k.     |           |
| ``[n, n + (N-1)*n)``     | steps since each (neighbour, component) was last received,   | [0, 1]    |
|                          | divided by the horizon (0 at reset: all nodes start equal)   |           |
| ``[-1]``                 | step fraction k / horizon                                    | [0, 1]    |

The log-diagonal is unbounded: a selection that starves a component lets M_i grow without limit
(like 1.5^k), and a well-fed one shrinks it towards 0. (Before, every entry was unbounded.)

``state()`` (centralized critic): every agent's observation, then
log diag Sigma_i(k) of the exact error covariance of every node.

Reward (per agent: each node has its own estimate)
--------------------------------------------------
| ``reward=``  | value after step k -> k+1 (squared metres)                               |
|--------------|--------------------------------------------------------------------------|
| ``"error"``  | -||xhat_i(k+1) - x(k+1)||^2 - component_cost * components received      |
| ``"trace"``  | -tr Sigma_i(k+1) (exact covariance, noise-free) - component_cost * ...   |

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
| ``step``               | k + 1 (0 at reset)                                                      |

Batching: every step of B copies is one set of numpy calls (stacked matmul
and solve; a single network call for all links); the only per-copy loop is at
reset, where each copy draws its whole episode's noise from its own generator.

Arguments (fields of ``BandwidthFusionConfig``, defaults = the paper)
------------------------------------------------------------------------
| field               | default                  | allowed                                   |
|---------------------|--------------------------|-------------------------------------------|
| num_uavs            | 4                        | 2..16                                     |
| transition          | I_3                      | (n, n), entries in [-1e6, 1e6], spectral  |
|                     |                          | radius <= 1.001 (finite over the horizon) |
| drift               | (0.5, 0.5, 0.5)          | (n,), entries in [-1e6, 1e6]              |
| measurement         | I_3                      | (m, n), entries in [-1e6, 1e6]            |
| process_noise       | diag(0.02, 0.05, 0.03)   | (n, n) PSD, entries <= 1e12               |
| measurement_noise   | diag(0.03, 0.04, 0.02)   | (m, m) or (N, m, m) PD, entries <= 1e12   |
| initial_state       | (10, 10, 10)             | (n,) in [-1e6, 1e6]: xhat_i(0); x(0) ~ N  |
| initial_cov         | diag(0.19, 0.09, 0.08)   | (n, n) positive definite, entries <= 1e12:|
|                     |                          | M_i(0) = Sigma_i(0) (the observation      |
|                     |                          | divides by it: a singular one is refused) |
| budget              | 5                        | (N-1)*min_per_link .. (N-1)*max_per_link  |
| min_per_link        | 1                        | 0..max_per_link                           |
| max_per_link        | 3                        | 0..n                                      |
| exact_budget        | True                     | False: sum_j t_ji <= budget               |
| horizon             | 50                       | 1..100000                                 |
| reward              | "error"                  | "error", "trace"                          |
| component_cost      | 0.0                      | [0, 1e12], per received component per step|
| weight_logit_scale  | 4.0                      | (0, 1000]                                 |
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np

import estimators.bandwidth_fusion as bf
from coloc_env.backends.fusion import BandwidthFusion
from coloc_env.config import as_array, check_choice, check_psd, check_range
from coloc_env.networks.bandwidth import Bandwidth
from coloc_env.primitives import BandwidthBudget, LinearMotion, LinearSensor
from coloc_env.primitives.noise import covariance_factor, sample_gaussian
from coloc_env.rendering import Link, Scene, ring_layout
from coloc_env.scenarios.base import Scenario
from coloc_env.scenarios.binding import PresetScenario
from coloc_env.worlds.drift import Drift

_COMPONENT_NAMES = "xyzabcdefghijklmnop"
ENUMERATED_DECODE_LIMIT = 2048  # feasible selections up to which decoding lists them (108 in the paper's setting)

# The paper's component selections (Sec. 2). T_ji = T_ij (eq. 5), so each
# unordered pair {i, j} (1-based as printed) maps to the diagonal of T_ji.
PAPER_SELECTIONS: dict[str, dict[tuple[int, int], tuple[int, ...]]] = {
    "T1": {(1, 2): (0, 1, 0), (1, 3): (1, 1, 0), (1, 4): (0, 1, 1),
           (2, 3): (1, 1, 0), (2, 4): (0, 1, 1), (3, 4): (0, 1, 0)},
    "T2": {(1, 2): (1, 0, 0), (1, 3): (1, 0, 1), (1, 4): (1, 0, 1),
           (2, 3): (1, 0, 1), (2, 4): (1, 0, 1), (3, 4): (0, 0, 1)},
    "T3": {(1, 2): (1, 0, 0), (1, 3): (0, 1, 1), (1, 4): (1, 1, 0),
           (2, 3): (0, 1, 1), (2, 4): (1, 0, 1), (3, 4): (1, 0, 0)},
}

# The paper's weight tables, p_ij = the weight fusion node i gives node j
# (rows sum to 1; the printed tables are symmetric).
PAPER_WEIGHTS: dict[str, tuple[tuple[float, ...], ...]] = {
    "P1": ((0.25, 0.25, 0.25, 0.25),) * 4,
    "P2": ((0.45, 0.15, 0.15, 0.25), (0.15, 0.45, 0.25, 0.15),
           (0.15, 0.25, 0.45, 0.15), (0.25, 0.15, 0.15, 0.45)),
    "P3": ((0.65, 0.15, 0.15, 0.05), (0.15, 0.65, 0.05, 0.15),
           (0.15, 0.05, 0.65, 0.15), (0.05, 0.15, 0.15, 0.65)),
}


def paper_selection(name: str) -> np.ndarray:
    """The paper's table ``name`` (T1, T2, T3) as an absolute selection (4, 4, 3), T_ii = I."""
    if name not in PAPER_SELECTIONS:
        raise ValueError(f"selection table must be one of {sorted(PAPER_SELECTIONS)}, got {name!r}")
    full = np.ones((4, 4, 3), dtype=bool)
    for (a, b), diag in PAPER_SELECTIONS[name].items():
        full[a - 1, b - 1] = full[b - 1, a - 1] = np.asarray(diag, bool)
    return full


def paper_weights(name: str) -> np.ndarray:
    """The paper's weight table ``name`` (P1, P2, P3), shape (4, 4)."""
    if name not in PAPER_WEIGHTS:
        raise ValueError(f"weight table must be one of {sorted(PAPER_WEIGHTS)}, got {name!r}")
    return np.array(PAPER_WEIGHTS[name], dtype=float)


def _eye(n):
    return tuple(tuple(float(i == j) for j in range(n)) for i in range(n))


def _diag(*values):
    return tuple(tuple(v if i == j else 0.0 for j in range(len(values))) for i, v in enumerate(values))


@dataclass(frozen=True)
class BandwidthFusionConfig:
    """Configuration of ``bandwidth_fusion``; defaults are the paper's simulation (Sec. 2)."""

    num_uavs: int = 4
    transition: tuple = _eye(3)
    drift: tuple = (0.5, 0.5, 0.5)
    measurement: tuple = _eye(3)
    process_noise: tuple = _diag(0.02, 0.05, 0.03)
    measurement_noise: tuple = _diag(0.03, 0.04, 0.02)
    initial_state: tuple = (10.0, 10.0, 10.0)
    initial_cov: tuple = _diag(0.19, 0.09, 0.08)
    budget: int = 5
    min_per_link: int = 1
    max_per_link: int = 3
    exact_budget: bool = True
    horizon: int = 50
    reward: str = "error"
    component_cost: float = 0.0
    weight_logit_scale: float = 4.0

    @property
    def motion(self) -> LinearMotion:
        return LinearMotion(np.asarray(self.transition, float), np.asarray(self.drift, float),
                            np.asarray(self.process_noise, float))

    @property
    def sensor_noise(self) -> np.ndarray:
        """V_j of every node, shape (N, m, m)."""
        V = np.asarray(self.measurement_noise, float)
        return V if V.ndim == 3 else np.broadcast_to(V, (self.num_uavs, *V.shape)).copy()

    @property
    def links(self) -> BandwidthBudget:
        return BandwidthBudget(self.num_uavs, np.asarray(self.transition).shape[0], self.budget,
                               self.min_per_link, self.max_per_link, self.exact_budget)

    def validate(self) -> None:
        from coloc_env.worlds.drift import check_linear_world  # the drift world's checks (its raw fields first)

        check_range("num_uavs", self.num_uavs, 2, 16, integer=True)
        check_linear_world("", self, strict_prior=True)
        self.motion.validate()
        n = self.motion.dim
        C = as_array("measurement", self.measurement, ndim=2)
        if C.shape[1] != n:
            raise ValueError(f"measurement must have shape (m, {n}), got {C.shape}")
        V = as_array("measurement_noise", self.measurement_noise)
        per_node = V if V.ndim == 3 else V[None]
        if V.ndim == 3 and V.shape[0] != self.num_uavs:
            raise ValueError(f"measurement_noise must be (m, m) or ({self.num_uavs}, m, m), got {V.shape}")
        for j, Vj in enumerate(per_node):
            LinearSensor(C, Vj).validate(n, noise_name="measurement_noise" + (f"[{j}]" if V.ndim == 3 else ""))
        as_array("initial_state", self.initial_state, shape=(n,))
        check_psd("initial_cov", self.initial_cov, n, strict=True)
        try:
            self.links.validate()
        except ValueError as exc:  # a cross-field range: name the fields it depends on
            raise ValueError(f"{exc} (with budget={self.budget}, min_per_link={self.min_per_link}, "
                             f"max_per_link={self.max_per_link}, num_uavs={self.num_uavs})") from exc
        check_range("horizon", self.horizon, 1, 100_000, integer=True)
        check_choice("reward", self.reward, ("error", "trace"))
        check_range("component_cost", self.component_cost, 0.0, 1e12)
        check_range("weight_logit_scale", self.weight_logit_scale, 0.0, 1e3, low_open=True)

    def fusion_model(self) -> bf.FusionModel:
        return bf.FusionModel(
            transition=np.asarray(self.transition, float),
            drift=np.asarray(self.drift, float),
            measurement=np.asarray(self.measurement, float),
            process_noise=np.asarray(self.process_noise, float),
            measurement_noise=self.sensor_noise,
        )

    def parts(self) -> tuple:
        """The (world, network, backend) configs this flat config stands for: ``drift`` with the same system
        and prior, ``bandwidth`` with the same budget (``ScoredBandwidth``), ``bandwidth_fusion``."""
        world = Drift(num_agents=self.num_uavs, transition=self.transition, drift=self.drift,
                      measurement=self.measurement, process_noise=self.process_noise,
                      measurement_noise=self.measurement_noise, initial_state=self.initial_state,
                      initial_cov=self.initial_cov, horizon=self.horizon)
        network = ScoredBandwidth(budget=self.budget, min_per_link=self.min_per_link,
                                  max_per_link=self.max_per_link, exact_budget=self.exact_budget)
        return world, network, BandwidthFusion(weight_logit_scale=self.weight_logit_scale)


@dataclass(frozen=True)
class ScoredBandwidth(Bandwidth):
    """The ``bandwidth`` network as the preset drives it: the same rules and delivery, but a budget is not
    refused beyond ``MAX_SELECTIONS`` feasible selections (the limit of a Discrete selection action). The
    preset's action is a score per (neighbour, component), decoded by the argmax over the feasible
    selections (``BandwidthBudget.best_selection``); the network's selection index only carries the
    result (int64, exact for the ~7e11 selections of N = 16)."""

    def budget_for(self, num_agents: int, dim: int, prefix: str = "network.") -> BandwidthBudget:
        links = BandwidthBudget(num_agents, dim, self.budget, self.min_per_link,
                                dim if self.max_per_link is None else self.max_per_link, self.exact_budget)
        links.validate(prefix)
        return links


@dataclass(frozen=True)
class NoiseFactors:
    """Square-root factors F (F F^T = covariance) of one config's noises, computed once per scenario."""

    initial: np.ndarray  # (n, n), of M(0)
    process: np.ndarray  # (n, n), of W
    measurement: np.ndarray  # (N, m, m), of each V_j


def noise_factors(config: BandwidthFusionConfig) -> NoiseFactors:
    model = config.fusion_model()
    return NoiseFactors(initial=covariance_factor(np.asarray(config.initial_cov, float)),
                        process=config.motion.noise_factor,
                        measurement=np.stack([covariance_factor(V) for V in model.measurement_noise]))


def draw_episode(config: BandwidthFusionConfig, rng: np.random.Generator,
                 factors: NoiseFactors | None = None) -> dict[str, np.ndarray]:
    """One episode's randomness, drawn from ``rng`` in the order ``reset`` draws it for a copy (the ``drift``
    world draws it from the episode's generator itself: ``BandwidthFusionScenario.part_generators``).

    Returns ``initial_state`` x(0) ~ N(xhat(0), M(0)) (n,), ``process_noise`` w(0..K-1) (K, n)
    and ``measurement_noise`` v_j(0..K-1) of every node (K, N, m).
    ``factors``: ``noise_factors`` of ``config``, when the caller has them.
    """
    factors = noise_factors(config) if factors is None else factors
    K, N, m = config.horizon, config.num_uavs, factors.measurement.shape[-1]
    x0 = np.asarray(config.initial_state, float) + sample_gaussian(rng, factors.initial, ())
    process = sample_gaussian(rng, factors.process, (K,))
    white = rng.standard_normal((K, N, m))
    measurement = (factors.measurement @ white[..., None])[..., 0]
    return {"initial_state": x0, "process_noise": process, "measurement_noise": measurement}


class BandwidthFusionScenario(PresetScenario):
    """Batched core of ``bandwidth_fusion``: the binding of ``BandwidthFusionConfig`` on the composable core
    (``drift`` / ``bandwidth`` / ``bandwidth_fusion``); the module docstring has the table."""

    name = "bandwidth_fusion"
    paper = "zhao2020"
    Config = BandwidthFusionConfig

    @classmethod
    def composition_options(cls, config) -> dict:
        return {"reward": config.reward}

    def __init__(self, config: BandwidthFusionConfig, batch: int = 1):
        super().__init__(config, batch)
        self.n = self.world.state_dim
        self.m = self.world.measurement_dim
        links = self.links
        # Up to a few thousand selections one matmul + argmax over the list is the faster decoder; beyond,
        # the dynamic programme (BandwidthBudget.best_selection). Both give the same selection (a test holds it).
        self._feasible = links.feasible if links.size <= ENUMERATED_DECODE_LIMIT else None
        self._feasible_flat = (None if self._feasible is None
                               else self._feasible.reshape(links.size, -1).astype(float))
        # weight_order[i] = absolute node index of [self, neighbour 0, ...] of receiver i
        self._weight_order = self.backend.weight_order
        self._initial_cov = np.asarray(config.initial_cov, float)
        # built once (check_actions reads it every step); float64: the paper's weight tables must survive
        # the softmax encoding exactly (float32 loses 1e-9)
        self._preset_action_space = gymnasium.spaces.Box(-1.0, 1.0, shape=(self.action_dim,), dtype=np.float64)
        B, N, n = self.batch, self.num_agents, self.n
        self.ages = np.zeros((B, N, N - 1, n))
        self.selection = np.zeros((B, N, N - 1, n), dtype=bool)

    # --- the parts' state, by the paper's names ------------------------------------------
    @property
    def model(self) -> bf.FusionModel:
        return self.backend.model

    @property
    def fusion(self) -> bf.FusionState:
        """Every node's xhat_i, M_i and the exact joint error covariance (``estimators.bandwidth_fusion``)."""
        return self.backend.fusion

    @property
    def links(self) -> BandwidthBudget:
        """The receivers' budget (the network's)."""
        return self.network.links

    @property
    def truth(self) -> np.ndarray:
        """The true state now (B, n): x(k+1) after step k, x(0) at reset."""
        return self.world.target_state()

    @property
    def trail(self) -> np.ndarray:
        """The episode's true states x(0..K) (B, K + 1, n)."""
        return self.world.truth

    @property
    def weights(self) -> np.ndarray:
        """(B, N, N) the fusion weights p_ij of the last step (1/N at reset)."""
        return self.backend.weights

    # --- description ------------------------------------------------------------
    @property
    def action_dim(self) -> int:
        return (self.num_agents - 1) * self.n + self.num_agents

    @property
    def obs_dim(self) -> int:
        return self.n + (self.num_agents - 1) * self.n + 1

    def observation_space(self):
        unbounded, fractions = self.n, (self.num_agents - 1) * self.n + 1
        low = np.concatenate([np.full(unbounded, -np.inf), np.zeros(fractions)])
        high = np.concatenate([np.full(unbounded, np.inf), np.ones(fractions)])
        return gymnasium.spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)

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

    def decode_actions(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Actions (B, N, A) -> receiver-relative selections (B, N, N-1, n) and absolute weights (B, N, N)."""
        selection, _, logits = self._decode(actions)
        return selection, self.backend.decode_weights(logits)

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
        log_rel = np.log(np.take_along_axis(weights, self._weight_order, axis=-1))
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

    def step(self, actions) -> None:
        actions = self.check_actions(actions)
        if np.any(self.k >= self.horizon):
            raise RuntimeError("step() on a copy whose episode is over; reset it first")
        selection, index, logits = self._decode(actions)
        self.network.offer_selection(index, selection)  # the network need not decode the index again
        self.advance(self.part_decisions(index, logits))

    def advance(self, decoded: np.ndarray, weights: np.ndarray | None = None) -> None:
        """One step of every copy under decoded decisions: the parts' blocks (B, N, 1 + N)
        (``part_decisions``), or receiver-relative selections (B, N, N-1, n) with absolute weights
        (B, N, N) (the fusion weights are then the softmax of their logarithms: the same to rounding, exact
        for equal weights)."""
        if weights is not None:
            index = self.links.index_of(decoded)
            if np.any(index < 0):
                raise ValueError("selection does not meet the bandwidth budget for every receiver")
            self.network.offer_selection(index, np.asarray(decoded, bool))
            with np.errstate(divide="ignore"):  # a zero weight: logit -inf, weight exactly 0
                logits = np.log(np.take_along_axis(np.asarray(weights, float),
                                                   np.broadcast_to(self._weight_order, np.shape(weights)), axis=-1))
            decoded = self.part_decisions(index, logits / self.config.weight_logit_scale)
        super().advance(decoded)
        self.selection = self.links.relative_selection(self.backend.delivered_selection)
        self.ages = np.where(self.selection, 0.0, self.ages + 1.0)
        self._reward = self.compute_reward()

    def compute_reward(self) -> np.ndarray:
        """The reward table of the module docstring, after ``advance``: xhat_i(k+1) against x(k+1)."""
        if self.config.reward == "error":
            loss = self._squared_error()
        else:
            loss = bf.node_traces(self.fusion.error_cov, self.num_agents)
        if self.config.component_cost == 0:  # -loss - 0 * count is -loss exactly: no count needed
            return -loss
        return -loss - self.config.component_cost * self.links.components_received(self.selection)

    def initial_cost(self) -> float:
        """The k = 0 term of J_K: sum_i tr M_i(0) = N tr M(0) (1.44 m^2 with the paper's values)."""
        return float(self.num_agents * np.trace(self._initial_cov))

    def episode_error(self, errors: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """The paper's J_K without its k = 0 term: the squared errors summed over the steps and nodes."""
        return Scenario.episode_error(self, errors, weights)

    # --- views -------------------------------------------------------------------
    def _squared_error(self) -> np.ndarray:
        """||xhat_i(k+1) - x(k+1)||^2 (B, N) (x(0) and xhat(0) at reset)."""
        return np.sum((self.fusion.estimate - self.truth[:, None, :]) ** 2, axis=-1)

    def observation(self) -> np.ndarray:
        B, N = self.batch, self.num_agents
        log_bound = np.log(np.diagonal(self.fusion.bound, axis1=-2, axis2=-1))
        ages = self.ages.reshape(B, N, -1) / self.horizon
        frac = np.broadcast_to((self.k / self.horizon)[:, None, None], (B, N, 1))
        return np.concatenate([log_bound, ages, frac], axis=-1).astype(np.float32)

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
            "true_position": np.broadcast_to(self.truth[:, None, :], (B, N, self.n)).copy(),
            "estimated_position": self.fusion.estimate.copy(),
            "position_error": np.sqrt(error),
            "error": error,
            "trace": exact.copy(),
            "trace_error": exact,
            "bound_trace": np.trace(self.fusion.bound, axis1=-2, axis2=-1),
            "components_received": received,
            "communication": received.astype(float),
            "messages_sent": self.network.messages_sent.copy(),
            "floats_sent": self.network.floats_sent.copy(),
            "weights": self.weights.copy(),
            "step": np.broadcast_to(self.k[:, None], (B, N)).copy(),
        }

    def scene(self, b: int) -> Scene:
        N, k = self.num_agents, int(self.k[b])
        node_cov = bf.node_covariances(self.fusion.error_cov[b], N)
        spread = max(1.0, 3.0 * float(np.sqrt(node_cov[:, :2, :2].diagonal(axis1=-2, axis2=-1).max())))
        truth = self.truth[b]
        centre = truth[:2]
        links = []
        for i in range(N):
            for kk, j in enumerate(self.links.neighbours[i]):
                comps = self.selection[b, i, kk]
                label = "".join(_COMPONENT_NAMES[c] for c in np.flatnonzero(comps))
                links.append(Link(source=int(j), target=i, value=float(comps.sum()), label=label))
        return Scene(
            title=f"bandwidth_fusion (zhao2020)  k = {k}/{self.horizon}",
            truth=truth[:2][None],
            estimates=self.fusion.estimate[b, :, :2],
            covariances=node_cov[:, :2, :2],
            trails=self.trail[b, max(0, k - 10) : k + 1, :2][None],
            node_positions=ring_layout(N),
            node_labels=self.agent_names,
            links=links,
            link_value_max=float(self.n),
            link_value_name="components received",
            extent=(centre[0] - spread, centre[0] + spread, centre[1] - spread, centre[1] + spread),
            notes=[f"mean tr Sigma_i = {bf.node_traces(self.fusion.error_cov[b], N).mean():.3f} m^2"],
        )
