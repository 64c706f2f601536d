"""``bandwidth_fusion``: bandwidth-limited distributed fusion (Zhao et al. 2020).

Paper: Zhao, Liu, Zhao, Gao, "A distributed fusion estimator with bandwidth
limitation for clustered UAVs' position and attitude estimation", Electronics
Optics & Control 27(4), 2020 (seed ``001_c743ba0d1c0e3ecf.txt``); estimator in
:mod:`estimators.bandwidth_fusion`.

N UAVs (the fusion nodes) estimate one position x in R^3 that moves with a
constant drift, x(k+1) = A x(k) + B + w(k), each from its own linear
measurement y_j(k) = C x(k) + v_j(k) (the paper linearizes UWB ranges to four
anchors into C = I). Every step each node forms an intermediate estimate
lambda_j; receiver i may take only ``budget`` components in total from its
neighbours' intermediate estimates (at least ``min_per_link`` and at most
``max_per_link`` from each), fills the rest with its own prediction and fuses
with weights p_ij. The agents choose what the paper fixes by hand: the
component selection T and the fusion weights p.

Action (one per receiver, the same Box for all agents)
------------------------------------------------------
``Box(-1, 1, shape=((N-1)*n + N,), float64)``; neighbours are indexed relative
to the receiver (neighbour k of ``uav_i`` is ``uav_{(i+1+k) mod N}``).

| slice                   | meaning                                                                 |
|-------------------------|-------------------------------------------------------------------------|
| ``[0, (N-1)*n)``        | score of (neighbour k, component c) at ``k*n + c``. Decoded to the      |
|                         | feasible selection with the highest total score (argmax over the 108    |
|                         | feasible selections of the paper's setting; ties go to the first in     |
|                         | :attr:`BandwidthBudget.feasible` order). Every feasible selection is    |
|                         | reachable: scores +1 selected / -1 not decode back to it exactly.       |
|                         | Beyond 2,048 selections found by :meth:`BandwidthBudget.best_selection`,|
|                         | a dynamic programme over links (the same argmax, ties included, without |
|                         | listing the ~7e11 selections of N = 16), so every N in 2..16 decodes    |
|                         | the same way.                                                           |
| ``[(N-1)*n, (N-1)*n+N)``| fusion-weight logits for [self, neighbour 0, ..., neighbour N-2];       |
|                         | p_i = softmax(``weight_logit_scale`` * a). A weight is never exactly 0. |

Out-of-range actions are clipped to [-1, 1]; a NaN or inf is a ``ValueError``.

Observation (per agent, ``Box(-inf, inf, shape=(n + (N-1)*n + 1,), float32)``)
---------------------------------------------------------------------------
| index                    | meaning                                                      |
|--------------------------|--------------------------------------------------------------|
| ``[0, n)``               | log of the diagonal of the node's own bound matrix M_i(k)    |
|                          | (eq. 19; local: it needs only the neighbours' M, which the   |
|                          | paper assumes known). Log because M can grow like 1.5^k.     |
| ``[n, n + (N-1)*n)``     | steps since each (neighbour, component) was last received,   |
|                          | divided by the horizon (0 at reset: all nodes start equal)   |
| ``[-1]``                 | step fraction k / horizon                                    |

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

``infos[agent]``: ``true_position``, ``estimated_position``, ``error``
(squared), ``trace_error`` (tr Sigma_i), ``bound_trace`` (tr M_i),
``components_received`` (and ``communication``, the same count: the key every
scenario uses for what ``coloc evaluate`` reports as communication),
``weights`` (the node's row p_i., absolute order), ``step``.

Batching: every step of B copies is one set of numpy calls (stacked matmul
and solve); the only per-copy loop is at reset, where each copy draws its
whole episode's noise from its own generator.

Arguments (fields of :class:`BandwidthFusionConfig`, defaults = the paper)
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
| weight_logit_scale  | 4.0                      | > 0                                       |
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np

import estimators.bandwidth_fusion as bf
from coloc_env.config import as_array, check_choice, check_psd, check_range
from coloc_env.rendering import Link, Scene, ring_layout
from coloc_env.scenarios.base import Scenario
from coloc_env.world import BandwidthBudget, LinearMotion, LinearSensor
from coloc_env.world.noise import covariance_factor, sample_gaussian

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
    """One episode's randomness, drawn from ``rng`` in the order ``reset`` draws it for a copy.

    Returns ``initial_state`` x(0) ~ N(xhat(0), M(0)) (n,), ``process_noise`` w(0..K-1) (K, n)
    and ``measurement_noise`` v_j(0..K-1) of every node (K, N, m). The reproduction
    (``train/reproduce/zhao2020.py``) feeds the same draws to
    :func:`estimators.bandwidth_fusion.simulate`, so that both see the same episodes.
    ``factors``: :func:`noise_factors` of ``config``, when the caller has them.
    """
    factors = noise_factors(config) if factors is None else factors
    K, N, m = config.horizon, config.num_uavs, factors.measurement.shape[-1]
    x0 = np.asarray(config.initial_state, float) + sample_gaussian(rng, factors.initial, ())
    process = sample_gaussian(rng, factors.process, (K,))
    white = rng.standard_normal((K, N, m))
    measurement = (factors.measurement @ white[..., None])[..., 0]
    return {"initial_state": x0, "process_noise": process, "measurement_noise": measurement}


class BandwidthFusionScenario(Scenario):
    """Batched core of ``bandwidth_fusion``; see the module docstring for the table."""

    name = "bandwidth_fusion"
    paper = "zhao2020"
    Config = BandwidthFusionConfig

    def __init__(self, config: BandwidthFusionConfig, batch: int = 1):
        super().__init__(config, batch)
        self.model = config.fusion_model()
        self.motion = config.motion
        self.sensor = LinearSensor(np.asarray(config.measurement, float), self.model.measurement_noise[0])
        self.links = config.links
        self.n = self.model.state_dim
        self.m = self.model.measurement_dim
        # Up to a few thousand selections one matmul + argmax over the list is the faster decoder; beyond,
        # the dynamic programme (BandwidthBudget.best_selection). Both give the same selection (a test holds it).
        self._feasible = self.links.feasible if self.links.size <= ENUMERATED_DECODE_LIMIT else None
        self._feasible_flat = (None if self._feasible is None
                               else self._feasible.reshape(self.links.size, -1).astype(float))
        # weight_order[i] = absolute node index of [self, neighbour 0, ...] of receiver i
        self._weight_order = np.concatenate([np.arange(config.num_uavs)[:, None], self.links.neighbours], axis=1)
        self._initial_estimate = np.asarray(config.initial_state, float)
        self._initial_cov = np.asarray(config.initial_cov, float)
        self._factors = noise_factors(config)
        B, N, n, m, K = self.batch, self.num_agents, self.n, self.m, self.horizon
        self.k = np.zeros(B, dtype=int)
        self.truth = np.zeros((B, n))
        self.trail = np.zeros((B, K + 1, n))
        self.fusion = bf.initial_state(self.model, self._initial_estimate, self._initial_cov, (B,))
        self._process = np.zeros((B, K, n))
        self._meas_noise = np.zeros((B, K, N, m))
        self.ages = np.zeros((B, N, N - 1, n))
        self.selection = np.zeros((B, N, N - 1, n), dtype=bool)
        self.weights = np.full((B, N, N), 1.0 / N)
        self._reward = np.zeros((B, N))

    # --- description ------------------------------------------------------------
    @property
    def action_dim(self) -> int:
        return (self.num_agents - 1) * self.n + self.num_agents

    @property
    def obs_dim(self) -> int:
        return self.n + (self.num_agents - 1) * self.n + 1

    def observation_space(self):
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(self.obs_dim,), dtype=np.float32)

    def action_space(self):
        # float64: the paper's weight tables must survive the softmax encoding exactly (float32 loses 1e-9)
        return gymnasium.spaces.Box(-1.0, 1.0, shape=(self.action_dim,), dtype=np.float64)

    def state_space(self):
        dim = self.num_agents * (self.obs_dim + self.n)
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(dim,), dtype=np.float32)

    # --- action encoding --------------------------------------------------------
    def decode_actions(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Actions (B, N, A) -> receiver-relative selections (B, N, N-1, n) and absolute weights (B, N, N)."""
        N, n = self.num_agents, self.n
        actions = np.clip(actions, -1.0, 1.0)
        scores = actions[..., : (N - 1) * n]
        if self._feasible is not None:  # argmax over the listed feasible selections (ties: the first)
            selection = self._feasible[np.argmax(scores @ self._feasible_flat.T, axis=-1)]
        else:  # the same argmax by dynamic programming over links, nothing listed
            selection = self.links.best_selection(scores.reshape(*actions.shape[:-1], N - 1, n))
        logits = self.config.weight_logit_scale * actions[..., (N - 1) * n :]
        logits = logits - logits.max(axis=-1, keepdims=True)
        relative = np.exp(logits)
        relative /= relative.sum(axis=-1, keepdims=True)
        weights = np.zeros(actions.shape[:-2] + (N, N))
        np.put_along_axis(weights, np.broadcast_to(self._weight_order, weights.shape), relative, axis=-1)
        return selection, weights

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
        idx = self._indices(env_index)
        if len(rngs) != len(idx):
            raise ValueError(f"reset needs one generator per copy: {len(idx)} copies, {len(rngs)} generators")
        N = self.num_agents
        for b, rng in zip(idx, rngs, strict=True):
            # One block per episode so that stepping never loops over copies.
            episode = draw_episode(self.config, rng, self._factors)
            self.truth[b] = episode["initial_state"]
            self._process[b] = episode["process_noise"]
            self._meas_noise[b] = episode["measurement_noise"]
        fresh = bf.initial_state(self.model, self._initial_estimate, self._initial_cov, (len(idx),))
        self.fusion.estimate[idx] = fresh.estimate
        self.fusion.bound[idx] = fresh.bound
        self.fusion.error_cov[idx] = fresh.error_cov
        self.k[idx] = 0
        self.trail[idx] = 0.0
        self.trail[idx, 0] = self.truth[idx]
        self.ages[idx] = 0.0
        self.selection[idx] = False  # nothing received before the first step
        self.weights[idx] = 1.0 / N
        self._reward[idx] = 0.0

    def step(self, actions) -> None:
        actions = self.check_actions(actions)
        if np.any(self.k >= self.horizon):
            raise RuntimeError("step() on a copy whose episode is over; reset it first")
        selection, weights = self.decode_actions(actions)
        self.advance(selection, weights)

    def advance(self, selection: np.ndarray, weights: np.ndarray) -> None:
        """Step with decoded decisions: relative selections (B, N, N-1, n), absolute weights (B, N, N)."""
        rows = np.arange(self.batch)
        full = self.links.full_selection(selection)
        y = self.sensor.measure(self.truth[:, None, :], self._meas_noise[rows, self.k])
        self.fusion = bf.step(self.model, self.fusion, y, full, weights)
        self.truth = self.motion.step(self.truth, self._process[rows, self.k])
        self.k = self.k + 1
        self.trail[rows, self.k] = self.truth
        self.ages = np.where(selection, 0.0, self.ages + 1.0)
        self.selection, self.weights = selection, weights
        if self.config.reward == "error":
            loss = np.sum((self.fusion.estimate - self.truth[:, None, :]) ** 2, axis=-1)
        else:
            loss = bf.node_traces(self.fusion.error_cov, self.num_agents)
        self._reward = -loss - self.config.component_cost * self.links.components_received(selection)

    def initial_cost(self) -> float:
        """The k = 0 term of J_K: sum_i tr M_i(0) = N tr M(0) (1.44 m^2 with the paper's values)."""
        return float(self.num_agents * np.trace(self._initial_cov))

    # --- views -------------------------------------------------------------------
    def observation(self) -> np.ndarray:
        B, N = self.batch, self.num_agents
        log_bound = np.log(np.diagonal(self.fusion.bound, axis1=-2, axis2=-1))
        ages = self.ages.reshape(B, N, -1) / self.horizon
        frac = np.broadcast_to((self.k / self.horizon)[:, None, None], (B, N, 1))
        return np.concatenate([log_bound, ages, frac], axis=-1).astype(np.float32)

    def reward(self) -> np.ndarray:
        return self._reward.copy()

    def done(self) -> np.ndarray:
        return self.k >= self.horizon

    def state(self) -> np.ndarray:
        node_cov = bf.node_covariances(self.fusion.error_cov, self.num_agents)
        log_exact = np.log(np.diagonal(node_cov, axis1=-2, axis2=-1)).reshape(self.batch, -1)
        return np.concatenate([self.observation().reshape(self.batch, -1), log_exact], axis=-1).astype(np.float32)

    def info(self) -> dict[str, np.ndarray]:
        B, N = self.batch, self.num_agents
        return {
            "true_position": np.broadcast_to(self.truth[:, None, :], (B, N, self.n)).copy(),
            "estimated_position": self.fusion.estimate.copy(),
            "error": np.sum((self.fusion.estimate - self.truth[:, None, :]) ** 2, axis=-1),
            "trace_error": bf.node_traces(self.fusion.error_cov, N),
            "bound_trace": np.trace(self.fusion.bound, axis1=-2, axis2=-1),
            "components_received": self.links.components_received(self.selection),
            "communication": self.links.components_received(self.selection).astype(float),
            "weights": self.weights.copy(),
            "step": np.broadcast_to(self.k[:, None], (B, N)).copy(),
        }

    def scene(self, b: int) -> Scene:
        N, k = self.num_agents, int(self.k[b])
        node_cov = bf.node_covariances(self.fusion.error_cov[b], N)
        spread = max(1.0, 3.0 * float(np.sqrt(node_cov[:, :2, :2].diagonal(axis1=-2, axis2=-1).max())))
        centre = self.truth[b, :2]
        links = []
        for i in range(N):
            for kk, j in enumerate(self.links.neighbours[i]):
                comps = self.selection[b, i, kk]
                label = "".join(_COMPONENT_NAMES[c] for c in np.flatnonzero(comps))
                links.append(Link(source=int(j), target=i, value=float(comps.sum()), label=label))
        return Scene(
            title=f"bandwidth_fusion (zhao2020)  k = {k}/{self.horizon}",
            truth=self.truth[b, :2][None],
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
