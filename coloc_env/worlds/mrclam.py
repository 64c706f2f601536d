"""World ``mrclam``: the recorded UTIAS MRCLAM run (odometry, camera range+bearing, Vicon truth), replayed.

Data: Leung K.Y.K., Halpern Y., Barfoot T.D., Liu H.H.T., "The UTIAS
multi-robot cooperative localization and mapping dataset", IJRR
30(8):969-974, 2011 (cite it with results on the data). Loader and noise
model: ``coloc_env.data.mrclam`` (``coloc_env.data.mrclam.load_cached``,
``coloc_env.data.mrclam_noise.NoiseModel``), through the run's replay tables
(``replay_tables``: loaded and calibrated once per data path, ``dt``, noise model and
calibration window, and cached). Nothing is simulated: the motion inputs, the
measurements and the truth are the data's, on the loader's grid of ``dt``
seconds (``dt`` is the slice length: the loader averages the odometry over
each slice and bins every measurement to its nearest slice).

Episodes: a batch copy replays a window of ``horizon`` steps of the run
starting at data step s, absolute step a = s + k at env step k. With
``start=None`` s is drawn at reset from the copy's world generator, uniformly
in [0, T - 1 - horizon] (T = steps of the run; the last step needs the Vicon
pose at s + horizon), so the copies of a batch replay different offsets of
the recording; ``start=S`` fixes it (every copy, every episode).

| quantity       | value                                                                                |
|----------------|--------------------------------------------------------------------------------------|
| motion model   | ``estimators.se2_models.SE2Odometry`` (state x, y, theta; input v, omega and    |
|                | their variances: the noise model's corrected odometry u'[a] and Q(u'))               |
| measurements   | ``range``, ``bearing`` (robot-robot camera sightings), ``landmark_range_bearing``    |
|                | (sightings of the 15 surveyed landmarks), ``position_fix`` (landmark pseudo-fixes)   |
| anchors        | none of the robots; the 15 landmarks (known positions) seen by the robots' cameras,  |
|                | also turned into pseudo position fixes of the robot that saw them (below)            |
| region         | the room: the square holding the landmarks and the run's Vicon track, 0.5 m spare    |
| truth          | Vicon (x, y) of the N robots at a; initial belief: the Vicon pose at s, covariance   |
|                | diag(initial_position_std^2, same, initial_heading_std^2), no cross terms            |
| sensing action | ``Discrete(N + 1)`` per agent: which robot it recorded at this step to use (itself:  |
|                | none; N: every robot it recorded); landmark sightings are always reported           |
| observation    | fraction of the other robots it recorded at this step; 1 if it sighted a landmark    |

Readings of step k (absolute a): ``inputs`` (B, N, 4) = (v', omega', var_v, var_omega)
(``coloc_env.data.mrclam_noise.NoiseModel.odometry`` and ``odometry_var`` at a: the
command logged ``odometry_delay_steps`` earlier, scaled). ``range``/``range_valid``
(B, N, N): [m, n] the range of the first line (file order) in which robot m recorded
robot n at a, where the sensing choice of m selects n (with ``robot_sightings="all"`` the
``obs_*`` lists below hold every such line, the matrices still the first). ``fix``/``fix_valid`` (B, N):
the landmark pseudo-fix of the ``mrclam_slices`` world (``coloc_env.data.mrclam_navigation.pseudo_fix``,
the rule of ``coloc_env.worlds.mrclam_slices`` at a single step): each robot runs its own
navigation filter, a UKF on (x, y, theta) from its odometry and its own landmark sightings
only (``coloc_env.data.mrclam_navigation.own_nav_update`` / ``own_nav_predict``, started at the
episode's initial belief, chi-square(2) 99.9 % gate; no robot-robot data, no Vicon after
the start). A robot whose filter accepted landmark sightings at a gets
p = l - r [cos(theta + b), sin(theta + b)] per sighting (theta: its filter's heading after
the step's updates), combined by inverse variance, with variance the smallest single
sigma_fix^2 = max(sigma_r^2, r^2 (sigma_b^2 + sigma_theta^2)) + |sigma_landmark|^2 (no 1/n
reduction: the sightings share the heading error) in ``extra["fix_var"]``;
``fix_noise_var()`` is one variance for backends that take a constant (the median over
the run's sightings at the initial heading variance). ``ukf_se2`` uses the sightings
themselves and ignores the fixes (using both would count them twice); with a backend that reads no
fixes (``Backend.reads_fixes`` False) the own-navigation filters are not run and ``fix_valid`` stays
False. ``extra`` keys:

| key                    | shape         | meaning                                                           |
|------------------------|---------------|-------------------------------------------------------------------|
| ``bearing``            | (B, N, N)     | bearing (rad) of the ``range`` reading [m, n], nan elsewhere      |
| ``range_bearing_cov``  | (B, N, N, 2, 2) | its R = diag(r_range (a_r + b_r z_r^2), sigma_b^2) (noise model)|
| ``obs_observer``       | (B, J)        | the step's selected observations in file order (robot by robot,   |
|                        |               | each robot's lines in its file's order): the observer, -1 = none; |
|                        |               | a robot's sighting of robot n once per step (its first line) or, |
|                        |               | with ``robot_sightings="all"``, every line                        |
| ``obs_subject``        | (B, J)        | the observed robot, -1 for a landmark                              |
| ``obs_landmark``       | (B, J)        | the landmark index 0..14, -1 for a robot                           |
| ``obs_target``         | (B, J, 2)     | the landmark's surveyed position, nan for a robot                  |
| ``obs_z``              | (B, J, 2)     | (range m, bearing rad)                                             |
| ``obs_cov``            | (B, J, 2, 2)  | R from the measured range                                          |
| ``fix_var``            | (B, N)        | variance per axis of the pseudo-fix (m^2), where ``fix_valid``     |

Arguments (``coloc_env.worlds.Mrclam``)

| field                | default      | allowed                                                           |
|----------------------|--------------|-------------------------------------------------------------------|
| data                 | None         | an MRCLAM dataset folder; None = ``$COLOC_MRCLAM_DATA`` at build   |
|                      |              | time (no data is read before an env is built)                     |
| num_agents           | 5            | 2..5: robots 0..N-1 (the others' sightings are left out)          |
| dt                   | 0.1          | [0.01, 1] s: the slice length of the loader's grid                |
| horizon              | 600          | 1..T-1-start steps (checked against the run at build time)        |
| start                | None         | None = drawn per episode; 0..T-1-horizon = a fixed first step     |
| noise_model          | "likelihood" | "likelihood", "calibrated", "baseline"                            |
|                      |              | (``coloc_env.data.mrclam_noise.NoiseModel``; "likelihood" is the  |
|                      |              | consistent one: its fit runs filters for 17-24 s at the first     |
|                      |              | build and is cached on disk, ``coloc_env.data.fit_cache``)        |
| calibration_s        | None         | (0, 3600] s of the run's start the noise is fitted on; None = the model's rule |
| initial_position_std | 0.01         | [1e-6, 1000] m (smaller: P(0) not numerically definite)           |
| initial_heading_std  | 0.01         | [1e-6, 10] rad                                                    |
| measurement_inflation | True        | True, False: False leaves the calibrated model's burst inflation  |
|                      |              | of R out (the ablation of ``coloc reproduce mrclam``); needs      |
|                      |              | ``noise_model="calibrated"`` (the others have none)               |
| robot_sightings      | "first"      | "first": robot m's sighting of robot n counts once per step (the  |
|                      |              | ``mrclam_relay`` scenario's rule); "all": every line, as          |
|                      |              | ``coloc reproduce mrclam`` applies them                           |

Estimation problem (what ``coloc_env.pcrb`` bounds; details in ``coloc_env.bounds.models.mrclam``):
recorded data have no generative model, so the bound is **model-based**: the PCRB of the noise model the
filters assume (``noise_model``), along the recorded Vicon trajectory with the sightings the robots took;
the state is every robot's pose, the prior the filters' initial covariance. It says what an estimator
matched to that model could reach, not what any estimator must exceed on the data.
"""

