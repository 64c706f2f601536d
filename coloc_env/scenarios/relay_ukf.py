"""``relay_ukf``: UKF cooperative localization distributed over relay chains (Wang et al. 2019).

Paper: Wang, Cui, Kong, Zhao, "A distributed cooperative localization
algorithm for mobile multi-platforms oriented to unpredicted communication
topology", Trans. Nanjing Univ. Aero. Astro. 36(2), 2019 (seed
``002_1a9a5ea84f86e0cc.txt``); estimator in ``estimators.ukf_relay``.

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

Action mask (``infos[agent]["action_mask"]``, ``vector_env(...).action_masks()``; (2N + 1,): index 0's
N choices, then index 1's N + 1; ``RelayUKFScenario.action_mask``): nothing is refused, so a mask
only drops a choice that does by definition what an explicit one does, from the distances at this
step (observation ``[N+1, 2N+1)``):

| index | masked                                          | valid                                                  |
|-------|-------------------------------------------------|--------------------------------------------------------|
| 0     | a platform beyond ``sensing_range`` (no         | itself (no measurement: saves the forced first hop's   |
|       | measurement, as itself)                         | cost) and every platform within ``sensing_range``      |
| 1     | itself (stop, as N); a platform beyond          | N = stop and every other platform within               |
|       | ``comm_range`` (the chain ends, as at N)        | ``comm_range`` (reached ones are not known in advance) |

Observation (per agent, ``Box(shape=(2N + 3,), float32)``)
---------------------------------------------------------
| index            | meaning                                                               | bounds     |
|------------------|-----------------------------------------------------------------------|------------|
| ``[0, N)``       | one-hot of the agent's own index (shared policy, absolute actions)     | [0, 1]     |
| ``[N]``          | 1 if this agent is the measuring platform this step, else 0           | [0, 1]     |
| ``[N+1, 2N+1)``  | distance to each platform / 100 m (0 for itself). Link-layer knowledge: | [0, inf)  |
|                  | the paper's topology rule ("communicate with the closest neighbour")  |            |
|                  | assumes each platform knows which neighbour is closest                |            |
| ``[2N+1]``       | log tr P_ii, the agent's own covariance (m^2)                         | unbounded  |
| ``[2N+2]``       | step fraction k / horizon                                             | [0, 1]     |

(Before the composable core every entry was unbounded; the one-hots, the flag and the fraction now
carry their bounds. The distances are unbounded because ``centres`` may be anywhere; log tr P_ii is
unbounded because dead reckoning without measurements grows P without limit.)

``state()`` (centralized critic): every agent's observation, then log of the
diagonal of the joint covariance P (2N values).

Reward (team: the decisions of one agent move every platform's estimate)
------------------------------------------------------------------------
| ``reward=`` | value for every agent after step k -> k+1 (metres; the paper's metric is a distance) |
|-------------|--------------------------------------------------------------------------------------|
| ``"error"`` | -mean_i ||xhat_i(k+1) - x_i(k+1)|| - sum over delivered hops of the hop cost          |
| ``"trace"`` | -mean_i sqrt(tr P_ii(k+1)) (the filter's own RMS error) - the same hop cost           |

Termination: none; truncation after ``horizon`` steps (the paper's 400 s / 0.5 s = 800).

Metric (``coloc evaluate``, ``RelayUKFScenario.episode_error``): the paper's, the
distance error of the estimate at each measurement time k = 0..K-1 after its update
(``posterior_error``), averaged over the steps and platforms, as
``train/reproduce/wang2019.py`` computes it. The reward's error is the one after the
prediction to k + 1, so an episode's mean reward differs from the metric by the odometry
drift of one step.

``infos[agent]``: ``true_position``, ``estimated_position`` (time k + 1, after the prediction),
``position_error`` and ``error`` (the same distance, m),
``posterior_error`` (the distance error at time k right after this step's measurement
update, before the prediction to k + 1: what the paper's metric averages), ``trace``
(tr P_ii, m^2), ``dead_reckoning_error`` (the same platform by odometry alone, m),
``measuring`` (this agent measured this step), ``partner`` (whom it ranged, -1),
``chain_position`` (its place in this step's chain, 0 = m, -1 not reached),
``relay_target`` (whom it passed to, -1), ``communication`` (hops it delivered this
step, 0 or 1; summed over agents = hops), ``messages_sent`` (= ``communication``: one message
per delivered hop, at its holder) and ``floats_sent`` (that hop's payload, ``coloc_env.backends.ukf.dcl_floats``:
10 + 5 r + 2 r (r - 1) floats with r platforms reached), ``hops`` and ``hop_cost`` (the team's, this
step), ``chain_stop`` (index into ``coloc_env.primitives.relay.STOP_REASONS``, -1 without
a measurement), ``step``.

Arguments (fields of ``RelayUKFConfig``, defaults = the paper's Sec. 4 / Table 1)
-------------------------------------------------------------------------------------
| field                   | default      | allowed                                                   |
|-------------------------|--------------|-----------------------------------------------------------|
| num_platforms           | 4            | 2..16                                                     |
| centres                 | None         | (N, 2) metres, entries in [-1e6, 1e6]; None = the layout above |
| start_angles            | None         | (N,) rad, entries in [-1e6, 1e6]; None = 2 pi i / N       |
| directions              | None         | (N,) of +1 (ccw) / -1 (cw); None = platform 1 clockwise   |
| speed                   | 1.0          | (0, 1e4] m/s                                              |
| turn_rate               | 0.015        | [1e-6, pi/dt] rad/s (smaller: a circle too large to be    |
|                         |              | finite)                                                   |
| dt                      | 0.5          | [1e-6, 3600] s                                            |
| horizon                 | 800          | 1..1000000 steps                                          |
| speed_noise_std         | 0.5          | [0, 1000] m/s                                             |
| turn_rate_noise_std     | 1e-3         | [0, 10] rad/s                                             |
| range_noise_var         | 1.0          | (0, 1e6] m^2                                              |
| measurement_probability | 0.5          | [0, 1]                                                    |
| sensing_range           | inf          | (0, inf] m                                                |
| comm_range              | inf          | (0, inf] m                                                |
| max_hops                | None         | 1..N-1 hops per measurement, None = no limit              |
| loss_at_zero            | 0.0          | [0, 1]                                                    |
| loss_length             | inf          | (0, inf] m (p_loss(d) = 1 - (1 - loss_at_zero) e^(-d/loss_length)) |
| hop_cost                | 0.0          | [0, 1e12] per delivered hop                               |
| hop_cost_per_m2         | 0.0          | [0, 1e12] per hop and squared metre                       |
| initial_position_std    | 0.1          | [1e-6, 1e6] m: P(0) = std^2 I (a Cholesky needs P > 0; the paper's |
|                         |              | start is known, and the estimates start at the truth)      |
| heading_noise           | True         | False: the paper's literal Q (speed noise only)           |
| ukf_lambda              | 0.0          | (-2N, 1e6] (the paper gives no value)                     |
| truncation              | "consistent" | "paper": leave P_RU unchanged on a truncated chain        |
| reward                  | "error"      | "error", "trace"                                          |

Batching: everything is vectorized over copies; two loops remain, over the
at most N-1 hops of a chain and over the at most N chain positions of the
UKF-DCL update (each vectorized over the copies whose chain reaches it).

Composition: this preset is a binding (``coloc_env.scenarios.binding``) on the composable
core: world ``circles`` (``num_anchors=0``, the config's layout and noise), network ``relay``
(``routing="per_holder"``, the config's links and hop costs) and backend ``ukf_dcl``;
``coloc_env.PRESETS["relay_ukf"]`` is that composition. The binding keeps the paper's action
codec (index 0 is the world's sensing choice, index 1 the network's next hop), its observation,
its team reward after the prediction, and its infos. Seeding: the world draws from the episode's
generator itself, in the order this scenario drew before the core (odometry noise, schedule,
range noise), so seeded episodes keep their readings; the relay's losses come from the network's
own counter-based draws (a child generator), no longer from the episode generator, so with
``loss_at_zero > 0`` or a finite ``loss_length`` the losses of a seed differ from earlier versions
(same distribution), as do the draws of a second episode after ``reset()`` without a seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np

import estimators.ukf_relay as ukf
from coloc_env.backends.ukf import UkfDcl
from coloc_env.config import as_array, check_choice, check_entries, check_range
from coloc_env.networks.relay import Relay
from coloc_env.primitives.odometry import OdometrySensor, RangeSensor
from coloc_env.primitives.relay import STOP_REASONS, RelayChain, RelayChainLinks, check_distance
from coloc_env.primitives.unicycle import CircularTracks
from coloc_env.rendering import Link, Scene
from coloc_env.scenarios.binding import PresetScenario
from coloc_env.worlds.circles import Circles

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
        """The circles flown: the ``circles`` world's (its layout where a field is None)."""
        return self.parts()[0].tracks

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

    def parts(self) -> tuple:
        """The (world, network, backend) configs this flat config stands for: ``circles`` without anchors,
        ``relay`` with one next hop per holder, ``ukf_dcl``."""
        world = Circles(num_agents=self.num_platforms, centres=self.centres, start_angles=self.start_angles,
                        directions=self.directions, speed=self.speed, turn_rate=self.turn_rate, dt=self.dt,
                        horizon=self.horizon, speed_noise_std=self.speed_noise_std,
                        turn_rate_noise_std=self.turn_rate_noise_std, range_noise_var=self.range_noise_var,
                        measurement_probability=self.measurement_probability, sensing_range=self.sensing_range,
                        num_anchors=0, initial_position_std=self.initial_position_std,
                        heading_noise=self.heading_noise)
        network = Relay(comm_range=self.comm_range, max_hops=self.max_hops, loss_at_zero=self.loss_at_zero,
                        loss_length=self.loss_length, routing="per_holder", hop_cost=self.hop_cost,
                        hop_cost_per_m2=self.hop_cost_per_m2)
        return world, network, UkfDcl(ukf_lambda=self.ukf_lambda, truncation=self.truncation,
                                       motion="displacement")  # wang2019: position-only state

    def validate(self) -> None:
        check_range("num_platforms", self.num_platforms, 2, 16, integer=True)
        N = self.num_platforms
        for name in ("centres", "start_angles", "directions"):
            value = getattr(self, name)
            if value is not None:
                shape = (N, 2) if name == "centres" else (N,)
                check_entries(name, as_array(name, value, shape=shape), -1e6, 1e6)
        check_range("dt", self.dt, 1e-6, 3600.0)
        check_range("speed", self.speed, 0.0, 1e4, low_open=True)
        check_range("turn_rate", self.turn_rate, 1e-6, np.pi / self.dt, high_label="pi/dt")
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
        check_range("ukf_lambda", self.ukf_lambda, -2.0 * N, 1e6, low_open=True, low_label="-2 num_platforms")
        check_choice("truncation", self.truncation, ("consistent", "paper"))
        check_choice("reward", self.reward, ("error", "trace"))


