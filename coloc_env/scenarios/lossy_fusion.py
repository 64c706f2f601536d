"""``lossy_fusion``: cooperative target localization over lossy, delayed links (Fu, Bi, Gao 2017).

Paper: Fu, Bi, Gao, "Multi-UAVs Cooperative Localization Algorithms with
Communication Constraints", Hindawi, 2017 (seed ``000_de65bd0f0f4a0cb7.txt``);
estimator in :mod:`estimators.lossy_fusion`.

L UAVs track one target moving with nearly constant velocity in 3-D (state
[x, vx, y, vy, z, vz], T = 1 s, white acceleration of variance q per axis).
Every UAV measures the target position with noise of variance r per axis.
``uav_0`` is the leader and the fusion centre; the followers ``uav_1`` ..
run their own Kalman filters and may send the leader a packet of three
estimates of the current state (filtered, one- and two-step predicted) with
their covariances. Each slot a follower's packet arrives on time
(probability ``on_time_probability``), one slot late (``late_probability``)
or is lost; the leader keeps the last packet delivered, compensates it with
weights on its three estimates (paper: eq. 29, which ignores the packet's age),
fuses its own estimate with the compensated ones by inverse-trace weights
(eq. 30) and feeds the fused estimate back into its own filter (eq. 31).
This is the paper's distributed algorithm (B). One env step is one slot.

The agents decide what the paper fixes: followers whether to transmit each
slot, the leader how to tilt the compensation and fusion weights away from
(29)/(30) (the fusion weights need this slot's covariances, which arrive only
after the decision, so the action scales the paper's weights instead of
replacing them; an all-zero weight action is the paper).

Action (the same Box for every agent; each reads its own part)
--------------------------------------------------------------
``Box(-1, 1, shape=(1 + L + 3 (L-1),), float64)``; out-of-range values are
clipped, a NaN or inf is a ``ValueError``.

| index                        | who       | meaning                                                          |
|------------------------------|-----------|------------------------------------------------------------------|
| ``[0]``                      | followers | transmit this slot if >= 0 (the leader's is ignored)             |
| ``[1, 1+L)``                 | leader    | fusion tilt t_i for [leader, uav_1, ...]: a_i proportional to    |
|                              |           | exp(``weight_logit_scale`` t_i) / tr P_i (0: eq. 30)             |
| ``[1+L, 1+L+3(L-1))``        | leader    | compensation tilt per follower f and packet entry j = 0, 1, 2    |
|                              |           | ([x(s|s), x(s|s-1), x(s|s-2)]) at ``1+L+3(f-1)+j``: weights      |
|                              |           | proportional to c_j exp(scale t_fj), c = eq. (29) (0: the paper) |

The followers' weight entries and the leader's transmit entry are ignored.

Observation (per agent, ``Box(-inf, inf, shape=(3 + 4 (L-1),), float32)``)
--------------------------------------------------------------------------
| index                      | leader                                        | follower                |
|----------------------------|-----------------------------------------------|-------------------------|
| ``[0]``                    | 1 (role)                                      | 0                       |
| ``[1]``                    | slots done / horizon                          | same                    |
| ``[2]``                    | log tr P0 (its fused covariance, eq. 30)      | log tr of its own P(k|k)|
| ``[3, 3+(L-1))``           | age in slots of the packet held from each     | 0                       |
|                            | follower, / 10                                |                         |
| ``[3+(L-1), 3+4(L-1))``    | log tr of the three covariances in that       | 0                       |
|                            | packet, follower-major                        |                         |

``state()`` (centralized critic): every agent's observation, then the one-hot
link outcome of each follower's last slot (on time, late, lost).

Reward (the fused estimate is shared: every agent gets the team's loss)
----------------------------------------------------------------------
| ``reward=``  | value after slot k (squared metres)                                     |
|--------------|-------------------------------------------------------------------------|
| ``"error"``  | -||H (x0hat(k) - x(k))||^2, the fused position error                     |
| ``"trace"``  | -tr(H P0(k) H^T), the leader's own (eq. 30) position covariance          |

minus ``message_cost`` for each packet the agent itself sent this slot
(followers only). Note that the paper's inverse-trace weights already minimize
tr P0 = sum a_i^2 tr P_i, so ``"trace"`` rewards exactly the paper's weights.

Termination: none; truncation after ``horizon`` slots (the paper's 100).

``infos[agent]``: ``true_position``, ``estimated_position`` (the fused
estimate, the same for all), ``error`` (its squared position error, the same
for all: ``coloc evaluate`` sums it over agents, i.e. L times the fused
error), ``claimed_trace`` (tr H P0 H^T), ``local_estimate`` and
``local_error`` (the agent's own filter: the leader's is the fused one),
``communication`` (packets this agent sent this slot), ``packet_age`` (age of
the packet the leader holds from this follower; 0 for the leader),
``link_outcome`` (this slot's draw: 0 on time, 1 late, 2 lost), ``delivered``
(what arrived: 0 on time, 1 late packet, 2 nothing), ``fusion_weight``
(a_i), ``step``.

Arguments (fields of :class:`LossyFusionConfig`, defaults = the paper)
---------------------------------------------------------------------
| field                | default                          | allowed                                  |
|----------------------|----------------------------------|------------------------------------------|
| num_uavs             | 2                                | 2..16 (L, leader included)               |
| period               | 1.0                              | > 0 (T, seconds)                         |
| accel_noise          | 5.0                              | >= 0 (q, m^2/s^4 per axis)               |
| measurement_noise    | 10.0                             | [1e-6, 1e12] (r, m^2 per axis)           |
| initial_state        | (100, 10, 100, 10, 100, 0)       | (6,) in [-1e6, 1e6]: X0, x(0) ~ N(X0, P0)|
| initial_cov          | diag(100, 5, 100, 5, 100, 5)     | (6, 6) positive definite (the observation|
|                      |                                  | divides by it), entries <= 1e12: P0      |
| on_time_probability  | 0.4                              | [0, 1] (alpha1)                          |
| late_probability     | 0.3                              | [0, 1] (alpha2), alpha1 + alpha2 in (0, 1]|
| horizon              | 100                              | 1..100000                                |
| reward               | "error"                          | "error", "trace"                         |
| message_cost         | 0.0                              | [0, 1e12], per packet sent               |
| weight_logit_scale   | 3.0                              | (0, 50]                                  |
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np

import estimators.lossy_fusion as lf
from coloc_env.config import as_array, check_choice, check_psd, check_range
from coloc_env.rendering import Link, Scene, ring_layout
from coloc_env.scenarios.base import Scenario
from coloc_env.world.delay_links import BernoulliDelayLink
from coloc_env.world.sensors import LinearSensor
from coloc_env.world.target import ConstantVelocityTarget

AGE_SCALE = 10.0
_OUTCOME_NAMES = {lf.ON_TIME: "on time", lf.LATE: "late", lf.LOST: "lost"}


def _diag(*values):
    return tuple(tuple(v if i == j else 0.0 for j in range(len(values))) for i, v in enumerate(values))


@dataclass(frozen=True)
class LossyFusionConfig:
    """Configuration of ``lossy_fusion``; defaults are the paper's simulation (Sec. 4)."""

    num_uavs: int = 2
    period: float = 1.0
    accel_noise: float = 5.0
    measurement_noise: float = 10.0
    initial_state: tuple = (100.0, 10.0, 100.0, 10.0, 100.0, 0.0)
    initial_cov: tuple = _diag(100.0, 5.0, 100.0, 5.0, 100.0, 5.0)
    on_time_probability: float = 0.4
    late_probability: float = 0.3
    horizon: int = 100
    reward: str = "error"
    message_cost: float = 0.0
    weight_logit_scale: float = 3.0

    @property
    def target(self) -> ConstantVelocityTarget:
        return ConstantVelocityTarget(3, self.period, self.accel_noise)

    @property
    def link(self) -> BernoulliDelayLink:
        return BernoulliDelayLink(self.on_time_probability, self.late_probability)

    @property
    def sensor(self) -> LinearSensor:
        return LinearSensor(self.target.position_matrix, float(self.measurement_noise) * np.eye(3))

    def validate(self) -> None:
        check_range("num_uavs", self.num_uavs, 2, 16, integer=True)
        self.target.validate()
        check_range("measurement_noise", self.measurement_noise, 1e-6, 1e12)
        as_array("initial_state", self.initial_state, shape=(6,), bound=1e6)
        check_psd("initial_cov", self.initial_cov, 6, strict=True, bound=1e12)
        self.link.validate("on_time_probability", "late_probability")
        check_range("horizon", self.horizon, 1, 100_000, integer=True)
        check_choice("reward", self.reward, ("error", "trace"))
        check_range("message_cost", self.message_cost, 0.0, 1e12)
        check_range("weight_logit_scale", self.weight_logit_scale, 0.0, 50.0, low_open=True)

    def lossy_model(self) -> lf.LossyModel:
        L, target = self.num_uavs, self.target
        return lf.LossyModel(
            transition=target.transition,
            process_noise=target.process_noise,
            measurement=target.position_matrix,
            measurement_noise=np.broadcast_to(self.sensor.noise, (L, 3, 3)).copy(),
            on_time=np.r_[1.0, np.full(L - 1, float(self.on_time_probability))],
            late=np.r_[0.0, np.full(L - 1, float(self.late_probability))],
        )

    def sample_episodes(self, rng: np.random.Generator, size: tuple[int, ...] = ()) -> dict[str, np.ndarray]:
        """Whole episodes drawn from ``rng`` in blocks, in this order: x(0), accelerations, measurement
        noise, link outcomes. Returns ``truth`` (*size, K, 6), ``z`` (*size, K, L, 3) and ``outcome``
        (*size, K, L) (the leader's column always on time)."""
        K, L = self.horizon, self.num_uavs
        target, sensor = self.target, self.sensor
        x0 = rng.multivariate_normal(np.asarray(self.initial_state, float), np.asarray(self.initial_cov, float),
                                     size=size)
        accelerations = target.sample_noise(rng, (*size, K - 1))
        noise = sensor.sample_noise(rng, (*size, K, L))
        follower_outcome = self.link.sample(rng, (*size, K, L - 1))
        truth = target.trajectory(x0, accelerations)
        z = sensor.measure(truth[..., None, :], noise)
        outcome = np.concatenate([np.full((*size, K, 1), lf.ON_TIME, np.int8), follower_outcome], axis=-1)
        return {"truth": truth, "z": z, "outcome": outcome}