from __future__ import annotations

import dataclasses
import functools
import os
from dataclasses import dataclass

import numpy as np

from coloc_env.config import BadInput
from coloc_env.data import mrclam, mrclam_navigation, mrclam_noise
from coloc_env.parts import WORLDS, Block, PartConfig, check_choice, check_range
from coloc_env.worlds.base import Readings, World
from estimators.se2_models import RangeBearingModel, SE2Odometry

NUM_ROBOTS = mrclam.NUM_ROBOTS


@dataclass(frozen=True)
class ReplayTables:
    """One run with what every episode needs, computed once per (path, dt, noise_model, calibration_s).

    ``noise`` the ``coloc_env.data.mrclam_noise.calibrate_noise`` dict, ``noise_model`` the
    ``coloc_env.data.mrclam_noise.NoiseModel`` built from it, ``measurement_cov`` (M, 2, 2) its R
    of every measurement line (from the measured range); ``first_index`` (T, N, N): index into
    the measurement arrays of the first line (file order) in which robot i recorded robot j at
    step t, -1 if none; ``landmark_count`` (T, N); ``extent`` (x0, x1, y0, y1) the box holding
    the run's Vicon track and the landmarks, 0.5 m to spare.
    """

    data: mrclam.MrclamData
    noise: dict
    noise_model: mrclam_noise.NoiseModel
    measurement_cov: np.ndarray
    first_index: np.ndarray
    landmark_count: np.ndarray
    extent: tuple[float, float, float, float]


