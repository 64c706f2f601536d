"""``lossy_fusion``: cooperative target localization over lossy, delayed links (Fu, Bi, Gao 2017).

Paper: Fu, Bi, Gao, "Multi-UAVs Cooperative Localization Algorithms with
Communication Constraints", Hindawi, 2017 (seed ``000_de65bd0f0f4a0cb7.txt``);
estimator in ``estimators.lossy_fusion``.

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

The preset is the composition ``target_cv`` / ``bernoulli_delay`` /
``prediction_compensation`` (``LossyFusionConfig.parts``) with this
action codec, observation and info. The world draws the episode (x(0), the
accelerations, the measurement noise) from the episode's generator
(``coloc_env.worlds.target_cv``); the link outcomes are the network's
counter-based draws from its own generator, fixed at reset
(``LossyFusionScenario.link_outcomes``). One reading differs from eq. (3)
as printed and changes no estimate: a "late" outcome after an on-time
packet delivers nothing (the packet it would re-deliver is the one already
held; ``delivered`` then says lost, and the held value and its age are the
same either way).

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

Observation (per agent, ``Box(shape=(3 + 4 (L-1) + L + 5,), float32)``)
---------------------------------------------------------------------
| index                      | leader                                        | follower                | bounds    |
|----------------------------|-----------------------------------------------|-------------------------|-----------|
| ``[0]``                    | 1 (role)                                      | 0                       | [0, 1]    |
| ``[1]``                    | slots done / horizon                          | same                    | [0, 1]    |
| ``[2]``                    | log tr P0 (its fused covariance, eq. 30)      | log tr of its own P(k|k)| unbounded |
| ``[3, 3+(L-1))``           | per follower, slots since its held packet     | 0                       | [0, inf)  |
|                            | arrived, / 10 (with ``time_stamps``: the      |                         |           |
|                            | packet's age, slots since it was formed)      |                         |           |
| ``[3+(L-1), 3+4(L-1))``    | log tr of the three covariances in that       | 0                       | unbounded |
|                            | packet, follower-major                        |                         |           |
| ``[3+4(L-1), 3+4(L-1)+L)`` | ``index``: one-hot of the UAV's own index     | same                    | [0, 1]    |
| ``[-5]``                   | ``log_trace``: log tr of the position block   | of its own P(k|k)       | [-50, 50] |
|                            | of its P0 (m^2), clipped                      |                         |           |
| ``[-4]``                   | ``displacement``: how far its position        | same (its own filter's) | [0, inf)  |
|                            | estimate moved since its reference packet,    |                         |           |
|                            | / 100 m                                       |                         |           |
| ``[-3]``                   | ``steps_since``: slots since its reference    | same                    | [0, 1]    |
|                            | packet / horizon                              |                         |           |
| ``[-2]``                   | ``message_value``: max(0, tr(P_ref + (k -     | same                    | [0, inf)  |
|                            | k_ref) Q_pos) - tr P_k), m^2                  |                         |           |
| ``[-1]``                   | ``communication_cost``: its copy's cost per   | same                    | [0, inf)  |
|                            | packet this episode (``communication_cost``,  |                         |           |
|                            | or the draw from ``cost_range``), m^2         |                         |           |

The named entries are the composed observation's features (``feature_index``). The reference packet is the
agent's last slot with a packet sent (``transmissions`` > 0; ``bernoulli_delay`` gives no acknowledgements), the
episode's start before any (``coloc_env.scenarios.composed``, "Since the last transmission"); the leader never
sends, so its reference stays the start. The event-triggered families (``agents.event_triggered``) decide a
follower's transmit entry (0): send = ``paper``'s (1, = ``always``), quiet = -1 (``silent``), every tilt
``paper``'s.

The log-traces are unbounded (a filter fed by nothing but losses grows its covariance without
limit); the packet ages have no upper bound, since a link can lose every packet of an episode of any
``horizon``.

Packets carry no time stamp in the paper, so without ``time_stamps`` the leader cannot
tell a late packet from an on-time one: it knows only when each packet arrived (a late
packet held since it arrived is one slot older than the entry says). With ``time_stamps=True``
the entry is the packet's age (packets stamped with their slot, one more number on the air, not
counted in ``floats_sent``, which counts the estimates).

``state()`` (centralized critic): every agent's observation, then the one-hot
link outcome of each follower's last slot (on time, late, lost).

Reward (the fused estimate is shared: every agent gets the team's loss)
----------------------------------------------------------------------
| ``reward=``  | value after slot k (m^2)                                                 |
|--------------|-------------------------------------------------------------------------|
| ``"error"``  | -||H (x0hat(k) - x(k))||^2, the fused squared position error (m^2)       |
| ``"trace"``  | -tr(H P0(k) H^T), the leader's own (eq. 30) position covariance (m^2,    |
|              | the unit of ``error``; the ``trace`` info key is the same number)        |

minus ``communication_cost`` (m^2; under ``cost_range``, its copy's draw of the episode) for each packet the
agent itself sent this
slot (followers only). Note that the paper's inverse-trace weights already minimize
tr P0 = sum a_i^2 tr P_i, so ``"trace"`` rewards exactly the paper's weights.

Termination: none; truncation after ``horizon`` slots (the paper's 100).

``infos[agent]``: ``true_position`` (3-D, m), ``estimated_position`` (the fused
estimate, the same for all), ``position_error`` (||H (x0hat - x)||, m),
``error`` (its square, m^2, the same for all; the episode metric averages it
over slots and agents), ``trace`` and ``claimed_trace`` (tr H P0 H^T, m^2),
``messages_sent`` (packets this agent sent this slot, as the network counts
them; also ``communication``), ``floats_sent`` (their floats: three
estimates and three covariances of the 6-state, 3 n + 3 n (n + 1) / 2 = 81 a
packet), ``local_estimate`` and
``local_error`` (the agent's own filter: the leader's is the fused one),
``packet_age`` (age of
the packet the leader holds from this follower; 0 for the leader),
``link_outcome`` (this slot's draw of the link to the leader: 0 on time, 1 late,
2 lost), ``delivered``
(what arrived: 0 on time, 1 late packet, 2 nothing), ``fusion_weight``
(a_i), the network's per-link counts ``transmissions``, ``link_attempts``, ``link_deliveries``,
``collisions`` (the table of ``coloc_env.networks.base``), ``step``.

Arguments (fields of ``LossyFusionConfig``, defaults = the paper)
---------------------------------------------------------------------
Each keyword sets the field of the same name of the part in ``sets``, whose check is the one that
runs (a refused value is reported as ``lossy_fusion: <keyword> must be ...``); ``preset``: read by
this module only. Older keywords, still accepted by ``make`` and ``parallel_env`` (give one name of
a pair): ``num_uavs`` for ``num_agents``, ``message_cost`` for ``communication_cost``.

| field               | default                      | allowed                                   | sets              |
|---------------------|------------------------------|-------------------------------------------|-------------------|
| num_agents          | 2                            | 2..16: L, the leader included             | world             |
| period              | 1.0                          | (0, 1e4] s: T; with accel_noise, the      | world             |
|                     |                              | process noise q G G^T must pass the       |                   |
|                     |                              | model's PSD check (a large q T^4 fails)   |                   |
| accel_noise         | 5.0                          | [0, 1e12] m^2/s^4 per axis: q             | world             |
| measurement_noise   | 10.0                         | [1e-6, 1e12] m^2 per axis: r              | world             |
| initial_state       | (100, 10, 100, 10, 100, 0)   | (6,) in [-1e6, 1e6]: X0; x(0) ~ N(X0, P0) | world             |
| initial_cov         | diag(100, 5, 100, 5, 100, 5) | (6, 6) positive definite, entries         | world             |
|                     |                              | <= 1e12: P0 (the observation divides by   |                   |
|                     |                              | its trace)                                |                   |
| on_time_probability | 0.4                          | [0, 1]: alpha1                            | network           |
| late_probability    | 0.3                          | [0, 1]: alpha2; alpha1 + alpha2 in (0, 1] | network           |
| horizon             | 100                          | 1..100000 slots                           | world, composition|
| reward              | "error"                      | "error", "trace" (both m^2)               | composition       |
| communication_cost  | 0.0                          | [0, 1e12] m^2 per packet sent             | composition       |
| cost_range          | None                         | None, or (lo, hi) with 0 <= lo <= hi      | composition       |
|                     |                              | <= 1e12: each copy draws its cost per     |                   |
|                     |                              | episode at reset (the composition's law), |                   |
|                     |                              | replacing ``communication_cost``          |                   |
| weight_logit_scale  | 3.0                          | (0, 50]                                   | backend           |
| time_stamps         | False                        | bool: packets carry their slot (the       | preset            |
|                     |                              | observation shows ages, not arrivals)     |                   |
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np

import estimators.lossy_fusion as lf
from coloc_env.backends.fusion import PredictionCompensation
from coloc_env.networks.bernoulli_delay import BernoulliDelay
from coloc_env.parts import check_flag
from coloc_env.rendering import Link, Scene, ring_layout
from coloc_env.scenarios.binding import PresetConfig, PresetScenario, keyword, register_preset
from coloc_env.worlds.target_cv import TargetCv

AGE_SCALE = 10.0
_OUTCOME_NAMES = {lf.ON_TIME: "on time", lf.LATE: "late", lf.LOST: "lost"}


@dataclass(frozen=True)
class LossyFusionConfig(PresetConfig):
    """Configuration of ``lossy_fusion``; defaults are the paper's simulation (Sec. 4)."""

    preset = "lossy_fusion"
    World, Network, Backend = TargetCv, BernoulliDelay, PredictionCompensation
    aliases = {"num_uavs": "num_agents", "message_cost": "communication_cost"}

    num_agents: int = keyword(2, "world.num_agents")
    period: float = keyword(1.0, "world.period")
    accel_noise: float = keyword(5.0, "world.accel_noise")
    measurement_noise: float = keyword(10.0, "world.measurement_noise")
    initial_state: tuple = keyword(TargetCv.initial_state, "world.initial_state")
    initial_cov: tuple = keyword(TargetCv.initial_cov, "world.initial_cov")
    on_time_probability: float = keyword(0.4, "network.on_time_probability")
    late_probability: float = keyword(0.3, "network.late_probability")
    horizon: int = keyword(100, "world.horizon", "composition.horizon")
    reward: str = keyword("error", "composition.reward")
    communication_cost: float = keyword(0.0, "composition.communication_cost")
    cost_range: tuple | None = keyword(None, "composition.cost_range")
    weight_logit_scale: float = keyword(3.0, "backend.weight_logit_scale")
    time_stamps: bool = keyword(False, "preset")

    def check_preset(self) -> None:
        check_flag("time_stamps", self.time_stamps)