class LossyFusionScenario(Scenario):
    """Batched core of ``lossy_fusion``; see the module docstring for the table."""

    name = "lossy_fusion"
    paper = "fu2017"
    Config = LossyFusionConfig

    def __init__(self, config: LossyFusionConfig, batch: int = 1):
        super().__init__(config, batch)
        self.model = config.lossy_model()
        self.H = config.target.position_matrix
        self._x0 = np.asarray(config.initial_state, float)
        self._P0 = np.asarray(config.initial_cov, float)
        self._compensation = lf.compensation_weights(self.model.on_time[1:], self.model.late[1:])
        B, L, K = self.batch, self.num_agents, self.horizon
        self.k = np.zeros(B, dtype=int)
        self.truth = np.zeros((B, K, 6))
        self.z = np.zeros((B, K, L, 3))
        self.outcome = np.zeros((B, K, L), dtype=np.int8)
        self.fusion = lf.distributed_initial(self.model, self._x0, self._P0, (B,))
        self.local = np.broadcast_to(self._x0, (B, L - 1, 6)).copy()
        self.local_cov = np.broadcast_to(self._P0, (B, L - 1, 6, 6)).copy()
        self.transmitted = np.zeros((B, L - 1), bool)
        self._reward = np.zeros((B, L))

    # --- description ------------------------------------------------------------
    @property
    def action_dim(self) -> int:
        L = self.num_agents
        return 1 + L + 3 * (L - 1)

    @property
    def obs_dim(self) -> int:
        return 3 + 4 * (self.num_agents - 1)

    def observation_space(self):
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(self.obs_dim,), dtype=np.float32)

    def action_space(self):
        # cached: check_actions asks for it every step
        if not hasattr(self, "_action_space"):
            self._action_space = gymnasium.spaces.Box(-1.0, 1.0, shape=(self.action_dim,), dtype=np.float64)
        return self._action_space

    def state_space(self):
        dim = self.num_agents * self.obs_dim + 3 * (self.num_agents - 1)
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(dim,), dtype=np.float32)

    # --- action encoding --------------------------------------------------------
    def decode_actions(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Actions (B, N, A) -> transmit (B, L-1) bool, compensation weights (B, L-1, 3), fusion factors (B, L)."""
        L, scale = self.num_agents, self.config.weight_logit_scale
        actions = np.clip(actions, -1.0, 1.0)
        transmit = actions[:, 1:, 0] >= 0.0
        leader = actions[:, 0]
        fusion_factors = np.exp(scale * leader[:, 1:1 + L])
        tilt = leader[:, 1 + L:].reshape(-1, L - 1, 3)
        compensation = self._compensation * np.exp(scale * tilt)
        compensation = compensation / compensation.sum(axis=-1, keepdims=True)
        return transmit, compensation, fusion_factors

    def paper_actions(self) -> np.ndarray:
        """The action (N, A) of the paper's algorithm: every follower transmits, weights (29)/(30)."""
        actions = np.zeros((self.num_agents, self.action_dim))
        actions[:, 0] = 1.0
        return actions

    # --- dynamics ----------------------------------------------------------------
    def reset(self, rngs, env_index=None) -> None:
        idx = self._indices(env_index)
        if len(rngs) != len(idx):
            raise ValueError(f"reset needs one generator per copy: {len(idx)} copies, {len(rngs)} generators")
        for b, rng in zip(idx, rngs, strict=True):
            # One block per episode so that stepping never loops over copies.
            episode = self.config.sample_episodes(rng)
            self.truth[b], self.z[b], self.outcome[b] = episode["truth"], episode["z"], episode["outcome"]
        fresh = lf.distributed_initial(self.model, self._x0, self._P0, (len(idx),))
        for field, value in vars(fresh).items():
            getattr(self.fusion, field)[idx] = value
        self.local[idx] = self._x0
        self.local_cov[idx] = self._P0
        self.transmitted[idx] = False
        self.k[idx] = 0
        self._reward[idx] = 0.0

    def step(self, actions) -> None:
        actions = self.check_actions(actions)
        if np.any(self.k >= self.horizon):
            raise RuntimeError("step() on a copy whose episode is over; reset it first")
        self.advance(*self.decode_actions(actions))

    def advance(self, transmit: np.ndarray, compensation: np.ndarray, fusion_factors: np.ndarray) -> None:
        """Step with decoded decisions: transmit (B, L-1), compensation (B, L-1, 3), fusion factors (B, L)."""
        rows = np.arange(self.batch)
        self.fusion = lf.distributed_step(self.model, self.fusion, self.z[rows, self.k], self.outcome[rows, self.k],
                                          transmit, compensation, fusion_factors)
        self.local = self.fusion.packet[..., 0, :].copy()
        self.local_cov = self.fusion.packet_cov[..., 0, :, :].copy()
        self.transmitted = np.asarray(transmit, bool).copy()
        self.k = self.k + 1
        if self.config.reward == "error":
            loss = self._fused_error()
        else:
            loss = self._claimed_trace()
        sent = np.concatenate([np.zeros((self.batch, 1)), self.transmitted], axis=1)
        self._reward = -loss[:, None] - self.config.message_cost * sent

    # --- views -------------------------------------------------------------------
    def _current_truth(self) -> np.ndarray:
        """x(k) of the last slot stepped (x(0) before the first step), (B, 6)."""
        return self.truth[np.arange(self.batch), np.maximum(self.k - 1, 0)]

    def _fused_error(self) -> np.ndarray:
        return np.sum(((self.fusion.fused - self._current_truth()) @ self.H.T) ** 2, axis=-1)

    def _claimed_trace(self) -> np.ndarray:
        return np.trace(self.H @ self.fusion.fused_cov @ self.H.T, axis1=-2, axis2=-1)

    def observation(self) -> np.ndarray:
        B, L = self.batch, self.num_agents
        obs = np.zeros((B, L, self.obs_dim))
        obs[:, 0, 0] = 1.0
        obs[:, :, 1] = (self.k / self.horizon)[:, None]
        obs[:, 0, 2] = np.log(np.trace(self.fusion.fused_cov, axis1=-2, axis2=-1))
        obs[:, 1:, 2] = np.log(np.trace(self.local_cov, axis1=-2, axis2=-1))
        obs[:, 0, 3:3 + (L - 1)] = self.fusion.held_age / AGE_SCALE
        obs[:, 0, 3 + (L - 1):] = np.log(np.trace(self.fusion.held_cov, axis1=-2, axis2=-1)).reshape(B, -1)
        return obs.astype(np.float32)

    def reward(self) -> np.ndarray:
        return self._reward.copy()

    def episode_error(self, errors: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """The paper's metric: the fused position MSE averaged over the slots (every agent holds the
        same fused error, so averaging over agents changes nothing)."""
        return np.asarray(errors, float).mean(axis=(-2, -1))

    def done(self) -> np.ndarray:
        return self.k >= self.horizon

    def _last_outcome(self) -> np.ndarray:
        """This slot's link draws (B, L); on time for every link before the first step."""
        last = self.outcome[np.arange(self.batch), np.maximum(self.k - 1, 0)]
        return np.where((self.k > 0)[:, None], last, lf.ON_TIME)

    def state(self) -> np.ndarray:
        one_hot = np.eye(3)[self._last_outcome()[:, 1:]] * (self.k > 0)[:, None, None]
        return np.concatenate([self.observation().reshape(self.batch, -1), one_hot.reshape(self.batch, -1)],
                              axis=-1).astype(np.float32)

    def info(self) -> dict[str, np.ndarray]:
        B, L = self.batch, self.num_agents
        truth = self._current_truth() @ self.H.T
        fused = self.fusion.fused @ self.H.T
        local = np.concatenate([self.fusion.fused[:, None], self.local], axis=1) @ self.H.T
        error = self._fused_error()
        zeros = np.zeros((B, 1))
        return {
            "true_position": np.broadcast_to(truth[:, None], (B, L, 3)).copy(),
            "estimated_position": np.broadcast_to(fused[:, None], (B, L, 3)).copy(),
            "error": np.broadcast_to(error[:, None], (B, L)).copy(),
            "claimed_trace": np.broadcast_to(self._claimed_trace()[:, None], (B, L)).copy(),
            "local_estimate": local,
            "local_error": np.sum((local - truth[:, None]) ** 2, axis=-1),
            "communication": np.concatenate([zeros, self.transmitted.astype(float)], axis=1),
            "packet_age": np.concatenate([zeros, self.fusion.held_age.astype(float)], axis=1),
            "link_outcome": self._last_outcome().astype(int),
            "delivered": np.concatenate([np.full((B, 1), lf.ON_TIME), self.fusion.delivered], axis=1).astype(int),
            "fusion_weight": self.fusion.weights.copy(),
            "step": np.broadcast_to(self.k[:, None], (B, L)).copy(),
        }

    def scene(self, b: int) -> Scene:
        L, k = self.num_agents, int(self.k[b])
        xy = [0, 2]  # x and y positions in the state
        estimates = np.concatenate([self.fusion.fused[b][None], self.local[b]])[:, xy]
        covs = np.concatenate([self.fusion.fused_cov[b][None], self.local_cov[b]])[:, xy][:, :, xy]
        truth_xy = self._current_truth()[b, xy]
        spread = max(20.0, 3.0 * float(np.sqrt(covs[:, [0, 1], [0, 1]].max())),
                     1.2 * float(np.abs(estimates - truth_xy).max()))
        start = max(0, k - 10)
        links = []
        for f in range(1, L):
            code = int(self.fusion.delivered[b, f - 1]) if k else lf.LOST
            sent = bool(self.transmitted[b, f - 1])
            value = {lf.ON_TIME: 1.0, lf.LATE: 0.5}.get(code, 0.0)
            label = _OUTCOME_NAMES[code] if code != lf.LOST else ("lost" if sent else "silent")
            if k and code == lf.LOST and sent and self._last_outcome()[b, f] == lf.LATE:
                label = "late, nothing sent before"
            links.append(Link(source=f, target=0, value=value, label=label))
        fused_err = float(self._fused_error()[b])
        return Scene(
            title=f"lossy_fusion (fu2017)  k = {k}/{self.horizon}",
            truth=truth_xy[None],
            estimates=estimates,
            covariances=covs,
            trails=self.truth[b, start:max(k, 1), :][:, xy][None],
            node_positions=ring_layout(L),
            node_labels=self.agent_names,
            estimate_labels=[f"{self.agent_names[0]} (fused)"] + [f"{a} (own filter)" for a in self.agent_names[1:]],
            links=links,
            link_value_max=1.0,
            link_value_name="packet (1 on time, 0.5 late)",
            extent=(truth_xy[0] - spread, truth_xy[0] + spread, truth_xy[1] - spread, truth_xy[1] + spread),
            notes=["uav_0: the fused estimate; followers: their own filters",
                   f"fused squared error {fused_err:.1f} m^2, claimed tr P0 {self._claimed_trace()[b]:.1f} m^2"],
        )