@functools.lru_cache(maxsize=4)
def replay_tables(path: str, dt: float, noise_model: str, calibration_s: float | None) -> ReplayTables:
    """The ``ReplayTables`` of the run at ``path`` (a resolved dataset folder) on the grid ``dt``, with the
    noise model ``noise_model`` fitted on ``calibration_s`` seconds (None: the model's rule); cached."""
    d = mrclam.load_cached(path, dt)
    model = mrclam_noise.NoiseModel.calibrate(d, noise_model, calibration_s)
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


def check_recording(prefix: str, data, noise_model: str, calibration_s) -> None:
    """The fields of a world that replays a recorded run: ``data`` (a dataset folder or None), ``noise_model``
    and ``calibration_s``; ValueError naming the field and its range."""
    if data is not None and not isinstance(data, (str, os.PathLike)):
        raise ValueError(f"{prefix}data must be a path to an MRCLAM dataset folder or None, got {data!r}")
    check_choice(f"{prefix}noise_model", noise_model, mrclam_noise.NOISE_MODELS)
    if calibration_s is not None:
        check_range(f"{prefix}calibration_s", calibration_s, 0.0, 3600.0, low_open=True)


def recording_tables(data, dt: float, noise_model: str, calibration_s, prefix: str = "world.") -> ReplayTables:
    """``replay_tables`` of the run ``data`` names (None: ``$COLOC_MRCLAM_DATA``); a missing or malformed dataset
    is a BadInput naming ``data``."""
    try:
        path = os.path.realpath(mrclam.resolve_data_path(data))
        return replay_tables(path, float(dt), noise_model, None if calibration_s is None else float(calibration_s))
    except ValueError as exc:  # a missing or malformed dataset: name the field
        raise BadInput(f"{prefix}data: {str(exc).removeprefix('data: ')}") from exc


