"""``gps_denied_nbp``: UAVs that lost GPS localize by dynamic NBP over range links (Wan et al. 2014).

Paper: Wan, Zhong, Zhang, "Cooperative localization of multi-UAVs via dynamic
nonparametric belief propagation under GPS signal loss condition", IJDSN 2014
(seed ``003_44c6eab8acc44e0f.txt``). Its equations were lost in extraction;
the model is the reconstruction in ``docs/wan2014.md`` (tags [paper] /
[chosen] as there). Estimator: ``estimators.dnbp``; baselines (LS of ref. [7],
dead reckoning): ``estimators.range_ls``.

N UAVs fly at a common nominal velocity in 2-D, each GPS receiver switches
between normal and fault by a Markov chain, UAVs within the range R measure
their distance and can talk: the ``gps_denied`` world, which draws each
episode (``coloc_env.worlds.gps_denied``). One env step is one time step tau:
the UAVs run ``num_iterations`` NBP iterations over the broadcast medium with
the paper's modified schedule (normal UAVs broadcast at iteration 0 to their
fault neighbours; a fault UAV may broadcast to its fault neighbours once it
has heard from theta distinct neighbours, theta = 3 -> 2 -> 1), then every
belief is propagated to tau + 1. The agents decide what the paper fixes:
whether to use each broadcast opportunity the schedule gives them.

Action (per UAV, ``MultiDiscrete([2] * num_iterations)``, int64)
-----------------------------------------------------------------
| index | meaning                                                                              |
|-------|--------------------------------------------------------------------------------------|
| ``n`` | 1 = broadcast my message in NBP iteration n of this step if the schedule allows it;  |
|       | a bit for an iteration in which the schedule does not allow me to send is ignored.   |

A value other than 0 or 1, a NaN or inf is a ``ValueError`` naming the iteration. ``paper``
(all ones) is the paper's schedule; all zeros reduces every fault UAV to dead
reckoning.

Observation (per UAV, ``Box(shape=(N + 14,), float32)``: the bounds column), about the coming step tau
----------------------------------------------------------------------------------------------
| index | meaning                                                                         |
|-------|---------------------------------------------------------------------------------|
| 0     | own GPS normal (1) or fault (0) at tau                                          |
| 1     | neighbours within R at tau, / (N - 1)                                           |
| 2     | GPS-normal neighbours at tau, / (N - 1)                                         |
| 3     | distinct UAVs heard from in the previous step, / (N - 1) (0 at reset)           |
| 4     | log(1 + spread) of the prior rho_tau, spread = sqrt(tr Cov(positions)) in metres |
| 5     | bimodality coefficient (g^2 + 1) / kappa of the prior along its principal axis  |
|       | (1/3 Gaussian, > 5/9 suggests a ring or two modes; at most 1 by Pearson's       |
|       | inequality kappa >= g^2 + 1, which the particles' moments obey too; clipped     |
|       | to 1 against rounding)                                                          |
| 6     | step fraction tau / horizon                                                     |
| 7     | what its neighbours already heard: the mean over its neighbours within R at tau |
|       | of the distinct UAVs each heard from in the previous step, / (N - 1) (0 without |
|       | neighbours and at reset) [chosen: each UAV's count rides on its beacon]          |

| index        | meaning (the composed observation's features, by name: ``feature_index``)  | bounds    |
|--------------|------------------------------------------------------------------------------|-----------|
| [8, 8 + N)   | ``index``: one-hot of the UAV's own index                                    | [0, 1]    |
| 8 + N        | ``log_trace``: log tr Cov_s of its belief (m^2, the ``trace`` info key),     | [-50, 50] |
|              | clipped                                                                      |           |
| 9 + N        | ``displacement``: how far its belief mean moved since its reference          | [0, inf)  |
|              | broadcast, / 100 m                                                           |           |
| 10 + N       | ``steps_since``: steps since its reference broadcast / horizon               | [0, 1]    |
| 11 + N       | ``message_value``: max(0, tr(Cov_ref + (k - k_ref) Q) - tr Cov_s), m^2       | [0, inf)  |
|              | (``Backend.message_value``; Q the backend's position process noise)          |           |
| 12 + N       | ``communication_cost``: lambda of its copy this episode                      | [0, inf)  |
|              | (``communication_cost``, or the draw from ``cost_range``), metres per        |           |
|              | broadcast                                                                    |           |

The reference broadcast is the UAV's last step with a broadcast (``transmissions`` > 0; the broadcast
network gives no acknowledgements), the episode's start before any (``coloc_env.scenarios.composed``,
"Since the last transmission"). The event-triggered families (``agents.event_triggered``) decide every
iteration bit of a step at once: send = ``paper`` (all ones, = ``always``), quiet = all zeros (``silent``).

Entry 4 is unbounded: a lost fault UAV's prior spreads without limit. Entry 7 serves
learning: a broadcast helps most where the neighbours heard little, which entry 3 (the UAV's own
count) does not show.

Truth is used only in the reward, never in observations. ``state()``
(centralized critic): every agent's observation, then log(1 + e_s) of the
last step's errors.

Reward (metres, the unit of ``error``: a distance)
--------------------------------------------------
e_s = ||p_hat_s - p_s|| of the belief mean at tau; sigma_s = sqrt(tr Cov_s), Cov_s the
backend's position covariance (the belief particles' sample covariance, plus the prior's
KDE kernel where the belief is its prior: ``estimators.dnbp``, "Reported covariance"; the
``trace`` info key is tr Cov_s, m^2); F_tau the
UAVs whose GPS is faulty at tau; lambda = ``communication_cost`` (under ``cost_range``, the copy's draw of the
episode).

| ``reward=`` | ``team_reward=True`` (every UAV)                   | ``team_reward=False`` (each UAV s) |
|-------------|-----------------------------------------------------|-------------------------------------|
| ``"error"`` | -mean_{s in F_tau} e_s - lambda (all broadcasts)     | -e_s - lambda (its own broadcasts)  |
| ``"trace"`` | -mean_{s in F_tau} sigma_s - lambda (all broadcasts) | -sigma_s - lambda (its broadcasts)  |

The mean over F_tau is 0 when no GPS is faulty. A broadcast is counted as the schedule
counts it (``infos["broadcasts"]``), heard or not. The reconstruction's optional
particle-count action (and its lambda_M term) is not implemented.

Termination: none; truncation after ``horizon`` steps (T = 30 [chosen]).

``infos[agent]``: ``true_position``, ``estimated_position`` (belief mean),
``position_error`` and ``error`` (the same distance, metres), ``trace`` (m^2, of the
position covariance Cov_s), ``fault`` (GPS faulty at tau), ``broadcasts`` (this
step, as the schedule counts them), ``communication`` (= broadcasts: what ``coloc
evaluate`` counts), ``messages_sent`` (the network's count at the sender: one per
broadcast that reached a listener), ``floats_sent`` (3 M + 1 floats per message),
``messages_received`` (directed: the messages this UAV took), ``neighbours``, the network's
per-link counts ``transmissions``, ``link_attempts``, ``link_deliveries``, ``collisions`` (the table
of ``coloc_env.networks.base``), ``step``.
At reset the estimate is the tau = 0 prior mean.

Composition: a binding (``coloc_env.scenarios.binding``) of world ``gps_denied``,
network ``broadcast`` (radius ``comm_range``, no loss) and backend ``dnbp``;
``coloc_env.PRESETS["gps_denied_nbp"]`` is that composition. Generators: the world
draws from the episode's generator itself, the backend from its first child, the
network from its second (``part_generators``).

Batching and seeding: reset draws each copy's whole episode from the copy's
generator in blocks (``coloc_env.worlds.gps_denied.sample_episode``); steps are
one batched call of ``estimators.dnbp.step`` (through the backend, each
iteration's delivery asked of the network) over copies, particles and
messages. What remains a loop over copies is the drawing of the particle
filter's random numbers (resampling, proposals, message directions): each copy
draws its block from its own estimator generator, so copy b of a batch is
bit-identical to the same seed run alone.

Arguments (fields of ``GpsDeniedNbpConfig``, defaults = docs/wan2014.md section 1)
--------------------------------------------------------------------------------
| field              | default     | allowed                   | tag / meaning                                |
|--------------------|-------------|---------------------------|----------------------------------------------|
| num_agents         | 10          | 2..128                    | N [chosen] (older name: ``num_uavs``)        |
| horizon            | 30          | 1..10000                  | T [chosen] (50 allowed)                      |
| dt                 | 1.0         | (0, 1000]                 | Delta t [chosen]                             |
| area               | 500         | (0, 1e7]                  | initial positions ~ U([0, area]^2) [chosen]  |
| nominal_velocity   | (20, 0)     | (2,) entries in [-1e4, 1e4] | v_nom [chosen]                             |
| velocity_spread    | 2.0         | [0, 1e4]                  | sigma_v0 [chosen]                            |
| accel_std          | 0.5         | [0, 1000]                 | sigma_a,true [chosen]                        |
| accel_noise_std    | 0.3         | [0.001, 1000]             | sigma_acc [chosen]                           |
| gps_std            | 3.0         | [0.001, 10000]            | sigma_gps [chosen]                           |
| range_std          | 2.0         | [0.001, 10000]            | sigma_d [chosen]                             |
| comm_range         | 300         | (0, 1e7]                  | R [chosen]; interesting band 200-350 [paper] |
| p_normal_to_fault  | 0.02        | [0, 1]                    | p_nf [chosen]                                |
| p_fault_to_normal  | 0.02        | [0, 1]                    | p_fn [chosen]                                |
| num_normal         | None        | None or 0..N              | fixed-proportion mode of Fig. 6(a) [paper]   |
| num_particles      | 100         | 2..5000                   | M [chosen]                                   |
| num_iterations     | 5           | 1..20                     | n_iter [chosen]; case study needs 3 [paper]  |
| oversampling       | 2           | 1..16                     | k_is [chosen]                                |
| defensive_weight   | 0.01        | [0, 0.999]                | eps_def [chosen]                             |
| init               | "warm"      | "warm", "cold"            | tau = 0 knowledge [chosen]                   |
| box_margin         | 150         | [0, 1e7]                  | cold box [-m, area+m]^2 [chosen]             |
| min_bandwidth      | 0.5         | [0.001, 10000]            | floor of h_ts [chosen]                       |
| initial_threshold  | 3           | 1..N, at most 64          | theta_0 [paper]                              |
| schedule           | "modified"  | "modified", "parallel"    | Sec. 3.4 [paper]; parallel = ablation        |
| kernel             | "truncated" | "exact", "truncated"      | belief-update mixture kernel [chosen]; the   |
|                    |             |                           | truncated one approximates (estimators.dnbp) |
| truncation         | 6.0         | [1, 10] bandwidths        | r of the truncated kernel [chosen]           |
| fault_message_power| 0.5         | (0, 1]                    | alpha: a fault sender's message enters as    |
|                    |             |                           | m^alpha [chosen] (estimators.dnbp); 1 = the  |
|                    |             |                           | paper's                                      |
| reward             | "error"     | "error", "trace"          | the reward table; the older "team" and "own" |
|                    |             |                           | are read as "error" with team_reward True /  |
|                    |             |                           | False                                        |
| team_reward        | True        | True, False               | the reward table's columns                   |
| communication_cost | 0.0         | [0, 1e12]                 | lambda, metres per broadcast (older name:    |
|                    |             |                           | ``broadcast_cost``)                          |
| cost_range         | None        | None, or (lo, hi) with 0 <= lo <= hi <= 1e12 | each copy draws its lambda per |
|                    |             |                           | episode at reset (the composition's rule and |
|                    |             |                           | generator: ``coloc_env.composition``); it    |
|                    |             |                           | replaces ``communication_cost``              |

Each keyword sets the part field of the same name (``comm_range``: the world's ranging radius and the
network's; ``horizon``, ``reward``, ``communication_cost`` and ``cost_range``: the composition's); each check is
the part's.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import gymnasium
import numpy as np

from coloc_env.backends.particles import Dnbp
from coloc_env.config import check_range
from coloc_env.networks.broadcast import Broadcast
from coloc_env.rendering import Scene
from coloc_env.scenarios.binding import PresetConfig, PresetScenario, keyword, register_preset
from coloc_env.worlds.gps_denied import GpsDenied

OBS_DIM = 8


@dataclass(frozen=True)
class GpsDeniedNbpConfig(PresetConfig):
    """Configuration of ``gps_denied_nbp``; defaults are docs/wan2014.md's (mostly [chosen])."""

    preset = "gps_denied_nbp"
    World, Network, Backend = GpsDenied, Broadcast, Dnbp
    aliases = {"num_uavs": "num_agents", "broadcast_cost": "communication_cost"}

    num_agents: int = keyword(10, "world.num_agents")
    horizon: int = keyword(30, "world.horizon", "composition.horizon")
    dt: float = keyword(1.0, "world.dt")
    area: float = keyword(500.0, "world.area")
    nominal_velocity: tuple = keyword((20.0, 0.0), "world.nominal_velocity")
    velocity_spread: float = keyword(2.0, "world.velocity_spread")
    accel_std: float = keyword(0.5, "world.accel_std")
    accel_noise_std: float = keyword(0.3, "world.accel_noise_std")
    gps_std: float = keyword(3.0, "world.gps_std")
    range_std: float = keyword(2.0, "world.range_std")
    comm_range: float = keyword(300.0, "world.comm_range", "network.comm_range")
    p_normal_to_fault: float = keyword(0.02, "world.p_normal_to_fault")
    p_fault_to_normal: float = keyword(0.02, "world.p_fault_to_normal")
    num_normal: int | None = keyword(None, "world.num_normal")
    num_particles: int = keyword(100, "backend.num_particles")
    num_iterations: int = keyword(5, "backend.num_iterations")
    oversampling: int = keyword(2, "backend.oversampling")
    defensive_weight: float = keyword(0.01, "backend.defensive_weight")
    init: str = keyword("warm", "backend.init")
    box_margin: float = keyword(150.0, "backend.box_margin")
    min_bandwidth: float = keyword(0.5, "backend.min_bandwidth")
    initial_threshold: int = keyword(3, "backend.initial_threshold")
    schedule: str = keyword("modified", "backend.schedule")
    kernel: str = keyword("truncated", "backend.kernel")
    truncation: float = keyword(6.0, "backend.truncation")
    fault_message_power: float = keyword(0.5, "backend.fault_message_power")
    reward: str = keyword("error", "composition.reward")
    team_reward: bool = keyword(True, "preset")
    communication_cost: float = keyword(0.0, "composition.communication_cost")
    cost_range: tuple | None = keyword(None, "composition.cost_range")

    def __post_init__(self):
        if isinstance(self.reward, str) and self.reward in ("team", "own"):  # the older spelling
            object.__setattr__(self, "team_reward", self.reward == "team")
            object.__setattr__(self, "reward", "error")

    def check_preset(self) -> None:
        """The backend's threshold against the world's N: a rule between two parts."""
        check_range("initial_threshold", self.initial_threshold, 1, self.num_agents, integer=True,
                    high_label="num_agents")


