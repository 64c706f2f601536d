"""``gps_denied_nbp``: UAVs that lost GPS localize by dynamic NBP over range links (Wan et al. 2014).

Paper: Wan, Zhong, Zhang, "Cooperative localization of multi-UAVs via dynamic
nonparametric belief propagation under GPS signal loss condition", IJDSN 2014
(seed ``003_44c6eab8acc44e0f.txt``). Its equations were lost in extraction;
the contract is the reconstruction ``shared/specs/wan2014_dnbp.md`` (tags
[paper] / [chosen] as there). Estimator: :mod:`estimators.dnbp`; baselines
(LS of ref. [7], dead reckoning): :mod:`estimators.range_ls`.

N UAVs fly at a common nominal velocity in 2-D (constant-velocity model driven
by an accelerometer, :class:`~coloc_env.world.cv_uav.ConstantVelocityUAVs`);
each GPS receiver switches between normal and fault by a Markov chain
(:class:`~coloc_env.world.gps_markov.MarkovGPS`); UAVs within the range R
measure their distance and can talk
(:class:`~coloc_env.world.range_network.RangeNetwork`). One env step is one
time step tau: the UAVs run ``num_iterations`` NBP iterations over the
broadcast medium with the paper's modified schedule (normal UAVs broadcast at
iteration 0 to their fault neighbours; a fault UAV may broadcast to its fault
neighbours once it has heard from theta distinct neighbours, theta = 3 -> 2 -> 1),
then every belief is propagated to tau + 1. The agents decide what the paper
fixes: whether to use each broadcast opportunity the schedule gives them.

Action (per UAV, ``MultiBinary(num_iterations)``, int8)
-------------------------------------------------------
| index | meaning                                                                              |
|-------|--------------------------------------------------------------------------------------|
| ``n`` | 1 = broadcast my message in NBP iteration n of this step if the schedule allows it;  |
|       | a bit for an iteration in which the schedule does not allow me to send is ignored.   |

Values are thresholded at 0.5; a NaN or inf is a ``ValueError``. ``paper``
(all ones) is the paper's schedule; all zeros reduces every fault UAV to dead
reckoning.

Observation (per UAV, ``Box(-inf, inf, shape=(7,), float32)``), about the coming step tau
--------------------------------------------------------------------------------------
| index | meaning                                                                         |
|-------|---------------------------------------------------------------------------------|
| 0     | own GPS normal (1) or fault (0) at tau                                          |
| 1     | neighbours within R at tau, / (N - 1)                                           |
| 2     | GPS-normal neighbours at tau, / (N - 1)                                         |
| 3     | distinct UAVs heard from in the previous step, / (N - 1) (0 at reset)           |
| 4     | log(1 + spread) of the prior rho_tau, spread = sqrt(tr Cov(positions)) in metres |
| 5     | bimodality coefficient (g^2 + 1) / kappa of the prior along its principal axis  |
|       | (1/3 Gaussian, > 5/9 suggests a ring or two modes)                              |
| 6     | step fraction tau / horizon                                                     |

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
``error`` (metres), ``fault`` (GPS faulty at tau), ``broadcasts`` (this
step), ``communication`` (= broadcasts: what ``coloc evaluate`` counts),
``messages_sent``, ``messages_received`` (directed messages),
``neighbours``, ``step``. At reset the estimate is the tau = 0 prior mean.

Batching and seeding: reset draws each copy's whole episode (truth,
accelerometer, GPS chain and fixes, ranges, the warm-start knowledge) from the
copy's generator in blocks, then spawns the copy's estimator generator from
it; steps are one batched call of :func:`estimators.dnbp.step` over copies,
particles and messages. What remains a loop over copies is the drawing of the
particle filter's random numbers (resampling, proposals, message directions):
each copy draws its block from its own estimator generator, so copy b of a
batch is bit-identical to the same seed run alone.

Arguments (fields of :class:`GpsDeniedNbpConfig`, defaults = spec §1)
------------------------------------------------------------------
| field              | default     | allowed                   | tag / meaning                                |
|--------------------|-------------|---------------------------|----------------------------------------------|
| num_uavs           | 10          | 2..64                     | N [chosen]                                   |
| horizon            | 30          | 1..10000                  | T [chosen] (50 allowed)                      |
| dt                 | 1.0         | > 0                       | Delta t [chosen]                             |
| area               | 500         | > 0                       | initial positions ~ U([0, area]^2) [chosen]  |
| nominal_velocity   | (20, 0)     | (2,)                      | v_nom [chosen]                               |
| velocity_spread    | 2.0         | >= 0                      | sigma_v0 [chosen]                            |
| accel_std          | 0.5         | >= 0                      | sigma_a,true [chosen]                        |
| accel_noise_std    | 0.3         | > 0                       | sigma_acc [chosen]                           |
| gps_std            | 3.0         | > 0                       | sigma_gps [chosen]                           |
| range_std          | 2.0         | > 0                       | sigma_d [chosen]                             |
| comm_range         | 300         | > 0                       | R [chosen]; interesting band 200-350 [paper] |
| p_normal_to_fault  | 0.02        | [0, 1]                    | p_nf [chosen]                                |
| p_fault_to_normal  | 0.02        | [0, 1]                    | p_fn [chosen]                                |
| num_normal         | None        | None or 0..N              | fixed-proportion mode of Fig. 6(a) [paper]   |
| num_particles      | 100         | 2..5000                   | M [chosen]                                   |
| num_iterations     | 5           | 1..20                     | n_iter [chosen]; case study needs 3 [paper]  |
| oversampling       | 2           | 1..16                     | k_is [chosen]                                |
| defensive_weight   | 0.01        | [0, 1)                    | eps_def [chosen]                             |
| init               | "warm"      | "warm", "cold"            | tau = 0 knowledge [chosen]                   |
| box_margin         | 150         | >= 0                      | cold box [-m, area+m]^2 [chosen]             |
| min_bandwidth      | 0.5         | > 0                       | floor of h_ts [chosen]                       |
| initial_threshold  | 3           | 1..N                      | theta_0 [paper]                              |
| schedule           | "modified"  | "modified", "parallel"    | Sec. 3.4 [paper]; parallel = ablation        |
| reward             | "team"      | "team", "own"             | see the reward table                         |
| broadcast_cost     | 0.0         | [0, 1e12]                 | lambda_c, metres per broadcast               |
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np

import estimators.dnbp as dn
from coloc_env.config import as_array, check_choice, check_range
from coloc_env.rendering import Link, Scene
from coloc_env.scenarios.base import Scenario
from coloc_env.world.broadcast_medium import BroadcastMedium
from coloc_env.world.cv_uav import ConstantVelocityUAVs
from coloc_env.world.gps_markov import MarkovGPS
from coloc_env.world.range_network import RangeNetwork

OBS_DIM = 7


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
        as_array("nominal_velocity", self.nominal_velocity, shape=(2,))
        check_range("velocity_spread", self.velocity_spread, 0.0, 1e4)
        check_range("dt", self.dt, 0.0, 1e3, low_open=True)
        check_range("accel_std", self.accel_std, 0.0, 1e3)
        check_range("accel_noise_std", self.accel_noise_std, 0.0, 1e3, low_open=True)
        check_range("gps_std", self.gps_std, 0.0, 1e4, low_open=True)
        check_range("range_std", self.range_std, 0.0, 1e4, low_open=True)
        for part in (self.motion, self.gps, self.network):  # the fields above are checked under their own names
            part.validate()
        if self.num_normal is not None:
            check_range("num_normal", self.num_normal, 0, self.num_uavs, integer=True)
        check_range("num_particles", self.num_particles, 2, 5000, integer=True)
        check_range("num_iterations", self.num_iterations, 1, 20, integer=True)
        check_range("oversampling", self.oversampling, 1, 16, integer=True)
        check_range("defensive_weight", self.defensive_weight, 0.0, 0.999)
        check_choice("init", self.init, ("warm", "cold"))
        check_range("box_margin", self.box_margin, 0.0, 1e7)
        check_range("min_bandwidth", self.min_bandwidth, 0.0, 1e4, low_open=True)
        check_range("initial_threshold", self.initial_threshold, 1, self.num_uavs, integer=True)
        check_choice("schedule", self.schedule, ("modified", "parallel"))
        check_choice("reward", self.reward, ("team", "own"))
        check_range("broadcast_cost", self.broadcast_cost, 0.0, 1e12)

    def estimator_model(self) -> dn.DnbpModel:
        """The dNBP parameters; the defensive box covers the whole flight (spec §4.3)."""
        travel = float(np.linalg.norm(self.nominal_velocity)) * self.dt * self.horizon
        m = self.box_margin
        return dn.DnbpModel(
            dt=self.dt, accel_noise_std=self.accel_noise_std, gps_std=self.gps_std, range_std=self.range_std,
            num_particles=self.num_particles, num_iterations=self.num_iterations, oversampling=self.oversampling,
            defensive_weight=self.defensive_weight, defensive_box=(-m, self.area + m + travel),
            cold_box=(-m, self.area + m), min_bandwidth=self.min_bandwidth,
            initial_threshold=self.initial_threshold, schedule=self.schedule)


@dataclass
class Episode:
    """One copy's whole episode (T slices, N UAVs), drawn at reset.

    ``truth`` (T, N, 4); ``accel`` (T, N, 2) readings a_hat(tau) (used to
    predict tau + 1); ``gps_normal`` (T, N); ``gps_fix`` (T, N, 2) (NaN where
    faulty); ``adjacency`` (T, N, N); ``ranges`` (T, N, N); ``init_position``
    and ``init_velocity`` (N, 2): the warm-start knowledge p~_0, v~_0.
    """

    truth: np.ndarray
    accel: np.ndarray
    gps_normal: np.ndarray
    gps_fix: np.ndarray
    adjacency: np.ndarray
    ranges: np.ndarray
    init_position: np.ndarray
    init_velocity: np.ndarray


def sample_episode(config: GpsDeniedNbpConfig, rng: np.random.Generator) -> Episode:
    """Draw an episode from ``rng`` in blocks, in a fixed order (spec §2)."""
    N, T = config.num_uavs, config.horizon
    motion, gps, network = config.motion, config.gps, config.network
    position = config.area * rng.random((N, 2))
    velocity = np.asarray(config.nominal_velocity, float) + config.velocity_spread * rng.standard_normal((N, 2))
    if config.num_normal is None:
        normal = gps.sample_states(rng, T, N)
    else:
        normal = gps.fixed_states(rng, T, N, config.num_normal)
    true_accel, reading = motion.sample_accelerations(rng, (T, N))
    gps_noise = gps.sample_noise(rng, (T, N))
    range_noise = network.sample_noise(rng, (T,), N)
    init_position = position + config.gps_std * rng.standard_normal((N, 2))
    init_velocity = velocity + config.velocity_spread * rng.standard_normal((N, 2))
    truth = motion.trajectory(np.concatenate([position, velocity], axis=-1), true_accel[:-1])
    adjacency, ranges = network.measure(truth[..., :2], range_noise)
    return Episode(truth=truth, accel=reading, gps_normal=normal,
                   gps_fix=gps.measure(truth[..., :2], gps_noise, normal), adjacency=adjacency, ranges=ranges,
                   init_position=init_position, init_velocity=init_velocity)


def initial_beliefs(config: GpsDeniedNbpConfig, model: dn.DnbpModel, episodes: list[Episode],
                    rngs: list[np.random.Generator]) -> dn.DnbpState:
    """The tau = 0 priors of the copies (warm: last fix before the loss; cold: the box)."""
    position = np.stack([e.init_position for e in episodes])
    if config.init == "warm":
        velocity = np.stack([e.init_velocity for e in episodes])
    else:
        velocity = np.broadcast_to(np.asarray(config.nominal_velocity, float), position.shape)
    return dn.initial_state(model, rngs, config.init, position, velocity, config.velocity_spread)


def bimodality(points: np.ndarray) -> np.ndarray:
    """Sarle's bimodality coefficient (g^2 + 1) / kappa of points (..., M, 2) along their principal axis."""
    centred = points - points.mean(axis=-2, keepdims=True)
    cov = np.einsum("...mi,...mj->...ij", centred, centred) / points.shape[-2]
    _, vectors = np.linalg.eigh(cov)
    x = np.einsum("...mi,...i->...m", centred, vectors[..., :, -1])
    m2 = np.mean(x**2, axis=-1)
    safe = np.maximum(m2, 1e-300)
    skew = np.mean(x**3, axis=-1) / safe**1.5
    kurt = np.mean(x**4, axis=-1) / safe**2
    return np.where(m2 > 1e-18, (skew**2 + 1.0) / np.maximum(kurt, 1e-12), 1.0 / 3.0)


