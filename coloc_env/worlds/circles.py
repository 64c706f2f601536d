"""World ``circles`` (wang2019): platforms on circles, odometry dead reckoning, ranges between platforms.

N platforms fly circles at constant speed and turn rate (wang2019 Sec. 4;
the layout of ``default_layout``, shared with the relay_ukf preset) and
measure their own speed and turn rate (odometry). At each step, with
probability ``measurement_probability``, one platform m (drawn uniformly)
measures its range to the platform its sensing choice names (none if it names
itself or a platform beyond ``sensing_range``). The first ``num_anchors``
platforms also get a position fix (GPS grade, ``fix_noise_std``) at every
step: the paper has none (its preset sets 0); the world's default of 3 of 6
gives least-squares and particle backends the anchors they need.

| quantity       | value                                                                            |
|----------------|----------------------------------------------------------------------------------|
| motion model   | ``estimators.models.OdometryDisplacement`` (state: position, 2)            |
| measurements   | ``range`` (one per step at most), ``position_fix`` (anchors)                     |
| anchors        | platforms 0..num_anchors-1 (fixes every step)                                    |
| sensing action | ``Discrete(N + 1)`` per agent: whom to range with if it measures (itself: none, N: nearest) |
| action mask    | a platform beyond ``sensing_range`` (no measurement, as itself); N where all are beyond it |
| observation    | 1 if this agent measures at this step                                            |

Arguments (``coloc_env.worlds.Circles``)

| field                   | default | allowed                                           |
|-------------------------|---------|---------------------------------------------------|
| num_agents              | 6       | 2..16 (also read as ``num_platforms``, wang2019's word) |
| centres                 | None    | (N, 2) metres, entries in [-1e6, 1e6]; None = ``default_layout`` |
| start_angles            | None    | (N,) rad, entries in [-1e6, 1e6]; None = 2 pi i / N |
| directions              | None    | (N,) of +1 (ccw) / -1 (cw); None = platform 1 cw  |
| speed                   | 1.0     | (0, 1e4] m/s                                      |
| turn_rate               | 0.015   | [1e-6, pi/dt] rad/s (smaller: a circle too large  |
|                         |         | to be finite)                                     |
| dt                      | 0.5     | [1e-6, 3600] s                                    |
| horizon                 | 800     | 1..1000000 steps (the composition's default)      |
| speed_noise_std         | 0.5     | [0, 1000] m/s                                     |
| turn_rate_noise_std     | 1e-3    | [0, 10] rad/s                                     |
| range_noise_var         | 1.0     | (0, 1e6] m^2                                      |
| measurement_probability | 0.5     | [0, 1]                                            |
| sensing_range           | inf     | (0, inf] m                                        |
| num_anchors             | 3       | 0..num_agents                                     |
| fix_noise_std           | 1.0     | (0, 1e4] m                                        |
| initial_position_std    | 0.1     | [1e-6, 1e6] m: the prior the agents start with    |
| heading_noise           | True    | False: the model the backends assume omits the integrated-heading term of Q |

Estimation problem (what ``coloc_env.pcrb`` bounds; details in ``coloc_env.bounds.models.circles``): the
state is every platform's (x, y, heading); the prior is exact (the filters start at the true pose); the
motion is driven by the odometry readings, their speed and turn-rate noise entering as process noise, so
the heading error is a random walk shared by every later step; the readings are the ranges each step's
measuring platform took and the anchors' fixes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import as_array, check_distance, check_entries
from coloc_env.parts import WORLDS, Block, PartConfig, check_flag, check_range
from coloc_env.worlds.base import Readings, World
from coloc_env.worlds.blocks.odometry import OdometrySensor, RangeSensor
from coloc_env.worlds.blocks.unicycle import CircularTracks, UnicycleMotion
from estimators.models import OdometryDisplacement


def default_layout(num_platforms: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centres (N, 2), start angles (N,), directions (N,): wang2019's four circles for N = 4, a ring otherwise."""
    i = np.arange(num_platforms)
    theta = -0.75 * np.pi + 2 * np.pi * i / num_platforms
    centres = np.round(8.0 * np.sqrt(2.0) * np.stack([np.cos(theta), np.sin(theta)], axis=-1), 12)
    return centres, 2 * np.pi * i / num_platforms, np.where(i == 1, -1.0, 1.0)


