"""``nlos_horizon``: adaptive finite-horizon estimation under LOS/NLOS switching and random delay (Gao et al. 2016).

Paper: Gao et al., "Adaptive finite-horizon group estimator ... mixed LOS/NLOS environments"
(seed ``004_4a0edde314525ef9.txt``); the formulas were lost in extraction, so the contract is
the reconstruction ``../shared/specs/gao2016_afge.md`` (labels [paper], [reconstructed],
[chosen] as there). Estimator: ``estimators.afge``.

Every agent is a target UAV ``uav_i`` that cannot localise itself directly: it fuses the
packets of its own J = 8 neighbours, each carrying the neighbour's navigation estimate
(truth + N(0, sigma_nav^2 I), as in the paper), the RSS and the AOA of the target, stamped with
the sending time. Each link switches between LOS and NLOS (a Markov chain per link, NLOS
biases the RSS and the AOA), each packet arrives after a random delay tau <= D or is lost.
The agent runs one delay-aware DFIR stack holding every horizon N = 1..N_max and decides,
each step, which horizon's estimate to output and which neighbours' packets to fuse; the
``paper`` policy is AHG (Algorithm 10) with the spec's defaults, so the env with ``paper``
equals AFGE. Agents do not exchange estimates, so they are independent copies of the
paper's single objective UAV with different paths (see the Arguments).

The preset is the composition ``nlos_orbit`` / ``random_delay`` / ``afge``
(``NlosHorizonConfig.parts``) with this action codec, observation, reward and info. The
world draws each episode from the episode's generator by ``draw_episode`` (truth,
readings and prior as the hand-wired scenario drew them); the packet delays are the
network's (its counter-based draws from its own child generator, Assumption 3's law:
``NlosHorizonScenario.packet_delays``), not the delay block of that draw, which the
world draws only to keep the stream. ``drawn_episodes`` gives the reproduction the env's
episodes with the network's delays.

Time line of one step (copy b, time k): receive, then decide (``coloc_env.scenarios.composed``).
Before the action the agent has received every packet that arrived up to k (the backend has
filtered the buffer with the last mask), and its observation describes them; the action then
picks the horizon whose estimate is output as x_hat(k) (reward for time k), the world moves to
k + 1 and the packets arriving then are buffered.

Action (one per agent, the same ``MultiDiscrete`` for all)
----------------------------------------------------------
``MultiDiscrete([N_max - N_min + 1, 2, 2, ..., 2])`` (J twos), int64.

| index   | meaning                                                                                     |
|---------|---------------------------------------------------------------------------------------------|
| ``0``   | horizon N = N_min + a[0] (replaces AHG). If DFIR_N has no estimate (fewer than two observed |
|         | stamps in the horizon) the output is the prediction A x_hat(k-1).                            |
| ``1+s`` | keep (1) / drop (0) the packets of the neighbour in RSS slot s: neighbours ordered by the    |
|         | RSS of their packet of the newest stamp (strongest first; neighbours with no newest packet  |
|         | follow by index). The bit applies to that neighbour's packets of every stamp in the buffer. |

[chosen] The config's ``n_strongest`` rule is applied after the mask (among the kept packets
of a stamp, the strongest ``n_strongest`` are fused), so keeping all reproduces the paper's
rule exactly; set ``n_strongest = num_neighbours`` to hand the whole selection to the agent.
A NaN/inf or a value outside the space is a ``ValueError``.

Observation (per agent, ``Box(low, high, shape=(D + 1 + 3 J + 2 M + 3,), float32)``; 41 by default)
----------------------------------------------------------------------------------------------
The ``afge`` backend's features (``coloc_env.backends.nlos``), then the step fraction.
Since the binding every entry has a finite bound (the column; the RSS, innovation and trace
entries are clipped to it: before, the space was unbounded and nothing was clipped).

| index                   | meaning                                                                  | bounds    |
|-------------------------|--------------------------------------------------------------------------|-----------|
| ``[0, D+1)``            | packets of stamp k - l known at time k, l = 0..D, divided by J           | [0, 1]    |
| ``D+1+3s + 0``          | slot s has a packet of the newest stamp (0/1)                            | [0, 1]    |
| ``D+1+3s + 1``          | its RSS, (RSS + 80 dBm) / 10 (0 when absent)                             | [-20, 20] |
| ``D+1+3s + 2``          | its mode: +1 NLOS, -1 LOS with ``mode_info="known"``, else 0             | [-1, 1]   |
| ``D+1+3J``              | log(1 + e^T S^-1 e) of the newest fused observation against the          | [0, 50]   |
|                         | prediction of the last output (0 without a fresh observation)            |           |
| ``D+2+3J``              | the last horizon used, / N_max (0 before the first output)               | [0, 1]    |
| ``[D+3+3J, D+3+3J+M)``  | log tr P_N (position block) for the M horizons of an AHG group centred on | [-50, 50] |
|                         | the last horizon (N_c(0) before the first; clipped as AHG clips its      |           |
|                         | centre); 14 where invalid                                                |           |
| ``[D+3+3J+M, D+3+3J+2M)``| the AHG cost J_N(k) of the same M horizons (``likelihood``'s: the one-  | [0, 50]   |
|                         | step predictive cost, or the in-sample residual for ``"paper"``) minus   |           |
|                         | the group's lowest: 0 marks AHG's pick; 50 where invalid (capped)        |           |
| ``[-1]``                | step fraction k / horizon                                                | [0, 1]    |

The AHG costs were added for learning (issue 15: the horizon agent should see the innovation
statistics AHG decides on; the observation had only the log-traces and the newest NIS).

``state()``: every agent's observation, then each agent's true estimation error (x, y) / 10 m.

Reward (per agent: each target has its own estimate)
----------------------------------------------------
| ``reward=`` | value for the output x_hat(k) (squared metres)                                  |
|-------------|----------------------------------------------------------------------------------|
| ``"error"`` | -||p_hat(k) - p(k)||^2 - packet_cost * packets used                               |
| ``"trace"`` | -tr P(k)[:2, :2] (the estimator's own covariance) - packet_cost * packets used    |

Termination: none; truncation after ``horizon`` steps (the paper's 1000 s flight).

``infos[agent]``: ``true_position``, ``estimated_position``, ``position_error`` (m), ``error``
(squared m), ``trace`` (tr of the output's position covariance), ``horizon`` (N used; 0 at
reset), ``valid`` (DFIR_N had an estimate), ``packets_received`` (packets arriving at k),
``communication`` (packets used: of those arriving at k, how many were fused),
``nlos_fraction`` (NLOS links among the neighbours in the RSA at k, the time of the output;
before the binding it was read at k + 1), ``messages_sent`` / ``floats_sent`` (0: the
packets come from world nodes, not from agents), ``step``.

Batching: B copies x N agents step in one set of numpy calls; the fused observations of
the D + 1 buffer stamps, the D + 1 stack advances over all horizons and the AHG costs are
all arrays (B, N, ...). The only loops are over the D + 1 buffer stamps (inside the
estimator) and, at reset, over the copies being reset (each draws its whole episode from its
own generator) and over time for the LOS/NLOS chains.

Arguments (fields of ``NlosHorizonConfig``, defaults = spec §9)
--------------------------------------------------------------------
| field               | default                      | allowed / source                                  |
|---------------------|------------------------------|---------------------------------------------------|
| num_uavs            | 4                            | 1..64 agents (targets) [chosen]                   |
| num_neighbours      | 8                            | 1..32, J [chosen]                                 |
| horizon             | 1000                         | 1..100000 steps (1000 s flight [paper])           |
| period              | 1.0                          | [1e-3, 1e4], T (s) [chosen]                       |
| accel_sigma         | 0.3                          | [1e-6, 1e3], sigma_a of the estimator's Q [chosen]|
| speed               | 20.0                         | [0, 1e4] m/s [chosen]                             |
| turn_rates_deg      | (3, -3, 3, -6)               | deg/s per turn, entries in [-1e4, 1e4] [chosen]   |
| turn_windows        | (200,260) (500,560) (700,730) (850,880) | [start, end) integer steps, <= 1e7 [chosen] |
| target_spacing      | 3000.0                       | [0, 1e7] m: uav_i starts at (0, i * spacing) [chosen] |
| schedule_shift      | 40                           | 0..100000 steps: uav_i's turns start i * shift later |
| orbit_radius        | (150, 900)                   | (low, high) m, entries in [0, 1e7], low <= high: |
|                     |                              | rho0 ~ U(.) [chosen]                              |
| orbit_wobble        | 200.0                        | [0, 1e6] m: a ~ U(0, .) [chosen]                  |
| orbit_wobble_rate   | (0.002, 0.01)                | (low, high) rad/s, entries in [0, 10], low <= high: |
|                     |                              | w ~ U(.) [chosen]                                 |
| orbit_bearing_rate  | 0.01                         | [0, 10] rad/s: om ~ U(-., .) [chosen]             |
| r_inf, r_sup        | 30, 1000                     | 0 < r_inf < r_sup (m) [chosen]                    |
| sigma_nav           | 2.0                          | (0, 1e4] m per axis [chosen]                      |
| tx_power_dbm        | 20.0                         | P_T in [-200, 200] dBm [chosen]                   |
| frequency_hz        | 2.4e9                        | f in [1, 1e13] Hz [chosen]                        |
| d0                  | 1.0                          | [1e-3, 1e6] m [chosen]                            |
| path_loss_exponent  | 2.2                          | n in [0.5, 10] (smaller: the RSS-inverted range   |
|                     |                              | overflows) [chosen]                               |
| sigma_db            | 2.0                          | (0, 100] dB, LOS [chosen]                         |
| sigma_theta_deg     | 0.1                          | [1e-6, 180] deg, LOS [paper]                      |
| nlos_bias_db        | 6.0                          | [-100, 100] dB, mu_db [chosen]                    |
| nlos_sigma_db       | 4.0                          | [0, 100] dB [chosen]                              |
| nlos_bias_deg       | 1.0                          | [-180, 180] deg, mu_theta [chosen]                |
| nlos_sigma_deg      | 1.0                          | [0, 180] deg [chosen]                             |
| p_nlos              | 0.3                          | pi in [0, 1] [chosen]                             |
| p10                 | 0.1                          | [0, 1], pi p10 <= 1 - pi [chosen]                 |
| buffer_length       | 3                            | D, 0..999 (N_min >= D + 1, N_max <= 1000) [chosen] |
| delay_probs         | (0.6, 0.2, 0.1, 0.05)        | D + 1 entries in [0, 1], sum <= 1 [chosen]        |
| n_strongest         | 4                            | 1..J [chosen] ("only the strongest" [paper])      |
| min_packets         | 1                            | n_min, 1..J [chosen]                              |
| weighting           | "distance"                   | "distance" (Def. 6), "information"                |
| mode_info           | "known"                      | "known", "mean", "blind"                          |
| window_min          | 4                            | N_min: 2..N_max and >= D + 1 [reconstructed]      |
| window_max          | 30                           | N_max: 2..1000 [chosen]                           |
| window_step         | 2                            | dN >= 1; N_max - N_min >= (M - 1) dN              |
| group_size          | 5                            | M, odd >= 1                                       |
| window_centre       | 12                           | N_c(0) in [N_min, N_max] (paper's best N)         |
| likelihood          | "predictive"                 | AHG cost for ``paper``: predictive, paper, smoothed |
| smoothing           | 0.5                          | lam in (0, 1) [chosen]                            |
| prior_std           | (50, 50, 5, 5)               | (4,) entries in (0, 1e6]: x_hat before any       |
|                     |                              | estimate = truth + N(0, P0)                       |
| reward              | "error"                      | "error", "trace"                                  |
| packet_cost         | 0.0                          | [0, 1e12] per packet used                         |

"horizon" is the episode length as in every scenario; the paper's horizon size N is
called the *window* here.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import gymnasium
import numpy as np

import estimators.afge as af
from coloc_env.config import ORBIT_LIMITS, as_array, check_choice, check_entries, check_range, check_step_windows
from coloc_env.primitives.flight import OrbitingNeighbours, OrbitParameters, TurnSchedulePath
from coloc_env.primitives.los_nlos import LosNlosChain
from coloc_env.primitives.radio import ReceiveSearchArea, RssAoaSensor
from coloc_env.primitives.random_delay import NEVER, BoundedRandomDelay
from coloc_env.rendering import Link, Scene
from coloc_env.scenarios.binding import PresetScenario


@dataclass(frozen=True)
class NlosHorizonConfig:
    """Configuration of ``nlos_horizon``; defaults are spec §9 (see the module docstring)."""

    num_uavs: int = 4
    num_neighbours: int = 8
    horizon: int = 1000
    period: float = 1.0
    accel_sigma: float = 0.3
    speed: float = 20.0
    turn_rates_deg: tuple = (3.0, -3.0, 3.0, -6.0)
    turn_windows: tuple = ((200, 260), (500, 560), (700, 730), (850, 880))
    target_spacing: float = 3000.0
    schedule_shift: int = 40
    orbit_radius: tuple = (150.0, 900.0)
    orbit_wobble: float = 200.0
    orbit_wobble_rate: tuple = (0.002, 0.01)
    orbit_bearing_rate: float = 0.01
    r_inf: float = 30.0
    r_sup: float = 1000.0
    sigma_nav: float = 2.0
    tx_power_dbm: float = 20.0
    frequency_hz: float = 2.4e9
    d0: float = 1.0
    path_loss_exponent: float = 2.2
    sigma_db: float = 2.0
    sigma_theta_deg: float = 0.1
    nlos_bias_db: float = 6.0
    nlos_sigma_db: float = 4.0
    nlos_bias_deg: float = 1.0
    nlos_sigma_deg: float = 1.0
    p_nlos: float = 0.3
    p10: float = 0.1
    buffer_length: int = 3
    delay_probs: tuple = (0.6, 0.2, 0.1, 0.05)
    n_strongest: int = 4
    min_packets: int = 1
    weighting: str = "distance"
    mode_info: str = "known"
    window_min: int = 4
    window_max: int = 30
    window_step: int = 2
    group_size: int = 5
    window_centre: int = 12
    likelihood: str = "predictive"
    smoothing: float = 0.5
    prior_std: tuple = (50.0, 50.0, 5.0, 5.0)
    reward: str = "error"
    packet_cost: float = 0.0

    def parts(self) -> tuple:
        """The (world, network, backend) configs this flat config stands for: ``nlos_orbit`` with the same
        flight, orbits, radio and prior, ``random_delay`` with (``delay_probs``, ``buffer_length``) and
        ``afge`` with the estimator's fields."""
        from coloc_env.backends.nlos import Afge  # the parts import this module (the world's episode draw)
        from coloc_env.networks.random_delay import RandomDelay
        from coloc_env.worlds.nlos_orbit import SCENARIO_FIELDS, NlosOrbit

        world = NlosOrbit(num_agents=self.num_uavs, horizon=self.horizon,
                          **{name: getattr(self, name) for name in SCENARIO_FIELDS})
        network = RandomDelay(delay_probs=tuple(self.delay_probs), buffer_length=self.buffer_length)
        backend = Afge(n_strongest=self.n_strongest, min_packets=self.min_packets, weighting=self.weighting,
                       mode_info=self.mode_info, window_min=self.window_min, window_max=self.window_max,
                       window_step=self.window_step, group_size=self.group_size, window_centre=self.window_centre,
                       likelihood=self.likelihood, smoothing=self.smoothing)
        return world, network, backend

    # --- the world and estimator parts this config describes ---------------------------
    @property
    def path(self) -> TurnSchedulePath:
        return TurnSchedulePath(speed=self.speed, turn_rates=tuple(np.deg2rad(self.turn_rates_deg).tolist()),
                                turn_windows=tuple(tuple(w) for w in self.turn_windows), period=self.period)

    @property
    def neighbours(self) -> OrbitingNeighbours:
        return OrbitingNeighbours(self.num_neighbours, tuple(self.orbit_radius), self.orbit_wobble,
                                  tuple(self.orbit_wobble_rate), self.orbit_bearing_rate, self.period)

    @property
    def area(self) -> ReceiveSearchArea:
        return ReceiveSearchArea(self.r_inf, self.r_sup)

    @property
    def signal(self) -> af.SignalModel:
        return af.SignalModel(
            tx_power_dbm=float(self.tx_power_dbm), frequency_hz=float(self.frequency_hz), d0=float(self.d0),
            exponent=float(self.path_loss_exponent), sigma_db=float(self.sigma_db),
            sigma_theta=float(np.deg2rad(self.sigma_theta_deg)), nlos_bias_db=float(self.nlos_bias_db),
            nlos_sigma_db=float(self.nlos_sigma_db), nlos_bias_theta=float(np.deg2rad(self.nlos_bias_deg)),
            nlos_sigma_theta=float(np.deg2rad(self.nlos_sigma_deg)), sigma_nav=float(self.sigma_nav),
            p_nlos=float(self.p_nlos))

    @property
    def chain(self) -> LosNlosChain:
        return LosNlosChain(self.p_nlos, self.p10)

    @property
    def delay(self) -> BoundedRandomDelay:
        return BoundedRandomDelay(tuple(self.delay_probs), self.buffer_length)

    @property
    def motion(self) -> af.MotionModel:
        return af.MotionModel(float(self.period), float(self.accel_sigma))

    @property
    def ahg(self) -> af.AHGParams:
        return af.AHGParams(self.window_min, self.window_max, self.window_step, self.group_size,
                            self.window_centre, self.likelihood, float(self.smoothing))

    @property
    def prior_cov(self) -> np.ndarray:
        return np.diag(np.asarray(self.prior_std, float) ** 2)

    def validate(self) -> None:
        check_range("num_uavs", self.num_uavs, 1, 64, integer=True)
        check_range("horizon", self.horizon, 1, 100_000, integer=True)
        check_range("period", self.period, 1e-3, 1e4)
        check_range("accel_sigma", self.accel_sigma, 1e-6, 1e3)
        check_range("speed", self.speed, 0.0, 1e4)
        rates = as_array("turn_rates_deg", self.turn_rates_deg, ndim=1, bound=1e4)
        windows = as_array("turn_windows", self.turn_windows)
        if windows.shape != (len(rates), 2):
            raise ValueError(f"turn_windows must have shape ({len(rates)}, 2), one [start, end) per entry of "
                             f"turn_rates_deg (a rate per turn), "
                             f"got {windows.shape}")
        check_step_windows("turn_windows", self.turn_windows, windows)
        self.path.validate()
        check_range("target_spacing", self.target_spacing, 0.0, 1e7)
        check_range("schedule_shift", self.schedule_shift, 0, 100_000, integer=True)
        check_range("num_neighbours", self.num_neighbours, 1, 32, integer=True)
        for name in ("orbit_radius", "orbit_wobble_rate"):
            pair = as_array(name, getattr(self, name), shape=(2,))
            check_entries(name, pair, 0.0, ORBIT_LIMITS[name])
            if pair[1] < pair[0]:
                raise ValueError(f"{name} must be (low, high) with 0 <= low <= high, got {getattr(self, name)}")
        check_range("orbit_wobble", self.orbit_wobble, 0.0, 1e6)
        check_range("orbit_bearing_rate", self.orbit_bearing_rate, 0.0, 10.0)
        check_range("r_inf", self.r_inf, 0.0, 1e9, low_open=True)
        check_range("r_sup", self.r_sup, 0.0, 1e9, low_open=True)
        self.area.validate()
        check_range("sigma_nav", self.sigma_nav, 0.0, 1e4, low_open=True)
        # the signal's own fields, in their own units, before the derived SignalModel converts them
        check_range("tx_power_dbm", self.tx_power_dbm, -200.0, 200.0)
        check_range("frequency_hz", self.frequency_hz, 1.0, 1e13)
        check_range("d0", self.d0, 1e-3, 1e6)
        check_range("path_loss_exponent", self.path_loss_exponent, 0.5, 10.0)
        check_range("sigma_db", self.sigma_db, 0.0, 100.0, low_open=True)
        check_range("sigma_theta_deg", self.sigma_theta_deg, 1e-6, 180.0)
        check_range("nlos_bias_db", self.nlos_bias_db, -100.0, 100.0)
        check_range("nlos_sigma_db", self.nlos_sigma_db, 0.0, 100.0)
        check_range("nlos_bias_deg", self.nlos_bias_deg, -180.0, 180.0)
        check_range("nlos_sigma_deg", self.nlos_sigma_deg, 0.0, 180.0)
        check_range("p_nlos", self.p_nlos, 0.0, 1.0)
        check_range("p10", self.p10, 0.0, 1.0)
        RssAoaSensor(self.signal).validate()
        self.chain.validate()
        # window_min >= D + 1 and window_max <= 1000: D = 1000 leaves no horizon
        check_range("buffer_length", self.buffer_length, 0, 999, integer=True)
        as_array("delay_probs", self.delay_probs, ndim=1)
        self.delay.validate()
        J = self.num_neighbours
        check_range("n_strongest (at most num_neighbours)", self.n_strongest, 1, J, integer=True)
        check_range("min_packets (at most num_neighbours)", self.min_packets, 1, J, integer=True)
        check_choice("weighting", self.weighting, af.WEIGHTINGS)
        check_choice("mode_info", self.mode_info, af.MODE_INFOS)
        check_range("window_max", self.window_max, 2, 1000, integer=True)
        check_range("window_min", self.window_min, 2, self.window_max, integer=True, high_label="window_max")
        if self.window_min < self.buffer_length + 1:
            raise ValueError(f"window_min must be >= buffer_length + 1 = {self.buffer_length + 1} (the group "
                             f"reflects the possible delay, spec §7), got {self.window_min}")
        check_range("window_step", self.window_step, 1, 1000, integer=True)
        check_range("group_size", self.group_size, 1, 999, integer=True)
        if self.group_size % 2 != 1:
            raise ValueError(f"group_size must be odd (M = 2h + 1), got {self.group_size}")
        if self.window_max - self.window_min < (self.group_size - 1) * self.window_step:
            raise ValueError(f"window_max - window_min must be >= (group_size - 1) * window_step = "
                             f"{(self.group_size - 1) * self.window_step}, got {self.window_max - self.window_min}")
        check_range("window_centre", self.window_centre, self.window_min, self.window_max, integer=True)
        check_choice("likelihood", self.likelihood, af.LIKELIHOODS)
        check_range("smoothing", self.smoothing, 0.0, 1.0, low_open=True, high_open=True)
        check_entries("prior_std", as_array("prior_std", self.prior_std, shape=(4,)), 0.0, 1e6, low_open=True)
        check_choice("reward", self.reward, ("error", "trace"))
        check_range("packet_cost", self.packet_cost, 0.0, 1e12)


