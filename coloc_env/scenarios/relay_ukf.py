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
step (observation ``[N+1, 2N+1)``); the rules are the ``circles`` world's and the ``relay`` network's:

| index | masked                                          | valid                                                  |
|-------|-------------------------------------------------|--------------------------------------------------------|
| 0     | a platform beyond ``sensing_range`` (no         | itself (no measurement: saves the forced first hop's   |
|       | measurement, as itself)                         | cost) and every platform within ``sensing_range``      |
| 1     | itself (stop, as N); a platform beyond          | N = stop and every other platform within               |
|       | ``comm_range`` (the chain ends, as at N)        | ``comm_range`` (reached ones are not known in advance) |

Observation (per agent, ``Box(shape=(2N + 7,), float32)``)
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
| ``[2N+3]``       | ``displacement``: how far its position estimate moved since its last  | [0, inf)   |
|                  | relayed hop (``transmissions`` > 0; the start before any), / 100 m    |            |
| ``[2N+4]``       | ``steps_since``: steps since that hop / horizon                       | [0, 1]     |
| ``[2N+5]``       | ``message_value``: max(0, tr(P_ref + (k - k_ref) Q_pos) - tr P_ii),   | [0, inf)   |
|                  | m^2 (``Backend.message_value``)                                       |            |
| ``[2N+6]``       | ``communication_cost``: its copy's cost per hop this episode          | [0, inf)   |
|                  | (``communication_cost``, or the draw from ``cost_range``), m          |            |

