"""World ``gps_denied`` (wan2014): constant-velocity UAVs, Markov GPS faults, ranges between UAVs in range.

N UAVs start uniformly in ``[0, side]^2`` at the nominal velocity plus a
spread and fly the constant-velocity model driven by a random acceleration
(``coloc_env.worlds.blocks.cv_uav.ConstantVelocityUAVs``); each reads a noisy
accelerometer. Each GPS receiver switches between normal and fault by a
Markov chain (``coloc_env.worlds.blocks.gps_markov.MarkovGPS``); a normal one
reports a fix. UAVs within ``comm_range`` measure their distance, one reading
per unordered pair seen by both ends
(``coloc_env.worlds.blocks.range_network.RangeNetwork``). The agents start from
a warm start: the last fix before the loss, p~_0 = p_0 + N(0, gps_std^2 I),
and a noisy velocity, v~_0 = v_0 + N(0, velocity_spread^2 I).

``sample_episode`` draws one copy's whole episode from the copy's generator at
reset, in blocks and in this order: start positions, start velocities, the GPS
states (Markov chain, or ``num_normal`` fixed normal UAVs), the true
accelerations and accelerometer readings, the GPS noise, the range noise,
p~_0, v~_0. The truth, fixes and ranges are computed from these draws.

Swarm size. With ``density`` None the start square has side ``area`` whatever
N is (wan2014's setting): doubling N doubles every UAV's neighbours within
``comm_range`` and quadruples the range readings (about 0.58 N^2 / 2 pairs at
the defaults). With ``density`` (UAVs per km^2) the side is
sqrt(N / density) km: the square grows with sqrt(N), every UAV keeps about
the same number of neighbours, and the readings grow like N (``density=40``
is the default square at N = 10).

| quantity       | value                                                                              |
|----------------|------------------------------------------------------------------------------------|
| motion model   | ``estimators.cv_models.ConstantVelocityAccel`` (state [p; v], 4; input: accelerometer, 2) |
| measurements   | ``range`` (symmetric, every pair within ``comm_range``), ``position_fix`` (GPS-normal UAVs) |
| anchors        | the GPS-normal UAVs of each step (a fix, sigma ``gps_std``)                         |
| sensing action | none                                                                               |
| observation    | 1 if my GPS is normal at this step                                                 |
| initial belief | mean [p~_0; v~_0] (the warm start), covariance diag(gps_std^2 I2, velocity_spread^2 I2) |

Arguments (``coloc_env.worlds.GpsDenied``; defaults = ``gps_denied_nbp``'s)

| field              | default   | allowed                                      |
|--------------------|-----------|----------------------------------------------|
| num_agents         | 10        | 2..128                                       |
| horizon            | 30        | 1..10000 steps (the composition's default)   |
| dt                 | 1.0       | (0, 1000] s                                  |
| area               | 500       | (0, 1e7] m: the side of the start square     |
| density            | None      | None (side ``area``) or [1e-3, 1e6] UAVs/km^2 (side sqrt(N / density) km) |
| nominal_velocity   | (20, 0)   | (2,) m/s, entries in [-1e4, 1e4]             |
| velocity_spread    | 2.0       | [0, 1e4] m/s                                 |
| accel_std          | 0.5       | [0, 1000] m/s^2 true acceleration            |
| accel_noise_std    | 0.3       | [0.001, 1000] m/s^2 accelerometer noise    |
| gps_std            | 3.0       | [0.001, 1e4] m                               |
| range_std          | 2.0       | [0.001, 1e4] m                               |
| comm_range         | 300       | (0, 1e7] m: the ranging radius               |
| p_normal_to_fault  | 0.02      | [0, 1]                                       |
| p_fault_to_normal  | 0.02      | [0, 1]                                       |
| num_normal         | None      | None (Markov chain) or 0..N fixed normal UAVs |

Estimation problem (what ``coloc_env.pcrb`` bounds; details in ``coloc_env.bounds.models.gps_denied``):
the state is every UAV's [p; v]; the prior is the filters' initial belief; the motion takes the
accelerometer reading as its input, its noise as process noise; the readings are a GPS fix for each UAV
whose receiver is normal at the step and one range per pair within ``comm_range``. A UAV with a noisy fix
is not a known anchor.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from coloc_env.config import MIN_STD, as_array, check_entries
from coloc_env.parts import WORLDS, PartConfig, check_range
from coloc_env.worlds.base import Readings, World
from coloc_env.worlds.blocks.cv_uav import ConstantVelocityUAVs
from coloc_env.worlds.blocks.gps_markov import MarkovGPS
from coloc_env.worlds.blocks.range_network import RangeNetwork
from estimators.cv_models import ConstantVelocityAccel


@WORLDS.register
@dataclass(frozen=True)
class GpsDenied(PartConfig):
    """Config of the ``gps_denied`` world (see the module table)."""

    name = "gps_denied"
    bound_model = "gps_denied"  # coloc_env.bounds.models.gps_denied
    estimand = "self"
    motion_kind = ConstantVelocityAccel.kind
    measurements = frozenset({"range", "position_fix"})
    anchors = "GPS-normal UAVs (a fix at every step their receiver is normal)"
    num_agents: int = 10
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
    density: float | None = None

    @property
    def side(self) -> float:
        """The side of the start square in metres: ``area``, or sqrt(N / density) km at a fixed density."""
        if self.density is None:
            return float(self.area)
        return 1000.0 * float(np.sqrt(self.num_agents / self.density))

    @property
    def motion(self) -> ConstantVelocityUAVs:
        return ConstantVelocityUAVs(self.dt, self.accel_std, self.accel_noise_std)

    @property
    def gps(self) -> MarkovGPS:
        return MarkovGPS(self.p_normal_to_fault, self.p_fault_to_normal, self.gps_std)

    @property
    def ranging(self) -> RangeNetwork:
        return RangeNetwork(self.comm_range, self.range_std)

    def check(self, prefix: str) -> None:
        check_range(f"{prefix}num_agents", self.num_agents, 2, 128, integer=True)
        check_range(f"{prefix}horizon", self.horizon, 1, 10_000, integer=True)
        check_range(f"{prefix}dt", self.dt, 0.0, 1e3, low_open=True)
        check_range(f"{prefix}area", self.area, 0.0, 1e7, low_open=True)
        check_entries(f"{prefix}nominal_velocity", as_array(f"{prefix}nominal_velocity", self.nominal_velocity,
                                                             shape=(2,)), -1e4, 1e4)
        check_range(f"{prefix}velocity_spread", self.velocity_spread, 0.0, 1e4)
        check_range(f"{prefix}accel_std", self.accel_std, 0.0, 1e3)
        check_range(f"{prefix}accel_noise_std", self.accel_noise_std, MIN_STD, 1e3)
        check_range(f"{prefix}gps_std", self.gps_std, MIN_STD, 1e4)
        check_range(f"{prefix}range_std", self.range_std, MIN_STD, 1e4)
        check_range(f"{prefix}comm_range", self.comm_range, 0.0, 1e7, low_open=True)
        check_range(f"{prefix}p_normal_to_fault", self.p_normal_to_fault, 0.0, 1.0)
        check_range(f"{prefix}p_fault_to_normal", self.p_fault_to_normal, 0.0, 1.0)
        if self.density is not None:
            check_range(f"{prefix}density", self.density, 1e-3, 1e6)
        if self.num_normal is not None:
            check_range(f"{prefix}num_normal", self.num_normal, 0, self.num_agents, integer=True,
                        high_label=f"{prefix}num_agents")

    def build(self, batch: int, horizon: int) -> GpsDeniedWorld:
        return GpsDeniedWorld(self, batch, horizon)


@dataclass
class Episode:
    """One copy's whole episode (T steps, N UAVs): ``truth`` (T, N, 4) [p; v]; ``accel`` (T, N, 2) the
    accelerometer readings a_hat(k) (the input from k to k + 1); ``gps_normal`` (T, N); ``gps_fix`` (T, N, 2)
    (NaN where faulty); ``adjacency`` (T, N, N); ``ranges`` (T, N, N); ``init_position`` and
    ``init_velocity`` (N, 2): the warm start p~_0, v~_0."""

    truth: np.ndarray
    accel: np.ndarray
    gps_normal: np.ndarray
    gps_fix: np.ndarray
    adjacency: np.ndarray
    ranges: np.ndarray
    init_position: np.ndarray
    init_velocity: np.ndarray


def sample_episode(config: GpsDenied, rng: np.random.Generator, horizon: int | None = None) -> Episode:
    """One episode of ``horizon`` steps (default ``config.horizon``) drawn from ``rng`` in the blocks and order
    of the module docstring."""
    N, T = config.num_agents, config.horizon if horizon is None else horizon
    motion, gps, ranging = config.motion, config.gps, config.ranging
    position = config.side * rng.random((N, 2))
    velocity = np.asarray(config.nominal_velocity, float) + config.velocity_spread * rng.standard_normal((N, 2))
    if config.num_normal is None:
        normal = gps.sample_states(rng, T, N)
    else:
        normal = gps.fixed_states(rng, T, N, config.num_normal)
    true_accel, reading = motion.sample_accelerations(rng, (T, N))
    gps_noise = gps.sample_noise(rng, (T, N))
    range_noise = ranging.sample_noise(rng, (T,), N)
    init_position = position + config.gps_std * rng.standard_normal((N, 2))
    init_velocity = velocity + config.velocity_spread * rng.standard_normal((N, 2))
    truth = motion.trajectory(np.concatenate([position, velocity], axis=-1), true_accel[:-1])
    adjacency, ranges = ranging.measure(truth[..., :2], range_noise)
    fix = gps.measure(truth[..., :2], gps_noise, normal)
    return Episode(truth=truth, accel=reading, gps_normal=normal, gps_fix=fix, adjacency=adjacency, ranges=ranges,
                   init_position=init_position, init_velocity=init_velocity)


class GpsDeniedWorld(World):
    """B copies of the episode (the ``Episode`` fields with a leading batch axis): ``truth`` (B, T, N, 4)
    [p; v] at steps 0..T-1, T = horizon; ``positions()`` is time k's slice (the last one after the horizon)."""

    symmetric_ranges = True
    agent_prefix = "uav"

    def __init__(self, config: GpsDenied, batch: int, horizon: int):
        super().__init__(config, batch, horizon)
        B, T, N = self.batch, self.horizon, config.num_agents
        self.motion_model = ConstantVelocityAccel(config.dt, config.accel_noise_std**2)
        self.truth = np.zeros((B, T, N, 4))
        self.accel = np.zeros((B, T, N, 2))
        self.gps_normal = np.zeros((B, T, N), bool)
        self.gps_fix = np.zeros((B, T, N, 2))
        self.adjacency = np.zeros((B, T, N, N), bool)
        self.ranges = np.zeros((B, T, N, N))
        self.init_position = np.zeros((B, N, 2))
        self.init_velocity = np.zeros((B, N, 2))

    def range_noise_var(self) -> float:
        return self.config.range_std**2

    def fix_noise_var(self) -> float:
        return self.config.gps_std**2

    def draw_episode(self, rngs, idx) -> None:
        """Each copy's episode (``sample_episode``) from its own generator."""
        for b, rng in zip(idx, rngs, strict=True):
            episode = sample_episode(self.config, rng, self.horizon)
            for field in dataclasses.fields(Episode):
                getattr(self, field.name)[b] = getattr(episode, field.name)

    def _slice(self, array: np.ndarray) -> np.ndarray:
        """Time k's slice (B, ...) of an episode array; the last slice after the horizon."""
        return array[np.arange(self.batch), np.minimum(self.k, self.horizon - 1)]

    def positions(self) -> np.ndarray:
        return self._slice(self.truth)[..., :2]

    def readings(self, sensing: np.ndarray) -> Readings:
        valid = self._slice(self.adjacency)
        normal = self._slice(self.gps_normal)
        return Readings(inputs=self._slice(self.accel), range=np.where(valid, self._slice(self.ranges), np.nan),
                        range_valid=valid, fix=np.where(normal[..., None], np.nan_to_num(self._slice(self.gps_fix)),
                                                        0.0), fix_valid=normal)

    def initial_belief(self):
        B, N, c = self.batch, self.num_agents, self.config
        mean = np.concatenate([self.init_position, self.init_velocity], axis=-1)
        var = np.array([c.gps_std**2] * 2 + [c.velocity_spread**2] * 2)
        return mean, np.broadcast_to(np.diag(var), (B, N, 4, 4)).copy()

    def observation_features(self) -> np.ndarray:
        return self._slice(self.gps_normal).astype(float)[..., None]

    def feature_bounds(self):
        return np.zeros(1), np.ones(1)

    def region(self):
        c = self.config
        travel = float(np.linalg.norm(c.nominal_velocity)) * self.dt * self.horizon
        return (0.0, c.side), (0.0, c.side + travel)

    def extent(self) -> float:
        return float(np.abs(self.truth[..., :2]).max()) + 50.0
