"""``mrclam_relay``: relay decisions on real robot data (UTIAS MRCLAM), replayed step by step.

Data: Leung K.Y.K., Halpern Y., Barfoot T.D., Liu H.H.T., "The UTIAS
multi-robot cooperative localization and mapping dataset", IJRR
30(8):969-974, 2011 (cite it with results on the data). Loader:
``coloc_env.data.mrclam``; estimator: ``estimators.ukf_relay_se2``
(UKF-DCL of wang2019 on planar robots with heading, range and bearing,
Roumeliotis-Bekey factored cross-covariances); relay links:
``coloc_env.primitives.relay`` (the link model of ``relay_ukf``).

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
   m -> n -> ... through the link model (loss, hop budget, comm range, hop
   cost), each holder passing it on by its action for m's chain (below);
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

Noise: ``coloc_env.data.mrclam.NoiseModel``, the model (and the code
applying it) of ``coloc reproduce mrclam``, fitted by
``coloc_env.data.mrclam.calibrate_noise`` against Vicon on the start of
the whole run (computed once per data path, ``dt``, ``noise_model`` and
``calibration_s``, and cached; episodes may overlap the calibration window).

* ``noise_model="calibrated"`` (default), fitted on the first
  ``coloc_env.data.mrclam.calibration_seconds`` (10 % of the run, at
  least 60 s: 75.6 s of dataset 6): the robots move as the command logged
  n = ``odometry_delay_steps`` (2 at dt 0.1) earlier times a scale c; the
  step a -> a + 1 integrates u'[a] = c * u[max(a - n, 0)] with a the absolute
  step: a command logged before the window start s when a - n < s, never one
  before step 0 of the run; per step and robot Q = diag(r_v (a_v + b_v v'^2),
  r_w (a_w + b_w w'^2)) (speed-dependent, inflated for errors correlated over
  steps); each observation's R = diag(r_range (a_r + b_r z_r^2), sigma_b^2)
  from its measured range z_r.
* ``noise_model="baseline"``: the model before it (first 60 s; constant
  1.4826 x MAD noise, raw commands). It is overconfident: with the paper
  policy its gate refuses 5-30 % of the observations of a 150-step window of
  dataset 6, the calibrated model's none (tests/coloc_env/test_mrclam_relay.py).

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

Observation (per agent, ``Box(shape=(3N + 3,), float32)``)
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

The sighting count and the distances have no upper bound in the model (a data set may hold any
number of sightings per step, robots anywhere); the log-trace is unbounded because a robot that sees
nothing dead-reckons with a growing covariance. (Before, every entry was unbounded.)

After the last step the measurement entries are 0. ``state()`` (centralized
critic): every agent's observation, then the log of the diagonal of each
robot's own covariance block (x, y, theta; 3N values).

Reward (team: one agent's decisions move every robot's estimate)
----------------------------------------------------------------
| ``reward=`` | value for every agent after step k -> k+1 (metres; a distance, as in ``relay_ukf``)  |
|-------------|--------------------------------------------------------------------------------------|
| ``"error"`` | -mean_i ||p_hat_i(k+1) - p_i(k+1)|| against Vicon - the hop cost of this step's hops   |
| ``"trace"`` | -mean_i sqrt(tr P_ii^pos(k+1)) (the filter's own RMS error) - the same hop cost        |

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
``chain_stop`` (index into ``coloc_env.primitives.relay.STOP_REASONS``, -1
without a chain), ``communication`` (hops it delivered this step over all
chains; summed over agents = hops), ``hops`` and ``hop_cost`` (the team's,
this step), ``step``.

Arguments (fields of ``MrclamRelayConfig``)
------------------------------------------------
| field                | default        | allowed                                                      |
|----------------------|----------------|--------------------------------------------------------------|
| data                 | None           | a dataset folder (``MRCLAM_DatasetK``); None = the           |
|                      |                | environment variable ``COLOC_MRCLAM_DATA`` (error if unset)  |
| dt                   | 0.1            | [0.01, 1] s, the step grid of the loader (finer: too many    |
|                      |                | steps to hold)                                               |
| window_steps         | 600            | 1..T-1 steps (600 = 60 s at dt 0.1)                          |
| noise_model          | "calibrated"   | "calibrated", "baseline" (see Noise)                         |
| calibration_s        | None           | (0, 3600] s of the run's start used to fit the noise; None = |
|                      |                | the model's rule (calibrated: max(60 s, 10 % of the run);    |
|                      |                | baseline: 60 s)                                              |
| initial_position_std | 0.01           | [1e-6, 1e3] m (smaller: P(0) not numerically definite)       |
| initial_heading_std  | 0.01           | [1e-6, 10] rad                                               |
| gate                 | 13.8155        | (0, 1e12] (chi-square(2) 99.9 %, as ``coloc reproduce mrclam``); |
|                      |                | None = apply every observation                               |
| comm_range           | inf            | (0, inf] m                                                   |
| max_hops             | None           | 1..N-1 hops per chain, None = no limit                       |
| loss_at_zero         | 0.0            | [0, 1]                                                       |
| loss_length          | inf            | (0, inf] m (p_loss(d) = 1 - (1 - loss_at_zero) e^(-d/loss_length)) |
| hop_cost             | 0.0            | [0, 1e12] per delivered hop                                  |
| hop_cost_per_m2      | 0.0            | [0, 1e12] per hop and squared metre                          |
| ukf_lambda           | 0.0            | (-3N, 1e6]                                                   |
| reward               | "error"        | "error", "trace"                                             |

The preset is the composition ``mrclam`` / ``relay`` (``routing="per_source"``) /
``ukf_se2`` (``MrclamRelayConfig.parts``) with this action codec (the
action vector passed verbatim), observation, team reward and info.

Randomness: per episode, the offset s from the episode's generator (its
first draw, as before the composable core); the loss of every step, source
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

import functools
import os
from dataclasses import dataclass

import gymnasium
import numpy as np

import estimators.ukf_relay_se2 as se2
from coloc_env.backends.ukf_se2 import UkfSe2
from coloc_env.config import check_choice, check_range
from coloc_env.data import mrclam
from coloc_env.networks.relay import Relay
from coloc_env.primitives.relay import STOP_REASONS, RelayChain, RelayChainLinks
from coloc_env.rendering import Link, Scene
from coloc_env.scenarios.binding import PresetScenario
from coloc_env.worlds.mrclam import Mrclam

NUM_ROBOTS = mrclam.NUM_ROBOTS
DISTANCE_SCALE = 10.0  # metres per unit in the observation
GATE = mrclam.GATE_999  # chi-square(2) 0.999 quantile, the gate of ``coloc reproduce mrclam``


@dataclass(frozen=True)
class ReplayTables:
    """One dataset with what every episode needs, computed once per (path, dt, noise_model, calibration_s).

    ``noise`` the ``coloc_env.data.mrclam.calibrate_noise`` dict, ``noise_model`` the
    ``coloc_env.data.mrclam.NoiseModel`` built from it, ``measurement_cov`` (M, 2, 2) its R
    of every measurement line (from the measured range); ``first_index`` (T, N, N): index into
    the measurement arrays of the first line (file order) in which robot i recorded robot j at
    step t, -1 if none; ``landmark_count`` (T, N).
    """

    data: mrclam.MrclamData
    noise: dict
    noise_model: mrclam.NoiseModel
    measurement_cov: np.ndarray
    first_index: np.ndarray
    landmark_count: np.ndarray
    extent: tuple[float, float, float, float]


@functools.lru_cache(maxsize=4)
def _tables(path: str, dt: float, noise_model: str, calibration_s: float | None) -> ReplayTables:
    d = mrclam.load_cached(path, dt)
    model = mrclam.NoiseModel.calibrate(d, noise_model, calibration_s)
    measurement_cov = model.measurement_cov(d.meas_range)
    N, T = NUM_ROBOTS, d.steps
    robot = np.flatnonzero(d.meas_subject <= N)
    keys = (d.meas_step[robot] * N + d.meas_robot[robot]) * N + (d.meas_subject[robot] - 1)
    unique, first = np.unique(keys, return_index=True)  # first occurrence = first in file order
    first_index = np.full(T * N * N, -1)
    first_index[unique] = robot[first]
    landmark = d.meas_subject > N
    landmark_count = np.zeros((T, N))
    np.add.at(landmark_count, (d.meas_step[landmark], d.meas_robot[landmark]), 1.0)
    points = np.concatenate([d.groundtruth[..., :2].reshape(-1, 2), d.landmarks])
    lo, hi = points.min(axis=0) - 0.5, points.max(axis=0) + 0.5
    for array in (measurement_cov, first_index, landmark_count):
        array.flags.writeable = False
    return ReplayTables(d, dict(model.calibration), model, measurement_cov, first_index.reshape(T, N, N),
                        landmark_count,
                        (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])))


@dataclass(frozen=True)
class MrclamRelayConfig:
    """Configuration of ``mrclam_relay`` (see the module docstring for the table)."""

    data: str | None = None
    dt: float = 0.1
    window_steps: int = 600
    noise_model: str = "calibrated"
    calibration_s: float | None = None
    initial_position_std: float = 0.01
    initial_heading_std: float = 0.01
    gate: float | None = GATE
    comm_range: float = float("inf")
    max_hops: int | None = None
    loss_at_zero: float = 0.0
    loss_length: float = float("inf")
    hop_cost: float = 0.0
    hop_cost_per_m2: float = 0.0
    ukf_lambda: float = 0.0
    reward: str = "error"

    @property
    def horizon(self) -> int:
        """Steps per episode: ``window_steps``."""
        return self.window_steps

    def parts(self) -> tuple:
        """The (world, network, backend) configs this flat config stands for: ``mrclam`` with the same run,
        grid and noise model (the window offset drawn per episode), ``relay`` with the same links and one next
        hop per measuring robot (``routing="per_source"``), ``ukf_se2``. Reads no data."""
        world = Mrclam(data=self.data, dt=self.dt, horizon=self.window_steps, noise_model=self.noise_model,
                       calibration_s=self.calibration_s, initial_position_std=self.initial_position_std,
                       initial_heading_std=self.initial_heading_std)
        network = Relay(comm_range=self.comm_range, max_hops=self.max_hops, loss_at_zero=self.loss_at_zero,
                        loss_length=self.loss_length, routing="per_source", hop_cost=self.hop_cost,
                        hop_cost_per_m2=self.hop_cost_per_m2)
        return world, network, UkfSe2(ukf_lambda=self.ukf_lambda, gate=self.gate)

    @property
    def links(self) -> RelayChainLinks:
        return RelayChainLinks(self.comm_range, self.max_hops, self.loss_at_zero, self.loss_length,
                               self.hop_cost, self.hop_cost_per_m2)

    @property
    def path(self) -> str:
        """The dataset folder: ``data``, else ``$COLOC_MRCLAM_DATA`` (ValueError naming ``data``)."""
        if self.data is not None and not isinstance(self.data, (str, os.PathLike)):
            raise ValueError(f"data must be a path to an MRCLAM dataset folder or None, got {self.data!r}")
        return os.path.realpath(mrclam.resolve_data_path(self.data))

    def tables(self) -> ReplayTables:
        path = self.path
        try:
            calibration_s = None if self.calibration_s is None else float(self.calibration_s)
            return _tables(path, float(self.dt), self.noise_model, calibration_s)
        except ValueError as exc:
            raise ValueError(f"data: {exc}") from exc

    def validate(self) -> None:
        N = NUM_ROBOTS
        check_range("dt", self.dt, 0.01, 1.0)
        check_range("window_steps", self.window_steps, 1, 10**9, integer=True)
        check_choice("noise_model", self.noise_model, mrclam.NOISE_MODELS)
        if self.calibration_s is not None:
            check_range("calibration_s", self.calibration_s, 0.0, 3600.0, low_open=True)
        check_range("initial_position_std", self.initial_position_std, 1e-6, 1e3)
        check_range("initial_heading_std", self.initial_heading_std, 1e-6, 10.0)
        if self.gate is not None:
            check_range("gate", self.gate, 0.0, 1e12, low_open=True)
        self.links.validate(N)
        check_range("ukf_lambda", self.ukf_lambda, -3.0 * N, 1e6, low_open=True, low_label="-3N")
        check_choice("reward", self.reward, ("error", "trace"))
        steps = self.tables().data.steps
        if self.window_steps > steps - 1:
            raise ValueError(f"window_steps must be in [1, {steps - 1}] for this run of {steps} steps "
                             f"(the last step needs the next Vicon pose), got {self.window_steps}")


@dataclass
class StepEvent:
    """What happened at the last step of each copy (B copies, N robots; chains are indexed by source)."""

    partner: np.ndarray  # (B, N) robot whose measurement each robot chose, -1 none
    relay: RelayChain  # rows B * N: the chain of source m in copy b at row b * N + m
    used: np.ndarray  # (B, N) bool: the chosen measurement was applied
    landmarks: np.ndarray  # (B, N) landmark sightings applied
    rejected: np.ndarray  # (B, N) observations refused by the gate
    measured: np.ndarray  # (B, N) robots recorded
    cost: np.ndarray  # (B,) hop cost


class MrclamRelayScenario(PresetScenario):
    """Batched core of ``mrclam_relay``: the binding of ``MrclamRelayConfig`` on the composable core
    (``mrclam`` / ``relay`` with ``routing="per_source"`` / ``ukf_se2``); the module docstring has the tables."""

    name = "mrclam_relay"
    paper = "mrclam"
    Config = MrclamRelayConfig
    agent_prefix = "robot"

    @classmethod
    def composition_options(cls, config) -> dict:
        return {"reward": config.reward}

    def __init__(self, config: MrclamRelayConfig, batch: int = 1):
        super().__init__(config, batch)
        N, B = self.num_agents, self.batch
        self.dead_reckoning = np.zeros((B, N, 3))
        self.measured = np.zeros((B, N))

    # --- the parts' state, by the scenario's names ----------------------------------------
    @property
    def tables(self) -> ReplayTables:
        return self.world.tables

    @property
    def data(self) -> mrclam.MrclamData:
        return self.world.data

    @property
    def noise_model(self) -> mrclam.NoiseModel:
        return self.world.noise_model

    @property
    def noise(self) -> dict:
        return dict(self.tables.noise)

    @property
    def start(self) -> np.ndarray:
        """The window offset s of each copy (B,)."""
        return self.world.start

    @property
    def estimate(self) -> np.ndarray:
        """Each robot's pose estimate (B, N, 3): after a step, the prediction to k + 1."""
        return self.backend.estimate

    @property
    def P_ii(self) -> np.ndarray:
        return self.backend.P_ii

    @property
    def phi(self) -> np.ndarray:
        return self.backend.phi

    @property
    def sigma(self) -> np.ndarray:
        return self.backend.sigma

    @property
    def event(self) -> StepEvent:
        """The last step's partners, chains (by source), applied and refused observations and hop cost."""
        backend = self.backend
        return StepEvent(partner=backend.partner.copy(), relay=backend.chains, used=backend.used.copy(),
                         landmarks=backend.landmarks_applied.copy(), rejected=backend.rejected.copy(),
                         measured=self.measured.copy(), cost=self.network.cost_sent.sum(axis=-1))

    def joint_cov(self, b: int) -> np.ndarray:
        """The joint covariance (3N, 3N) of copy b that the factors stand for."""
        return self.backend.joint_cov(b)

    # --- description ------------------------------------------------------------
    @property
    def num_agents(self) -> int:
        return NUM_ROBOTS

    @property
    def horizon(self) -> int:
        return self.config.window_steps

    @property
    def obs_dim(self) -> int:
        return 3 * self.num_agents + 3

    def observation_space(self):
        N = self.num_agents
        low = np.concatenate([np.zeros(2 * N + 1 + N), [-np.inf], [0.0]])
        high = np.concatenate([np.ones(2 * N), np.full(1 + N, np.inf), [np.inf], [1.0]])
        return gymnasium.spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)

    def action_space(self):
        N = self.num_agents
        return gymnasium.spaces.MultiDiscrete([N] + [N + 1] * N, dtype=np.int64)

    def action_mask(self) -> np.ndarray:
        """(B, N, N + N (N + 1)) bool: the choices valid now. Index 0: the robots it recorded at this step (its
        observation's entries [N, 2N)) and itself ("none"); any other robot gives no measurement, as itself
        does. Index 1 + m: the core's per-source ``next_hop`` rule without its "nearest" entry (itself, the
        source m and a robot beyond ``comm_range`` end the chain, as N = stop does; stop stays valid)."""
        B, N = self.batch, self.num_agents
        a = np.minimum(self.absolute_step(), self.data.steps - 1)
        live = (self.k < self.horizon)[:, None, None]
        partner = ((self.tables.first_index[a] >= 0) & live) | np.eye(N, dtype=bool)
        _, next_hop = self.block_choice_masks()  # (B, N holders, N sources, N + 2)
        return np.concatenate([partner, next_hop[..., :N + 1].reshape(B, N, -1)], axis=-1)

    def state_space(self):
        dim = self.num_agents * self.obs_dim + 3 * self.num_agents
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(dim,), dtype=np.float32)

    # --- dynamics ------------------------------------------------------------------
    def reset(self, rngs, env_index=None) -> None:
        super().reset(rngs, env_index)
        idx = self._indices(env_index)
        self.dead_reckoning[idx] = self.data.groundtruth[self.start[idx]]
        self.measured[idx] = 0.0

    def decode_actions(self, actions) -> np.ndarray:
        """Actions (B, N, 1 + N) -> the parts' blocks, verbatim: the world's ``partner`` (never its "every
        robot" entry N) and the network's per-source ``next_hop`` table (N = stop; itself = stop, as there)."""
        N = self.num_agents
        relay = f"action[1:] (whom to relay each source's chain to, {N} = stop)"
        return self.check_discrete_actions(actions, ("action[0] (whose measurement to use)", *[relay] * N))

    def absolute_step(self) -> np.ndarray:
        """The data step a = s + k of each copy (B,)."""
        return self.world.absolute_step()

    def advance(self, decoded) -> None:
        self.measured = (self.tables.first_index[self.absolute_step()] >= 0).sum(axis=-1).astype(float)
        super().advance(decoded)
        u = self.readings.inputs[..., :2]  # u'[a], the noise model's odometry the backend predicted with
        self.dead_reckoning[:] = se2.motion(self.dead_reckoning, u, self.data.dt)[0]

    def compute_reward(self) -> np.ndarray:
        """The team's: minus the mean over robots of the error (or RMS) after the time update to k + 1, minus the
        hop cost of the step's chains."""
        if self.config.reward == "error":
            loss = self.position_error().mean(axis=-1)
        else:
            loss = np.sqrt(self.own_traces()).mean(axis=-1)
        cost = self.network.cost_sent.sum(axis=-1)
        return np.repeat((-loss - cost)[:, None], self.num_agents, axis=1)

    # --- views -------------------------------------------------------------------------
    def truth(self) -> np.ndarray:
        """Vicon poses (B, N, 3) at the current step."""
        return self.world.poses()

    def position_error(self) -> np.ndarray:
        """||p_hat_i - p_i|| (B, N), metres, against Vicon, of the current estimate (after a step: k + 1)."""
        return np.linalg.norm(self.estimate[..., :2] - self.truth()[..., :2], axis=-1)

    def own_traces(self) -> np.ndarray:
        """tr of each robot's position covariance (B, N), m^2."""
        return self.P_ii[..., 0, 0] + self.P_ii[..., 1, 1]

    def distances(self) -> np.ndarray:
        """Vicon distances between robots at the current step (B, N, N)."""
        p = self.truth()[..., :2]
        return np.linalg.norm(p[:, :, None, :] - p[:, None, :, :], axis=-1)

    def observation(self) -> np.ndarray:
        B, N = self.batch, self.num_agents
        live = (self.k < self.horizon)[:, None]
        a = self.absolute_step()
        measured = (self.tables.first_index[a] >= 0) & live[..., None]
        landmarks = np.where(live, self.tables.landmark_count[a], 0.0)
        frac = np.broadcast_to((self.k / self.horizon)[:, None], (B, N))
        obs = np.concatenate([np.broadcast_to(np.eye(N), (B, N, N)), measured.astype(float), landmarks[..., None],
                              self.distances() / DISTANCE_SCALE, np.log(self.own_traces())[..., None],
                              frac[..., None]], axis=-1)
        return obs.astype(np.float32)

    def episode_error(self, errors: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """Mean distance error ||p_hat_i - p_i|| over the steps and robots (as ``relay_ukf``)."""
        return np.asarray(errors, float).mean(axis=(-2, -1))

    def state(self) -> np.ndarray:
        log_var = np.log(np.diagonal(self.P_ii, axis1=-2, axis2=-1)).reshape(self.batch, -1)
        return np.concatenate([self.observation().reshape(self.batch, -1), log_var], axis=-1).astype(np.float32)

    def info(self) -> dict[str, np.ndarray]:
        B, N = self.batch, self.num_agents
        backend, chains = self.backend, self.backend.chains
        truth = self.truth()
        team = lambda values: np.repeat(np.asarray(values)[:, None], N, axis=1)  # noqa: E731
        error = self.position_error()
        return {
            "true_position": truth[..., :2].copy(),
            "estimated_position": self.estimate[..., :2].copy(),
            "position_error": error,
            "error": error.copy(),
            "heading_error": np.abs(se2.wrap(self.estimate[..., 2] - truth[..., 2])),
            "trace": self.own_traces(),
            "dead_reckoning_error": np.linalg.norm(self.dead_reckoning[..., :2] - truth[..., :2], axis=-1),
            "measured": self.measured.copy(),
            "partner": backend.partner.copy(),
            "used": backend.used.copy(),
            "landmarks": backend.landmarks_applied.copy(),
            "rejected": backend.rejected.copy(),
            "chain_length": chains.length.reshape(B, N).copy(),
            "chain_stop": chains.stop.reshape(B, N).copy(),
            "messages_sent": self.network.messages_sent.copy(),
            "floats_sent": self.network.floats_sent.copy(),
            "communication": self.network.messages_sent.copy(),
            "hops": team(self.network.messages_sent.sum(axis=-1)),
            "hop_cost": team(self.network.cost_sent.sum(axis=-1)),
            "step": team(self.k),
        }

    def scene(self, b: int) -> Scene:
        N, k, start = self.num_agents, int(self.k[b]), int(self.start[b])
        truth = self.data.groundtruth[start + k, :, :2]
        x0, x1, y0, y1 = self.tables.extent
        chains = self.backend.chains
        links, notes = [], []
        for m in range(N):
            row = b * N + m
            hops = [int(p) for p in chains.chain[row] if p >= 0]
            links += [Link(source=p, target=q, value=1.0, label=(f"{m}:range" if h == 0 else f"{m}:{h + 1}"))
                      for h, (p, q) in enumerate(zip(hops[:-1], hops[1:], strict=True))]
            if hops:
                notes.append(f"chain {' -> '.join(map(str, hops))} ({STOP_REASONS[chains.stop[row]]})")
        notes.append(f"mean error {self.position_error()[b].mean():.3f} m, "
                     f"{int(self.backend.landmarks_applied[b].sum())} landmark sightings")
        centre = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1)])
        # the map holds the run's tracks and every landmark, with a margin for the ellipses
        landmarks = np.asarray(self.data.landmarks, float)
        low = np.minimum([x0, y0], landmarks.min(axis=0)) - 0.3
        high = np.maximum([x1, y1], landmarks.max(axis=0)) + 0.3
        return Scene(
            title=(f"mrclam_relay (MRCLAM dataset)  t = {(start + k) * self.data.dt:.1f} s, "
                   f"window step {k}/{self.horizon}"),
            truth=truth,
            estimates=self.estimate[b, :, :2],
            covariances=self.P_ii[b, :, :2, :2],
            trails=np.swapaxes(self.data.groundtruth[start:start + k + 1, :, :2], 0, 1),
            node_positions=(truth - centre) / max(x1 - x0, y1 - y0),
            node_labels=self.agent_names,
            links=links,
            link_value_max=1.0,
            link_value_name="relay hop of the last step (source:hop)",
            extent=(float(low[0]), float(high[0]), float(low[1]), float(high[1])),
            landmarks=landmarks,
            notes=notes[-4:],
        )
