"""World ``nlos_orbit`` (gao2016): target UAVs, each localizing itself from J orbiting neighbours' RSS/AOA.

The world of the ``nlos_horizon`` scenario, drawn the same way: each copy's episode is
``coloc_env.scenarios.nlos_horizon.draw_episode`` on the world's generator (orbits,
LOS/NLOS modes, RSS/AOA noise, navigation noise, the scenario's delay uniforms, prior, in
that order), so for the same generator the truth, the readings and the prior are the
scenario's bit for bit. The delays that call draws are **not used**: delivery is the
network's (``random_delay`` is gao2016's Assumption 3); they are drawn only to keep the
stream, and so the prior, identical to the scenario's.

Every agent ``uav_i`` is a target that cannot localize itself directly: it flies straight
legs and coordinated turns (``coloc_env.primitives.flight.TurnSchedulePath``; uav_i starts
at (0, i * target_spacing), its turns i * schedule_shift steps later). J neighbours orbit
each target (``coloc_env.primitives.flight.OrbitingNeighbours``); they are part of the world,
not agents. A neighbour inside the target's receive-search area (Def. 1, r_inf <= d <=
r_sup on the true distance) measures the RSS and the AOA of the target (spec §4,
``coloc_env.primitives.radio.RssAoaSensor``), the bias of its link's LOS/NLOS Markov chain
(``coloc_env.primitives.los_nlos.LosNlosChain``) included, and sends a packet stamped k
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
| initial belief | mean truth(0) + N(0, diag(prior_std^2)) (the scenario's prior), cov diag(prior_std^2) |

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

Arguments (``coloc_env.worlds.NlosOrbit``; defaults = ``nlos_horizon``'s, spec §9)

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

Estimation problem (what ``coloc_env.pcrb`` bounds; details in ``coloc_env.bound_models.nlos_orbit``):
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
from coloc_env.primitives.flight import OrbitParameters
from coloc_env.primitives.los_nlos import LosNlosChain
from coloc_env.primitives.radio import ReceiveSearchArea
from coloc_env.primitives.random_delay import NEVER
from coloc_env.scenarios.nlos_horizon import NlosHorizonConfig, draw_episode_parts, target_paths
from coloc_env.worlds.base import Readings, World
from estimators.afge import SignalModel
from estimators.nlos_models import ConstantVelocityWhiteAccel, RssAoaModel

SENSORS = ("rss", "aoa")
SCENARIO_FIELDS = ("num_neighbours", "period", "accel_sigma", "speed", "turn_rates_deg", "turn_windows",
                    "target_spacing", "schedule_shift", "orbit_radius", "orbit_wobble", "orbit_wobble_rate",
                    "orbit_bearing_rate", "r_inf", "r_sup", "sigma_nav", "tx_power_dbm", "frequency_hz", "d0",
                    "path_loss_exponent", "sigma_db", "sigma_theta_deg", "nlos_bias_db", "nlos_sigma_db",
                    "nlos_bias_deg", "nlos_sigma_deg", "p_nlos", "p10", "prior_std")


@WORLDS.register
@dataclass(frozen=True)
class NlosOrbit(PartConfig):
    """Config of the ``nlos_orbit`` world (see the module table)."""

    name = "nlos_orbit"
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

    def scenario_config(self, horizon: int | None = None) -> NlosHorizonConfig:
        """The ``nlos_horizon`` config whose episode draw this world uses (its estimator fields at their defaults)."""
        fields = {f: getattr(self, f) for f in SCENARIO_FIELDS}
        return NlosHorizonConfig(num_uavs=self.num_agents, horizon=self.horizon if horizon is None else horizon,
                                 **fields)

    @property
    def signal(self) -> SignalModel:
        """The RSS/AOA model of the packets (what the sensors draw and the backends assume)."""
        return self.scenario_config().signal

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
        ReceiveSearchArea(self.r_inf, self.r_sup).validate(f"{p}r_inf", f"{p}r_sup")
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
        LosNlosChain(self.p_nlos, self.p10).validate(f"{p}p_nlos", f"{p}p10")
        check_entries(f"{p}prior_std", as_array(f"{p}prior_std", self.prior_std, shape=(4,)), 0.0, 1e6, low_open=True)
        sensors = tuple(self.sensors) if isinstance(self.sensors, (tuple, list)) else None
        if not sensors or any(s not in SENSORS for s in sensors) or len(set(sensors)) != len(sensors):
            raise ValueError(f"{p}sensors must be a non-empty subset of {SENSORS} without repeats, "
                             f"got {self.sensors!r}")
        check_flag(f"{p}report_mode", self.report_mode)

    def build(self, batch: int, horizon: int) -> NlosOrbitWorld:
        return NlosOrbitWorld(self, batch, horizon)


class NlosOrbitWorld(World):
    agent_prefix = "uav"

    def __init__(self, config: NlosOrbit, batch: int, horizon: int):
        super().__init__(config, batch, horizon)
        c = config
        self.scenario_config = c.scenario_config(self.horizon)
        self.motion_model = ConstantVelocityWhiteAccel(float(c.period), float(c.accel_sigma) ** 2)
        self.signal = self.scenario_config.signal
        self.measurement_model = RssAoaModel(self.signal)
        self.chain = self.scenario_config.chain
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
        self.orbits = OrbitParameters(*(np.zeros((B, N, J)) for _ in range(5)))

    @property
    def dt(self) -> float:
        return float(self.config.period)

    @property
    def prior_cov(self) -> np.ndarray:
        return self.scenario_config.prior_cov

    def draw_episode(self, rngs, idx) -> None:
        """Each copy's episode by ``coloc_env.scenarios.nlos_horizon.draw_episode`` (its delays unused)."""
        sc = self.scenario_config
        truth = target_paths(sc, sc.num_uavs, sc.horizon + 1)  # every copy's: drawn from nothing
        for b, rng in zip(idx, rngs, strict=True):
            ep, distance = draw_episode_parts(sc, rng, truth=truth)
            self.truth[b], self.rss[b], self.aoa[b], self.nav[b] = ep.truth, ep.rss, ep.aoa, ep.nav
            self.modes[b], self.prior[b] = ep.modes, ep.prior
            self.in_rsa[b] = ep.delays != NEVER  # draw_episode marks the neighbours outside the RSA with NEVER
            self.distance[b] = distance
            for name in ("radius", "wobble", "wobble_rate", "phase", "bearing_rate"):
                getattr(self.orbits, name)[b] = getattr(ep.orbits, name)

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
