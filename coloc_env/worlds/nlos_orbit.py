"""World ``nlos_orbit`` (gao2016): target UAVs, each localizing itself from J orbiting neighbours' RSS/AOA.

The world owns its generative model: ``draw_episode`` draws each copy's whole episode at reset from
the world's generator, in this order: the orbits of the neighbours, the LOS/NLOS modes, the RSS/AOA
noise, the navigation noise, one uniform per packet (stamp, target, neighbour) and the prior's error.
The world uses no packet uniform: delivery is the network's (``random_delay``, gao2016's Assumption 3,
draws the delays from its own generator). They are drawn all the same, so that the prior's error comes
after them, and kept in ``Episode.packet_uniforms`` for code that wants one delay per packet on the
world's own episode (``coloc_env.networks.blocks.bounded_delay.BoundedRandomDelay.from_uniforms``).

Every agent ``uav_i`` is a target that cannot localize itself directly: it flies straight
legs and coordinated turns (``coloc_env.worlds.blocks.flight.TurnSchedulePath``; uav_i starts
at (0, i * target_spacing), its turns i * schedule_shift steps later). J neighbours orbit
each target (``coloc_env.worlds.blocks.flight.OrbitingNeighbours``); they are part of the world,
not agents. A neighbour inside the target's receive-search area (Def. 1, r_inf <= d <=
r_sup on the true distance) measures the RSS and the AOA of the target (docs/gao2016.md §4,
``coloc_env.worlds.blocks.radio.RssAoaSensor``), the bias of its link's LOS/NLOS Markov chain
(``coloc_env.worlds.blocks.los_nlos.LosNlosChain``) included, and sends a packet stamped k
with its own navigation estimate (truth + N(0, sigma_nav^2 I)) to the target: the backend
asks the network for its delivery (``coloc_env.networks.base.Network.node_packets``).

| quantity       | value                                                                              |
|----------------|------------------------------------------------------------------------------------|
| motion model   | ``estimators.nlos_models.ConstantVelocityWhiteAccel`` (state [p; v], 4; no input); |
|                | the truth is the turn schedule, the model is what the backends assume (sigma_a)     |
| measurements   | ``rss``, ``aoa`` (each switchable by ``sensors``), ``los_nlos`` (with ``report_mode``) |
| anchors        | orbiting neighbours with navigation estimates (world nodes, J per agent)           |
| sensing action | none                                                                               |
| observation    | none (the backend shows what arrived)                                              |
| initial belief | mean truth(0) + N(0, diag(prior_std^2)), cov diag(prior_std^2)                       |

Readings of time k (``coloc_env.worlds.base.Readings``; ``inputs`` (B, N, 0), no
ranges, no fixes) carry the neighbours' packets in ``extra``:

| key        | shape        | meaning                                                               |
|------------|--------------|-----------------------------------------------------------------------|
| ``measured`` | (B, N, J) bool | neighbour j of uav_i is in its RSA at k: it measured and sends     |
| ``rss``    | (B, N, J)    | RSS of the target at j (dBm) (with ``"rss"`` in ``sensors``)           |
| ``aoa``    | (B, N, J)    | AOA of the target seen from j (rad, 0 = east) (with ``"aoa"``)         |
| ``nav``    | (B, N, J, 2) | j's own navigation estimate of its position (m)                       |
| ``mode``   | (B, N, J) int8 | 1 = the link is NLOS at k (with ``report_mode``)                    |

``NlosOrbitWorld.neighbour_distances`` gives the true target-neighbour distances (B, N, J)
at k: link state for the network (the radios sense it), never an estimator input.

Arguments (``coloc_env.worlds.NlosOrbit``; defaults = ``nlos_horizon``'s, docs/gao2016.md §9)

| field               | default                      | allowed                                          |
|---------------------|------------------------------|--------------------------------------------------|
| num_agents          | 4                            | 1..64 targets                                    |
| num_neighbours      | 8                            | 1..32, J                                         |
| horizon             | 1000                         | 1..100000 steps (the composition's default)      |
| period              | 1.0                          | [1e-3, 1e4] s, T                                 |
| accel_sigma         | 0.3                          | [1e-6, 1000] m/s^2: sigma_a of the model the backends assume |
| speed               | 20.0                         | [0, 1e4] m/s                                     |
| turn_rates_deg      | (3, -3, 3, -6)               | deg/s per turn, entries in [-1e4, 1e4]           |
| turn_windows        | (200,260) (500,560) (700,730) (850,880) | one [start, end) per turn: integer    |
|                     |                              | steps, 0 <= start < end <= 1e7                   |
| target_spacing      | 3000.0                       | [0, 1e7] m                                       |
| schedule_shift      | 40                           | 0..100000 steps                                  |
| orbit_radius        | (150, 900)                   | (low, high), entries in [0, 1e7], low <= high, m |
| orbit_wobble        | 200.0                        | [0, 1e6] m                                       |
| orbit_wobble_rate   | (0.002, 0.01)                | (low, high), entries in [0, 10], low <= high, rad/s |
| orbit_bearing_rate  | 0.01                         | [0, 10] rad/s                                    |
| r_inf, r_sup        | 30, 1000                     | 0 < r_inf < r_sup <= 1e9 m (RSA)                 |
| sigma_nav           | 2.0                          | (0, 1e4] m per axis                              |
| tx_power_dbm        | 20.0                         | [-200, 200] dBm                                  |
| frequency_hz        | 2.4e9                        | [1, 1e13] Hz                                     |
| d0                  | 1.0                          | [1e-3, 1e6] m                                    |
| path_loss_exponent  | 2.2                          | [0.5, 10] (smaller: the RSS-inverted range       |
|                     |                              | overflows)                                       |
| sigma_db            | 2.0                          | (0, 100] dB, LOS                                 |
| sigma_theta_deg     | 0.1                          | [1e-6, 180] deg, LOS                             |
| nlos_bias_db        | 6.0                          | [-100, 100] dB                                   |
| nlos_sigma_db       | 4.0                          | [0, 100] dB                                      |
| nlos_bias_deg       | 1.0                          | [-180, 180] deg                                  |
| nlos_sigma_deg      | 1.0                          | [0, 180] deg                                     |
| p_nlos              | 0.3                          | [0, 1], pi                                       |
| p10                 | 0.1                          | [0, 1], pi p10 <= 1 - pi                         |
| prior_std           | (50, 50, 5, 5)               | (4,) entries in (0, 1e6]                         |
| sensors             | ("rss", "aoa")               | a non-empty subset of ("rss", "aoa")             |
| report_mode         | True                         | the LOS/NLOS flag travels with each packet (mode_info "known") |

Estimation problem (what ``coloc_env.pcrb`` bounds; details in ``coloc_env.bounds.models.nlos_orbit``):
each target's [p; v] alone; the prior is ``prior_std``; the motion is the filters' white-acceleration
model (the truth's turn schedule is smoother than that model); the readings are the RSS/AOA of every
neighbour inside the receive-search area with the LOS/NLOS mode known (a genie bound: an estimator that
infers the mode can only do worse), the neighbours' navigation error eliminated as a Gaussian nuisance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import ORBIT_LIMITS, as_array, check_entries, check_step_windows
from coloc_env.parts import WORLDS, PartConfig, check_flag, check_range
from coloc_env.worlds.base import Readings, World
from coloc_env.worlds.blocks.flight import OrbitingNeighbours, OrbitParameters, TurnSchedulePath
from coloc_env.worlds.blocks.los_nlos import LosNlosChain
from coloc_env.worlds.blocks.radio import ReceiveSearchArea, RssAoaSensor
from estimators.afge import SignalModel
from estimators.nlos_models import ConstantVelocityWhiteAccel, RssAoaModel

SENSORS = ("rss", "aoa")
ORBIT_FIELDS = ("radius", "wobble", "wobble_rate", "phase", "bearing_rate")


@WORLDS.register
@dataclass(frozen=True)
class NlosOrbit(PartConfig):
    """Config of the ``nlos_orbit`` world (see the module table)."""

    name = "nlos_orbit"
    bound_model = "nlos_orbit"  # coloc_env.bounds.models.nlos_orbit
    estimand = "self"
    motion_kind = ConstantVelocityWhiteAccel.kind
    anchors = "orbiting neighbours with navigation estimates (J world nodes per agent, not agents)"
    num_agents: int = 4
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
    prior_std: tuple = (50.0, 50.0, 5.0, 5.0)
    sensors: tuple = SENSORS
    report_mode: bool = True

    @property
    def measurements(self) -> frozenset:
        return frozenset(self.sensors) | (frozenset({"los_nlos"}) if self.report_mode else frozenset())

    # --- the generative model's pieces ---------------------------------------------------------------
    @property
    def path(self) -> TurnSchedulePath:
        """Every target's flight (uav_i's shifted by i * schedule_shift steps, ``target_paths``)."""
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
    def signal(self) -> SignalModel:
        """The RSS/AOA model of the packets (what the sensors draw and the backends assume); angles in rad."""
        return SignalModel(
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
    def motion_model(self) -> ConstantVelocityWhiteAccel:
        """The white-acceleration model the backends assume (variance accel_sigma^2)."""
        return ConstantVelocityWhiteAccel(float(self.period), float(self.accel_sigma) ** 2)

    @property
    def prior_cov(self) -> np.ndarray:
        return np.diag(np.asarray(self.prior_std, float) ** 2)

    def check(self, prefix: str) -> None:
        p = prefix
        check_range(f"{p}num_agents", self.num_agents, 1, 64, integer=True)
        check_range(f"{p}num_neighbours", self.num_neighbours, 1, 32, integer=True)
        check_range(f"{p}horizon", self.horizon, 1, 100_000, integer=True)
        check_range(f"{p}period", self.period, 1e-3, 1e4)
        check_range(f"{p}accel_sigma", self.accel_sigma, 1e-6, 1e3)
        check_range(f"{p}speed", self.speed, 0.0, 1e4)
        rates = as_array(f"{p}turn_rates_deg", self.turn_rates_deg, ndim=1, bound=1e4)
        windows = as_array(f"{p}turn_windows", self.turn_windows)
        if windows.shape != (len(rates), 2):
            raise ValueError(f"{p}turn_windows must have shape ({len(rates)}, 2), one [start, end) per entry of "
                             f"{p}turn_rates_deg (a rate per turn), "
                             f"got {windows.shape}")
        check_step_windows(f"{p}turn_windows", self.turn_windows, windows)
        check_range(f"{p}target_spacing", self.target_spacing, 0.0, 1e7)
        check_range(f"{p}schedule_shift", self.schedule_shift, 0, 100_000, integer=True)
        for name in ("orbit_radius", "orbit_wobble_rate"):
            pair = as_array(f"{p}{name}", getattr(self, name), shape=(2,))
            check_entries(f"{p}{name}", pair, 0.0, ORBIT_LIMITS[name])
            if pair[1] < pair[0]:
                raise ValueError(f"{p}{name} must be (low, high) with 0 <= low <= high, got {getattr(self, name)}")
        check_range(f"{p}orbit_wobble", self.orbit_wobble, 0.0, 1e6)
        check_range(f"{p}orbit_bearing_rate", self.orbit_bearing_rate, 0.0, 10.0)
        self.area.validate(f"{p}r_inf", f"{p}r_sup")
        check_range(f"{p}sigma_nav", self.sigma_nav, 0.0, 1e4, low_open=True)
        check_range(f"{p}tx_power_dbm", self.tx_power_dbm, -200.0, 200.0)
        check_range(f"{p}frequency_hz", self.frequency_hz, 1.0, 1e13)
        check_range(f"{p}d0", self.d0, 1e-3, 1e6)
        check_range(f"{p}path_loss_exponent", self.path_loss_exponent, 0.5, 10.0)
        check_range(f"{p}sigma_db", self.sigma_db, 0.0, 100.0, low_open=True)
        check_range(f"{p}sigma_theta_deg", self.sigma_theta_deg, 1e-6, 180.0)
        check_range(f"{p}nlos_bias_db", self.nlos_bias_db, -100.0, 100.0)
        check_range(f"{p}nlos_sigma_db", self.nlos_sigma_db, 0.0, 100.0)
        check_range(f"{p}nlos_bias_deg", self.nlos_bias_deg, -180.0, 180.0)
        check_range(f"{p}nlos_sigma_deg", self.nlos_sigma_deg, 0.0, 180.0)
        self.chain.validate(f"{p}p_nlos", f"{p}p10")
        check_entries(f"{p}prior_std", as_array(f"{p}prior_std", self.prior_std, shape=(4,)), 0.0, 1e6, low_open=True)
        sensors = tuple(self.sensors) if isinstance(self.sensors, (tuple, list)) else None
        if not sensors or any(s not in SENSORS for s in sensors) or len(set(sensors)) != len(sensors):
            raise ValueError(f"{p}sensors must be a non-empty subset of {SENSORS} without repeats, "
                             f"got {self.sensors!r}")
        check_flag(f"{p}report_mode", self.report_mode)

    def build(self, batch: int, horizon: int) -> NlosOrbitWorld:
        return NlosOrbitWorld(self, batch, horizon)


@dataclass
class Episode:
    """One copy's whole episode, stamps 0..K, targets T, neighbours J (``draw_episode``).

    ``truth`` (K+1, T, 4); ``rss``/``aoa`` (K+1, T, J); ``nav`` (K+1, T, J, 2) the neighbours' own position
    estimates; ``modes`` (K+1, T, J) int8 (1 = NLOS); ``distance`` (K+1, T, J) the true target-neighbour
    distances; ``in_rsa`` (K+1, T, J) the neighbour is in the target's receive-search area (it measures and
    sends); ``packet_uniforms`` (K+1, T, J) one U(0, 1) per packet, unused by the world; ``prior`` (T, 4) the
    prior mean; ``orbits`` (T, J) the neighbours' orbit parameters.
    """

    truth: np.ndarray
    rss: np.ndarray
    aoa: np.ndarray
    nav: np.ndarray
    modes: np.ndarray
    distance: np.ndarray
    in_rsa: np.ndarray
    packet_uniforms: np.ndarray
    prior: np.ndarray
    orbits: OrbitParameters


def target_paths(config: NlosOrbit, steps: int) -> np.ndarray:
    """True states (steps, T, 4) of the T = ``num_agents`` targets: uav_i starts at (0, i * target_spacing)
    and turns i * schedule_shift steps later. Deterministic: it draws nothing."""
    path = config.path
    return np.stack([path.trajectory(steps, start=(0.0, i * float(config.target_spacing)),
                                     shift=i * int(config.schedule_shift)) for i in range(config.num_agents)], axis=1)


def in_turn(config: NlosOrbit, steps: int) -> np.ndarray:
    """(steps, T) True where target i is turning."""
    path = config.path
    return np.stack([path.in_turn(steps, i * int(config.schedule_shift)) for i in range(config.num_agents)], axis=1)


def draw_episode(config: NlosOrbit, rng: np.random.Generator, horizon: int | None = None,
                 truth: np.ndarray | None = None) -> Episode:
    """One copy's episode of ``horizon`` steps (default ``config.horizon``) drawn from ``rng`` in the order of
    the module docstring. ``truth``: the targets' paths if the caller has them (``target_paths`` of the same
    config and horizon + 1 steps; a batch's reset computes them once)."""
    K1 = (config.horizon if horizon is None else int(horizon)) + 1
    T, J = config.num_agents, config.num_neighbours
    truth = target_paths(config, K1) if truth is None else truth
    orbits = config.neighbours.sample(rng, (T,))
    senders = truth[:, :, None, :2] + config.neighbours.offsets(orbits, K1)  # (K+1, T, J, 2)
    modes = config.chain.sample(rng, K1, (T, J))
    white = rng.standard_normal((K1, T, J, 2))
    rss, aoa = RssAoaSensor(config.signal).measure(truth[:, :, None, :2], senders, modes, white)
    nav = senders + config.sigma_nav * rng.standard_normal((K1, T, J, 2))
    distance = np.linalg.norm(truth[:, :, None, :2] - senders, axis=-1)
    packet_uniforms = rng.random((K1, T, J))
    prior = truth[0] + rng.standard_normal((T, 4)) * np.asarray(config.prior_std, float)
    return Episode(truth, rss, aoa, nav, modes, distance, config.area.contains(distance), packet_uniforms, prior,
                   orbits)