@WORLDS.register
@dataclass(frozen=True)
class Mrclam(PartConfig):
    """Config of the ``mrclam`` world (see the module tables). Validation reads no data."""

    name = "mrclam"
    bound_model = "mrclam"  # coloc_env.bounds.models.mrclam
    estimand = "self"
    motion_kind = SE2Odometry.kind
    measurements = frozenset({"range", "bearing", "landmark_range_bearing", "position_fix"})
    anchors = ("none of the robots; 15 surveyed landmarks seen by the robots' cameras (range + bearing), "
               "also given as pseudo position fixes of the robot that saw them")
    data: str | None = None
    num_agents: int = NUM_ROBOTS
    dt: float = 0.1
    horizon: int = 600
    start: int | None = None
    noise_model: str = "likelihood"
    calibration_s: float | None = None
    initial_position_std: float = 0.01
    initial_heading_std: float = 0.01
    measurement_inflation: bool = True
    robot_sightings: str = "first"

    def check(self, prefix: str) -> None:
        check_recording(prefix, self.data, self.noise_model, self.calibration_s)
        check_range(f"{prefix}num_agents", self.num_agents, 2, NUM_ROBOTS, integer=True)
        check_range(f"{prefix}dt", self.dt, 0.01, 1.0)
        check_range(f"{prefix}horizon", self.horizon, 1, 10**9, integer=True)
        if self.start is not None:
            check_range(f"{prefix}start", self.start, 0, 10**9, integer=True)
        check_range(f"{prefix}initial_position_std", self.initial_position_std, 1e-6, 1e3)
        check_range(f"{prefix}initial_heading_std", self.initial_heading_std, 1e-6, 10.0)
        check_choice(f"{prefix}measurement_inflation", self.measurement_inflation, (True, False))
        if not self.measurement_inflation and self.noise_model != "calibrated":
            raise ValueError(f"{prefix}measurement_inflation=False needs noise_model='calibrated' (the "
                             f"{self.noise_model!r} model has no measurement inflation), got {self.noise_model!r}")
        check_choice(f"{prefix}robot_sightings", self.robot_sightings, ("first", "all"))

    def tables(self, prefix: str = "world.") -> ReplayTables:
        """The replay tables of the run (``replay_tables``: loaded and calibrated once per path; a missing or
        malformed dataset is a BadInput naming ``data``)."""
        tables = recording_tables(self.data, self.dt, self.noise_model, self.calibration_s, prefix)
        if self.measurement_inflation:
            return tables
        # the same fit without the burst inflation of R (the cached tables keep it)
        model = mrclam_noise.NoiseModel.from_calibration(tables.noise, tables.noise_model.kind,
                                                         inflate_measurements=False)
        cov = model.measurement_cov(tables.data.meas_range)
        cov.flags.writeable = False
        return dataclasses.replace(tables, noise_model=model, measurement_cov=cov)

    def check_run(self, prefix: str = "world.", horizon: str | None = None) -> ReplayTables:
        """The checks that need the run (it is loaded): the dataset (``data``), ``horizon`` in [1, T - 1] and
        ``start`` in [0, T - 1 - horizon] (the last step needs the next Vicon pose); BadInput naming the field
        (``horizon``: the name to give that field in the message). Returns the tables."""
        tables = self.tables(prefix)
        T, K = tables.data.steps, self.horizon
        if K > T - 1:
            raise BadInput(f"{horizon or prefix + 'horizon'} must be in [1, {T - 1}] for this run of {T} steps "
                           f"(the last step needs the next Vicon pose), got {K}")
        if self.start is not None and self.start > T - 1 - K:
            raise BadInput(f"{prefix}start must be in [0, {T - 1 - K}] for a horizon of {K} steps in this run "
                           f"of {T} steps, got {self.start}")
        return tables

    def build(self, batch: int, horizon: int) -> MrclamWorld:
        return MrclamWorld(self, batch, horizon)