@dataclass
class Episode:
    """One copy's whole episode, stamps 0..K (K = horizon), targets T, neighbours J.

    ``truth`` (K+1, T, 4); ``rss``/``aoa`` (K+1, T, J); ``nav`` (K+1, T, J, 2) the neighbours'
    own position estimates; ``modes`` (K+1, T, J) int8 (1 = NLOS); ``delays`` (K+1, T, J) int16
    (``NEVER`` where the neighbour was outside the RSA); ``prior`` (T, 4); ``orbits`` (T, J).
    """

    truth: np.ndarray
    rss: np.ndarray
    aoa: np.ndarray
    nav: np.ndarray
    modes: np.ndarray
    delays: np.ndarray
    prior: np.ndarray
    orbits: OrbitParameters


def target_paths(config: NlosHorizonConfig, targets: int, steps: int) -> np.ndarray:
    """True states (steps, T, 4): uav_i starts at (0, i * spacing), turns delayed by i * shift."""
    path = config.path
    return np.stack([path.trajectory(steps, start=(0.0, i * float(config.target_spacing)),
                                     shift=i * int(config.schedule_shift)) for i in range(targets)], axis=1)


def in_turn(config: NlosHorizonConfig, targets: int, steps: int) -> np.ndarray:
    """(steps, T) True where target i is turning."""
    return np.stack([config.path.in_turn(steps, i * int(config.schedule_shift)) for i in range(targets)], axis=1)