The named entries are the composed observation's features (``feature_index``: ``index`` [0, N),
``log_trace`` [2N+1], ``step_fraction`` [2N+2] and these). The event-triggered families
(``agents.event_triggered``) decide the relay entry: send = ``paper``'s choice, quiet = N (stop), so their
extremes are ``always`` (= ``paper``) and ``silent`` (= ``no_relay``). ``uncertainty`` reads the holder's own
log tr P_ii: the simpler reading of "the holder's uncertainty about the next platform" (the holder does not
know which platform its message would reach before the paper's chain rule picks it).

The distances are unbounded because ``centres`` may be anywhere; log tr P_ii is unbounded because
dead reckoning without measurements grows P without limit.

``state()`` (centralized critic): every agent's observation, then log of the
diagonal of the joint covariance P (2N values).

Reward (team: the decisions of one agent move every platform's estimate)
------------------------------------------------------------------------
| ``reward=`` | value for every agent after step k -> k+1 (metres; the paper's metric is a distance) |
|-------------|--------------------------------------------------------------------------------------|
| ``"error"`` | -mean_i ||xhat_i(k+1) - x_i(k+1)|| (m) - the step's hop costs                        |
| ``"trace"`` | -mean_i sqrt(tr P_ii(k+1)) (m: the filter's own RMS error, in the unit of ``error``) |
|             | - the same hop costs; the ``trace`` info key stays tr P_ii in m^2                    |

The step's hop costs: ``communication_cost`` (under ``cost_range``, the copy's draw of the episode) per
delivered hop (one message each) plus
``hop_cost_per_m2`` d^2 for a hop of length d, summed over the chain (metres of error, as the
reward; ``coloc_env.scenarios.relay_codec``).

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
step: the hop costs the reward subtracts), ``chain_stop`` (index into
``coloc_env.networks.blocks.relay_chain.STOP_REASONS``, -1 without a measurement), the network's per-link counts
``transmissions``, ``link_attempts`` (hops it sent, the lost one included), ``link_deliveries``, ``collisions``
(the table of ``coloc_env.networks.base``), ``step``.

Arguments (fields of ``RelayUKFConfig``, defaults = the paper's Sec. 4 / Table 1)
-------------------------------------------------------------------------------------
| field                   | default      | allowed                                                   |
|-------------------------|--------------|-----------------------------------------------------------|
| num_agents              | 4            | 2..16 (older name ``num_platforms``)                      |
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
| communication_cost      | 0.0          | [0, 1e12] m per delivered hop (one message); older name ``hop_cost`` |
| cost_range              | None         | None, or (lo, hi) with 0 <= lo <= hi <= 1e12:                        |
|                         |              | each copy draws its cost per episode at reset                        |
|                         |              | (``coloc_env.composition``'s law), replacing                         |
|                         |              | ``communication_cost``                                               |
| hop_cost_per_m2         | 0.0          | [0, 1e12] m per hop and squared metre                     |
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
(``routing="per_holder"``, the config's links and ``hop_cost_per_m2``) and backend ``ukf_dcl``
(``motion="displacement"``: the paper's position-only state); ``coloc_env.PRESETS["relay_ukf"]``
is that composition. Each keyword sets the part field of the same name (``communication_cost`` the
composition's); the parts check them, the rules that tie a part field to the team's size
(``max_hops``, ``ukf_lambda``) with ``num_agents``. The
binding keeps the paper's action codec (index 0 is the world's sensing choice, index 1 the
network's next hop), its observation, its team reward after the prediction, and its infos.
Seeding: the world draws from the episode's generator itself (odometry noise, schedule, range
noise); the relay's losses are the network's own counter-based draws from a child generator.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np

import estimators.ukf_relay as ukf
from coloc_env.backends.ukf import UkfDcl
from coloc_env.networks.blocks.relay_chain import STOP_REASONS, RelayChain
from coloc_env.networks.relay import Relay
from coloc_env.rendering import Scene
from coloc_env.scenarios.binding import keyword, register_preset
from coloc_env.scenarios.relay_codec import RelayTeamConfig, RelayTeamScenario, chain_links
from coloc_env.worlds.circles import Circles

DISTANCE_SCALE = 100.0  # metres per unit in the observation


@dataclass(frozen=True)
class RelayUKFConfig(RelayTeamConfig):
    """Configuration of ``relay_ukf``; defaults are the paper's simulation (Sec. 4, Table 1)."""

    preset = "relay_ukf"
    World, Network, Backend = Circles, Relay, UkfDcl
    # no anchors; one next hop per holder; wang2019's position-only state
    fixed = {"world.num_anchors": 0, "network.routing": "per_holder", "backend.motion": "displacement"}
    team_label = "num_agents"
    aliases = {**RelayTeamConfig.aliases, "num_platforms": "num_agents"}

    num_agents: int = keyword(4, "world.num_agents")
    centres: tuple | None = keyword(None, "world.centres")
    start_angles: tuple | None = keyword(None, "world.start_angles")
    directions: tuple | None = keyword(None, "world.directions")
    speed: float = keyword(1.0, "world.speed")
    turn_rate: float = keyword(0.015, "world.turn_rate")
    dt: float = keyword(0.5, "world.dt")
    horizon: int = keyword(800, "world.horizon", "composition.horizon")
    speed_noise_std: float = keyword(0.5, "world.speed_noise_std")
    turn_rate_noise_std: float = keyword(1e-3, "world.turn_rate_noise_std")
    range_noise_var: float = keyword(1.0, "world.range_noise_var")
    measurement_probability: float = keyword(0.5, "world.measurement_probability")
    sensing_range: float = keyword(float("inf"), "world.sensing_range")
    initial_position_std: float = keyword(0.1, "world.initial_position_std")
    heading_noise: bool = keyword(True, "world.heading_noise")
    truncation: str = keyword("consistent", "backend.truncation")

    @property
    def team_size(self) -> int:
        return self.num_agents


@register_preset
class RelayUKFScenario(RelayTeamScenario):
    """``relay_ukf`` as a binding: ``circles`` / ``relay`` / ``ukf_dcl`` with the paper's action codec,
    observation, team reward and infos (module docstring)."""

    name = "relay_ukf"
    paper = "wang2019"
    Config = RelayUKFConfig
    version = 2
    metric = "distance error averaged over the steps and platforms"
    metric_unit = "m"
    communication = "relays"
    policy_module = "agents.relay_ukf"
    agent_prefix = "platform"
    metric_error_key = "posterior_error"
    distance_scale = DISTANCE_SCALE
    agent_state_dim = 2

    def __init__(self, config: RelayUKFConfig, batch: int = 1):
        super().__init__(config, batch)
        B, N = self.batch, self.num_agents
        self.dead_reckoning = np.zeros((B, N, 2))
        self.posterior_error = np.zeros((B, N))

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

    # --- codec ---------------------------------------------------------------------------------------
    @property
    def num_agents(self) -> int:
        return self.config.num_agents

    def action_space(self):
        N = self.num_agents
        return gymnasium.spaces.MultiDiscrete([N, N + 1], dtype=np.int64)

    def action_mask(self) -> np.ndarray:
        """(B, N, 2N + 1) bool, the "Action masks" table: index 0's N choices, then index 1's N + 1 (the
        parts' ``partner`` and ``next_hop`` rules without their ``nearest`` entries, which this codec lacks)."""
        (partner, _), relay = self.relay_masks()
        return np.concatenate([partner[:, :, 0, :self.num_agents], relay], axis=-1)

    def decode_actions(self, actions) -> np.ndarray:
        """Actions (B, N, 2) -> the parts' blocks: whom to range with (the world's sensing choice; never its
        ``nearest`` entry) and whom to relay to (the network's next hop; N = stop, as the network's)."""
        N = self.num_agents
        return self.check_discrete_actions(
            actions, ("action[0] (whom to range with)", f"action[1] (whom to relay to, {N} = stop)"))

    def preset_entries(self) -> np.ndarray:
        """1 where the agent measures at this step (B, N, 1)."""
        return (np.arange(self.num_agents)[None, :] == self.world.measuring()[:, None])[..., None]

    def feature_bounds(self):
        return np.zeros(1), np.ones(1)

    # --- dynamics ------------------------------------------------------------------------------------
    def reset(self, rngs, env_index=None) -> None:
        super().reset(rngs, env_index)
        idx = self._indices(env_index)
        self.dead_reckoning[idx] = self.world.truth[0]
        self.posterior_error[idx] = 0.0  # the estimates start at the truth

    def advance(self, decoded) -> None:
        super().advance(decoded)
        self.posterior_error = self.position_error()
        speed, heading = self.readings.inputs[..., 0], self.readings.inputs[..., 1]
        self.dead_reckoning, _ = ukf.time_update(self.dead_reckoning, None, speed, heading, self.config.dt, 0.0)

    # --- views ---------------------------------------------------------------------------------------
    def true_position(self) -> np.ndarray:
        return self.world.positions().copy()

    def team_error(self) -> np.ndarray:
        """||xhat_i(k+1) - x_i(k+1)|| (B, N), metres: the current estimate after a step's prediction."""
        return np.linalg.norm(self.backend.mean - self.world.positions(), axis=-1)

    def own_traces(self) -> np.ndarray:
        """tr P_ii (B, N) of the current estimate (the joint covariance's diagonal, in pairs)."""
        return self.own_variances().reshape(self.batch, self.num_agents, 2).sum(axis=-1)

    def own_variances(self) -> np.ndarray:
        return np.diagonal(self.backend.cov, axis1=-2, axis2=-1)

    def info(self) -> dict[str, np.ndarray]:
        B, N = self.batch, self.num_agents
        chain = self.chain
        measuring = np.arange(N)[None, :] == np.where(chain.length > 0, chain.chain[:, 0], -1)[:, None]
        partner = np.where(chain.length > 0, np.argmax(self.readings.range_valid.any(axis=1), axis=-1), -1) \
            if self.readings is not None else np.full(B, -1)
        return {**self.team_info(), "posterior_error": self.posterior_error.copy(), "measuring": measuring,
                "partner": np.where(measuring, partner[:, None], -1), "chain_position": chain.position_of(N),
                "relay_target": chain.next_hop(N), "hops": self.team(chain.hops), "chain_stop": self.team(chain.stop)}

    def scene(self, b: int) -> Scene:
        N, k, truth = self.num_agents, int(self.k[b]), self.world.truth
        reach = self.world.extent()
        hops, links = chain_links(self.chain.chain[b])
        reason = STOP_REASONS[self.chain.stop[b]] if self.chain.stop[b] >= 0 else "no measurement"
        return Scene(
            title=f"relay_ukf (wang2019)  t = {k * self.config.dt:.1f} s", truth=truth[k], estimates=self.estimate[b],
            covariances=np.stack([self.cov[b, 2 * i:2 * i + 2, 2 * i:2 * i + 2] for i in range(N)]),
            trails=np.swapaxes(truth[: k + 1], 0, 1), node_positions=truth[k] / reach, node_labels=self.agent_names,
            links=links, link_value_max=1.0, link_value_name="relay hop of the last step",
            extent=(-reach, reach, -reach, reach),
            notes=[f"chain {' -> '.join(map(str, hops)) or '-'} ({reason})",
                   f"mean error {self.team_error()[b].mean():.2f} m"])