@WORLDS.register
@dataclass(frozen=True)
class Circles(PartConfig):
    """Config of the ``circles`` world (see the module table)."""

    name = "circles"
    bound_model = "circles"  # coloc_env.bounds.models.circles
    aliases = {"num_platforms": "num_agents"}  # wang2019 calls the agents platforms
    estimand = "self"
    motion_kind = OdometryDisplacement.kind
    measurements = frozenset({"range", "position_fix"})
    anchors = "platforms 0..num_anchors-1 (a position fix every step)"
    num_agents: int = 6
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
    num_anchors: int = 3
    fix_noise_std: float = 1.0
    initial_position_std: float = 0.1
    heading_noise: bool = True

    def check(self, prefix: str) -> None:
        check_range(f"{prefix}num_agents", self.num_agents, 2, 16, integer=True)
        check_range(f"{prefix}dt", self.dt, 1e-6, 3600.0)
        check_range(f"{prefix}speed", self.speed, 0.0, 1e4, low_open=True)
        check_range(f"{prefix}turn_rate", self.turn_rate, 1e-6, np.pi / self.dt, high_label=f"pi/{prefix}dt")
        N = self.num_agents
        for name in ("centres", "start_angles", "directions"):
            value = getattr(self, name)
            if value is not None:
                arr = as_array(f"{prefix}{name}", value, shape=(N, 2) if name == "centres" else (N,))
                check_entries(f"{prefix}{name}", arr, -1e6, 1e6)
        self.tracks.validate(prefix)
        check_range(f"{prefix}horizon", self.horizon, 1, 1_000_000, integer=True)
        self.odometry.validate(prefix)
        check_range(f"{prefix}range_noise_var", self.range_noise_var, 0.0, 1e6, low_open=True)
        check_range(f"{prefix}measurement_probability", self.measurement_probability, 0.0, 1.0)
        check_distance(f"{prefix}sensing_range", self.sensing_range)
        check_range(f"{prefix}num_anchors", self.num_anchors, 0, self.num_agents, integer=True,
                    high_label=f"{prefix}num_agents")
        check_range(f"{prefix}fix_noise_std", self.fix_noise_std, 0.0, 1e4, low_open=True)
        check_range(f"{prefix}initial_position_std", self.initial_position_std, 1e-6, 1e6)
        check_flag(f"{prefix}heading_noise", self.heading_noise)

    @property
    def tracks(self) -> CircularTracks:
        """The circles flown: the given layout, ``default_layout`` where a field is None."""
        centres, angles, directions = default_layout(self.num_agents)
        return CircularTracks(
            centres=centres if self.centres is None else np.asarray(self.centres, float),
            start_angles=angles if self.start_angles is None else np.asarray(self.start_angles, float),
            directions=directions if self.directions is None else np.asarray(self.directions, float),
            speed=self.speed, turn_rate=self.turn_rate, dt=self.dt)

    @property
    def odometry(self) -> OdometrySensor:
        """The speed and turn-rate readings' noise."""
        return OdometrySensor(self.speed_noise_std, self.turn_rate_noise_std)

    @property
    def range_sensor(self) -> RangeSensor:
        return RangeSensor(self.range_noise_var, self.sensing_range)

    def build(self, batch: int, horizon: int) -> CirclesWorld:
        return CirclesWorld(self, batch, horizon)