def draw_episode(config: NlosHorizonConfig, rng: np.random.Generator, targets: int | None = None) -> Episode:
    """Draw one copy's episode from ``rng`` in a fixed order (orbits, modes, RSS/AOA noise,
    navigation noise, delays, prior); ``targets`` defaults to ``num_uavs``."""
    return draw_episode_parts(config, rng, targets)[0]


def draw_episode_parts(config: NlosHorizonConfig, rng: np.random.Generator, targets: int | None = None,
                       truth: np.ndarray | None = None) -> tuple[Episode, np.ndarray]:
    """``draw_episode`` and the target-neighbour distances (K+1, T, J) it computed. ``truth``: the targets'
    paths if the caller has them (``target_paths`` of the same config, targets and horizon: they draw
    nothing, so a batch's reset computes them once)."""
    T = config.num_uavs if targets is None else targets
    K1, J = config.horizon + 1, config.num_neighbours
    truth = target_paths(config, T, K1) if truth is None else truth
    orbits = config.neighbours.sample(rng, (T,))
    senders = truth[:, :, None, :2] + config.neighbours.offsets(orbits, K1)  # (K+1, T, J, 2)
    modes = config.chain.sample(rng, K1, (T, J))
    white = rng.standard_normal((K1, T, J, 2))
    rss, aoa = RssAoaSensor(config.signal).measure(truth[:, :, None, :2], senders, modes, white)
    nav = senders + config.sigma_nav * rng.standard_normal((K1, T, J, 2))
    distance = np.linalg.norm(truth[:, :, None, :2] - senders, axis=-1)
    delays = np.where(config.area.contains(distance), config.delay.sample(rng, (K1, T, J)), NEVER).astype(np.int16)
    prior = truth[0] + rng.standard_normal((T, 4)) * np.asarray(config.prior_std, float)
    return Episode(truth, rss, aoa, nav, modes, delays, prior, orbits), distance


