"""``mrclam_relay``: relay decisions on real robot data (UTIAS MRCLAM), replayed step by step.

Data: Leung K.Y.K., Halpern Y., Barfoot T.D., Liu H.H.T., "The UTIAS
multi-robot cooperative localization and mapping dataset", IJRR
30(8):969-974, 2011 (cite it with results on the data). Loader:
``coloc_env.data.mrclam``; estimator: ``estimators.ukf_relay_se2``
(UKF-DCL of wang2019 on planar robots with heading, range and bearing,
Roumeliotis-Bekey factored cross-covariances); relay links:
``coloc_env.networks.blocks.relay_chain`` (the link model of ``relay_ukf``).

The world is the recorded run: five robots in a 15 m x 8 m room, their
odometry, their camera measurements (range, bearing) of each other and of 15
landmarks, and the Vicon ground truth, on the loader's grid of ``dt`` seconds.
An episode replays a window of ``window_steps`` steps starting at a random
offset s, drawn at reset uniformly from [0, T - 1 - window_steps] (T = steps
of the run; the last step needs the Vicon pose at s + window_steps). Nothing
is simulated except the links: the motion, the measurements and the truth are
the data's.

Each env step is one data step k -> k+1 (absolute step a = s + k):

1. each robot m that recorded measurements of other robots at a chooses one of
   them (action index 0); its location information travels along a relay chain
   m -> n -> ... through the link model (loss, hop budget, comm range), each
   holder passing it on by its action for m's chain (below);
2. the estimator applies, in file order within step a (robot by robot, each
   robot's lines in the order of its file): every landmark sighting, to the
   robot that saw it (UKF-DCL on the chain [m] alone: no communication, the
   exact truncated-chain update, always used), and every chosen robot
   measurement whose chain reached the measured robot (UKF-DCL along the
   chain actually delivered; a chain that reaches everyone gives exactly the
   centralized UKF-CCL). Observations whose normalized innovation exceeds
   ``gate`` are rejected (the dataset holds misread barcodes);
3. every robot predicts to a + 1 from its odometry (factored DCL time update;
   the noise model's corrected odometry of the absolute step a, below), and
   the error is taken against the Vicon pose at a + 1.

Several robots may measure in one step, each starting its own chain, so the
relay decision is per source: a routing table (one next hop per measuring
robot), not one next hop per agent as in ``relay_ukf`` (where only one
platform measures per step). With a single next hop per agent, two chains
passing the same holder could not both be complete.

Noise: the ``mrclam`` world's (``coloc_env.data.mrclam_noise.NoiseModel``, the model
and the code of ``coloc reproduce mrclam``), fitted by
``coloc_env.data.mrclam_noise.calibrate_noise`` against Vicon on the start of
the whole run (``coloc_env.worlds.mrclam.replay_tables``: once per data path, ``dt``,
``noise_model`` and ``calibration_s``, and cached; episodes may overlap the
calibration window).

* ``noise_model="calibrated"``, fitted on the first
  ``coloc_env.data.mrclam_noise.calibration_seconds`` (10 % of the run, at
  least 60 s: 75.6 s of dataset 6): the robots move as the command logged
  n = ``odometry_delay_steps`` (2 at dt 0.1) earlier times a scale c; the
  step a -> a + 1 integrates u'[a] = c * u[max(a - n, 0)] with a the absolute
  step: a command logged before the window start s when a - n < s, never one
  before step 0 of the run; per step and robot Q = diag(r_v (a_v + b_v v'^2),
  r_w (a_w + b_w w'^2)) (speed-dependent, inflated for errors correlated over
  steps); each observation's R = diag(r_range (a_r + b_r z_r^2), sigma_b^2)
  from its measured range z_r.
* ``noise_model="baseline"``: the simpler model (first 60 s; constant
  1.4826 x MAD noise, raw commands). It is overconfident: with the paper
  policy its gate refuses 5-30 % of the observations of a 150-step window of
  dataset 6, the calibrated model's none (tests/coloc_env/test_mrclam_relay.py).
* ``noise_model="likelihood"`` (default): the calibrated shapes with the four variances
  scaled to maximize the likelihood of UKF-CCL's pose errors on the calibration
  window (``coloc_env.data.mrclam_noise.fit_noise_scales``). The consistent model: with the
  ``paper`` policy on dataset 6 (``coloc evaluate``, 100 episodes) its mean position NEES is
  1.99 (2 degrees of freedom) and its pose NEES 2.58 (3), the calibrated model's 4.08 and 5.21
  (docs/consistency.md). The fit runs filters for 17-24 s of CPU the first time a run is used
  and is cached on disk (``coloc_env.data.fit_cache``: ``$COLOC_FIT_CACHE``, else
  ``~/.cache/coloc/fits``), so that later processes build the env as fast as with the
  calibrated model.

Initial estimate: the Vicon pose at the window start, with
covariance diag(``initial_position_std``^2, same, ``initial_heading_std``^2)
per robot and no cross-correlation.

Action (per agent, ``MultiDiscrete([N] + [N + 1] * N)``, int64, N = 5, absolute robot indices)
-------------------------------------------------------------------------------------------
| index      | meaning                                                                        |
|------------|--------------------------------------------------------------------------------|
| 0          | which robot it recorded a measurement of at this step to use (one per step);   |
|            | itself, or a robot it has no measurement of this step = none                   |
| 1 + m      | for the chain of robot m's measurement, if it reaches this agent: whom to pass |
|            | it to next; N or itself = stop. A robot already reached, beyond                |
|            | ``comm_range``, a spent hop budget or a lost packet also ends the chain.       |
|            | The measuring robot always sends to the measured one first, so index 1 + i     |
|            | of agent i is not used                                                         |

``infos[agent]["action_mask"]`` (``MrclamRelayScenario.action_mask``): index 0 allows the robots
it recorded and itself; index 1 + m masks itself, the source m and robots beyond ``comm_range`` (each
does what N = stop does); nothing is masked on what a robot cannot observe.

If a robot recorded the same robot twice in one step, the first line in file
order is the one used (dataset 6 has no such case). Non-integer or
out-of-range actions and NaN/inf are a ``ValueError``.

Observation (per agent, ``Box(shape=(3N + 7,), float32)``)
--------------------------------------------------------
| index             | meaning                                                                 | bounds    |
|-------------------|-------------------------------------------------------------------------|-----------|
| ``[0, N)``        | one-hot of the agent's own index (shared policy, absolute actions)       | [0, 1]    |
| ``[N, 2N)``       | 1 where the agent recorded a measurement of robot j at this step (the    | [0, 1]    |
|                   | choices of action index 0), else 0                                      |           |
| ``[2N]``          | landmark sightings it recorded at this step                             | [0, inf)  |
| ``[2N+1, 3N+1)``  | distance to each robot / 10 m (Vicon; 0 for itself): link-layer          | [0, inf)  |
|                   | knowledge, as in ``relay_ukf``                                           |           |
| ``[3N+1]``        | log tr of its own position covariance (m^2)                             | unbounded |
| ``[3N+2]``        | step fraction k / window_steps                                          | [0, 1]    |
| ``[3N+3]``        | ``displacement``: how far its position estimate moved since its last    | [0, inf)  |
|                   | relayed hop (``transmissions`` > 0; the window start before any), / 100 m |         |
| ``[3N+4]``        | ``steps_since``: steps since that hop / window_steps                    | [0, 1]    |
| ``[3N+5]``        | ``message_value``: max(0, tr(P_ref + (k - k_ref) Q_pos) - tr P_ii), m^2 | [0, inf)  |
|                   | (``Backend.message_value``)                                             |           |
| ``[3N+6]``        | ``communication_cost``: its copy's cost per delivered hop this episode  | [0, inf)  |
|                   | (``communication_cost``, or the draw from ``cost_range``), m            |           |

The named entries are the composed observation's features (``feature_index``: ``index`` [0, N),
``log_trace`` [3N+1], ``step_fraction`` [3N+2] and these). The event-triggered families
(``agents.event_triggered``) decide every relay entry (1..N) of an agent at once: send = ``paper``'s routing,
quiet = N (stop), so their extremes are ``always`` (= ``paper``) and ``silent`` (= ``no_relay``); the
measurement choice (entry 0) is ``paper``'s. ``uncertainty`` reads the holder's own log tr P_ii (the simpler
reading of "the holder's uncertainty about the next platform").

The sighting count and the distances have no upper bound in the model (a data set may hold any
number of sightings per step, robots anywhere); the log-trace is unbounded because a robot that sees
nothing dead-reckons with a growing covariance.

After the last step the measurement entries are 0. ``state()`` (centralized
critic): every agent's observation, then the log of the diagonal of each
robot's own covariance block (x, y, theta; 3N values).

Reward (team: one agent's decisions move every robot's estimate)
----------------------------------------------------------------
| ``reward=`` | value for every agent after step k -> k+1 (m: ``error`` is a distance)                |
|-------------|--------------------------------------------------------------------------------------|
| ``"error"`` | -mean_i ||p_hat_i(k+1) - p_i(k+1)|| against Vicon - C                                 |
| ``"trace"`` | -mean_i sqrt(tr P_ii^pos(k+1)) (m: the filter's own RMS position error, the unit of   |
|             | ``error``; the ``trace`` info key is tr P_ii^pos itself, m^2) - C                    |

C, the team's communication cost of the step, in the reward's unit (m): the copy's cost per hop (``communication_cost``,
or under ``cost_range`` its draw of the episode) per
delivered hop (one hop is one message of the relay network) plus ``hop_cost_per_m2`` d^2 per hop of
length d (the network's ``cost_sent``), summed over every chain of the step.

Termination: none; truncation after ``window_steps`` steps. The episode metric
(``episode_error``) is the mean distance error over the steps and robots.

``infos[agent]``: ``true_position`` (Vicon), ``estimated_position``, ``error``
(distance, m), ``heading_error`` (|wrapped|, rad), ``trace`` (tr of the
position block, m^2), ``dead_reckoning_error`` (the same robot by the noise
model's odometry alone from the window start, m), ``measured`` (robots it recorded this step),
``partner`` (the robot whose measurement it chose, -1), ``used`` (that
measurement reached the measured robot and passed the gate), ``landmarks``
(landmark sightings applied to it), ``rejected`` (its observations refused by
the gate), ``chain_length`` (robots its chain reached, 0 without a chain),
``chain_stop`` (index into ``coloc_env.networks.blocks.relay_chain.STOP_REASONS``, -1
without a chain), ``communication`` (hops it delivered this step over all
chains; summed over agents = hops), ``hops`` and ``hop_cost`` (the team's, this
step: hops delivered and C), the network's per-link counts ``transmissions``, ``link_attempts``,
``link_deliveries``, ``collisions`` (the table of ``coloc_env.networks.base``), ``step``.

Arguments (fields of ``MrclamRelayConfig``)
------------------------------------------------
| field                | default        | allowed                                                      |
|----------------------|----------------|--------------------------------------------------------------|
| data                 | None           | a dataset folder (``MRCLAM_DatasetK``); None = the           |
|                      |                | environment variable ``COLOC_MRCLAM_DATA`` (error if unset)  |
| dt                   | 0.1            | [0.01, 1] s, the step grid of the loader (finer: too many    |
|                      |                | steps to hold)                                               |
| window_steps         | 600            | 1..T-1 steps (600 = 60 s at dt 0.1)                          |
| noise_model          | "likelihood"   | "likelihood", "calibrated", "baseline" (see Noise)           |
| calibration_s        | None           | (0, 3600] s of the run's start used to fit the noise; None = |
|                      |                | the model's rule (likelihood and calibrated: max(60 s, 10 %  |
|                      |                | of the run); baseline: 60 s)                                 |
| initial_position_std | 0.01           | [1e-6, 1e3] m (smaller: P(0) not numerically definite)       |
| initial_heading_std  | 0.01           | [1e-6, 10] rad                                               |
| gate                 | 13.8155        | (0, 1e12] (chi-square(2) 99.9 %, as ``coloc reproduce mrclam``); |
|                      |                | None = apply every observation                               |
| comm_range           | inf            | (0, inf] m                                                   |
| max_hops             | None           | 1..N-1 hops per chain, None = no limit                       |
| loss_at_zero         | 0.0            | [0, 1]                                                       |
| loss_length          | inf            | (0, inf] m (p_loss(d) = 1 - (1 - loss_at_zero) e^(-d/loss_length)) |
| communication_cost   | 0.0            | [0, 1e12] m per delivered hop (old name ``hop_cost``, still  |
|                      |                | accepted)                                                    |
| cost_range           | None           | None, or (lo, hi) with 0 <= lo <= hi <= 1e12:                |
|                      |                | each copy draws its cost per episode at reset                |
|                      |                | (``coloc_env.composition``'s law), replacing                 |
|                      |                | ``communication_cost``                                       |
| hop_cost_per_m2      | 0.0            | [0, 1e12] m per hop and squared metre of its length          |
| ukf_lambda           | 0.0            | (-3N, 1e6]                                                   |
| reward               | "error"        | "error", "trace"                                             |

The preset is the composition ``mrclam`` / ``relay`` (``routing="per_source"``) /
``ukf_se2`` (``MrclamRelayConfig.parts``) with this action codec (the
action vector passed verbatim), observation, team reward and info; the observation,
state, team reward and shared infos are the relay-chain presets' codec
(``coloc_env.scenarios.relay_codec``, shared with ``relay_ukf``). Each keyword
sets the part field of the same name, except ``window_steps`` (the world's and
the composition's ``horizon``) and ``communication_cost`` (the composition's: a
delivered hop is one message of the relay network, which prices only its length); each
is checked by its part, ``max_hops`` also against the N - 1 hops a chain can
have, and, when an env is built (validation reads no data), ``data`` and
``window_steps`` against the run.

Randomness: per episode, the offset s from the episode's generator (its
first draw: the world draws from that generator itself); the loss of every step, source
and hop is the relay network's counter-based draw from its own key (a child
of the episode's generator), so the same seed gives the same window and the
same losses whatever the policy and the loss probability.

Batching: the state is held in arrays indexed by copy, and nothing loops over
the copies: per observation slot the relay chains of every copy are resolved in
one vectorized network call and the estimator updates the copies with one
stacked UKF-DCL update per kind of observation and chain length
(``estimators.ukf_relay_se2.dcl_update_rows``); the time update, the
world's readings and the dead reckoning are one call for all copies.
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np

import estimators.ukf_relay_se2 as se2
from coloc_env.backends.ukf_se2 import UkfSe2
from coloc_env.config import BadInput
from coloc_env.data import mrclam, mrclam_noise
from coloc_env.networks.blocks.relay_chain import STOP_REASONS
from coloc_env.networks.relay import Relay
from coloc_env.rendering import Scene
from coloc_env.scenarios.binding import keyword, register_preset
from coloc_env.scenarios.relay_codec import RelayTeamConfig, RelayTeamScenario, chain_links
from coloc_env.worlds.mrclam import Mrclam

NUM_ROBOTS = mrclam.NUM_ROBOTS
DISTANCE_SCALE = 10.0  # metres per unit in the observation


@dataclass(frozen=True)
class MrclamRelayConfig(RelayTeamConfig):
    """Configuration of ``mrclam_relay`` (see the module docstring for the table)."""

    preset = "mrclam_relay"
    World, Network, Backend = Mrclam, Relay, UkfSe2
    fixed = {"network.routing": "per_source"}  # one next hop per measuring robot
    team_label = "N"  # the robots of the run, not a keyword

    data: str | None = keyword(None, "world.data")
    dt: float = keyword(0.1, "world.dt")
    window_steps: int = keyword(600, "world.horizon", "composition.horizon")
    noise_model: str = keyword("likelihood", "world.noise_model")
    calibration_s: float | None = keyword(None, "world.calibration_s")
    initial_position_std: float = keyword(0.01, "world.initial_position_std")
    initial_heading_std: float = keyword(0.01, "world.initial_heading_std")
    gate: float | None = keyword(mrclam_noise.GATE_999, "backend.gate")

    @property
    def team_size(self) -> int:
        return NUM_ROBOTS

    @property
    def horizon(self) -> int:
        """Steps per episode: ``window_steps``."""
        return self.window_steps


@register_preset
class MrclamRelayScenario(RelayTeamScenario):
    """Batched core of ``mrclam_relay``: the binding of ``MrclamRelayConfig`` on the composable core
    (``mrclam`` / ``relay`` with ``routing="per_source"`` / ``ukf_se2``); the module docstring has the tables.
    The run and its window offsets are the world's (``world.data``, ``world.tables``, ``world.start``), the
    estimates, covariance factors, chains and applied observations the backend's (``backend.estimate``,
    ``backend.P_ii``, ``backend.joint_cov(b)``, ``backend.chains``, ``backend.used``, ...)."""

    name = "mrclam_relay"
    paper = "mrclam"
    Config = MrclamRelayConfig
    version = 2  # 2: noise_model="likelihood" by default (1: "calibrated")
    metric = "distance error against Vicon averaged over the steps and robots"
    metric_unit = "m"
    communication = "messages delivered"
    episode_length_field = "window_steps"
    policy_module = "agents.mrclam_relay"
    agent_prefix = "robot"

    def __init__(self, config: MrclamRelayConfig, batch: int = 1):
        try:  # the world's checks on the loaded run, under the preset's keywords
            config.parts()[0].check_run("", horizon="window_steps")
        except ValueError as exc:
            raise BadInput(f"{self.name}: {exc}") from exc
        super().__init__(config, batch)
        N, B = self.num_agents, self.batch
        self.dead_reckoning = np.zeros((B, N, 3))
        self.measured = np.zeros((B, N))

    distance_scale = DISTANCE_SCALE
    agent_state_dim = 3

    @property
    def estimate(self) -> np.ndarray:
        """Each robot's pose estimate (B, N, 3): after a step, the prediction to k + 1."""
        return self.backend.estimate

    # --- codec ---------------------------------------------------------------------------------------
    @property
    def num_agents(self) -> int:
        return NUM_ROBOTS

    @property
    def horizon(self) -> int:
        return self.config.window_steps

    def action_space(self):
        N = self.num_agents
        return gymnasium.spaces.MultiDiscrete([N] + [N + 1] * N, dtype=np.int64)

    def action_mask(self) -> np.ndarray:
        """(B, N, N + N (N + 1)) bool: the choices valid now. Index 0: the robots it recorded at this step (its
        observation's entries [N, 2N)) and itself ("none"); any other robot gives no measurement, as itself
        does. Index 1 + m: the ``relay`` network's per-source ``next_hop`` rule without its "nearest" entry
        (itself, the source m and a robot beyond ``comm_range`` end the chain, as N = stop does)."""
        _, relay = self.relay_masks()
        return np.concatenate([self._recorded() | np.eye(self.num_agents, dtype=bool), relay], axis=-1)

    def decode_actions(self, actions) -> np.ndarray:
        """Actions (B, N, 1 + N) -> the parts' blocks, verbatim: the world's ``partner`` (never its "every
        robot" entry N) and the network's per-source ``next_hop`` table (N = stop; itself = stop, as there)."""
        N = self.num_agents
        relay = f"action[1:] (whom to relay each source's chain to, {N} = stop)"
        return self.check_discrete_actions(actions, ("action[0] (whose measurement to use)", *[relay] * N))

    def preset_entries(self) -> np.ndarray:
        """The robots each one recorded at this step (N) and its landmark sightings (1): (B, N, N + 1)."""
        landmarks = self.world.tables.landmark_count[self.world.absolute_step()]
        return np.concatenate([self._recorded(), np.where((self.k < self.horizon)[:, None], landmarks, 0.0)[..., None]],
                              axis=-1)

    def feature_bounds(self):
        N = self.num_agents
        return np.zeros(N + 1), np.concatenate([np.ones(N), [np.inf]])

    # --- dynamics ------------------------------------------------------------------
    def reset(self, rngs, env_index=None) -> None:
        super().reset(rngs, env_index)
        idx = self._indices(env_index)
        self.dead_reckoning[idx] = self.world.data.groundtruth[self.world.start[idx]]
        self.measured[idx] = 0.0

    def advance(self, decoded) -> None:
        self.measured = self._recorded().sum(axis=-1).astype(float)
        super().advance(decoded)
        u = self.readings.inputs[..., :2]  # u'[a], the noise model's odometry the backend predicted with
        self.dead_reckoning[:] = se2.motion(self.dead_reckoning, u, self.world.dt)[0]

    # --- views -------------------------------------------------------------------------
    def _recorded(self) -> np.ndarray:
        """(B, N, N) robot i recorded robot j at the current data step (False after the last step)."""
        a = np.minimum(self.world.absolute_step(), self.world.data.steps - 1)
        return (self.world.tables.first_index[a] >= 0) & (self.k < self.horizon)[:, None, None]

    def true_position(self) -> np.ndarray:
        """Vicon positions (B, N, 2) at the current step (the poses, with headings: ``world.poses()``)."""
        return self.world.positions()

    def reported_pose(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The current pose estimates (B, N, 3), the Vicon poses at their time and the estimates' covariances
        (B, N, 3, 3) (after a step: the prediction to k + 1, as the infos' positions)."""
        return self.backend.estimate.copy(), self.world.poses().copy(), self.backend.P_ii.copy()

    def team_error(self) -> np.ndarray:
        """||p_hat_i - p_i|| (B, N), metres, against Vicon, of the current estimate (after a step: k + 1)."""
        return np.linalg.norm(self.backend.estimate[..., :2] - self.world.poses()[..., :2], axis=-1)

    def position_error(self) -> np.ndarray:
        return self.team_error()

    def own_traces(self) -> np.ndarray:
        """tr of each robot's position covariance (B, N), m^2."""
        return self.backend.P_ii[..., 0, 0] + self.backend.P_ii[..., 1, 1]

    def own_variances(self) -> np.ndarray:
        return np.diagonal(self.backend.P_ii, axis1=-2, axis2=-1).reshape(self.batch, -1)

    def info(self) -> dict[str, np.ndarray]:
        B, N = self.batch, self.num_agents
        backend, chains, truth = self.backend, self.backend.chains, self.world.poses()
        return {**self.team_info(), "heading_error": np.abs(se2.wrap(backend.estimate[..., 2] - truth[..., 2])),
                "measured": self.measured.copy(), "partner": backend.partner.copy(), "used": backend.used.copy(),
                "landmarks": backend.landmarks_applied.copy(), "rejected": backend.rejected.copy(),
                "chain_length": chains.length.reshape(B, N).copy(), "chain_stop": chains.stop.reshape(B, N).copy(),
                "hops": self.team(self.network.messages_sent.sum(axis=-1))}

    def scene(self, b: int) -> Scene:
        N, k, start, data = self.num_agents, int(self.k[b]), int(self.world.start[b]), self.world.data
        truth = data.groundtruth[start + k, :, :2]
        x0, x1, y0, y1 = self.world.tables.extent
        chains = self.backend.chains
        links, notes = [], []
        for m in range(N):
            hops, hop_links = chain_links(chains.chain[b * N + m], prefix=f"{m}:")
            links += hop_links
            if hops:
                notes.append(f"chain {' -> '.join(map(str, hops))} ({STOP_REASONS[chains.stop[b * N + m]]})")
        notes.append(f"mean error {self.team_error()[b].mean():.3f} m, "
                     f"{int(self.backend.landmarks_applied[b].sum())} landmark sightings")
        centre = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1)])
        # the map holds the run's tracks and every landmark, with a margin for the ellipses
        landmarks = np.asarray(data.landmarks, float)
        low = np.minimum([x0, y0], landmarks.min(axis=0)) - 0.3
        high = np.maximum([x1, y1], landmarks.max(axis=0)) + 0.3
        return Scene(
            title=f"mrclam_relay (MRCLAM dataset)  t = {(start + k) * data.dt:.1f} s, window step {k}/{self.horizon}",
            truth=truth, estimates=self.backend.estimate[b, :, :2], covariances=self.backend.P_ii[b, :, :2, :2],
            trails=np.swapaxes(data.groundtruth[start:start + k + 1, :, :2], 0, 1),
            node_positions=(truth - centre) / max(x1 - x0, y1 - y0), node_labels=self.agent_names, links=links,
            link_value_max=1.0, link_value_name="relay hop of the last step (source:hop)",
            extent=(float(low[0]), float(high[0]), float(low[1]), float(high[1])), landmarks=landmarks,
            notes=notes[-4:])
