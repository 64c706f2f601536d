"""``relay_ukf``: UKF cooperative localization distributed over relay chains (Wang et al. 2019).

Paper: Wang, Cui, Kong, Zhao, "A distributed cooperative localization
algorithm for mobile multi-platforms oriented to unpredicted communication
topology", Trans. Nanjing Univ. Aero. Astro. 36(2), 2019 (seed
``002_1a9a5ea84f86e0cc.txt``); estimator in :mod:`estimators.ukf_relay`.

N platforms fly circles (Sec. 4: A1, A3, A4 counter-clockwise, A2 clockwise;
1 m/s, 0.015 rad/s, so radius ~66.7 m) and localize by dead reckoning from
noisy odometry (speed and turn rate). At each step, with probability
``measurement_probability``, one platform m (drawn uniformly by the env)
measures its range to a platform n, and the location information of that
measurement travels along a relay chain m -> n -> ...; every platform it
reaches updates its own position estimate by UKF-DCL (equal to the
centralized UKF when the chain reaches everyone). The agents decide what the
paper fixes by hand: whom m ranges with, and whom each holder of the
location information passes it to next, or stop.

Geometry (the paper prints no coordinates): circle centres at (-8, -8),
(8, -8), (8, 8), (-8, 8) m, start points at polar angles 0, pi/2, pi,
3 pi/2 about them, so the platforms stay inside a 149 m square (largest
distance between two platforms 156 m, smallest 11 m) and the nearest
neighbour of each platform changes over time. For other N: centres on a
ring of radius 8 sqrt(2) m, start angles 2 pi i / N, platform 1 clockwise.
Initial positions and headings are known.

Each env step is one time step k -> k+1 (dt = 0.5 s, 800 steps = 400 s):
the measurement of step k happens at time k, on positions the observation
shows (the chain is resolved within the step), then every platform predicts
to k+1 from its odometry.

Action (per agent, ``MultiDiscrete([N, N + 1])``, int64, absolute platform indices)
---------------------------------------------------------------------------------
| index | meaning                                                                      |
|-------|------------------------------------------------------------------------------|
| 0     | whom to range with if this agent is the measuring platform this step; itself |
|       | (or a platform beyond ``sensing_range``) = no measurement this step           |
| 1     | whom to pass the location information to next if it reaches this agent;      |
|       | N or itself = stop. A platform already reached, beyond ``comm_range``, a     |
|       | spent hop budget or a lost packet also ends the chain (never revisits).      |

The measuring platform always sends to the measured one first (Algorithm 1
needs n's sigma points); its own index 1 is not used. Non-integer or
out-of-range actions and NaN/inf are a ``ValueError``. Whether a measurement
happens and who measures is drawn by the env: a policy cannot measure more
often than ``measurement_probability``.

Observation (per agent, ``Box(-inf, inf, shape=(2N + 3,), float32)``)
--------------------------------------------------------------------
| index            | meaning                                                               |
|------------------|-----------------------------------------------------------------------|
| ``[0, N)``       | one-hot of the agent's own index (shared policy, absolute actions)     |
| ``[N]``          | 1 if this agent is the measuring platform this step, else 0           |
| ``[N+1, 2N+1)``  | distance to each platform / 100 m (0 for itself). Link-layer knowledge: |
|                  | the paper's topology rule ("communicate with the closest neighbour")  |
|                  | assumes each platform knows which neighbour is closest                |
| ``[2N+1]``       | log tr P_ii, the agent's own covariance (m^2)                         |
| ``[2N+2]``       | step fraction k / horizon                                             |

``state()`` (centralized critic): every agent's observation, then log of the
diagonal of the joint covariance P (2N values).

Reward (team: the decisions of one agent move every platform's estimate)
------------------------------------------------------------------------
| ``reward=`` | value for every agent after step k -> k+1 (metres; the paper's metric is a distance) |
|-------------|--------------------------------------------------------------------------------------|
| ``"error"`` | -mean_i ||xhat_i(k+1) - x_i(k+1)|| - sum over delivered hops of the hop cost          |
| ``"trace"`` | -mean_i sqrt(tr P_ii(k+1)) (the filter's own RMS error) - the same hop cost           |

Termination: none; truncation after ``horizon`` steps (the paper's 400 s / 0.5 s = 800).

Metric (``coloc evaluate``, :meth:`RelayUKFScenario.episode_error`): the paper's, the
distance error of the estimate at each measurement time k = 0..K-1 after its update
(``posterior_error``), averaged over the steps and platforms, as
``train/reproduce/wang2019.py`` computes it. The reward's error is the one after the
prediction to k + 1, so an episode's mean reward differs from the metric by the odometry
drift of one step.

``infos[agent]``: ``true_position``, ``estimated_position``, ``error`` (distance, m),
``posterior_error`` (the distance error at time k right after this step's measurement
update, before the prediction to k + 1: what the paper's metric averages), ``trace``
(tr P_ii, m^2), ``dead_reckoning_error`` (the same platform by odometry alone, m),
``measuring`` (this agent measured this step), ``partner`` (whom it ranged, -1),
``chain_position`` (its place in this step's chain, 0 = m, -1 not reached),
``relay_target`` (whom it passed to, -1), ``communication`` (hops it delivered this
step, 0 or 1; summed over agents = hops), ``hops`` and ``hop_cost`` (the team's, this
step), ``chain_stop`` (index into :data:`coloc_env.world.relay.STOP_REASONS`, -1 without
a measurement), ``step``.

Arguments (fields of :class:`RelayUKFConfig`, defaults = the paper's Sec. 4 / Table 1)
-------------------------------------------------------------------------------------
| field                   | default      | allowed                                                   |
|-------------------------|--------------|-----------------------------------------------------------|
| num_platforms           | 4            | 2..16                                                     |
| centres                 | None         | (N, 2) metres; None = the layout above                    |
| start_angles            | None         | (N,) rad; None = 2 pi i / N                               |
| directions              | None         | (N,) of +1 (ccw) / -1 (cw); None = platform 1 clockwise   |
| speed                   | 1.0          | > 0 m/s                                                   |
| turn_rate               | 0.015        | [1e-6, pi/dt] rad/s (smaller: a circle too large to be    |
|                         |              | finite)                                                   |
| dt                      | 0.5          | [1e-6, 3600] s                                            |
| horizon                 | 800          | 1..1000000 steps                                          |
| speed_noise_std         | 0.5          | >= 0 m/s                                                  |
| turn_rate_noise_std     | 1e-3         | >= 0 rad/s                                                |
| range_noise_var         | 1.0          | > 0 m^2                                                   |
| measurement_probability | 0.5          | [0, 1]                                                    |
| sensing_range           | inf          | > 0 m                                                     |
| comm_range              | inf          | > 0 m                                                     |
| max_hops                | None         | 1..N-1 hops per measurement, None = no limit              |
| loss_at_zero            | 0.0          | [0, 1]                                                    |
| loss_length             | inf          | > 0 m (p_loss(d) = 1 - (1 - loss_at_zero) e^(-d/loss_length)) |
| hop_cost                | 0.0          | >= 0 per delivered hop                                    |
| hop_cost_per_m2         | 0.0          | >= 0 per hop and squared metre                            |
| initial_position_std    | 0.1          | [1e-6, 1e6] m: P(0) = std^2 I (a Cholesky needs P > 0; the paper's |
|                         |              | start is known, and the estimates start at the truth)      |
| heading_noise           | True         | False: the paper's literal Q (speed noise only)           |
| ukf_lambda              | 0.0          | > -2N (the paper gives no value)                          |
| truncation              | "consistent" | "paper": leave P_RU unchanged on a truncated chain        |
| reward                  | "error"      | "error", "trace"                                          |

Batching: everything is vectorized over copies; two loops remain, over the
at most N-1 hops of a chain and over the at most N chain positions of the
UKF-DCL update (each vectorized over the copies whose chain reaches it).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import gymnasium
import numpy as np

import estimators.ukf_relay as ukf
from coloc_env.config import as_array, check_choice, check_range
from coloc_env.rendering import Link, Scene
from coloc_env.scenarios.base import Scenario
from coloc_env.world.odometry import OdometrySensor, RangeSensor
from coloc_env.world.relay import STOP_REASONS, RelayChain, RelayChainLinks, check_distance
from coloc_env.world.unicycle import CircularTracks, UnicycleMotion
from coloc_env.worlds.circles import default_layout

DISTANCE_SCALE = 100.0  # metres per unit in the observation


@dataclass(frozen=True)
class RelayUKFConfig:
    """Configuration of ``relay_ukf``; defaults are the paper's simulation (Sec. 4, Table 1)."""

    num_platforms: int = 4
    centres: tuple | None = None
    start_angles: tuple | None = None
    directions: tuple | None = None
    speed: float = 1.0
    turn_rate: float = 0.015
    dt: float = 0.5
    horizon: int = 800
    speed_noise_std: float = 0.5
    turn_rate_noise_std: float = 1e-3
    range_noise_var: float = 1.0
    measurement_probability: float = 0.5
    sensing_range: float = float("inf")
    comm_range: float = float("inf")
    max_hops: int | None = None
    loss_at_zero: float = 0.0
    loss_length: float = float("inf")
    hop_cost: float = 0.0
    hop_cost_per_m2: float = 0.0
    initial_position_std: float = 0.1
    heading_noise: bool = True
    ukf_lambda: float = 0.0
    truncation: str = "consistent"
    reward: str = "error"

    @property
    def tracks(self) -> CircularTracks:
        centres, angles, directions = default_layout(self.num_platforms)
        return CircularTracks(
            centres=centres if self.centres is None else np.asarray(self.centres, float),
            start_angles=angles if self.start_angles is None else np.asarray(self.start_angles, float),
            directions=directions if self.directions is None else np.asarray(self.directions, float),
            speed=self.speed, turn_rate=self.turn_rate, dt=self.dt)

    @property
    def odometry(self) -> OdometrySensor:
        return OdometrySensor(self.speed_noise_std, self.turn_rate_noise_std)

    @property
    def range_sensor(self) -> RangeSensor:
        return RangeSensor(self.range_noise_var, self.sensing_range)

    @property
    def links(self) -> RelayChainLinks:
        return RelayChainLinks(self.comm_range, self.max_hops, self.loss_at_zero, self.loss_length,
                               self.hop_cost, self.hop_cost_per_m2)

    def validate(self) -> None:
        check_range("num_platforms", self.num_platforms, 2, 16, integer=True)
        N = self.num_platforms
        for name in ("centres", "start_angles", "directions"):
            value = getattr(self, name)
            if value is not None:
                shape = (N, 2) if name == "centres" else (N,)
                as_array(name, value, shape=shape)
        check_range("dt", self.dt, 1e-6, 3600.0)
        check_range("speed", self.speed, 0.0, 1e4, low_open=True)
        check_range("turn_rate", self.turn_rate, 1e-6, np.pi / self.dt)
        self.tracks.validate()
        check_range("horizon", self.horizon, 1, 1_000_000, integer=True)
        self.odometry.validate()
        check_range("range_noise_var", self.range_noise_var, 0.0, 1e6, low_open=True)
        check_distance("sensing_range", self.sensing_range)
        check_range("measurement_probability", self.measurement_probability, 0.0, 1.0)
        self.links.validate(N)
        check_range("initial_position_std", self.initial_position_std, 1e-6, 1e6)
        if not isinstance(self.heading_noise, (bool, np.bool_)):
            raise ValueError(f"heading_noise must be True or False, got {self.heading_noise!r}")
        check_range("ukf_lambda", self.ukf_lambda, -2.0 * N, 1e6, low_open=True)
        check_choice("truncation", self.truncation, ("consistent", "paper"))
        check_choice("reward", self.reward, ("error", "trace"))