def fuse_buffer(config: NlosHorizonConfig, rss, aoa, nav, modes, delays, lags, keep, fixes=None):
    """Fused observations of buffered stamps from their packets (spec §4-5).

    Packets on the last axis J: ``rss``/``aoa``/``modes``/``delays`` (..., J), ``nav``
    (..., J, 2); ``lags`` (...) how long ago each stamp was (negative: not yet sent);
    ``keep`` (..., J) the agent's mask; ``fixes`` the packets' ``packet_fixes`` if known.
    Returns (Y, y, gamma, used).
    """
    return af.fuse_packets(config.signal, rss, aoa, nav, modes, delays, lags, keep, config.n_strongest,
                           config.mode_info, config.weighting, config.min_packets, fixes=fixes)


def fused_by_stamp_and_lag(config: NlosHorizonConfig, episode: Episode):
    """All fused observations of an episode with every packet kept, by (stamp, lag):
    arrays (K+1, T, D+1, ...) -> moved to (T, K+1, D+1, ...) for ``estimators.afge.run_fixed_mask``."""
    lags = np.broadcast_to(np.arange(config.buffer_length + 1), (*episode.rss.shape[:2], config.buffer_length + 1))
    Y, y, gamma, _ = fuse_buffer(config, episode.rss[:, :, None], episode.aoa[:, :, None], episode.nav[:, :, None],
                                 episode.modes[:, :, None], episode.delays[:, :, None], lags, np.ones(1, bool))
    return np.moveaxis(Y, 0, 1), np.moveaxis(y, 0, 1), np.moveaxis(gamma, 0, 1)


