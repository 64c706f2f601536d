"""World ``mrclam_slices``: the recorded UTIAS MRCLAM run in slices, mapped to dNBP's constant-velocity model.

Data: Leung K.Y.K., Halpern Y., Barfoot T.D., Liu H.H.T., "The UTIAS
multi-robot cooperative localization and mapping dataset", IJRR
30(8):969-974, 2011 (cite it with results on the data). The run is loaded
and its noise model fitted once per data path (``coloc_env.worlds.mrclam.replay_tables``),
on the loader's grid of ``GRID_DT`` = 0.1 s, then mapped once to a table of
slices (``slice_table``, cached); an episode replays ``horizon`` slices of that
table. Nothing is simulated; Vicon enters the readings only through the noise
calibration and the start pose of the robots' own navigation filters (step 0
of the run).

The robots that sighted a landmark in a slice play wan2014's GPS-normal UAVs
(a pseudo-fix), the others are "faulty" and have only robot-robot ranges.
The mapping (``build_slices``; N the robots, dt = ``GRID_DT`` the loader's grid,
L = ``slice_steps``):

* **Time slices.** Slice tau is data step k_tau = L tau (Delta t = L dt, 1 s at
  the defaults), so that robot-robot ranges accumulate in a slice (dataset 6: a
  robot takes part in a robot-robot range in ~1/3 of the 1-s slices).
  Measurements of steps [k_tau - floor(L/2), k_tau - floor(L/2) + L) are binned to
  slice tau. The truth of slice tau is the Vicon position at k_tau.
* **Heading.** The state (p, v) has no heading, so the heading that turns the
  odometry speed into a displacement and a landmark bearing into a direction
  comes from outside: each robot's OWN navigation filter, a UKF on (x, y, theta)
  (``coloc_env.data.mrclam_navigation.own_navigation``, started at the Vicon pose of step 0
  with std ``coloc_env.data.mrclam_navigation.OWN_NAV_INITIAL_STD``) driven by its corrected odometry and updated only
  with its own landmark sightings (chi-square(2) 99.9 % gate), no robot-robot
  measurement: the analogue of a UAV's GPS/INS heading. Dead-reckoned heading is
  useless here (dataset 6: off by 0.2-1.3 rad after 100 s).
* **Motion prior.** Between slices robot s moves by Delta p_tau = sum_k dt v'_k
  [cos theta_k, sin theta_k] over the L data steps (v' the calibrated,
  delay-corrected odometry speed, theta_k the own-nav heading). The readings
  carry it as the velocity reading Delta p_tau / Delta t (``extra["velocity"]``)
  with zero acceleration input, so a constant-velocity prediction moves by
  Delta p_tau + (Delta t^2 / 2) e, e ~ N(0, sigma_acc^2 I2), sigma_acc =
  2 sigma_Delta / Delta t^2, sigma_Delta^2 = sum_k dt^2 sigma_v,k^2 + |Delta p|^2
  sigma_theta^2 (calibrated speed variance, own-nav heading variance at the
  slice): the position random-walk std per slice. One sigma_acc per slice, the
  largest over the robots (``extra["accel_std"]``). The last slice of the run
  moves by what is left of the run.
* **Pseudo-fixes.** A robot whose own-nav gate accepted a landmark sighting in
  the slice is normal and gets p = l - r [cos(theta + b), sin(theta + b)] +
  (D(k_tau) - D(k)) per sighting at step k (l: the landmark's surveyed position,
  r, b: measured range and bearing, theta: own-nav heading at k, D: the
  displacement track above, which carries the fix from k to k_tau), with the
  isotropic sigma_fix^2 = max(sigma_r^2, r^2 (sigma_b^2 + sigma_theta^2)) +
  |sigma_landmark|^2 (``coloc_env.data.mrclam_navigation.fix_std``). Several sightings:
  their inverse-variance mean with the SMALLEST single sigma_fix (no 1/n
  reduction: they share the heading error). One sigma_gps per slice, the largest
  sigma_fix of its normal robots (``extra["gps_std"]``).
* **Ranges.** An edge is a robot pair with a robot-robot range (either
  direction) in the slice; d_st = the median of those ranges (robust to a
  misread), the same reading for both ends. Bearings of robot sightings are not
  used. sigma_d^2 = the calibrated range variance at d_st + the motion within
  the bin, (L / sqrt(12) dt (|v_s| + |v_t|))^2 (the std of a time offset uniform
  over the bin); one sigma_d per slice, the largest over its edges
  (``extra["range_std"]``).

Episodes: copy b replays slices s_b .. s_b + horizon - 1 of the table, slice
s_b + k at env step k (after the last one, the last). With ``start=None`` s_b
is drawn at reset from the copy's world generator, uniformly in [0, S -
horizon] (S = slices of the run), so the copies of a batch replay different
stretches and their per-slice sigmas differ; ``start=S0`` fixes it for every
copy and episode (then every copy replays the same data).

| quantity       | value                                                                                |
|----------------|--------------------------------------------------------------------------------------|
| motion model   | ``estimators.cv_models.ConstantVelocityAccel`` with Delta t = L dt; input: zero     |
|                | acceleration; its noise the median over the run's slices of sigma_acc^2 (per-slice   |
|                | value: ``extra["accel_std"]``)                                                       |
| measurements   | ``range`` (symmetric: one median per edge), ``position_fix`` (the pseudo-fixes)      |
| anchors        | the robots that sighted a landmark in the slice (a pseudo-fix)                       |
| truth          | Vicon (x, y) of the N robots at k_tau                                                |
| initial belief | mean [Vicon position at the first slice; 0], covariance initial_std^2 I4             |
| region         | ``region``, else the room: the square holding the 15 landmarks and the run's Vicon   |
|                | track, 0.5 m to spare                                                                |
| sensing action | none                                                                                 |
| observation    | 1 if the robot is normal (has a pseudo-fix) in the slice                             |

Readings of step k (slice t = s_b + k): ``inputs`` (B, N, 2) zeros; ``range`` /
``range_valid`` (B, N, N) the edges' medians (symmetric); ``fix`` / ``fix_valid``
(B, N) the pseudo-fixes. ``extra`` (the per-step keys of ``coloc_env.backends.particles``,
each of copy b's slice; backends that do not read them use ``fix_noise_var()``,
``range_noise_var()`` and the motion model's noise: the medians over the run):

| key            | shape     | meaning                                                                    |
|----------------|-----------|----------------------------------------------------------------------------|
| ``velocity``   | (B, N, 2) | Delta p / Delta t to the next slice (m/s)                                  |
| ``gps_std``    | (B,)      | the largest sigma_fix of the slice's normal robots (``initial_std`` when   |
|                |           | none), at least 1e-3 m                                                     |
| ``range_std``  | (B,)      | the slice's sigma_d (0.1 m when it has no edge), at least 1e-3 m           |
| ``accel_std``  | (B,)      | the slice's sigma_acc, at least 1e-4 m/s^2                                 |

A particle filter's warm start (``dnbp``) spreads its particles by ``initial_std``
(``warm_start_std``), the std of the initial belief.

Arguments (``coloc_env.worlds.MrclamSlices``)

| field           | default      | allowed                                                              |
|-----------------|--------------|----------------------------------------------------------------------|
| data            | None         | an MRCLAM dataset folder; None = ``$COLOC_MRCLAM_DATA`` at build time |
|                 |              | (no data is read before an env is built)                             |
| num_agents      | 5            | 2..5: robots 0..N-1 (the others' sightings, ranges and sigmas left out) |
| slice_steps     | 10           | 1..600 grid steps of 0.1 s per slice (Delta t = 0.1 slice_steps s)   |
| horizon         | 100          | 1..S-start slices (checked against the run at build time)            |
| start           | None         | None = drawn per episode; 0..S-horizon = a fixed first slice         |
| noise_model     | "calibrated" | "calibrated", "baseline", "likelihood" (``coloc_env.data.mrclam_noise.NoiseModel``) |
| calibration_s   | None         | (0, 3600] s of the run's start the noise is fitted on; None = the model's rule |
| initial_std     | 0.01         | [1e-6, 1000] m: the initial belief's std (m per axis, m/s likewise)  |
| ranges          | True         | True, False: False = no robot-robot ranges (the GPS-only baseline)   |
| region          | None         | None = the room, or (lo, hi) m per axis, entries in [-1e4, 1e4], lo < hi |
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from coloc_env.config import BadInput, as_array, check_entries
from coloc_env.data import mrclam, mrclam_navigation, mrclam_noise
from coloc_env.parts import WORLDS, PartConfig, check_flag, check_range
from coloc_env.worlds.base import Readings, World
from coloc_env.worlds.mrclam import check_recording, recording_tables, replay_tables
from estimators.cv_models import ConstantVelocityAccel

NUM_ROBOTS = mrclam.NUM_ROBOTS
GRID_DT = 0.1  # s: the loader's grid the slices are cut from
NO_EDGE_RANGE_STD = 0.1  # m: sigma_d of a slice without an edge (no range to weigh with it)
MIN_GPS_STD, MIN_RANGE_STD, MIN_ACCEL_STD = 1e-3, 1e-3, 1e-4  # floors of the per-slice sigmas


@dataclass(frozen=True)
class Slices:
    """The run mapped to slices (S slices, all ``NUM_ROBOTS`` robots) by the rules of the module docstring.

    | field            | shape     | meaning                                                            |
    |------------------|-----------|--------------------------------------------------------------------|
    | steps            | (S,)      | the data step k_tau of each slice                                  |
    | truth            | (S, N, 2) | Vicon positions at k_tau                                           |
    | normal           | (S, N)    | the robot has a pseudo-fix                                         |
    | fix              | (S, N, 2) | the pseudo-fix (0 where not normal)                                |
    | fix_std          | (S, N)    | its sigma_fix (0 where not normal)                                 |
    | adjacency        | (S, N, N) | the edges (symmetric)                                              |
    | ranges           | (S, N, N) | their median ranges (0 elsewhere)                                  |
    | edge_var         | (S, N, N) | sigma_d^2 of every pair (read where ``adjacency``)                 |
    | velocity         | (S, N, 2) | Delta p / Delta t to the next slice                                |
    | displacement_var | (S, N)    | sigma_Delta^2 of that displacement                                 |
    | own_nav          | (S, N, 2) | each robot's own navigation filter's position (the heading source) |
    | dt               | float     | Delta t (s)                                                        |

    ``range_std`` (S,) and ``accel_std`` (S,) are each slice's sigma_d and sigma_acc over all the robots.
    """

    steps: np.ndarray
    truth: np.ndarray
    normal: np.ndarray
    fix: np.ndarray
    fix_std: np.ndarray
    adjacency: np.ndarray
    ranges: np.ndarray
    edge_var: np.ndarray
    velocity: np.ndarray
    displacement_var: np.ndarray
    own_nav: np.ndarray
    dt: float

    def __len__(self) -> int:
        return len(self.steps)

    @property
    def range_std(self) -> np.ndarray:
        return slice_range_std(self.adjacency, self.edge_var)

    @property
    def accel_std(self) -> np.ndarray:
        return slice_accel_std(self.displacement_var, self.dt)


def slice_range_std(adjacency: np.ndarray, edge_var: np.ndarray) -> np.ndarray:
    """sigma_d of each slice, (..., N, N) -> (...): the largest over its edges (0 without an edge)."""
    return np.sqrt(np.max(np.where(adjacency, edge_var, 0.0), axis=(-2, -1)))


def slice_accel_std(displacement_var: np.ndarray, dt: float) -> np.ndarray:
    """sigma_acc of each slice, (..., N) -> (...): 2 sigma_Delta / Delta t^2, sigma_Delta the robots' largest."""
    return 2.0 * np.sqrt(np.max(displacement_var, axis=-1)) / dt**2