@register_preset
class LossyFusionScenario(PresetScenario):
    """Batched core of ``lossy_fusion``: the binding of ``LossyFusionConfig`` on the composable core
    (``target_cv`` / ``bernoulli_delay`` / ``prediction_compensation``); the module docstring has the table."""

    name = "lossy_fusion"
    paper = "fu2017"
    Config = LossyFusionConfig
    version = 2
    metric = "fused position MSE averaged over the slots"
    metric_unit = "m^2"
    communication = "messages transmitted"
    policy_module = "agents.lossy_fusion"
    appended_features = ("index", "log_trace", "displacement", "steps_since", "message_value", "communication_cost")

    def __init__(self, config: LossyFusionConfig, batch: int = 1):
        super().__init__(config, batch)
        self.H = self.world.metric
        self._action_space = gymnasium.spaces.Box(-1.0, 1.0, shape=(self.action_dim,), dtype=np.float64)
        self._outcomes = np.zeros((self.batch, self.horizon, self.num_agents), np.int8)
        self._since_arrival = np.zeros((self.batch, self.num_agents - 1))  # slots since each held packet arrived

    # --- the parts' state, by the paper's names ------------------------------------------
    @property
    def model(self) -> lf.LossyModel:
        return self.backend.model

    @property
    def fusion(self) -> lf.DistributedState:
        """The leader's and the followers' filter state (``estimators.lossy_fusion.DistributedState``)."""
        return self.backend.fusion

    @property
    def z(self) -> np.ndarray:
        """Every UAV's measurement of every slot (B, K, L, 3)."""
        return self.world.observations

    @property
    def local(self) -> np.ndarray:
        """The followers' own x(k|k) (B, L - 1, 6): the first entry of the packet each would send."""
        return self.fusion.packet[..., 0, :]

    @property
    def local_cov(self) -> np.ndarray:
        return self.fusion.packet_cov[..., 0, :, :]

    @property
    def transmitted(self) -> np.ndarray:
        """(B, L - 1) the followers that sent their packet this slot."""
        return self.network.messages_sent[:, 1:] > 0

    def link_outcomes(self) -> np.ndarray:
        """(B, K, L) each follower's link outcome to the leader at each slot (0 on time, 1 late, 2 lost; the
        leader's own column on time): the network's draws, fixed at reset (its
        ``coloc_env.networks.bernoulli_delay.BernoulliDelayNetwork.slot_outcomes``)."""
        return self._outcomes.copy()

    # --- description ------------------------------------------------------------
    @property
    def action_dim(self) -> int:
        L = self.num_agents
        return 1 + L + 3 * (L - 1)

    @property
    def obs_dim(self) -> int:
        return 3 + 4 * (self.num_agents - 1) + self.appended_size()

    def observation_space(self):
        followers = self.num_agents - 1
        low = np.concatenate([[0.0, 0.0, -np.inf], np.zeros(followers), np.full(3 * followers, -np.inf)])
        high = np.concatenate([[1.0, 1.0, np.inf], np.full(followers, np.inf), np.full(3 * followers, np.inf)])
        return self.extend_space(gymnasium.spaces.Box(low.astype(np.float32), high.astype(np.float32),
                                                      dtype=np.float32))

    def transport_entries(self) -> tuple[np.ndarray, np.ndarray]:
        """Entry 0, the transmit decision (>= 0 transmits); quiet: -1 (``silent``)."""
        entries, quiet = np.zeros(self.action_dim, bool), np.zeros(self.action_dim)
        entries[0], quiet[0] = True, -1.0
        return entries, quiet

    def preset_feature_positions(self) -> dict[str, int]:
        """The composed table's features among this observation's own entries: ``step_fraction`` (entry 1)."""
        return {"step_fraction": 1}

    def state_space(self):
        dim = self.num_agents * self.obs_dim + 3 * (self.num_agents - 1)
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(dim,), dtype=np.float32)

    # --- action encoding --------------------------------------------------------
    def decode_actions(self, actions) -> np.ndarray:
        """Actions (B, N, A) -> the parts' blocks: the network's ``transmit`` (1 where entry 0 >= 0) and the
        backend's fusion and compensation tilts (entries 1.., clipped to [-1, 1]), in the same order."""
        arr = np.clip(self.check_actions(actions), -1.0, 1.0)
        return np.concatenate([(arr[..., :1] >= 0.0).astype(float), arr[..., 1:]], axis=-1)

    # --- dynamics ----------------------------------------------------------------
    def reset(self, rngs, env_index=None) -> None:
        super().reset(rngs, env_index)
        idx = self._indices(env_index)
        codes = self.network.slot_outcomes(range(self.horizon))[:, :, :, 0]  # every link to the leader
        codes[..., 0] = lf.ON_TIME
        self._outcomes[idx] = codes[idx]
        self._since_arrival[idx] = self.fusion.held_age[idx]  # the prior held as packet: no arrival yet

    def advance(self, decoded) -> None:
        super().advance(decoded)
        arrived = self.fusion.delivered != lf.LOST
        self._since_arrival = np.where(arrived, 0.0, self._since_arrival + 1.0)

    # --- views -------------------------------------------------------------------
    def true_position(self) -> np.ndarray:
        """The target's true position H x(k) at the slot of the current estimate, once per UAV (B, L, 3) (the
        episode's states x(0..K) are ``world.truth``)."""
        truth = self._truth_state @ self.H.T
        return np.broadcast_to(truth[:, None], (self.batch, self.num_agents, 3)).copy()

    def _fused_error(self) -> np.ndarray:
        return self.target_error()[:, 0]

    def _claimed_trace(self) -> np.ndarray:
        return np.trace(self.H @ self.fusion.fused_cov @ self.H.T, axis1=-2, axis2=-1)

    def observation(self) -> np.ndarray:
        B, L = self.batch, self.num_agents
        fusion = self.fusion
        obs = np.zeros((B, L, self.obs_dim - self.appended_size()))
        obs[:, 0, 0] = 1.0
        obs[:, :, 1] = (self.k / self.horizon)[:, None]
        # the ndarray.trace method: np.trace's dispatch costs more than the trace at these sizes
        obs[:, 0, 2] = np.log(fusion.fused_cov.trace(axis1=-2, axis2=-1))
        obs[:, 1:, 2] = np.log(self.local_cov.trace(axis1=-2, axis2=-1))
        age = fusion.held_age if self.config.time_stamps else self._since_arrival
        obs[:, 0, 3:3 + (L - 1)] = age / AGE_SCALE
        obs[:, 0, 3 + (L - 1):] = np.log(fusion.held_cov.trace(axis1=-2, axis2=-1)).reshape(B, -1)
        return self.extend_observation(obs)

    def episode_error(self, errors: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """The paper's metric: the fused position MSE averaged over the slots (every agent holds the
        same fused error, so averaging over agents changes nothing)."""
        return np.asarray(errors, float).mean(axis=(-2, -1))

    def _last_outcome(self) -> np.ndarray:
        """This slot's link draws (B, L); on time for every link before the first step."""
        last = self._outcomes[np.arange(self.batch), np.maximum(self.k - 1, 0)]
        return np.where((self.k > 0)[:, None], last, lf.ON_TIME)

    def state(self) -> np.ndarray:
        one_hot = np.eye(3)[self._last_outcome()[:, 1:]] * (self.k > 0)[:, None, None]
        return np.concatenate([self.observation().reshape(self.batch, -1), one_hot.reshape(self.batch, -1)],
                              axis=-1).astype(np.float32)

    def info(self) -> dict[str, np.ndarray]:
        B, L = self.batch, self.num_agents
        fusion = self.fusion
        truth = self.true_position()
        fused = self.backend.posterior_state[:, 0] @ self.H.T
        local = np.concatenate([fusion.fused[:, None], self.local], axis=1) @ self.H.T
        error = self._fused_error()
        claimed = self._claimed_trace()
        zeros = np.zeros((B, 1))
        team = lambda values: np.broadcast_to(np.asarray(values)[:, None], (B, L)).copy()  # noqa: E731
        return {
            "true_position": truth,
            "estimated_position": np.broadcast_to(fused[:, None], (B, L, 3)).copy(),
            "position_error": team(np.sqrt(error)),
            "error": team(error),
            "trace": team(claimed),
            "claimed_trace": team(claimed),
            "local_estimate": local,
            "local_error": np.sum((local - truth) ** 2, axis=-1),
            "messages_sent": self.network.messages_sent.copy(),
            **self.link_counts(),
            "floats_sent": self.network.floats_sent.copy(),
            "communication": self.network.messages_sent.copy(),
            "packet_age": np.concatenate([zeros, fusion.held_age.astype(float)], axis=1),
            "link_outcome": self._last_outcome().astype(int),
            "delivered": np.concatenate([np.full((B, 1), lf.ON_TIME), fusion.delivered], axis=1).astype(int),
            "fusion_weight": fusion.weights.copy(),
            "step": team(self.k),
        }

    def scene(self, b: int) -> Scene:
        L, k = self.num_agents, int(self.k[b])
        xy = [0, 2]  # x and y positions in the state
        estimates = np.concatenate([self.fusion.fused[b][None], self.local[b]])[:, xy]
        covs = np.concatenate([self.fusion.fused_cov[b][None], self.local_cov[b]])[:, xy][:, :, xy]
        truth_xy = self._truth_state[b, xy]
        spread = max(20.0, 3.0 * float(np.sqrt(covs[:, [0, 1], [0, 1]].max())),
                     1.2 * float(np.abs(estimates - truth_xy).max()))
        start = max(0, k - 10)
        last = self._last_outcome()
        links = []
        for f in range(1, L):
            code = int(self.fusion.delivered[b, f - 1]) if k else lf.LOST
            sent = bool(self.transmitted[b, f - 1])
            value = {lf.ON_TIME: 1.0, lf.LATE: 0.5}.get(code, 0.0)
            label = _OUTCOME_NAMES[code] if code != lf.LOST else ("lost" if sent else "silent")
            if k and code == lf.LOST and sent and last[b, f] == lf.LATE:
                label = "late, nothing sent before"
            links.append(Link(source=f, target=0, value=value, label=label))
        fused_err = float(self._fused_error()[b])
        return Scene(
            title=f"lossy_fusion (fu2017)  k = {k}/{self.horizon}",
            truth=truth_xy[None],
            estimates=estimates,
            covariances=covs,
            trails=self.world.truth[b, start:max(k, 1), :][:, xy][None],
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