class NlosHorizonScenario(PresetScenario):
    """Batched core of ``nlos_horizon``: the binding of ``NlosHorizonConfig`` on the composable core
    (``nlos_orbit`` / ``random_delay`` / ``afge``, receiving before deciding); the module docstring has the
    tables."""

    name = "nlos_horizon"
    paper = "gao2016"
    Config = NlosHorizonConfig

    def __init__(self, config: NlosHorizonConfig, batch: int = 1):
        super().__init__(config, batch)
        be = self.backend
        be.adaptive = False  # the codec never asks the backend for AHG (v = 0); the paper policy runs it
        self.motion = be.motion
        self.ahg = be.ahg
        self.D, self.J, self.S = be.D, be.J, be.S
        self.episode_id = np.zeros(self.batch, dtype=np.int64)
        self._preset_action_space = gymnasium.spaces.MultiDiscrete(
            [config.window_max - config.window_min + 1] + [2] * self.J, dtype=np.int64)
        low, high = be.feature_bounds()
        self._observation_space = gymnasium.spaces.Box(np.r_[low, 0.0].astype(np.float32),
                                                       np.r_[high, 1.0].astype(np.float32), dtype=np.float32)

    # --- the parts' state, by the scenario's names ----------------------------------------
    @property
    def truth(self) -> np.ndarray:
        """True states (B, K + 1, N, 4) of the episode's targets, stamps 0..K."""
        return self.world.truth

    @property
    def pending(self) -> dict:
        """The backend's buffer at the current time filtered with the last mask, before the agent acts
        (``coloc_env.backends.nlos.PacketFirBackend.receive``): ``x``, ``P``, ``valid`` per horizon."""
        return self.backend.pending

    def packet_delays(self) -> np.ndarray:
        """(B, K + 1, N, J) int64: the delay the network gives the packet of stamp s from neighbour j to
        uav_i, -1 where none was sent (outside the RSA) or it was lost; the network's counter-based draws,
        fixed at reset (replayed here on a copy of the network, its own rule)."""
        net, w = copy.deepcopy(self.network), self.world
        B, K1 = self.batch, self.horizon + 1
        out = np.empty((B, K1, self.num_agents, self.J), np.int64)
        for s in range(K1):
            net.begin(np.full(B, s), w.truth[:, s, :, :2], np.zeros((B, self.num_agents, 0), np.int64))
            out[:, s] = net.node_packets(w.in_rsa[:, s], w.distance[:, s], self.backend.config.payload, slot=0)
        return out

    # --- description ------------------------------------------------------------
    @property
    def obs_dim(self) -> int:
        return self.D + 1 + 3 * self.J + 2 * self.config.group_size + 3

    def observation_space(self):
        return self._observation_space

    def action_space(self):
        return self._preset_action_space

    def state_space(self):
        dim = self.num_agents * (self.obs_dim + 2)
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(dim,), dtype=np.float32)

    def encode_actions(self, window: np.ndarray, keep_slots: np.ndarray | None = None) -> np.ndarray:
        """Actions (..., 1 + J) int64 for horizons ``window`` (...) and slot bits (..., J) (default: keep all)."""
        window = np.asarray(window, np.int64)
        keep = np.ones((*window.shape, self.J), np.int64) if keep_slots is None else np.asarray(keep_slots, np.int64)
        return np.concatenate([(window - self.config.window_min)[..., None], keep], axis=-1)

    def decode_actions(self, actions) -> np.ndarray:
        """Actions (B, N, 1 + J) -> the backend's blocks: ``horizon`` v = a[0] + 1 (N = N_min + a[0]; the
        preset offers no v = 0, AHG inside the backend: its ``paper`` policy runs AHG as an agent) and
        ``keep`` a[1:], the slot bits."""
        a = self.check_discrete_actions(
            actions, ("action[0] (horizon N - N_min)", *[f"action[1:{1 + self.J}] (keep 1 / drop 0)"] * self.J))
        return np.concatenate([a[..., :1] + 1, a[..., 1:]], axis=-1)

    # --- costs for policies -------------------------------------------------------
    def horizon_costs(self, likelihood: str) -> np.ndarray:
        """AHG costs J_N(k) (B, N, S) of every horizon N = 1..S at the current time, computed with
        the last mask (``predictive`` or ``paper``; ``smoothed`` is the policy's own forgetting of
        the predictive costs)."""
        if likelihood not in ("predictive", "paper"):
            raise ValueError(f"likelihood must be 'predictive' or 'paper' here, got {likelihood!r}")
        return self.backend.costs(self.pending, likelihood)

    @property
    def horizon_valid(self) -> np.ndarray:
        """(B, N, S): DFIR_N has an estimate at the current time (last mask)."""
        return self.pending["valid"]

    @property
    def fresh(self) -> np.ndarray:
        """(B, N): gamma(k, 0), a fused observation of the newest stamp exists (last mask)."""
        return self.pending["fresh"]

    # --- dynamics ----------------------------------------------------------------
    def reset(self, rngs, env_index=None) -> None:
        super().reset(rngs, env_index)
        self.episode_id[self._indices(env_index)] += 1

    def compute_reward(self) -> np.ndarray:
        be = self.backend
        if self.config.reward == "error":
            loss = np.sum((be.posterior_position - self._truth) ** 2, axis=-1)
        else:
            loss = np.trace(be.posterior_position_cov, axis1=-2, axis2=-1)
        return -loss - self.config.packet_cost * be.packets_used

    def constant_horizon_errors(self) -> np.ndarray:
        """Summed squared error (B, N, S) of every constant horizon N = 1..S from now to the end of
        the episode, all packets kept (privileged: a look-ahead on a copy of the world)."""
        sim = copy.deepcopy(self)
        be = sim.backend
        A = self.motion.transition
        pred = np.broadcast_to(be.pred_x[:, :, None, :], (*be.prev_valid.shape, 4)).copy()
        total = np.zeros(be.prev_valid.shape)
        action = sim.encode_actions(np.full((sim.batch, sim.num_agents), self.config.window_min))
        while not np.all(sim.k >= sim.horizon):
            t = be.pending
            out = np.where(t["valid"][..., None], t["x"], pred)
            total += np.sum((out[..., :2] - sim.world.positions()[:, :, None, :]) ** 2, axis=-1)
            pred = out @ A.T
            sim.step(action)
        return total

    # --- views -------------------------------------------------------------------
    def observation(self) -> np.ndarray:
        B, N = self.batch, self.num_agents
        frac = np.broadcast_to((self.k / self.horizon)[:, None, None], (B, N, 1))
        return np.concatenate([self.backend.observation_features(), frac], axis=-1).astype(np.float32)

    def episode_error(self, errors: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """Time-averaged squared position error over k >= min(50, horizon - 1), mean over the agents.

        The paper's time-averaged RMSE (spec §12, ``train/reproduce/gao2016.py``)
        is the square root of the mean of this over episodes.
        """
        warm = min(50, self.horizon - 1)
        return np.asarray(errors, float)[..., warm:, :].mean(axis=(-2, -1))

    def _output_time(self) -> np.ndarray:
        """(B,) the time of the last output (k - 1; 0 at reset)."""
        return np.maximum(self.k - 1, 0)

    def state(self) -> np.ndarray:
        error = (self.backend.posterior_position - self._truth) / 10.0
        return np.concatenate([self.observation().reshape(self.batch, -1), error.reshape(self.batch, -1)],
                              axis=-1).astype(np.float32)

    def info(self) -> dict[str, np.ndarray]:
        B, N = self.batch, self.num_agents
        be, w = self.backend, self.world
        rows, now = np.arange(B), self._output_time()
        started = (self.k > 0)[:, None]
        in_range = w.in_rsa[rows, now]
        nlos = (w.modes[rows, now] == 1) & in_range
        error = np.sum((be.posterior_position - self._truth) ** 2, axis=-1)
        return {
            "true_position": self._truth.copy(),
            "estimated_position": be.posterior_position.copy(),
            "position_error": np.sqrt(error),
            "error": error,
            "trace": np.trace(be.posterior_position_cov, axis1=-2, axis2=-1),
            "messages_sent": self.network.messages_sent.copy(),
            "floats_sent": self.network.floats_sent.copy(),
            "horizon": be.horizon_used.copy(),
            "valid": be.valid_used.copy(),
            "packets_received": np.where(started, be.packets_arrived, 0.0),
            "communication": np.where(started, be.packets_used, 0.0),
            "nlos_fraction": nlos.sum(-1) / np.maximum(in_range.sum(-1), 1),
            "step": np.broadcast_to(self.k[:, None], (B, N)).copy(),
        }

    def scene(self, b: int) -> Scene:
        k = int(self.k[b])
        now = max(k - 1, 0)
        w, be = self.world, self.backend
        truth = w.truth[b, now]
        offsets = self.config.neighbours.offsets(
            OrbitParameters(*(getattr(w.orbits, n)[b, 0] for n in
                              ("radius", "wobble", "wobble_rate", "phase", "bearing_rate"))), now + 1)[now]
        used = be.used[b, 0].sum(axis=0)  # packets fused per neighbour of uav_0 over the buffer
        modes = w.modes[b, now, 0]
        J = self.J
        nodes = np.vstack([[0.0, 0.0], offsets / max(float(self.config.r_sup), 1.0)])
        links = [Link(source=j + 1, target=0, value=float(used[j]), label="N" if modes[j] else "L") for j in range(J)]
        return Scene(
            title=f"nlos_horizon (gao2016)  k = {k}/{self.horizon}",
            truth=truth[:, :2],
            estimates=be.posterior_position[b],
            covariances=be.posterior_position_cov[b],
            trails=np.swapaxes(w.truth[b, max(0, now - 30):now + 1, :, :2], 0, 1),
            node_positions=nodes,
            node_labels=["uav_0"] + [f"nb_{j}" for j in range(J)],
            links=links,
            link_value_max=float(self.D + 1),
            link_value_name="packets of uav_0's buffer fused (L/N = LOS/NLOS)",
            notes=[f"uav_0: horizon {int(be.horizon_used[b, 0])}, error "
                   f"{np.linalg.norm(be.posterior_position[b, 0] - truth[0, :2]):.1f} m"],
        )


def drawn_episodes(config: NlosHorizonConfig, seeds) -> list[Episode]:
    """The episodes ``env.reset(seed=s)`` draws for each of ``seeds``, as ``Episode`` (the layout of
    ``draw_episode``), with the delays of the env's network (``NlosHorizonScenario.packet_delays``;
    ``NEVER`` where no packet was sent or it was lost). Filters run on these are paired with the env's
    policies episode by episode."""
    seeds = list(seeds)
    core = NlosHorizonScenario(config, batch=len(seeds))
    core.reset([np.random.default_rng(s) for s in seeds])
    w, delays = core.world, core.packet_delays()
    names = ("radius", "wobble", "wobble_rate", "phase", "bearing_rate")
    return [Episode(truth=w.truth[b].copy(), rss=w.rss[b].copy(), aoa=w.aoa[b].copy(), nav=w.nav[b].copy(),
                    modes=w.modes[b].copy(), delays=np.where(delays[b] >= 0, delays[b], NEVER).astype(np.int16),
                    prior=w.prior[b].copy(), orbits=OrbitParameters(*(getattr(w.orbits, n)[b].copy() for n in names)))
            for b in range(len(seeds))]