def build_slices(d: mrclam.MrclamData, model: mrclam_noise.NoiseModel, slice_steps: int = 10,
                 num_slices: int | None = None, navigation: tuple | None = None) -> Slices:
    """Map ``d`` to slices 0..num_slices-1 (all that fit by default) by the rules of the module docstring.

    ``navigation``: ``coloc_env.data.mrclam_navigation.own_navigation(d, model, Vicon pose of step 0)`` of ``d``
    where the caller has it (the filters are causal: the slices read its prefix); None: run here."""
    N, L = NUM_ROBOTS, int(slice_steps)
    S_max = (d.steps - 1) // L + 1
    S = S_max if num_slices is None else min(int(num_slices), S_max)
    d = d.window(0, min(d.steps, L * S + L // 2))  # the steps the slices use (and the next)
    if navigation is None:
        navigation = mrclam_navigation.own_navigation(d, model, d.groundtruth[0].copy())
    pose, cov, accepted = navigation[0][:d.steps], navigation[1][:d.steps], navigation[2][:len(d.meas_step)]
    u = model.odometry(d, np.arange(d.steps))
    q = model.odometry_var(u)
    dt, slice_dt = d.dt, d.dt * L
    heading = pose[..., 2]
    step_disp = dt * u[..., 0, None] * np.stack([np.cos(heading), np.sin(heading)], axis=-1)
    track = np.concatenate([np.zeros((1, N, 2)), np.cumsum(step_disp, axis=0)])  # D(k), (T + 1, N, 2)
    along_var = np.concatenate([np.zeros((1, N)), np.cumsum(dt * dt * q[..., 0], axis=0)])
    steps = L * np.arange(S)
    bin_of = (d.meas_step + L // 2) // L  # step k -> its slice, bins [k_tau - L//2, k_tau - L//2 + L)
    keep = bin_of < S
    fix = np.zeros((S, N, 2))
    fstd = np.zeros((S, N))
    # landmark sightings accepted by the robot's own-nav gate
    idx = np.flatnonzero(keep & accepted & (d.meas_subject > N))
    k, r, tau = d.meas_step[idx], d.meas_robot[idx], bin_of[idx]
    land = d.landmarks[d.meas_subject[idx] - N - 1]
    offset = track[steps[tau], r] - track[k, r]
    p = mrclam_navigation.pseudo_fix(land, d.meas_range[idx], d.meas_bearing[idx], heading[k, r], offset)
    R = model.measurement_cov(d.meas_range[idx])
    sd = mrclam_navigation.fix_std(d.meas_range[idx], R[:, 0, 0], R[:, 1, 1], cov[k, r, 2, 2],
                        np.sum(d.landmark_std[d.meas_subject[idx] - N - 1] ** 2, axis=-1))
    w = 1.0 / sd**2
    wsum = np.zeros((S, N))
    np.add.at(wsum, (tau, r), w)
    np.add.at(fix, (tau, r), w[:, None] * p)
    normal = wsum > 0
    fix[normal] /= wsum[normal][:, None]
    fstd[:] = np.inf
    np.minimum.at(fstd, (tau, r), sd)
    fstd[~normal] = 0.0
    # robot-robot ranges: median per unordered pair and slice
    rr = np.flatnonzero(keep & (d.meas_subject <= N))
    a, b = d.meas_robot[rr], d.meas_subject[rr] - 1
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    adjacency = np.zeros((S, N, N), bool)
    ranges = np.zeros((S, N, N))
    key = (bin_of[rr] * N + lo) * N + hi
    order = np.argsort(key, kind="stable")
    uniq, start = np.unique(key[order], return_index=True)
    for kk, group in zip(uniq, np.split(order, start[1:]), strict=True):
        t_, i_, j_ = kk // (N * N), (kk // N) % N, kk % N
        ranges[t_, i_, j_] = ranges[t_, j_, i_] = float(np.median(d.meas_range[rr[group]]))
        adjacency[t_, i_, j_] = adjacency[t_, j_, i_] = True
    speed = np.abs(u[steps, :, 0])
    motion = L / np.sqrt(12.0) * dt * (speed[:, :, None] + speed[:, None, :])
    edge_var = model.measurement_cov(ranges)[..., 0, 0] + motion**2
    # motion prior: displacement to the next slice (the last slice: what is left of the run)
    nxt = np.minimum(steps + L, d.steps)
    disp = track[nxt] - track[steps]
    disp_var = along_var[nxt] - along_var[steps] + np.sum(disp**2, axis=-1) * cov[steps, :, 2, 2]
    return Slices(steps=steps, truth=d.groundtruth[steps, :, :2].copy(), normal=normal, fix=fix, fix_std=fstd,
                  adjacency=adjacency, ranges=ranges, edge_var=edge_var, velocity=disp / slice_dt,
                  displacement_var=disp_var, own_nav=pose[steps, :, :2].copy(), dt=slice_dt)


@functools.lru_cache(maxsize=2)
def _navigation(path: str, noise_model: str, calibration_s: float | None) -> tuple:
    """The whole run's own navigation (``coloc_env.data.mrclam_navigation.own_navigation`` from the Vicon pose of
    step 0); cached in the process and on disk (``cached_own_navigation``), read-only."""
    tables = replay_tables(path, GRID_DT, noise_model, calibration_s)
    navigation = mrclam_navigation.cached_own_navigation(tables.data, tables.noise_model,
                                                         tables.data.groundtruth[0].copy())
    for array in navigation:
        array.flags.writeable = False
    return navigation


@functools.lru_cache(maxsize=4)
def slice_table(path: str, slice_steps: int, noise_model: str, calibration_s: float | None) -> Slices:
    """The whole run at ``path`` (a resolved dataset folder) as ``Slices`` of ``slice_steps`` grid steps, its
    noise model ``noise_model`` fitted on ``calibration_s`` seconds (None: the model's rule); cached, read-only."""
    tables = replay_tables(path, GRID_DT, noise_model, calibration_s)
    table = build_slices(tables.data, tables.noise_model, slice_steps,
                         navigation=_navigation(path, noise_model, calibration_s))
    for f in dataclasses.fields(table):
        value = getattr(table, f.name)
        if isinstance(value, np.ndarray):
            value.flags.writeable = False
    return table


@WORLDS.register
@dataclass(frozen=True)
class MrclamSlices(PartConfig):
    """Config of the ``mrclam_slices`` world (see the module tables). Validation reads no data."""

    name = "mrclam_slices"
    bound_model = "mrclam_slices"  # coloc_env.bounds.models.mrclam_slices
    estimand = "self"
    motion_kind = ConstantVelocityAccel.kind
    measurements = frozenset({"range", "position_fix"})
    anchors = "the robots that sighted a landmark in the slice (a pseudo position fix)"
    data: str | None = None
    num_agents: int = NUM_ROBOTS
    slice_steps: int = 10
    horizon: int = 100
    start: int | None = None
    noise_model: str = "calibrated"
    calibration_s: float | None = None
    initial_std: float = 0.01
    ranges: bool = True
    region: tuple | None = None

    @property
    def dt(self) -> float:
        """Delta t (s): ``GRID_DT`` ``slice_steps``."""
        return GRID_DT * self.slice_steps

    @property
    def velocity_spread(self) -> float:
        """The initial belief's velocity std (m/s): ``initial_std``."""
        return self.initial_std

    def check(self, prefix: str) -> None:
        check_recording(prefix, self.data, self.noise_model, self.calibration_s)
        check_range(f"{prefix}num_agents", self.num_agents, 2, NUM_ROBOTS, integer=True)
        check_range(f"{prefix}slice_steps", self.slice_steps, 1, 600, integer=True)
        check_range(f"{prefix}horizon", self.horizon, 1, 10**9, integer=True)
        if self.start is not None:
            check_range(f"{prefix}start", self.start, 0, 10**9, integer=True)
        check_range(f"{prefix}initial_std", self.initial_std, 1e-6, 1e3)
        check_flag(f"{prefix}ranges", self.ranges)
        if self.region is not None:
            box = as_array(f"{prefix}region", self.region, shape=(2,))
            check_entries(f"{prefix}region", box, -1e4, 1e4)
            if not box[0] < box[1]:
                raise ValueError(f"{prefix}region must be (lo, hi) with lo < hi, got {tuple(self.region)}")

    def tables(self, prefix: str = "world.") -> tuple:
        """The run's ``coloc_env.worlds.mrclam.ReplayTables`` and its ``Slices`` (``slice_table``); a missing or
        malformed dataset is a BadInput naming ``data``."""
        replay = recording_tables(self.data, GRID_DT, self.noise_model, self.calibration_s, prefix)
        calibration_s = None if self.calibration_s is None else float(self.calibration_s)
        return replay, slice_table(replay.data.path, int(self.slice_steps), self.noise_model, calibration_s)

    def build(self, batch: int, horizon: int) -> MrclamSlicesWorld:
        return MrclamSlicesWorld(self, batch, horizon)


class MrclamSlicesWorld(World):
    """The run's slices replayed from each copy's first slice ``start`` (B,): the truth is the slices' Vicon
    positions, ``slices.truth`` (S, N, 2); ``positions()`` (B, N, 2) at the current slice."""

    agent_prefix = "robot"
    symmetric_ranges = True

    def __init__(self, config: MrclamSlices, batch: int, horizon: int):
        super().__init__(config, batch, horizon)
        replay, self.slices = config.tables()
        self.noise_model = replay.noise_model
        S, K = len(self.slices), self.horizon
        run = f"this run of {S} slices of world.slice_steps = {config.slice_steps} grid steps"
        if K > S:
            raise BadInput(f"world.horizon must be in [1, {S}] slices for {run}, got {K}")
        if config.start is not None and config.start > S - K:
            raise BadInput(f"world.start must be in [0, {S - K}] for a horizon of {K} slices in {run}, got "
                           f"{config.start}")
        if config.region is not None:
            self.square = (float(config.region[0]), float(config.region[1]))
        else:  # the room: replay_tables' box of the landmarks and the Vicon track, as a square
            x0, x1, y0, y1 = replay.extent
            self.square = (min(x0, y0), max(x1, y1))
        self.motion_model = ConstantVelocityAccel(self.slices.dt, float(np.median(self._accel_std() ** 2)))
        self.start = np.zeros(self.batch, dtype=int)

    @property
    def dt(self) -> float:
        return self.slices.dt

    def _accel_std(self) -> np.ndarray:
        return slice_accel_std(self.slices.displacement_var[:, :self.num_agents], self.slices.dt)

    def fix_noise_var(self) -> float:
        """The median over the run's slices with a pseudo-fix of their sigma_gps^2 (the per-slice value is
        ``extra["gps_std"]``); ``initial_std``^2 in a run without one."""
        sl, N = self.slices, self.num_agents
        normal = sl.normal[:, :N].any(axis=1)
        if not normal.any():
            return float(self.config.initial_std**2)
        return float(np.median(np.max(sl.fix_std[normal, :N], axis=1) ** 2))

    def range_noise_var(self) -> float:
        """The median over the run's slices with an edge of their sigma_d^2 (per slice: ``extra["range_std"]``)."""
        sl, N = self.slices, self.num_agents
        adjacency, edge_var = sl.adjacency[:, :N, :N], sl.edge_var[:, :N, :N]
        edged = adjacency.any(axis=(1, 2))
        if not edged.any():
            return NO_EDGE_RANGE_STD**2
        return float(np.median(slice_range_std(adjacency[edged], edge_var[edged]) ** 2))

    def warm_start_std(self) -> float:
        """``initial_std``: the std of the initial belief's positions."""
        return float(self.config.initial_std)

    # --- dynamics -------------------------------------------------------------------------
    def draw_episode(self, rngs, idx) -> None:
        span = len(self.slices) - self.horizon + 1  # first slices 0 .. S - horizon
        for c, rng in enumerate(rngs):
            self.start[idx[c]] = rng.integers(0, span) if self.config.start is None else self.config.start

    def slice_index(self) -> np.ndarray:
        """The table slice of each copy now (B,): s_b + k, the episode's last after the horizon."""
        return self.start + np.minimum(self.k, self.horizon - 1)

    def positions(self) -> np.ndarray:
        return self.slices.truth[self.slice_index(), :self.num_agents].copy()

    def initial_belief(self):
        B, N, s = self.batch, self.num_agents, self.config.initial_std
        mean = np.zeros((B, N, 4))
        mean[..., :2] = self.slices.truth[self.start, :N]
        return mean, np.broadcast_to(s**2 * np.eye(4), (B, N, 4, 4)).copy()

    def readings(self, sensing: np.ndarray) -> Readings:
        sl, B, N, t = self.slices, self.batch, self.num_agents, self.slice_index()
        normal = sl.normal[t, :N]
        adjacency = sl.adjacency[t, :N, :N] & bool(self.config.ranges)
        gps = np.where(normal.any(axis=1), np.max(sl.fix_std[t, :N], axis=1), self.config.initial_std)
        range_std = np.where(adjacency.any(axis=(1, 2)), slice_range_std(adjacency, sl.edge_var[t, :N, :N]),
                             NO_EDGE_RANGE_STD)
        extra = {"velocity": sl.velocity[t, :N].copy(), "gps_std": np.maximum(gps, MIN_GPS_STD),
                 "range_std": np.maximum(range_std, MIN_RANGE_STD),
                 "accel_std": np.maximum(slice_accel_std(sl.displacement_var[t, :N], sl.dt), MIN_ACCEL_STD)}
        return Readings(inputs=np.zeros((B, N, 2)), range=np.where(adjacency, sl.ranges[t, :N, :N], np.nan),
                        range_valid=adjacency, fix=sl.fix[t, :N].copy(), fix_valid=normal.copy(), extra=extra)

    def observation_features(self) -> np.ndarray:
        live = (self.k < self.horizon)[:, None]
        normal = self.slices.normal[self.slice_index(), :self.num_agents]
        return np.where(live, normal, False).astype(float)[..., None]

    def feature_bounds(self):
        return np.zeros(1), np.ones(1)

    def region(self):
        """``region``, else the room: the square holding the 15 landmarks and the run's Vicon track, 0.5 m to
        spare; the same square at the start and over the episode."""
        return self.square, self.square

    def extent(self) -> float:
        return max(abs(self.square[0]), abs(self.square[1]))