def bimodality(points: np.ndarray, centred: np.ndarray | None = None) -> np.ndarray:
    """Sarle's bimodality coefficient (g^2 + 1) / kappa of points (..., M, 2) along their principal axis
    (``centred``: points minus their mean, where the caller has them)."""
    if centred is None:
        centred = points - points.mean(axis=-2, keepdims=True)
    cov = np.einsum("...mi,...mj->...ij", centred, centred) / points.shape[-2]
    _, vectors = np.linalg.eigh(cov)
    x = np.einsum("...mi,...i->...m", centred, vectors[..., :, -1])
    m2 = np.mean(x**2, axis=-1)
    safe = np.maximum(m2, 1e-300)
    skew = np.mean(x**3, axis=-1) / safe**1.5
    kurt = np.mean(x**4, axis=-1) / safe**2
    # Pearson's inequality kappa >= g^2 + 1 (empirical moments included) bounds it by 1; rounding may not
    return np.minimum(np.where(m2 > 1e-18, (skew**2 + 1.0) / np.maximum(kurt, 1e-12), 1.0 / 3.0), 1.0)


@register_preset
class GpsDeniedNbpScenario(PresetScenario):
    """``gps_denied_nbp`` as a binding: ``gps_denied`` / ``broadcast`` / ``dnbp`` with the paper's per-iteration
    broadcast codec, observation, reward and infos (module docstring)."""

    name = "gps_denied_nbp"
    paper = "wan2014"
    Config = GpsDeniedNbpConfig
    version = 2
    metric = "position error of the GPS-fault UAVs averaged over their (step, UAV)"
    metric_unit = "m"
    communication = "broadcasts"
    policy_module = "agents.gps_denied_nbp"
    appended_features = ("index", "log_trace", "displacement", "steps_since", "message_value", "communication_cost")
    metric_weight_key = "fault"

    def __init__(self, config: GpsDeniedNbpConfig, batch: int = 1):
        super().__init__(config, batch)
        B, N, n = self.batch, config.num_agents, config.num_iterations
        self.delivered = np.zeros((B, n, N, N), bool)
        self.broadcasts = np.zeros((B, N), int)
        self.heard = np.zeros((B, N), int)
        self.fault = np.zeros((B, N), bool)

    def observation_space(self):
        high = np.array([1.0, 1.0, 1.0, 1.0, np.inf, 1.0, 1.0, 1.0], np.float32)
        return self.extend_space(gymnasium.spaces.Box(np.zeros(OBS_DIM, np.float32), high, dtype=np.float32))

    def transport_entries(self) -> tuple[np.ndarray, np.ndarray]:
        """Every iteration's broadcast bit; quiet: 0 (``silent``)."""
        n = int(self.config.num_iterations)
        return np.ones(n, bool), np.zeros(n)

    def preset_feature_positions(self) -> dict[str, int]:
        """The composed table's features among this observation's own entries: ``step_fraction`` (entry 6)."""
        return {"step_fraction": 6}

    def state_space(self):
        dim = self.num_agents * (self.observation_space().shape[0] + 1)
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(dim,), dtype=np.float32)

    # --- dynamics ----------------------------------------------------------------
    def part_generators(self, rng):
        """This preset's rule: the world draws from the episode's generator itself, the backend (the particle
        filter) from its first child, the network (lossless by default) from its second."""
        backend, network = rng.spawn(2)
        return rng, network, backend

    def reset(self, rngs, env_index=None) -> None:
        super().reset(rngs, env_index)
        idx = self._indices(env_index)
        self.delivered[idx] = False
        self.broadcasts[idx] = 0
        self.heard[idx] = 0
        self.fault[idx] = ~self.world.gps_normal[idx, 0]

    def decode_actions(self, actions) -> np.ndarray:
        """Actions (B, N, n_iter) of 0/1 -> the broadcast network's ``transmit`` block (one entry per round)."""
        n = int(self.config.num_iterations)
        return self.check_discrete_actions(actions, [f"action[{i}] (broadcast in NBP iteration {i})"
                                                     for i in range(n)])

    def advance(self, decoded) -> None:
        super().advance(decoded)
        result = self.backend.last_result
        self.fault = ~np.asarray(self.readings.fix_valid, bool)
        self.delivered, self.broadcasts, self.heard = result.delivered, result.broadcasts, result.received

    def compute_reward(self) -> np.ndarray:
        """The reward table: the error (or the belief's RMS) of the fault UAVs' mean (team) or each UAV's own,
        minus the cost of the broadcasts."""
        loss = self.position_error() if self.config.reward == "error" else np.sqrt(self.posterior_traces())
        cost, fault = self.costs, self.fault  # each copy's lambda this episode
        if self.config.team_reward:
            mean_fault = np.sum(loss * fault, axis=1) / np.maximum(fault.sum(axis=1), 1)
            team = -mean_fault - cost * self.broadcasts.sum(axis=1)
            return np.repeat(team[:, None], self.num_agents, axis=1)
        return -loss - cost[:, None] * self.broadcasts

    # --- views -------------------------------------------------------------------
    def _slice(self, array: np.ndarray, k: np.ndarray) -> np.ndarray:
        return array[np.arange(self.batch), np.minimum(k, self.horizon - 1)]

    def observation(self) -> np.ndarray:
        N = self.num_agents
        normal = self._slice(self.world.gps_normal, self.k)
        adjacency = self._slice(self.world.adjacency, self.k)
        prior = self.backend.state.prior[..., :2]
        centred = prior - prior.mean(axis=2, keepdims=True)
        spread = np.sqrt(np.mean(np.sum(centred**2, axis=-1), axis=-1))
        frac = np.broadcast_to((self.k / self.horizon)[:, None], normal.shape)
        neighbours = adjacency.sum(axis=-1)
        neighbours_heard = (adjacency * self.heard[:, None, :]).sum(axis=-1) / np.maximum(neighbours, 1)
        obs = np.stack([
            normal.astype(float),
            neighbours / (N - 1),
            (adjacency & normal[:, None, :]).sum(axis=-1) / (N - 1),
            self.heard / (N - 1),
            np.log1p(spread),
            bimodality(prior, centred),
            frac,
            neighbours_heard / (N - 1),
        ], axis=-1)
        return self.extend_observation(obs)

    def episode_error(self, errors: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """The paper's metric: the mean error of the fault UAVs over every (step, UAV) with a faulty
        GPS (``weights`` = the ``fault`` flags); 0 for an episode without any fault."""
        errors = np.asarray(errors, float)
        fault = np.ones_like(errors) if weights is None else np.asarray(weights, float)
        count = fault.sum(axis=(-2, -1))
        return np.where(count > 0, (errors * fault).sum(axis=(-2, -1)) / np.maximum(count, 1), 0.0)

    def state(self) -> np.ndarray:
        obs = self.observation().reshape(self.batch, -1)
        return np.concatenate([obs, np.log1p(self.position_error())], axis=-1).astype(np.float32)

    def info(self) -> dict[str, np.ndarray]:
        B, N = self.batch, self.num_agents
        error = self.position_error()
        return {
            "true_position": self.true_position(),
            "estimated_position": self.backend.posterior_position.copy(),
            "position_error": error,
            "error": error.copy(),
            "trace": np.trace(self.backend.position_cov(), axis1=-2, axis2=-1),
            "fault": self.fault.copy(),
            "broadcasts": self.broadcasts.copy(),
            "communication": self.broadcasts.astype(float),
            "messages_sent": self.network.messages_sent.copy(),
            **self.link_counts(),
            "floats_sent": self.network.floats_sent.copy(),
            "messages_received": self.delivered.sum(axis=(1, 2)),
            "neighbours": self._slice(self.world.adjacency, np.maximum(self.k - 1, 0)).sum(axis=-1),
            "step": np.broadcast_to(self.k[:, None], (B, N)).copy(),
        }

    def scene(self, b: int) -> Scene:
        """The core's scene with the slice the estimates refer to, the GPS faults and the fault UAVs' error."""
        k = max(int(self.k[b]) - 1, 0)
        fault = ~self.world.gps_normal[b, k]
        mean_fault = float(self.position_error()[b][fault].mean()) if fault.any() else 0.0
        return dataclasses.replace(
            super().scene(b), title=f"gps_denied_nbp (wan2014)  tau = {k}/{self.horizon}",
            trails=np.swapaxes(self.world.truth[b, max(0, k - 10): k + 1, :, :2], 0, 1),
            node_status=["GPS fault" if f else "" for f in fault],
            notes=[f"mean fault-UAV error {mean_fault:.1f} m; broadcasts this step {int(self.broadcasts[b].sum())}"])
