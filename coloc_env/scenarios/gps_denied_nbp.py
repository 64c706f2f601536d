"""``gps_denied_nbp``: UAVs that lost GPS localize by dynamic NBP over range links (Wan et al. 2014).

Paper: Wan, Zhong, Zhang, "Cooperative localization of multi-UAVs via dynamic
nonparametric belief propagation under GPS signal loss condition", IJDSN 2014
(seed ``003_44c6eab8acc44e0f.txt``). Its equations were lost in extraction;
the contract is the reconstruction ``shared/specs/wan2014_dnbp.md`` (tags
[paper] / [chosen] as there). Estimator: ``estimators.dnbp``; baselines
(LS of ref. [7], dead reckoning): ``estimators.range_ls``.

N UAVs fly at a common nominal velocity in 2-D (constant-velocity model driven
by an accelerometer, ``coloc_env.primitives.cv_uav.ConstantVelocityUAVs``);
each GPS receiver switches between normal and fault by a Markov chain
(``coloc_env.primitives.gps_markov.MarkovGPS``); UAVs within the range R
measure their distance and can talk
(``coloc_env.primitives.range_network.RangeNetwork``). One env step is one
time step tau: the UAVs run ``num_iterations`` NBP iterations over the
broadcast medium with the paper's modified schedule (normal UAVs broadcast at
iteration 0 to their fault neighbours; a fault UAV may broadcast to its fault
neighbours once it has heard from theta distinct neighbours, theta = 3 -> 2 -> 1),
then every belief is propagated to tau + 1. The agents decide what the paper
fixes: whether to use each broadcast opportunity the schedule gives them.

Action (per UAV, ``MultiDiscrete([2] * num_iterations)``, int64; ``MultiBinary`` before issue 14,
which RLlib's PPO refuses)
------------------------------------------------------------------------------------------------
| index | meaning                                                                              |
|-------|--------------------------------------------------------------------------------------|
| ``n`` | 1 = broadcast my message in NBP iteration n of this step if the schedule allows it;  |
|       | a bit for an iteration in which the schedule does not allow me to send is ignored.   |

A value other than 0 or 1, a NaN or inf is a ``ValueError`` naming the iteration. ``paper``
(all ones) is the paper's schedule; all zeros reduces every fault UAV to dead
reckoning.

Observation (per UAV, ``Box(shape=(8,), float32)``: entries 0-3 and 5-7 in [0, 1], 4 in [0, inf)),
about the coming step tau
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

Entry 4 alone is unbounded: a lost fault UAV's prior spreads without limit. (Before, entry 5 was
bounded by [0, inf) too.)

Entry 7 was added for learning (issue 15): a broadcast helps most where the neighbours heard
little; without it a UAV knew only its own count (entry 3).

Truth is used only in the reward, never in observations. ``state()``
(centralized critic): every agent's observation, then log(1 + e_s) of the
last step's errors.

Reward (metres; spec §9)
------------------------
| ``reward=``  | value after step tau                                                                 |
|--------------|--------------------------------------------------------------------------------------|
| ``"team"``   | every UAV: -mean_{s in F_tau} e_{s,tau} - broadcast_cost * (broadcasts of all UAVs)   |
|              | (0 error term when no GPS is faulty); e = ||p_hat - p|| of the belief mean           |
| ``"own"``    | each UAV: -e_{s,tau} - broadcast_cost * (its own broadcasts)                         |

The spec's optional particle-count action (and its lambda_M term) is not implemented.

Termination: none; truncation after ``horizon`` steps (T = 30 [chosen]).

``infos[agent]``: ``true_position``, ``estimated_position`` (belief mean),
``position_error`` and ``error`` (the same distance, metres), ``trace`` (m^2, of the
belief particles' sample covariance), ``fault`` (GPS faulty at tau), ``broadcasts`` (this
step, as the schedule counts them), ``communication`` (= broadcasts: what ``coloc
evaluate`` counts), ``messages_sent`` (the network's count at the sender: one per
broadcast that reached a listener; before issue 14 this key counted directed
deliveries), ``floats_sent`` (3 M + 1 floats per message), ``messages_received``
(directed: the messages this UAV took), ``neighbours``, ``step``. At reset the estimate
is the tau = 0 prior mean.

Composition: a binding (``coloc_env.scenarios.binding``) of world ``gps_denied``
(the same flight, GPS chain and ranging), network ``broadcast`` (radius ``comm_range``,
no loss) and backend ``dnbp`` (``init`` included); ``coloc_env.PRESETS["gps_denied_nbp"]``
is that composition. The world draws from the episode's generator itself and the
estimator from its first child, as before the core, so the same seed and actions give
the same numbers bit for bit.

Batching and seeding: reset draws each copy's whole episode (truth,
accelerometer, GPS chain and fixes, ranges, the warm-start knowledge) from the
copy's generator in blocks, then spawns the copy's estimator generator from
it; steps are one batched call of ``estimators.dnbp.step`` (through the backend,
each iteration's delivery asked of the network) over copies,
particles and messages. What remains a loop over copies is the drawing of the
particle filter's random numbers (resampling, proposals, message directions):
each copy draws its block from its own estimator generator, so copy b of a
batch is bit-identical to the same seed run alone.

Arguments (fields of ``GpsDeniedNbpConfig``, defaults = spec §1)
------------------------------------------------------------------
| field              | default     | allowed                   | tag / meaning                                |
|--------------------|-------------|---------------------------|----------------------------------------------|
| num_uavs           | 10          | 2..64                     | N [chosen]                                   |
| horizon            | 30          | 1..10000                  | T [chosen] (50 allowed)                      |
| dt                 | 1.0         | (0, 1000]                 | Delta t [chosen]                             |
| area               | 500         | (0, 1e7]                  | initial positions ~ U([0, area]^2) [chosen]  |
| nominal_velocity   | (20, 0)     | (2,) entries in [-1e4, 1e4] | v_nom [chosen]                               |
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
| initial_threshold  | 3           | 1..N                      | theta_0 [paper]                              |
| schedule           | "modified"  | "modified", "parallel"    | Sec. 3.4 [paper]; parallel = ablation        |
| kernel             | "truncated" | "exact", "truncated"      | belief-update mixture kernel [chosen]; the   |
|                    |             |                           | truncated one approximates (estimators.dnbp; |
|                    |             |                           | the default since issue 18, "exact" before)  |
| truncation         | 6.0         | [1, 10] bandwidths        | r of the truncated kernel [chosen]           |
| reward             | "team"      | "team", "own"             | see the reward table                         |
| broadcast_cost     | 0.0         | [0, 1e12]                 | lambda_c, metres per broadcast               |
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np

import estimators.dnbp as dn
from coloc_env.backends.particles import Dnbp
from coloc_env.config import MIN_STD, as_array, check_choice, check_entries, check_range
from coloc_env.networks.broadcast import Broadcast
from coloc_env.primitives.cv_uav import ConstantVelocityUAVs
from coloc_env.primitives.gps_markov import MarkovGPS
from coloc_env.primitives.range_network import RangeNetwork
from coloc_env.rendering import Link, Scene
from coloc_env.scenarios.binding import PresetScenario
from coloc_env.worlds.gps_denied import GpsDenied

OBS_DIM = 8


@dataclass(frozen=True)
class GpsDeniedNbpConfig:
    """Configuration of ``gps_denied_nbp``; defaults are spec §1 (mostly [chosen])."""

    num_uavs: int = 10
    horizon: int = 30
    dt: float = 1.0
    area: float = 500.0
    nominal_velocity: tuple = (20.0, 0.0)
    velocity_spread: float = 2.0
    accel_std: float = 0.5
    accel_noise_std: float = 0.3
    gps_std: float = 3.0
    range_std: float = 2.0
    comm_range: float = 300.0
    p_normal_to_fault: float = 0.02
    p_fault_to_normal: float = 0.02
    num_normal: int | None = None
    num_particles: int = 100
    num_iterations: int = 5
    oversampling: int = 2
    defensive_weight: float = 0.01
    init: str = "warm"
    box_margin: float = 150.0
    min_bandwidth: float = 0.5
    initial_threshold: int = 3
    schedule: str = "modified"
    kernel: str = "truncated"
    truncation: float = 6.0
    reward: str = "team"
    broadcast_cost: float = 0.0

    @property
    def motion(self) -> ConstantVelocityUAVs:
        return ConstantVelocityUAVs(self.dt, self.accel_std, self.accel_noise_std)

    @property
    def gps(self) -> MarkovGPS:
        return MarkovGPS(self.p_normal_to_fault, self.p_fault_to_normal, self.gps_std)

    @property
    def network(self) -> RangeNetwork:
        return RangeNetwork(self.comm_range, self.range_std)

    def validate(self) -> None:
        check_range("num_uavs", self.num_uavs, 2, 64, integer=True)
        check_range("horizon", self.horizon, 1, 10_000, integer=True)
        check_range("area", self.area, 0.0, 1e7, low_open=True)
        check_entries("nominal_velocity", as_array("nominal_velocity", self.nominal_velocity, shape=(2,)), -1e4, 1e4)
        check_range("velocity_spread", self.velocity_spread, 0.0, 1e4)
        check_range("dt", self.dt, 0.0, 1e3, low_open=True)
        check_range("accel_std", self.accel_std, 0.0, 1e3)
        # the particle filter divides by these squared (kernel bandwidths, likelihoods): coloc_env.config.MIN_STD
        check_range("accel_noise_std", self.accel_noise_std, MIN_STD, 1e3)
        check_range("gps_std", self.gps_std, MIN_STD, 1e4)
        check_range("range_std", self.range_std, MIN_STD, 1e4)
        for part in (self.motion, self.gps, self.network):  # the fields above are checked under their own names
            part.validate()
        if self.num_normal is not None:
            check_range("num_normal", self.num_normal, 0, self.num_uavs, integer=True, high_label="num_uavs")
        check_range("num_particles", self.num_particles, 2, 5000, integer=True)
        check_range("num_iterations", self.num_iterations, 1, 20, integer=True)
        check_range("oversampling", self.oversampling, 1, 16, integer=True)
        check_range("defensive_weight", self.defensive_weight, 0.0, 0.999)
        check_choice("init", self.init, ("warm", "cold"))
        check_range("box_margin", self.box_margin, 0.0, 1e7)
        check_range("min_bandwidth", self.min_bandwidth, MIN_STD, 1e4)
        check_range("initial_threshold", self.initial_threshold, 1, self.num_uavs, integer=True,
                    high_label="num_uavs")
        check_choice("schedule", self.schedule, ("modified", "parallel"))
        check_choice("kernel", self.kernel, dn.KERNELS)
        check_range("truncation", self.truncation, *dn.TRUNCATION_RANGE)
        check_choice("reward", self.reward, ("team", "own"))
        check_range("broadcast_cost", self.broadcast_cost, 0.0, 1e12)

    def parts(self) -> tuple:
        """The (world, network, backend) configs this flat config stands for: ``gps_denied`` with the same
        flight, GPS chain and ranging, ``broadcast`` over the ranging radius without loss, ``dnbp``."""
        world = GpsDenied(num_agents=self.num_uavs, horizon=self.horizon, dt=self.dt, area=self.area,
                          nominal_velocity=self.nominal_velocity, velocity_spread=self.velocity_spread,
                          accel_std=self.accel_std, accel_noise_std=self.accel_noise_std, gps_std=self.gps_std,
                          range_std=self.range_std, comm_range=self.comm_range,
                          p_normal_to_fault=self.p_normal_to_fault, p_fault_to_normal=self.p_fault_to_normal,
                          num_normal=self.num_normal)
        backend = Dnbp(num_particles=self.num_particles, num_iterations=self.num_iterations,
                       oversampling=self.oversampling, defensive_weight=self.defensive_weight,
                       box_margin=self.box_margin, min_bandwidth=self.min_bandwidth,
                       initial_threshold=self.initial_threshold, schedule=self.schedule, init=self.init,
                       kernel=self.kernel, truncation=self.truncation)
        return world, Broadcast(comm_range=self.comm_range, loss=0.0), backend

    def estimator_model(self) -> dn.DnbpModel:
        """The dNBP parameters; the defensive box covers the whole flight (spec §4.3)."""
        travel = float(np.linalg.norm(self.nominal_velocity)) * self.dt * self.horizon
        m = self.box_margin
        return dn.DnbpModel(
            dt=self.dt, accel_noise_std=self.accel_noise_std, gps_std=self.gps_std, range_std=self.range_std,
            num_particles=self.num_particles, num_iterations=self.num_iterations, oversampling=self.oversampling,
            defensive_weight=self.defensive_weight, defensive_box=(-m, self.area + m + travel),
            cold_box=(-m, self.area + m), min_bandwidth=self.min_bandwidth,
            initial_threshold=self.initial_threshold, schedule=self.schedule, kernel=self.kernel,
            truncation=self.truncation)


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


class GpsDeniedNbpScenario(PresetScenario):
    """``gps_denied_nbp`` as a binding: ``gps_denied`` / ``broadcast`` / ``dnbp`` with the paper's per-iteration
    broadcast codec, observation, reward and infos (module docstring)."""

    name = "gps_denied_nbp"
    paper = "wan2014"
    Config = GpsDeniedNbpConfig
    metric_weight_key = "fault"

    def __init__(self, config: GpsDeniedNbpConfig, batch: int = 1):
        super().__init__(config, batch)
        B, N, n = self.batch, config.num_uavs, config.num_iterations
        self.delivered = np.zeros((B, n, N, N), bool)
        self.broadcasts = np.zeros((B, N), int)
        self.heard = np.zeros((B, N), int)
        self.fault = np.zeros((B, N), bool)

    # --- the paper scenario's names for the parts' state (tests, policies, the reproduction, the renderer) -----
    @property
    def model(self) -> dn.DnbpModel:
        return self.backend.model

    @property
    def belief_state(self) -> dn.DnbpState:
        return self.backend.state

    @property
    def estimator_rngs(self) -> list:
        return self.backend.rngs

    @property
    def truth(self) -> np.ndarray:
        """(B, T, N, 4) true [position, velocity] of every slice."""
        return self.world.truth

    @property
    def gps_normal(self) -> np.ndarray:
        return self.world.gps_normal

    @property
    def adjacency(self) -> np.ndarray:
        return self.world.adjacency

    @property
    def estimate(self) -> np.ndarray:
        """Belief means (B, N, 2) of the last step's slice tau (the tau = 0 prior mean at reset)."""
        return self.backend.posterior_position

    @property
    def errors(self) -> np.ndarray:
        return self.position_error()

    # --- description ------------------------------------------------------------
    @property
    def num_agents(self) -> int:
        return self.config.num_uavs

    def observation_space(self):
        low = np.zeros(OBS_DIM, np.float32)
        high = np.array([1.0, 1.0, 1.0, 1.0, np.inf, 1.0, 1.0, 1.0], np.float32)
        return gymnasium.spaces.Box(low, high, dtype=np.float32)

    def action_space(self):
        return gymnasium.spaces.MultiDiscrete([2] * int(self.config.num_iterations), dtype=np.int64)

    def state_space(self):
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(self.num_agents * (OBS_DIM + 1),), dtype=np.float32)

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
        """The reward table: the fault UAVs' mean error (team) or each UAV's own, minus the broadcast cost."""
        errors, fault, cost = self.position_error(), self.fault, self.config.broadcast_cost
        if self.config.reward == "team":
            mean_fault = np.sum(errors * fault, axis=1) / np.maximum(fault.sum(axis=1), 1)
            team = -mean_fault - cost * self.broadcasts.sum(axis=1)
            return np.repeat(team[:, None], self.num_agents, axis=1)
        return -errors - cost * self.broadcasts

    # --- views -------------------------------------------------------------------
    def _slice(self, array: np.ndarray, k: np.ndarray) -> np.ndarray:
        return array[np.arange(self.batch), np.minimum(k, self.horizon - 1)]

    def observation(self) -> np.ndarray:
        N = self.num_agents
        normal = self._slice(self.gps_normal, self.k)
        adjacency = self._slice(self.adjacency, self.k)
        prior = self.belief_state.prior[..., :2]
        centred = prior - prior.mean(axis=2, keepdims=True)
        spread = np.sqrt(np.mean(np.sum(centred**2, axis=-1), axis=-1))
        frac = np.broadcast_to((self.k / self.horizon)[:, None], normal.shape)
        neighbours = adjacency.sum(axis=-1)
        neighbours_heard = (adjacency * self.heard[:, None, :]).sum(axis=-1) / np.maximum(neighbours, 1)
        obs = np.stack([
            normal.astype(float),
            adjacency.sum(axis=-1) / (N - 1),
            (adjacency & normal[:, None, :]).sum(axis=-1) / (N - 1),
            self.heard / (N - 1),
            np.log1p(spread),
            bimodality(prior, centred),
            frac,
            neighbours_heard / (N - 1),
        ], axis=-1)
        return obs.astype(np.float32)

    def episode_error(self, errors: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """The paper's metric: the mean error of the fault UAVs over every (step, UAV) with a faulty
        GPS (``weights`` = the ``fault`` flags); 0 for an episode without any fault."""
        errors = np.asarray(errors, float)
        fault = np.ones_like(errors) if weights is None else np.asarray(weights, float)
        count = fault.sum(axis=(-2, -1))
        return np.where(count > 0, (errors * fault).sum(axis=(-2, -1)) / np.maximum(count, 1), 0.0)

    def state(self) -> np.ndarray:
        obs = self.observation().reshape(self.batch, -1)
        return np.concatenate([obs, np.log1p(self.errors)], axis=-1).astype(np.float32)

    def _estimated_slice(self) -> np.ndarray:
        """The slice the current estimates refer to: tau - 1 after a step, 0 at reset."""
        return np.maximum(self.k - 1, 0)

    def info(self) -> dict[str, np.ndarray]:
        B, N = self.batch, self.num_agents
        k_est = self._estimated_slice()
        error = self.position_error()
        return {
            "true_position": self._truth.copy(),
            "estimated_position": self.backend.posterior_position.copy(),
            "position_error": error,
            "error": error.copy(),
            "trace": np.trace(self.backend.position_cov(), axis1=-2, axis2=-1),
            "fault": self.fault.copy(),
            "broadcasts": self.broadcasts.copy(),
            "communication": self.broadcasts.astype(float),
            "messages_sent": self.network.messages_sent.copy(),
            "floats_sent": self.network.floats_sent.copy(),
            "messages_received": self.delivered.sum(axis=(1, 2)),
            "neighbours": self._slice(self.adjacency, k_est).sum(axis=-1),
            "step": np.broadcast_to(self.k[:, None], (B, N)).copy(),
        }

    def scene(self, b: int) -> Scene:
        N, k = self.num_agents, int(self.k[b])
        k_est = max(k - 1, 0)
        truth = self.truth[b, k_est, :, :2]
        particles = self.belief_state.belief[b, :, :, :2]
        centred = particles - particles.mean(axis=1, keepdims=True)
        cov = np.einsum("nmi,nmj->nij", centred, centred) / particles.shape[1]
        fault = ~self.gps_normal[b, k_est]
        low, high = truth.min(axis=0) - 120.0, truth.max(axis=0) + 120.0
        centre, half = 0.5 * (low + high), 0.5 * float(np.max(high - low))
        counts = self.delivered[b].sum(axis=0)
        # every message of the step, plus each silent edge once (drawn faint)
        edges = self.adjacency[b, k_est] & ((counts > 0) | (np.arange(N)[:, None] < np.arange(N)))
        links = [Link(source=int(t), target=int(s), value=float(counts[t, s]))
                 for t, s in zip(*np.nonzero(edges | (counts > 0)), strict=True)]
        mean_fault = float(self.errors[b][fault].mean()) if fault.any() else 0.0
        return Scene(
            title=f"gps_denied_nbp (wan2014)  tau = {k_est}/{self.horizon}",
            truth=truth,
            estimates=self.estimate[b],
            covariances=cov,
            trails=np.swapaxes(self.truth[b, max(0, k_est - 10): k_est + 1, :, :2], 0, 1),
            particles=particles,
            node_positions=(truth - centre) / max(half, 1e-9),
            node_labels=list(self.agent_names),
            node_status=["GPS fault" if fault[i] else "" for i in range(N)],
            links=links,
            link_value_max=float(self.config.num_iterations),
            link_value_name="iterations with a message",
            extent=(centre[0] - half, centre[0] + half, centre[1] - half, centre[1] + half),
            notes=[f"mean fault-UAV error {mean_fault:.1f} m; broadcasts this step {int(self.broadcasts[b].sum())}"],
        )