class MrclamWorld(World):
    """The run replayed from each copy's window start ``start`` (B,): the truth is the run's Vicon poses,
    ``data.groundtruth`` (steps, N, 3) [x, y, heading]; ``poses()`` (B, N, 3) at the current data step."""

    agent_prefix = "robot"

    def __init__(self, config: Mrclam, batch: int, horizon: int):
        super().__init__(config, batch, horizon)
        self.tables = dataclasses.replace(config, horizon=self.horizon).check_run()
        self.data = self.tables.data
        self.noise_model = self.tables.noise_model
        self.motion_model = SE2Odometry(self.data.dt)
        self.landmarks = np.asarray(self.data.landmarks)
        B, N = self.batch, self.num_agents
        self.start = np.zeros(B, dtype=int)
        # the robots' own navigation filters (the heading source of the pseudo-fixes) and the fixes of step a
        self.nav_pose = np.zeros((B, N, 3))
        self.nav_cov = np.zeros((B, N, 3, 3))
        self.fix = np.zeros((B, N, 2))
        self.fix_var = np.zeros((B, N))
        self.fix_valid = np.zeros((B, N), dtype=bool)
        self._accepted = np.zeros(len(self.data.meas_step), dtype=bool)

    # --- description --------------------------------------------------------------------
    @property
    def dt(self) -> float:
        return self.data.dt

    def sensing_blocks(self) -> list[Block]:
        N = self.num_agents
        return [Block("partner", 1, N + 1, f"which robot it recorded at this step to use: a robot, itself = none, "
                      f"{N} = every robot it recorded", default=N, maximum=N, minimum=N)]

    def measurement_model(self) -> RangeBearingModel:
        """The noise model's R as a ``estimators.se2_models.RangeBearingModel`` (R at the measured range)."""
        m = self.noise_model
        a, b = m.range_var
        return RangeBearingModel(m.range_inflation * a, m.bearing_var, m.range_inflation * b)

    def fix_noise_var(self) -> float:
        """Variance per axis (m^2) of a pseudo-fix: the median over the run's landmark sightings of
        ``coloc_env.data.mrclam_navigation.fix_std``^2 with the heading variance at initial_heading_std^2 (the
        per-reading value, with the own-navigation heading variance of the step, is ``extra["fix_var"]``)."""
        d = self.data
        lines = np.flatnonzero(d.meas_subject > NUM_ROBOTS)
        if not len(lines):
            return float(self.config.initial_position_std**2)
        R = self.tables.measurement_cov[lines]
        landmark_var = np.sum(d.landmark_std[d.meas_subject[lines] - NUM_ROBOTS - 1] ** 2, axis=-1)
        sd = mrclam_navigation.fix_std(d.meas_range[lines], R[:, 0, 0], R[:, 1, 1], self.config.initial_heading_std**2,
                            landmark_var)
        return float(np.median(sd**2))

    def range_noise_var(self) -> float:
        """Variance (m^2) of a robot-robot range at the median recorded range (R varies with the range;
        the per-reading value is ``extra["range_bearing_cov"]``)."""
        d = self.data
        robot = d.meas_subject <= NUM_ROBOTS
        r = float(np.median(d.meas_range[robot])) if robot.any() else 0.0
        return float(self.noise_model.measurement_cov(r)[0, 0])

    # --- dynamics -------------------------------------------------------------------------
    def draw_episode(self, rngs, idx) -> None:
        span = self.data.steps - self.horizon  # offsets 0 .. T - 1 - horizon
        for c, rng in enumerate(rngs):
            self.start[idx[c]] = rng.integers(0, span) if self.config.start is None else self.config.start
        mean, cov = self.initial_belief()
        self.nav_pose[idx], self.nav_cov[idx] = mean[idx], cov[idx]
        self.fix_valid[idx] = False
        if not self.fixes_needed:  # nobody reads the pseudo-fixes: no own-navigation filters to run
            return
        for b in idx:
            self._navigate(int(b))

    def _navigate(self, b: int) -> None:
        """Copy b's own-navigation landmark updates of step a (file order) and the pseudo-fixes they give."""
        d, N = self.data, self.num_agents
        a = int(self.start[b] + self.k[b])
        x, P = self.nav_pose[b], self.nav_cov[b]
        mrclam_navigation.own_nav_update(d, self.noise_model, a, x, P, self._accepted, robots=N)
        s = d.measurements_at(a)
        lines = np.arange(s.start, s.stop)[self._accepted[s]]
        self._accepted[s] = False
        self.fix_valid[b] = False
        if not len(lines):
            return
        r = d.meas_robot[lines]
        landmark = d.meas_subject[lines] - NUM_ROBOTS - 1
        p = mrclam_navigation.pseudo_fix(self.landmarks[landmark], d.meas_range[lines], d.meas_bearing[lines], x[r, 2])
        R = self.tables.measurement_cov[lines]
        sd = mrclam_navigation.fix_std(d.meas_range[lines], R[:, 0, 0], R[:, 1, 1], P[r, 2, 2],
                            np.sum(d.landmark_std[landmark] ** 2, axis=-1))
        w = 1.0 / sd**2
        for i in np.unique(r):
            mine = r == i
            self.fix[b, i] = (w[mine, None] * p[mine]).sum(axis=0) / w[mine].sum()
            self.fix_var[b, i] = float(np.min(sd[mine])) ** 2
            self.fix_valid[b, i] = True

    def advance(self) -> None:
        """k -> k + 1: the own-navigation filters predict with u'[a], then take the sightings of a + 1."""
        if not self.fixes_needed:
            super().advance()
            return
        a = self.absolute_step()
        N = self.num_agents
        u = self.noise_model.odometry(self.data, a)[:, :N]
        q = self.noise_model.odometry_var(u)
        for b in range(self.batch):
            self.nav_pose[b], self.nav_cov[b] = mrclam_navigation.own_nav_predict(
                self.nav_pose[b], self.nav_cov[b], u[b], q[b], self.data.dt)
        super().advance()
        for b in np.flatnonzero(self.k <= self.horizon):
            self._navigate(int(b))

    def absolute_step(self) -> np.ndarray:
        """The data step a = s + k of each copy (B,)."""
        return self.start + self.k

    def poses(self) -> np.ndarray:
        """Vicon poses (B, N, 3) at the current step."""
        return self.data.groundtruth[self.absolute_step(), :self.num_agents]

    def positions(self) -> np.ndarray:
        return self.poses()[..., :2].copy()

    def initial_belief(self):
        B, N = self.batch, self.num_agents
        c = self.config
        mean = self.data.groundtruth[self.start, :N].copy()
        std = np.array([c.initial_position_std, c.initial_position_std, c.initial_heading_std])
        cov = np.broadcast_to(np.diag(std**2), (B, N, 3, 3)).copy()
        return mean, cov

    def _lines(self, a: np.ndarray, choice: np.ndarray):
        """The measurement lines of step a[b] that copy b's robots report, in file order: ``lines`` (B, J)
        (0 where ``valid`` is False) and ``valid`` (B, J), J the largest count; all copies at once."""
        d, N, NR = self.data, self.num_agents, NUM_ROBOTS
        lo, hi = np.searchsorted(d.meas_step, np.stack([a, a + 1]))
        width = int((hi - lo).max(initial=0))
        cand = lo[:, None] + np.arange(width)  # (B, W): the lines binned to a[b], file order
        inside = cand < hi[:, None]
        cand = np.where(inside, cand, 0)
        m, subject = d.meas_robot[cand], d.meas_subject[cand]
        keep = inside & (m < N)
        robot = subject <= NR
        n = np.minimum(np.maximum(subject - 1, 0), NR - 1)
        first = self.tables.first_index[a[:, None], np.minimum(m, NR - 1), n] == cand
        if self.config.robot_sightings == "all":
            first = np.ones_like(first)
        mine = choice[np.arange(len(a))[:, None], np.minimum(m, N - 1)]
        chosen = (mine == N) | (mine == n)
        keep &= ~robot | ((n < N) & first & chosen & (n != m))
        count = keep.sum(axis=1)
        J = int(count.max(initial=0))
        order = np.argsort(~keep, axis=1, kind="stable")[:, :J]  # the kept lines first, in file order
        valid = np.arange(J) < count[:, None]
        return np.where(valid, np.take_along_axis(cand, order, axis=1), 0), valid

    def readings(self, sensing: np.ndarray) -> Readings:
        B, N, d = self.batch, self.num_agents, self.data
        a = self.absolute_step()
        choice = np.asarray(sensing, int).reshape(B, N, -1)[..., 0]
        u = self.noise_model.odometry(d, a)[:, :N]  # (B, N, 2): u'[a]
        inputs = np.concatenate([u, self.noise_model.odometry_var(u)], axis=-1)
        lines, valid = self._lines(a, choice)
        sub = d.meas_subject[lines]
        is_robot = valid & (sub <= NUM_ROBOTS)
        sighting = valid & (sub > NUM_ROBOTS)
        landmark = np.where(sighting, sub - NUM_ROBOTS - 1, -1)
        observer = np.where(valid, d.meas_robot[lines], -1)
        subject = np.where(is_robot, sub - 1, -1)
        target = np.where(sighting[..., None], self.landmarks[np.maximum(landmark, 0)], np.nan)
        z = np.where(valid[..., None], np.stack([d.meas_range[lines], d.meas_bearing[lines]], axis=-1), np.nan)
        cov = np.where(valid[..., None, None], self.tables.measurement_cov[lines], 0.0)
        pair = is_robot
        if self.config.robot_sightings == "all":  # the matrices keep each pair's first line, as with "first"
            first = self.tables.first_index[a[:, None], d.meas_robot[lines], np.clip(sub - 1, 0, NUM_ROBOTS - 1)]
            pair = pair & (first == lines)
        b, j = np.nonzero(pair)
        line = lines[b, j]
        rm, rn = d.meas_robot[line], d.meas_subject[line] - 1
        ranges = np.full((B, N, N), np.nan)
        bearing = np.full((B, N, N), np.nan)
        pair_cov = np.zeros((B, N, N, 2, 2))
        valid_pairs = np.zeros((B, N, N), dtype=bool)
        valid_pairs[b, rm, rn] = True
        ranges[b, rm, rn] = d.meas_range[line]
        bearing[b, rm, rn] = d.meas_bearing[line]
        pair_cov[b, rm, rn] = self.tables.measurement_cov[line]
        extra = {"bearing": bearing, "range_bearing_cov": pair_cov, "obs_observer": observer,
                 "obs_subject": subject, "obs_landmark": landmark, "obs_target": target, "obs_z": z, "obs_cov": cov}
        extra["fix_var"] = self.fix_var.copy()
        return Readings(inputs=inputs, range=ranges, range_valid=valid_pairs, fix=self.fix.copy(),
                        fix_valid=self.fix_valid.copy(), extra=extra)

    def observation_features(self) -> np.ndarray:
        N = self.num_agents
        a = np.minimum(self.absolute_step(), self.data.steps - 1)
        recorded = self.tables.first_index[a][:, :N, :N] >= 0  # (B, N, N)
        sighted = self.tables.landmark_count[a][:, :N] > 0
        live = (self.k < self.horizon)[:, None]
        fraction = np.where(live, recorded.sum(axis=-1) / (N - 1), 0.0)
        return np.stack([fraction, np.where(live, sighted, False).astype(float)], axis=-1)

    def feature_bounds(self):
        return np.zeros(2), np.ones(2)

    def region(self):
        """The room, known in advance (a map, not a track): the square holding the 15 landmarks and the whole
        run's Vicon positions, 0.5 m to spare; the same square at the start and over the episode."""
        points = np.concatenate([self.data.groundtruth[..., :2].reshape(-1, 2), self.landmarks])
        square = (float(points.min()) - 0.5, float(points.max()) + 0.5)
        return square, square

    def extent(self) -> float:
        points = np.concatenate([self.data.groundtruth[..., :2].reshape(-1, 2), self.landmarks])
        return float(np.abs(points).max()) + 0.5