class CirclesWorld(World):
    """``truth`` (K+1, N, 2): the platforms' true positions at steps 0..K, the same for every copy (the
    tracks draw nothing; the copies differ in their odometry, schedule and range noise)."""

    agent_prefix = "platform"

    def __init__(self, config: Circles, batch: int, horizon: int):
        super().__init__(config, batch, horizon)
        N, K, B = config.num_agents, self.horizon, self.batch
        self.tracks = config.tracks
        self.truth, self.true_heading, self._speed, self._turn_rate = self.tracks.trajectory(K)
        # C order: np.take(truth, k, axis=0) of the strided trajectory copied the whole table on every call
        self.truth = np.ascontiguousarray(self.truth)
        # every copy flies the same tracks: the distances between the platforms at each step, once
        # (sqrt of the summed squared differences, the same floats as ||p_i - p_j|| at each step)
        self.distance_table = np.sqrt(np.sum((self.truth[:, :, None, :] - self.truth[:, None, :, :]) ** 2, axis=-1))
        self.odometry, self.range_sensor = config.odometry, config.range_sensor
        self.motion_model = OdometryDisplacement(config.dt, config.speed_noise_std**2)
        self.measured_speed = np.zeros((B, K, N))
        self.measured_heading = np.zeros((B, K, N))
        self.schedule = np.full((B, K), -1)
        self.range_noise = np.zeros((B, K))
        self.fix_noise = np.zeros((B, K, config.num_anchors, 2))

    def sensing_blocks(self) -> list[Block]:
        N = self.num_agents
        return [Block("partner", 1, N + 1, f"whom to range with if this agent measures now: a platform, itself = "
                      f"no measurement, {N} = the nearest", default=N, maximum=N, minimum=N)]

    def sensing_masks(self, distances) -> list[np.ndarray]:
        """``partner``: a platform beyond ``sensing_range`` gives no measurement, as itself does (itself stays
        valid: the way to decline a measurement); N (the nearest) only where a platform is within it."""
        N = self.num_agents
        others = ~np.eye(N, dtype=bool)
        reach = (distances() <= self.range_sensor.max_range) & others
        mask = np.empty((self.batch, N, 1, N + 1), dtype=bool)
        mask[:, :, 0, :N] = reach | ~others
        mask[:, :, 0, N] = reach.any(axis=-1)
        return [mask]

    def range_noise_var(self) -> float:
        return self.config.range_noise_var

    def fix_noise_var(self) -> float:
        return self.config.fix_noise_std**2

    def draw_episode(self, rngs, idx) -> None:
        N, K, A = self.num_agents, self.horizon, self.config.num_anchors
        speed_noise = np.empty((len(idx), K, N))
        turn_noise = np.empty((len(idx), K, N))
        for c, rng in enumerate(rngs):
            speed_noise[c], turn_noise[c] = self.odometry.sample_noise(rng, (K, N))
            occurs = rng.random(K)
            who = rng.integers(0, N, size=K)
            self.schedule[idx[c]] = np.where(occurs < self.config.measurement_probability, who, -1)
            self.range_noise[idx[c]] = self.range_sensor.sample_noise(rng, (K,))
            self.fix_noise[idx[c]] = self.config.fix_noise_std * rng.standard_normal((K, A, 2))
        speed, turn = self.odometry.measure(self._speed, self._turn_rate, speed_noise, turn_noise)
        self.measured_speed[idx] = speed
        heading = UnicycleMotion(self.config.dt).headings(self.true_heading[0][None, :], np.swapaxes(turn, 1, 2))
        self.measured_heading[idx] = np.swapaxes(heading, 1, 2)

    def positions(self) -> np.ndarray:
        return self.truth[self.k]

    def distances(self) -> np.ndarray:
        """True distances between the platforms at k (B, N, N), from ``distance_table``."""
        return self.distance_table[self.k]

    def turn_rate_noise_var(self) -> float:
        """sigma_omega^2 (rad^2/s^2) of the turn-rate readings as the backends assume it: 0 with
        ``heading_noise=False`` (the model that omits the integrated heading's error)."""
        return self.config.turn_rate_noise_std**2 if self.config.heading_noise else 0.0

    def initial_belief(self):
        B, N = self.batch, self.num_agents
        mean = np.broadcast_to(self.truth[0], (B, N, 2)).copy()
        cov = np.broadcast_to(self.config.initial_position_std**2 * np.eye(2), (B, N, 2, 2)).copy()
        return mean, cov

    def heading_variance(self, k: np.ndarray) -> np.ndarray:
        if not self.config.heading_noise:
            return np.zeros(np.shape(k))
        return self.odometry.heading_variance(k, self.config.dt)

    def measuring(self) -> np.ndarray:
        """The measuring platform at k (B,), -1 for none (and after the horizon)."""
        k = np.minimum(self.k, self.horizon - 1)
        who = self.schedule[np.arange(self.batch), k]
        return np.where(self.k < self.horizon, who, -1)

    def readings(self, sensing: np.ndarray) -> Readings:
        B, N = self.batch, self.num_agents
        rows, k = np.arange(B), self.k
        measuring = self.schedule[rows, k]
        source = np.maximum(measuring, 0)
        partner = sensing[rows, source, 0].astype(int)
        # the source's distances from the table: the floats RangeSensor.true_range gives for (p_source, p_j)
        distance = self.distance_table[k, source]
        distance[rows, source] = np.inf
        partner = np.where(partner == N, np.argmin(distance, axis=-1), partner)
        true_range = self.distance_table[k, source, partner]
        attempt = (measuring >= 0) & (partner != source) & (true_range <= self.range_sensor.max_range)
        valid = np.zeros((B, N, N), dtype=bool)
        valid[rows[attempt], source[attempt], partner[attempt]] = True
        ranges = np.full((B, N, N), np.nan)  # RangeSensor.measure: the true range plus the drawn noise
        ranges[rows, source, partner] = np.where(attempt, true_range + self.range_noise[rows, k], np.nan)
        fix = np.zeros((B, N, 2))
        A = self.config.num_anchors
        if A:
            fix[:, :A] = self.positions()[:, :A] + self.fix_noise[rows, k]
        fix_valid = np.zeros((B, N), dtype=bool)
        fix_valid[:, :A] = True
        inputs = np.stack([self.measured_speed[rows, k], self.measured_heading[rows, k],
                           np.broadcast_to(self.heading_variance(k)[:, None], (B, N))], axis=-1)
        return Readings(inputs=inputs, range=ranges, range_valid=valid, fix=fix, fix_valid=fix_valid)

    def observation_features(self) -> np.ndarray:
        ids = np.arange(self.num_agents)[None, :]
        return (ids == self.measuring()[:, None]).astype(float)[..., None]

    def feature_bounds(self):
        return np.zeros(1), np.ones(1)

    def region(self):
        # the tracks are the mission plan, known in advance: the square around them, with 10 m to spare
        square = (float(self.truth.min()) - 10.0, float(self.truth.max()) + 10.0)
        return square, square

    def extent(self) -> float:
        return float(np.abs(self.truth).max()) + 10.0