class NlosOrbitWorld(World):
    """B copies of the episode (the ``Episode`` fields with a leading batch axis): ``truth`` (B, K+1, N, 4)
    [p_x, p_y, v_x, v_y] of the targets at stamps 0..K; ``positions()`` is stamp k's positions."""

    agent_prefix = "uav"

    def __init__(self, config: NlosOrbit, batch: int, horizon: int):
        super().__init__(config, batch, horizon)
        c = config
        self.motion_model = c.motion_model
        self.signal = c.signal
        self.measurement_model = RssAoaModel(self.signal)
        self.chain = c.chain
        self.neighbours = c.neighbours
        B, K1, N, J = self.batch, self.horizon + 1, c.num_agents, c.num_neighbours
        self.num_neighbours = J
        self.truth = np.zeros((B, K1, N, 4))
        self.rss = np.zeros((B, K1, N, J))
        self.aoa = np.zeros((B, K1, N, J))
        self.nav = np.zeros((B, K1, N, J, 2))
        self.modes = np.zeros((B, K1, N, J), np.int8)
        self.in_rsa = np.zeros((B, K1, N, J), bool)
        self.distance = np.zeros((B, K1, N, J))
        self.prior = np.zeros((B, N, 4))
        self.orbits = OrbitParameters(*(np.zeros((B, N, J)) for _ in ORBIT_FIELDS))

    @property
    def dt(self) -> float:
        return float(self.config.period)

    @property
    def prior_cov(self) -> np.ndarray:
        return self.config.prior_cov

    def draw_episode(self, rngs, idx) -> None:
        """Each copy's episode by ``draw_episode`` from its own generator."""
        truth = target_paths(self.config, self.horizon + 1)  # the same for every copy: drawn from nothing
        for b, rng in zip(idx, rngs, strict=True):
            ep = draw_episode(self.config, rng, self.horizon, truth)
            self.truth[b], self.rss[b], self.aoa[b], self.nav[b] = ep.truth, ep.rss, ep.aoa, ep.nav
            self.modes[b], self.prior[b], self.in_rsa[b], self.distance[b] = ep.modes, ep.prior, ep.in_rsa, ep.distance
            for name in ORBIT_FIELDS:
                getattr(self.orbits, name)[b] = getattr(ep.orbits, name)

    def orbit_parameters(self, b: int, agent: int = 0) -> OrbitParameters:
        """The orbit parameters (J,) of copy ``b``'s target ``agent``'s neighbours."""
        return OrbitParameters(*(getattr(self.orbits, name)[b, agent] for name in ORBIT_FIELDS))

    def _slice(self, array: np.ndarray) -> np.ndarray:
        return array[np.arange(self.batch), np.minimum(self.k, self.horizon)]

    def positions(self) -> np.ndarray:
        return self._slice(self.truth)[..., :2]

    def neighbour_distances(self) -> np.ndarray:
        """True target-neighbour distances (B, N, J) at k (link state for the network)."""
        return self._slice(self.distance)

    def readings(self, sensing: np.ndarray) -> Readings:
        B, N = self.batch, self.num_agents
        extra = {"measured": self._slice(self.in_rsa), "nav": self._slice(self.nav)}
        if "rss" in self.config.sensors:
            extra["rss"] = self._slice(self.rss)
        if "aoa" in self.config.sensors:
            extra["aoa"] = self._slice(self.aoa)
        if self.config.report_mode:
            extra["mode"] = self._slice(self.modes)
        return Readings(inputs=np.zeros((B, N, 0)), range=np.full((B, N, N), np.nan),
                        range_valid=np.zeros((B, N, N), bool), fix=np.zeros((B, N, 2)),
                        fix_valid=np.zeros((B, N), bool), extra=extra)

    def initial_belief(self):
        B, N = self.batch, self.num_agents
        return self.prior.copy(), np.broadcast_to(self.prior_cov, (B, N, 4, 4)).copy()

    def extent(self) -> float:
        return float(np.abs(self.truth[..., :2]).max()) + float(self.config.r_sup)