class RelayUKFScenario(PresetScenario):
    """``relay_ukf`` as a binding: ``circles`` / ``relay`` / ``ukf_dcl`` with the paper's action codec,
    observation, team reward and infos (module docstring)."""

    name = "relay_ukf"
    paper = "wang2019"
    Config = RelayUKFConfig
    agent_prefix = "platform"
    metric_error_key = "posterior_error"

    def __init__(self, config: RelayUKFConfig, batch: int = 1):
        super().__init__(config, batch)
        B, N = self.batch, self.num_agents
        self.dead_reckoning = np.zeros((B, N, 2))
        self.posterior_error = np.zeros((B, N))

    @classmethod
    def composition_options(cls, config: RelayUKFConfig) -> dict:
        return {"reward": config.reward}

    # --- the paper scenario's names for the parts' state (tests, policies, the reproduction) ---------------
    @property
    def truth(self) -> np.ndarray:
        """True positions (K + 1, N, 2): every copy flies the same circles (no process noise)."""
        return self.world.truth

    @property
    def true_heading(self) -> np.ndarray:
        return self.world.true_heading

    @property
    def schedule(self) -> np.ndarray:
        """The measuring platform of each step (B, K), -1 for none."""
        return self.world.schedule

    @property
    def measured_speed(self) -> np.ndarray:
        return self.world.measured_speed

    @property
    def measured_heading(self) -> np.ndarray:
        return self.world.measured_heading

    @property
    def estimate(self) -> np.ndarray:
        """Each platform's current estimate (B, N, 2): after a step, the prediction to k + 1."""
        return self.backend.mean

    @property
    def cov(self) -> np.ndarray:
        """The joint covariance (B, 2N, 2N) (the distributed filter's rows, held together)."""
        return self.backend.cov

    @property
    def chain(self) -> RelayChain:
        """This step's relay chain (length 0 where no measurement was taken)."""
        chain = self.network.last_chain
        if chain is None:
            B, N = self.batch, self.num_agents
            chain = RelayChain(chain=np.full((B, N), -1), length=np.zeros(B, dtype=int),
                               hop_distance=np.full((B, max(N - 1, 1)), np.nan), stop=np.full(B, -1))
        return chain

    # --- description ------------------------------------------------------------
    @property
    def num_agents(self) -> int:
        return self.config.num_platforms

    @property
    def obs_dim(self) -> int:
        return 2 * self.num_agents + 3

    def observation_space(self):
        N = self.num_agents
        low = np.concatenate([np.zeros(N + 1), np.zeros(N), [-np.inf], [0.0]])
        high = np.concatenate([np.ones(N + 1), np.full(N, np.inf), [np.inf], [1.0]])
        return gymnasium.spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)

    def action_space(self):
        N = self.num_agents
        return gymnasium.spaces.MultiDiscrete([N, N + 1], dtype=np.int64)

    def action_mask(self) -> np.ndarray:
        """(B, N, 2N + 1) bool, the "Action masks" table: index 0's N choices, then index 1's N + 1 (the
        core's ``partner`` and ``next_hop`` rules without their ``nearest`` entries, which this codec lacks)."""
        N = self.num_agents
        partner, next_hop = self.block_choice_masks()
        return np.concatenate([partner[:, :, 0, :N], next_hop[:, :, 0, :N + 1]], axis=-1)

    def state_space(self):
        dim = self.num_agents * self.obs_dim + 2 * self.num_agents
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(dim,), dtype=np.float32)

    # --- dynamics ------------------------------------------------------------------
    def reset(self, rngs, env_index=None) -> None:
        super().reset(rngs, env_index)
        idx = self._indices(env_index)
        self.dead_reckoning[idx] = self.world.truth[0]
        self.posterior_error[idx] = 0.0  # the estimates start at the truth

    def decode_actions(self, actions) -> np.ndarray:
        """Actions (B, N, 2) -> the parts' blocks: whom to range with (the world's sensing choice; never its
        ``nearest`` entry) and whom to relay to (the network's next hop; N = stop, as the network's)."""
        N = self.num_agents
        return self.check_discrete_actions(
            actions, ("action[0] (whom to range with)", f"action[1] (whom to relay to, {N} = stop)"))

    def advance(self, decoded) -> None:
        super().advance(decoded)
        self.posterior_error = self.position_error()
        speed, heading = self.readings.inputs[..., 0], self.readings.inputs[..., 1]
        self.dead_reckoning, _ = ukf.time_update(self.dead_reckoning, None, speed, heading, self.config.dt, 0.0)

    def compute_reward(self) -> np.ndarray:
        """The team's: minus the mean over platforms of the error (or RMS) after the prediction to k + 1, minus
        the hop cost of the step's chain."""
        if self.config.reward == "error":
            loss = self.prior_error().mean(axis=-1)
        else:
            loss = np.sqrt(self.own_traces()).mean(axis=-1)
        cost = self.network.cost_sent.sum(axis=-1)
        return np.repeat((-loss - cost)[:, None], self.num_agents, axis=1)

    # --- views -------------------------------------------------------------------------
    def prior_error(self) -> np.ndarray:
        """||xhat_i(k+1) - x_i(k+1)|| (B, N), metres: the current estimate after a step's prediction."""
        return np.linalg.norm(self.backend.mean - self.world.positions(), axis=-1)

    def own_traces(self) -> np.ndarray:
        """tr P_ii (B, N) of the current estimate (the joint covariance's diagonal, in pairs)."""
        return np.diagonal(self.backend.cov, axis1=-2, axis2=-1).reshape(self.batch, self.num_agents, 2).sum(axis=-1)

    def distances(self) -> np.ndarray:
        """True distances between platforms at the current step (B, N, N)."""
        return self.world.distances()

    def observation(self) -> np.ndarray:
        B, N = self.batch, self.num_agents
        table = self.world.distance_table
        cached = getattr(self, "_scaled_distances", None)
        if cached is None or cached[0] is not table:  # the world's table of distances, in the observation's unit
            cached = self._scaled_distances = (table, (table / DISTANCE_SCALE).astype(np.float32))
        obs = np.empty((B, N, 2 * N + 3), dtype=np.float32)  # each entry cast from float64, as astype would
        obs[:, :, :N] = np.eye(N)
        obs[:, :, N] = np.arange(N)[None, :] == self.world.measuring()[:, None]
        obs[:, :, N + 1:2 * N + 1] = cached[1][self.world.k]
        obs[:, :, 2 * N + 1] = np.log(self.own_traces())
        obs[:, :, 2 * N + 2] = (self.k / self.horizon)[:, None]
        return obs

    def episode_error(self, errors: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """The paper's metric: the distance error ||xhat_i - x_i|| averaged over the steps and platforms.

        ``errors`` are the ``posterior_error`` infos (``metric_error_key``): time k after its
        measurement update, k = 0..K-1, as the reproduction averages them.
        """
        return np.asarray(errors, float).mean(axis=(-2, -1))

    def state(self) -> np.ndarray:
        log_var = np.log(np.diagonal(self.backend.cov, axis1=-2, axis2=-1))
        return np.concatenate([self.observation().reshape(self.batch, -1), log_var], axis=-1).astype(np.float32)

    def info(self) -> dict[str, np.ndarray]:
        B, N = self.batch, self.num_agents
        chain = self.chain
        ids = np.arange(N)[None, :]
        measuring_platform = np.where(chain.length > 0, chain.chain[:, 0], -1)
        measuring = ids == measuring_platform[:, None]
        partner = np.where(chain.length > 0, np.argmax(self.readings.range_valid.any(axis=1), axis=-1), -1) \
            if self.readings is not None else np.full(B, -1)
        relay_target = chain.next_hop(N)
        team = lambda values: np.repeat(np.asarray(values)[:, None], N, axis=1)  # noqa: E731
        truth = np.broadcast_to(self.world.positions(), (B, N, 2)).copy()
        error = self.prior_error()
        return {
            "true_position": truth,
            "estimated_position": self.backend.mean.copy(),
            "position_error": error,
            "error": error.copy(),
            "posterior_error": self.posterior_error.copy(),
            "trace": self.own_traces(),
            "dead_reckoning_error": np.linalg.norm(self.dead_reckoning - truth, axis=-1),
            "measuring": measuring,
            "partner": np.where(measuring, partner[:, None], -1),
            "chain_position": chain.position_of(N),
            "relay_target": relay_target,
            "communication": (relay_target >= 0).astype(float),
            "messages_sent": self.network.messages_sent.copy(),
            "floats_sent": self.network.floats_sent.copy(),
            "hops": team(chain.hops),
            "hop_cost": team(self.network.cost_sent.sum(axis=-1)),
            "chain_stop": team(chain.stop),
            "step": team(self.k),
        }

    def scene(self, b: int) -> Scene:
        N, k = self.num_agents, int(self.k[b])
        positions = self.truth[k]
        reach = float(np.abs(self.truth).max()) + 10.0
        chain = self.chain.chain[b]
        hops = [int(p) for p in chain if p >= 0]
        links = [Link(source=a, target=c, value=1.0, label=("range" if h == 0 else str(h + 1)))
                 for h, (a, c) in enumerate(zip(hops[:-1], hops[1:], strict=True))]
        reason = STOP_REASONS[self.chain.stop[b]] if self.chain.stop[b] >= 0 else "no measurement"
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
                   f"mean error {self.prior_error()[b].mean():.2f} m"],
        )