@dataclass
class MeasurementEvent:
    """What happened at time k in each copy: who measured whom, the chain, the range."""

    measuring: np.ndarray  # (B,) platform m, -1 if no measurement was scheduled
    partner: np.ndarray  # (B,) platform n chosen by m, -1 without a measurement
    used: np.ndarray  # (B,) bool: the chain reached n, the estimator updated
    relay: RelayChain  # length 0 where no measurement was taken
    range: np.ndarray  # (B,) measured range z (nan where unused)
    cost: np.ndarray  # (B,) hop cost of the delivered hops


class RelayUKFScenario(Scenario):
    """Batched core of ``relay_ukf``; see the module docstring for the tables."""

    name = "relay_ukf"
    paper = "wang2019"
    Config = RelayUKFConfig
    agent_prefix = "platform"
    metric_error_key = "posterior_error"

    def __init__(self, config: RelayUKFConfig, batch: int = 1):
        super().__init__(config, batch)
        if config.truncation == "paper":
            warnings.warn(ukf.PAPER_RULE_WARNING, UserWarning, stacklevel=2)
        N, K, B = self.num_agents, self.horizon, self.batch
        self.tracks = config.tracks
        self.odometry_sensor = config.odometry
        self.range_sensor = config.range_sensor
        self.links = config.links
        # The truth has no process noise: every copy flies the same circles.
        self.truth, self.true_heading, self._speed, self._turn_rate = self.tracks.trajectory(K)
        self._initial_cov = config.initial_position_std**2 * np.eye(2 * N)
        self.k = np.zeros(B, dtype=int)
        self.estimate = np.zeros((B, N, 2))
        self.cov = np.zeros((B, 2 * N, 2 * N))
        self.dead_reckoning = np.zeros((B, N, 2))
        self.measured_speed = np.zeros((B, K, N))
        self.measured_heading = np.zeros((B, K, N))
        self.schedule = np.full((B, K), -1)  # measuring platform at each step, -1 none
        self._range_noise = np.zeros((B, K))
        self._loss_uniforms = np.zeros((B, K, max(N - 1, 1)))
        self.event = self._empty_event(B)
        self._reward = np.zeros((B, N))
        self.posterior_error = np.zeros((B, N))

    # --- description ------------------------------------------------------------
    @property
    def num_agents(self) -> int:
        return self.config.num_platforms


    @property
    def obs_dim(self) -> int:
        return 2 * self.num_agents + 3

    def observation_space(self):
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(self.obs_dim,), dtype=np.float32)

    def action_space(self):
        N = self.num_agents
        return gymnasium.spaces.MultiDiscrete([N, N + 1], dtype=np.int64)

    def state_space(self):
        dim = self.num_agents * self.obs_dim + 2 * self.num_agents
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(dim,), dtype=np.float32)

    def heading_variance(self, k: np.ndarray) -> np.ndarray:
        """sigma_phi^2 of the heading used at step k (0 when ``heading_noise`` is off), shape like k."""
        if not self.config.heading_noise:
            return np.zeros(np.shape(k))
        return self.odometry_sensor.heading_variance(k, self.config.dt)

    def odometry(self, k: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Measured speed (B, N), integrated heading (B, N) and heading variance (B, 1) at step ``k`` (default: now)."""
        k = self.k if k is None else np.asarray(k)
        rows = np.arange(self.batch)
        return (self.measured_speed[rows, k], self.measured_heading[rows, k],
                self.heading_variance(k)[:, None])

    # --- dynamics ------------------------------------------------------------------
    def reset(self, rngs, env_index=None) -> None:
        idx = self._indices(env_index)
        if len(rngs) != len(idx):
            raise ValueError(f"reset needs one generator per copy: {len(idx)} copies, {len(rngs)} generators")
        N, K = self.num_agents, self.horizon
        speed_noise = np.empty((len(idx), K, N))
        turn_noise = np.empty((len(idx), K, N))
        occurs = np.empty((len(idx), K))
        who = np.empty((len(idx), K), dtype=int)
        for c, rng in enumerate(rngs):
            # One block per episode, in a fixed order, so that stepping never loops over copies.
            speed_noise[c], turn_noise[c] = self.odometry_sensor.sample_noise(rng, (K, N))
            occurs[c] = rng.random(K)
            who[c] = rng.integers(0, N, size=K)
            self._range_noise[idx[c]] = self.range_sensor.sample_noise(rng, (K,))
            self._loss_uniforms[idx[c]] = rng.random((K, self._loss_uniforms.shape[-1]))
        speed, turn = self.odometry_sensor.measure(self._speed, self._turn_rate, speed_noise, turn_noise)
        self.measured_speed[idx] = speed
        # Known initial heading; the platform integrates its measured turn rate (Sec. 1).
        heading = UnicycleMotion(self.config.dt).headings(self.true_heading[0][None, :],
                                                          np.swapaxes(turn, 1, 2))
        self.measured_heading[idx] = np.swapaxes(heading, 1, 2)
        # Uniforms compared with p: the same draws give nested schedules across p.
        self.schedule[idx] = np.where(occurs < self.config.measurement_probability, who, -1)
        self.k[idx] = 0
        self.estimate[idx] = self.truth[0]
        self.dead_reckoning[idx] = self.truth[0]
        self.cov[idx] = self._initial_cov
        fresh = self._empty_event(len(idx))
        for name in ("measuring", "partner", "used", "range", "cost"):
            getattr(self.event, name)[idx] = getattr(fresh, name)
        for name in ("chain", "length", "hop_distance", "stop"):
            getattr(self.event.relay, name)[idx] = getattr(fresh.relay, name)
        self._reward[idx] = 0.0
        self.posterior_error[idx] = 0.0  # the estimates start at the truth

    def _empty_event(self, count: int) -> MeasurementEvent:
        N = self.num_agents
        relay = RelayChain(chain=np.full((count, N), -1), length=np.zeros(count, dtype=int),
                           hop_distance=np.full((count, max(N - 1, 1)), np.nan), stop=np.full(count, -1))
        return MeasurementEvent(measuring=np.full(count, -1), partner=np.full(count, -1),
                                used=np.zeros(count, dtype=bool), relay=relay, range=np.full(count, np.nan),
                                cost=np.zeros(count))

    def decode_actions(self, actions) -> np.ndarray:
        """Actions (B, N, 2) -> int array, after checking finiteness, integrality and range."""
        N = self.num_agents
        return self.check_discrete_actions(
            actions, ("action[0] (whom to range with)", f"action[1] (whom to relay to, {N} = stop)"))

    def step(self, actions) -> None:
        if np.any(self.k >= self.horizon):
            raise RuntimeError("step() on a copy whose episode is over; reset it first")
        event = self.measurement_event(self.decode_actions(actions))
        self.measurement_update(event)
        self.time_update()

    def measurement_event(self, actions: np.ndarray) -> MeasurementEvent:
        """Resolve this step's measurement and relay chain from decoded actions (B, N, 2)."""
        B, N = self.batch, self.num_agents
        rows = np.arange(B)
        positions = np.broadcast_to(self.truth[self.k], (B, N, 2))
        measuring = self.schedule[rows, self.k]
        source = np.maximum(measuring, 0)
        partner = np.where(measuring >= 0, actions[rows, source, 0], -1)
        in_view = self.range_sensor.in_range(positions[rows, source], positions[rows, np.maximum(partner, 0)])
        attempt = (measuring >= 0) & (partner != measuring) & in_view
        relay = self.links.resolve(positions, source, np.where(attempt, partner, source), actions[..., 1],
                                   self._loss_uniforms[rows, self.k])
        relay.chain[~attempt] = -1
        relay.length[~attempt] = 0
        relay.hop_distance[~attempt] = np.nan
        relay.stop[~attempt] = -1
        used = relay.length >= 2
        z = np.where(used, self.range_sensor.measure(positions[rows, source], positions[rows, np.maximum(partner, 0)],
                                                     self._range_noise[rows, self.k]), np.nan)
        cost = self.links.cost(relay.hop_distance).sum(axis=-1)
        return MeasurementEvent(measuring=measuring, partner=partner, used=used, relay=relay, range=z, cost=cost)

    def measurement_update(self, event: MeasurementEvent) -> None:
        """UKF-DCL along each copy's chain (copies without a used measurement keep their estimates)."""
        self.event = event
        sub = np.flatnonzero(event.used)
        if len(sub) == 0:
            return
        try:
            self.estimate[sub], self.cov[sub] = ukf.dcl_update(
                self.estimate[sub], self.cov[sub], event.relay.chain[sub], event.relay.length[sub],
                event.range[sub], self.config.range_noise_var, self.config.ukf_lambda, self.config.truncation)
        except np.linalg.LinAlgError as exc:
            if self.config.truncation != "paper":
                raise
            raise ukf.paper_rule_failure(exc, int(self.k[sub].max())) from exc

    def time_update(self) -> None:
        """Every platform predicts k -> k+1 from its odometry (eq. 1); the truth moves; rewards.

        First records ``posterior_error``, the error at time k after its measurement update.
        """
        self.posterior_error = self.position_error()
        speed, heading, heading_var = self.odometry()
        self.estimate, self.cov = ukf.time_update(self.estimate, self.cov, speed, heading, self.config.dt,
                                                  self.config.speed_noise_std**2, heading_var)
        self.dead_reckoning, _ = ukf.time_update(self.dead_reckoning, None, speed, heading, self.config.dt, 0.0)
        self.k = self.k + 1
        if self.config.reward == "error":
            loss = self.position_error().mean(axis=-1)
        else:
            loss = np.sqrt(self.own_traces()).mean(axis=-1)
        self._reward = np.repeat((-loss - self.event.cost)[:, None], self.num_agents, axis=1)

    # --- views -------------------------------------------------------------------------
    def position_error(self) -> np.ndarray:
        """||xhat_i - x_i|| (B, N), metres."""
        return np.linalg.norm(self.estimate - self.truth[self.k], axis=-1)

    def own_traces(self) -> np.ndarray:
        """tr P_ii (B, N)."""
        diag = np.diagonal(self.cov, axis1=-2, axis2=-1)
        return diag.reshape(self.batch, self.num_agents, 2).sum(axis=-1)

    def distances(self) -> np.ndarray:
        """True distances between platforms at the current step (B, N, N)."""
        positions = self.truth[self.k]
        return np.linalg.norm(positions[:, :, None, :] - positions[:, None, :, :], axis=-1)

    def observation(self) -> np.ndarray:
        B, N = self.batch, self.num_agents
        identity = np.broadcast_to(np.eye(N), (B, N, N))
        k_now = np.minimum(self.k, self.horizon - 1)
        measuring = self.schedule[np.arange(B), k_now]
        flag = ((np.arange(N)[None, :] == measuring[:, None]) & (self.k < self.horizon)[:, None]).astype(float)
        frac = np.broadcast_to((self.k / self.horizon)[:, None], (B, N))
        obs = np.concatenate([identity, flag[..., None], self.distances() / DISTANCE_SCALE,
                              np.log(self.own_traces())[..., None], frac[..., None]], axis=-1)
        return obs.astype(np.float32)

    def episode_error(self, errors: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """The paper's metric: the distance error ||xhat_i - x_i|| averaged over the steps and platforms.

        ``errors`` are the ``posterior_error`` infos (:attr:`metric_error_key`): time k after its
        measurement update, k = 0..K-1, as the reproduction averages them.
        """
        return np.asarray(errors, float).mean(axis=(-2, -1))

    def reward(self) -> np.ndarray:
        return self._reward.copy()

    def done(self) -> np.ndarray:
        return self.k >= self.horizon

    def state(self) -> np.ndarray:
        log_var = np.log(np.diagonal(self.cov, axis1=-2, axis2=-1))
        return np.concatenate([self.observation().reshape(self.batch, -1), log_var], axis=-1).astype(np.float32)

    def info(self) -> dict[str, np.ndarray]:
        B, N = self.batch, self.num_agents
        event = self.event
        ids = np.arange(N)[None, :]
        measuring = (ids == event.measuring[:, None]) & (event.relay.length[:, None] > 0)
        relay_target = event.relay.next_hop(N)
        team = lambda values: np.repeat(np.asarray(values)[:, None], N, axis=1)  # noqa: E731
        return {
            "true_position": np.broadcast_to(self.truth[self.k], (B, N, 2)).copy(),
            "estimated_position": self.estimate.copy(),
            "error": self.position_error(),
            "posterior_error": self.posterior_error.copy(),
            "trace": self.own_traces(),
            "dead_reckoning_error": np.linalg.norm(self.dead_reckoning - self.truth[self.k], axis=-1),
            "measuring": measuring,
            "partner": np.where(measuring, event.partner[:, None], -1),
            "chain_position": event.relay.position_of(N),
            "relay_target": relay_target,
            "communication": (relay_target >= 0).astype(float),
            "hops": team(event.relay.hops),
            "hop_cost": team(event.cost),
            "chain_stop": team(event.relay.stop),
            "step": team(self.k),
        }

    def scene(self, b: int) -> Scene:
        N, k = self.num_agents, int(self.k[b])
        positions = self.truth[k]
        reach = float(np.abs(self.truth).max()) + 10.0
        chain = self.event.relay.chain[b]
        hops = [int(p) for p in chain if p >= 0]
        links = [Link(source=a, target=c, value=1.0, label=("range" if h == 0 else str(h + 1)))
                 for h, (a, c) in enumerate(zip(hops[:-1], hops[1:], strict=True))]
        reason = STOP_REASONS[self.event.relay.stop[b]] if self.event.relay.stop[b] >= 0 else "no measurement"
        cov_blocks = np.stack([self.cov[b, 2 * i:2 * i + 2, 2 * i:2 * i + 2] for i in range(N)])
        return Scene(
            title=f"relay_ukf (wang2019)  t = {k * self.config.dt:.1f} s",
            truth=positions,
            estimates=self.estimate[b],
            covariances=cov_blocks,
            trails=np.swapaxes(self.truth[: k + 1], 0, 1),
            node_positions=positions / reach,
            node_labels=self.agent_names,
            links=links,
            link_value_max=1.0,
            link_value_name="relay hop of the last step",
            extent=(-reach, reach, -reach, reach),
            notes=[f"chain {' -> '.join(map(str, hops)) or '-'} ({reason})",
                   f"mean error {self.position_error()[b].mean():.2f} m"],
        )