class GpsDeniedNbpScenario(Scenario):
    """Batched core of ``gps_denied_nbp``; see the module docstring for the tables."""

    name = "gps_denied_nbp"
    paper = "wan2014"
    Config = GpsDeniedNbpConfig
    metric_weight_key = "fault"

    def __init__(self, config: GpsDeniedNbpConfig, batch: int = 1):
        super().__init__(config, batch)
        self.model = config.estimator_model()
        self.medium = BroadcastMedium()
        B, N, T, M, n = self.batch, config.num_uavs, config.horizon, config.num_particles, config.num_iterations
        self.k = np.zeros(B, dtype=int)
        self.truth = np.zeros((B, T, N, 4))
        self.accel = np.zeros((B, T, N, 2))
        self.gps_normal = np.zeros((B, T, N), bool)
        self.gps_fix = np.zeros((B, T, N, 2))
        self.adjacency = np.zeros((B, T, N, N), bool)
        self.ranges = np.zeros((B, T, N, N))
        self.estimator_rngs: list[np.random.Generator | None] = [None] * B
        particles = np.zeros((B, N, M, 4))
        self.belief_state = dn.DnbpState(prior=particles, prior_bandwidth=np.ones((B, N)),
                                         prior_uniform=np.zeros((B, N), bool), belief=particles.copy(),
                                         estimate=np.zeros((B, N, 2)))
        self.estimate = np.zeros((B, N, 2))
        self.errors = np.zeros((B, N))
        self.delivered = np.zeros((B, n, N, N), bool)
        self.broadcasts = np.zeros((B, N), int)
        self.heard = np.zeros((B, N), int)
        self._reward = np.zeros((B, N))

    # --- description ------------------------------------------------------------
    def observation_space(self):
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(OBS_DIM,), dtype=np.float32)

    def action_space(self):
        return gymnasium.spaces.MultiBinary(int(self.config.num_iterations))

    def state_space(self):
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(self.num_agents * (OBS_DIM + 1),), dtype=np.float32)

    # --- dynamics ----------------------------------------------------------------
    def reset(self, rngs, env_index=None) -> None:
        idx = self._indices(env_index)
        if len(rngs) != len(idx):
            raise ValueError(f"reset needs one generator per copy: {len(idx)} copies, {len(rngs)} generators")
        episodes = [sample_episode(self.config, rng) for rng in rngs]
        self.start(idx, episodes, [rng.spawn(1)[0] for rng in rngs])

    def start(self, idx, episodes: list[Episode], estimator_rngs: list[np.random.Generator]) -> None:
        """Begin the given episodes in copies ``idx`` with their own estimator generators."""
        idx = self._indices(idx)
        for b, ep, rng in zip(idx, episodes, estimator_rngs, strict=True):
            self.truth[b], self.accel[b] = ep.truth, ep.accel
            self.gps_normal[b], self.gps_fix[b] = ep.gps_normal, ep.gps_fix
            self.adjacency[b], self.ranges[b] = ep.adjacency, ep.ranges
            self.estimator_rngs[b] = rng
        fresh = initial_beliefs(self.config, self.model, episodes, [self.estimator_rngs[b] for b in idx])
        for name in ("prior", "prior_bandwidth", "prior_uniform", "belief", "estimate"):
            getattr(self.belief_state, name)[idx] = getattr(fresh, name)
        self.k[idx] = 0
        self.estimate[idx] = fresh.estimate
        self.errors[idx] = np.linalg.norm(fresh.estimate - self.truth[idx, 0, :, :2], axis=-1)
        self.delivered[idx] = False
        self.broadcasts[idx] = 0
        self.heard[idx] = 0
        self._reward[idx] = 0.0

    def _slice(self, array: np.ndarray, k: np.ndarray) -> np.ndarray:
        return array[np.arange(self.batch), np.minimum(k, self.horizon - 1)]

    def step(self, actions) -> None:
        actions = self.check_actions(actions)
        outside = (actions != 0) & (actions != 1)
        if np.any(outside):  # MultiBinary: exactly 0 or 1, as MultiDiscrete refuses a value out of range
            copy, agent, i = np.argwhere(outside)[0]
            raise ValueError(f"action[{i}] (broadcast in NBP iteration {i}) of {self.agent_names[agent]} must be "
                             f"0 or 1 (MultiBinary), got {actions[copy, agent, i]:g}")
        if np.any(self.k >= self.horizon):
            raise RuntimeError("step() on a copy whose episode is over; reset it first")
        self.advance(actions > 0.5)

    def advance(self, broadcast: np.ndarray) -> None:
        """Step with decoded decisions: broadcast (B, N, n_iter) bool."""
        k = self.k
        normal = self._slice(self.gps_normal, k)
        self.belief_state, result = dn.step(
            self.model, self.belief_state, normal, self._slice(self.gps_fix, k),
            self.medium.over(self._slice(self.adjacency, k)), self._slice(self.ranges, k), self._slice(self.accel, k),
            self.estimator_rngs, broadcast)
        truth = self._slice(self.truth, k)[..., :2]
        self.estimate = result.estimate
        self.errors = np.linalg.norm(result.estimate - truth, axis=-1)
        self.delivered, self.broadcasts, self.heard = result.delivered, result.broadcasts, result.received
        fault = ~normal
        cost = self.config.broadcast_cost
        if self.config.reward == "team":
            mean_fault = np.sum(self.errors * fault, axis=1) / np.maximum(fault.sum(axis=1), 1)
            team = -mean_fault - cost * self.broadcasts.sum(axis=1)
            self._reward = np.repeat(team[:, None], self.num_agents, axis=1)
        else:
            self._reward = -self.errors - cost * self.broadcasts
        self.k = k + 1

    # --- views -------------------------------------------------------------------
    def observation(self) -> np.ndarray:
        N = self.num_agents
        normal = self._slice(self.gps_normal, self.k)
        adjacency = self._slice(self.adjacency, self.k)
        prior = self.belief_state.prior[..., :2]
        centred = prior - prior.mean(axis=2, keepdims=True)
        spread = np.sqrt(np.mean(np.sum(centred**2, axis=-1), axis=-1))
        frac = np.broadcast_to((self.k / self.horizon)[:, None], normal.shape)
        obs = np.stack([
            normal.astype(float),
            adjacency.sum(axis=-1) / (N - 1),
            (adjacency & normal[:, None, :]).sum(axis=-1) / (N - 1),
            self.heard / (N - 1),
            np.log1p(spread),
            bimodality(prior),
            frac,
        ], axis=-1)
        return obs.astype(np.float32)

    def episode_error(self, errors: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """The paper's metric: the mean error of the fault UAVs over every (step, UAV) with a faulty
        GPS (``weights`` = the ``fault`` flags); 0 for an episode without any fault."""
        errors = np.asarray(errors, float)
        fault = np.ones_like(errors) if weights is None else np.asarray(weights, float)
        count = fault.sum(axis=(-2, -1))
        return np.where(count > 0, (errors * fault).sum(axis=(-2, -1)) / np.maximum(count, 1), 0.0)

    def reward(self) -> np.ndarray:
        return self._reward.copy()

    def done(self) -> np.ndarray:
        return self.k >= self.horizon

    def state(self) -> np.ndarray:
        obs = self.observation().reshape(self.batch, -1)
        return np.concatenate([obs, np.log1p(self.errors)], axis=-1).astype(np.float32)

    def _estimated_slice(self) -> np.ndarray:
        """The slice the current estimates refer to: tau - 1 after a step, 0 at reset."""
        return np.maximum(self.k - 1, 0)

    def info(self) -> dict[str, np.ndarray]:
        B, N = self.batch, self.num_agents
        k_est = self._estimated_slice()
        return {
            "true_position": self._slice(self.truth, k_est)[..., :2].copy(),
            "estimated_position": self.estimate.copy(),
            "error": self.errors.copy(),
            "fault": ~self._slice(self.gps_normal, k_est),
            "broadcasts": self.broadcasts.copy(),
            "communication": self.broadcasts.astype(float),
            "messages_sent": self.delivered.sum(axis=(1, 3)),
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
        labels = [f"{name}{' (fault)' if fault[i] else ''}" for i, name in enumerate(self.agent_names)]
        mean_fault = float(self.errors[b][fault].mean()) if fault.any() else 0.0
        return Scene(
            title=f"gps_denied_nbp (wan2014)  tau = {k_est}/{self.horizon}",
            truth=truth,
            estimates=self.estimate[b],
            covariances=cov,
            trails=np.swapaxes(self.truth[b, max(0, k_est - 10): k_est + 1, :, :2], 0, 1),
            particles=particles,
            node_positions=(truth - centre) / max(half, 1e-9),
            node_labels=labels,
            links=links,
            link_value_max=float(self.config.num_iterations),
            link_value_name="iterations with a message",
            extent=(centre[0] - half, centre[0] + half, centre[1] - half, centre[1] + half),
            notes=[f"mean fault-UAV error {mean_fault:.1f} m; broadcasts this step {int(self.broadcasts[b].sum())}"],
        )
