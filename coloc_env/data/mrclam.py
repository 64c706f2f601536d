"""Loader of the UTIAS Multi-Robot Cooperative Localization and Mapping (MRCLAM) dataset.

Leung K.Y.K., Halpern Y., Barfoot T.D., Liu H.H.T., "The UTIAS multi-robot
cooperative localization and mapping dataset", International Journal of
Robotics Research 30(8):969-974, 2011. Cite it when reporting results on the
data. The project does not ship the data: download the datasets from the
UTIAS site (http://asrl.utias.utoronto.ca/datasets/mrclam/) and pass the
folder of one of them (``MRCLAM_DatasetK``) as ``data=PATH`` / ``--data DIR``,
or set the environment variable ``COLOC_MRCLAM_DATA``.

One dataset folder holds, for robots K = 1..5, ``RobotK_Odometry.dat``
(time, v [m/s], w [rad/s]: commanded velocities, ~67 Hz),
``RobotK_Measurement.dat`` (time, barcode, range [m], bearing [rad]),
``RobotK_Groundtruth.dat`` (time, x, y, theta: Vicon), plus ``Barcodes.dat``
(subject 1-20 -> barcode) and ``Landmark_Groundtruth.dat`` (subject 6-20,
x, y, x std, y std). Lines starting with ``#`` are comments.

Time alignment on a fixed step ``dt`` (:func:`load`):

* The grid t_k = t_0 + k dt, k = 0..T-1, starts when every robot has both
  odometry and ground truth and ends before the first robot's stream stops.
* ``odometry[k]`` = the mean over [t_k, t_k + dt) of the commands held
  (zero-order hold) from each timestamp to the next: the exact integral of
  the piecewise-constant command divided by dt. It drives the motion from
  t_k to t_{k+1}.
* ``groundtruth[k]`` = the Vicon pose linearly interpolated at t_k (heading
  unwrapped before interpolation, wrapped to (-pi, pi] after).
* A measurement at time t goes to the nearest step, k = round((t - t_0)/dt)
  (at most dt/2 early or late); those outside [0, T) are dropped. Barcodes
  not in ``Barcodes.dat`` (a handful of misreads in the data) are dropped and
  counted in ``dropped_unknown_barcode``.

Errors: a missing path, a folder that is not a dataset (missing file), a
malformed line (wrong number of fields, a non-number, a non-finite value,
time going backwards), an unknown subject in ``Barcodes.dat`` or
``Landmark_Groundtruth.dat`` raise ``ValueError`` naming the file and line.
The loader only reads.
"""

from __future__ import annotations

import functools
import os
import warnings
from dataclasses import dataclass

import numpy as np

__all__ = [
    "ENV_VAR", "NUM_LANDMARKS", "NUM_ROBOTS", "MrclamData", "calibrate_noise", "load", "load_cached",
    "resolve_data_path",
]

ENV_VAR = "COLOC_MRCLAM_DATA"
NUM_ROBOTS = 5
NUM_LANDMARKS = 15  # subjects 6..20
NUM_SUBJECTS = NUM_ROBOTS + NUM_LANDMARKS


@dataclass(frozen=True)
class MrclamData:
    """One dataset on the step grid. Robot r (0-based) is subject r + 1; landmark l is subject l + 6.

    * ``time``          (T,)          seconds since ``t0`` (t_k = k dt)
    * ``odometry``      (T, 5, 2)     mean (v, w) over [t_k, t_k + dt)
    * ``groundtruth``   (T, 5, 3)     Vicon (x, y, theta) at t_k
    * ``landmarks``     (15, 2)       landmark positions (subject 6..20), ``landmark_std`` (15, 2)
    * measurements, one entry each, sorted by step then robot: ``meas_step`` (M,),
      ``meas_robot`` (M,) 0..4 (the observer), ``meas_subject`` (M,) 1..20 (0-based
      robot = subject - 1, landmark = subject - 6), ``meas_range`` (M,), ``meas_bearing`` (M,)
    """

    path: str
    dt: float
    t0: float
    time: np.ndarray
    odometry: np.ndarray
    groundtruth: np.ndarray
    landmarks: np.ndarray
    landmark_std: np.ndarray
    barcodes: dict
    meas_step: np.ndarray
    meas_robot: np.ndarray
    meas_subject: np.ndarray
    meas_range: np.ndarray
    meas_bearing: np.ndarray
    dropped_unknown_barcode: int

    @property
    def steps(self) -> int:
        return len(self.time)

    def measurements_at(self, k: int) -> slice:
        """The slice of the measurement arrays binned to step k."""
        lo, hi = np.searchsorted(self.meas_step, [k, k + 1])
        return slice(int(lo), int(hi))

    def window(self, start: int, steps: int) -> MrclamData:
        """Steps [start, start + steps) as a dataset of its own (time and steps renumbered from 0)."""
        if not 0 <= start < self.steps or steps < 1 or start + steps > self.steps:
            raise ValueError(f"window [{start}, {start + steps}) must lie in [0, {self.steps}) with steps >= 1")
        keep = (self.meas_step >= start) & (self.meas_step < start + steps)
        return MrclamData(
            path=self.path, dt=self.dt, t0=self.t0 + start * self.dt, time=self.time[:steps].copy(),
            odometry=self.odometry[start:start + steps], groundtruth=self.groundtruth[start:start + steps],
            landmarks=self.landmarks, landmark_std=self.landmark_std, barcodes=self.barcodes,
            meas_step=self.meas_step[keep] - start, meas_robot=self.meas_robot[keep],
            meas_subject=self.meas_subject[keep], meas_range=self.meas_range[keep],
            meas_bearing=self.meas_bearing[keep], dropped_unknown_barcode=self.dropped_unknown_barcode)


def resolve_data_path(data: str | os.PathLike | None) -> str:
    """``data``, else ``$COLOC_MRCLAM_DATA``; ValueError when neither is set or the path is not a folder."""
    if data is None or str(data) == "":
        data = os.environ.get(ENV_VAR, "")
        if not data:
            raise ValueError(
                f"data: no MRCLAM dataset folder given; pass data=PATH (--data DIR) or set {ENV_VAR} to a "
                "folder such as MRCLAM_Dataset6 (download: http://asrl.utias.utoronto.ca/datasets/mrclam/)")
    path = os.fspath(data)
    if not os.path.isdir(path):
        raise ValueError(f"data: {path!r} is not a folder (expected an MRCLAM dataset folder, e.g. MRCLAM_Dataset6)")
    return path


def _read_table(path: str, columns: int, integer_columns: tuple[int, ...] = (),
                time_column: int | None = 0) -> np.ndarray:
    """Rows of ``columns`` finite numbers; ValueError naming the file and the line otherwise.

    Fast path: ``np.loadtxt`` and vectorized checks; on any failure the line-by-line
    parser re-reads the file to name the offending line.
    """
    name = os.path.basename(path)
    if not os.path.isfile(path):
        raise ValueError(f"{path}: missing file {name}: not an MRCLAM dataset folder")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            table = np.loadtxt(path, comments="#", ndmin=2, dtype=float)
        ok = (table.shape[0] > 0 and table.shape[1] == columns and np.isfinite(table).all()
              and all(np.all(table[:, c] == np.round(table[:, c])) for c in integer_columns)
              and (time_column is None or np.all(np.diff(table[:, time_column]) >= 0)))
    except (ValueError, UserWarning, UnicodeDecodeError):
        ok = False
    if ok:
        return table
    return _read_table_lines(path, columns, integer_columns, time_column)


def _read_table_lines(path: str, columns: int, integer_columns: tuple[int, ...],
                      time_column: int | None) -> np.ndarray:
    name = os.path.basename(path)
    rows = []
    try:
        with open(path, encoding="utf-8") as fh:
            lines = fh.readlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read {name}: {exc}") from exc
    previous = -np.inf
    for number, line in enumerate(lines, start=1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        fields = text.split()
        if len(fields) != columns:
            raise ValueError(f"{path}, line {number}: expected {columns} fields, got {len(fields)}: {text!r}")
        try:
            values = [float(f) for f in fields]
        except ValueError as exc:
            raise ValueError(f"{path}, line {number}: not a number: {text!r}") from exc
        if not all(np.isfinite(values)):
            raise ValueError(f"{path}, line {number}: non-finite value: {text!r}")
        for c in integer_columns:
            if values[c] != int(values[c]):
                raise ValueError(f"{path}, line {number}: field {c + 1} must be an integer: {text!r}")
        if time_column is not None:
            if values[time_column] < previous:
                raise ValueError(f"{path}, line {number}: time goes backwards ({values[time_column]} < {previous})")
            previous = values[time_column]
        rows.append(values)
    if not rows:
        raise ValueError(f"{path}: {name} holds no data lines")
    return np.asarray(rows, dtype=float)


def _held_mean(t: np.ndarray, values: np.ndarray, grid: np.ndarray, dt: float) -> np.ndarray:
    """Mean over [g, g + dt) of the zero-order hold of ``values`` (held from t_j to t_{j+1}), per column."""
    cumulative = np.concatenate([np.zeros((1, values.shape[1])), np.cumsum(values[:-1] * np.diff(t)[:, None], axis=0)])

    def integral(at):
        j = np.clip(np.searchsorted(t, at, side="right") - 1, 0, len(t) - 1)
        return cumulative[j] + values[j] * (at - t[j])[:, None]

    return (integral(grid + dt) - integral(grid)) / dt


def load(data: str | os.PathLike | None = None, dt: float = 0.1) -> MrclamData:
    """Parse one MRCLAM dataset folder onto the step grid of ``dt`` seconds (see the module docstring)."""
    if not (isinstance(dt, (int, float)) and np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
    dt = float(dt)
    path = resolve_data_path(data)
    file = functools.partial(os.path.join, path)

    barcode_rows = _read_table(file("Barcodes.dat"), 2, (0, 1), time_column=None)
    barcodes: dict[int, int] = {}
    for subject, code in barcode_rows.astype(int):
        if not 1 <= subject <= NUM_SUBJECTS:
            raise ValueError(f"{file('Barcodes.dat')}: subject {subject} outside 1..{NUM_SUBJECTS}")
        barcodes[int(code)] = int(subject)
    if sorted(barcodes.values()) != list(range(1, NUM_SUBJECTS + 1)):
        raise ValueError(f"{file('Barcodes.dat')}: must map each subject 1..{NUM_SUBJECTS} to one distinct barcode")

    landmark_rows = _read_table(file("Landmark_Groundtruth.dat"), 5, (0,), time_column=None)
    landmarks = np.full((NUM_LANDMARKS, 2), np.nan)
    landmark_std = np.full((NUM_LANDMARKS, 2), np.nan)
    for row in landmark_rows:
        subject = int(row[0])
        if not NUM_ROBOTS < subject <= NUM_SUBJECTS:
            raise ValueError(f"{file('Landmark_Groundtruth.dat')}: subject {subject} is not a landmark "
                             f"({NUM_ROBOTS + 1}..{NUM_SUBJECTS})")
        landmarks[subject - NUM_ROBOTS - 1] = row[1:3]
        landmark_std[subject - NUM_ROBOTS - 1] = row[3:5]
    if np.isnan(landmarks).any():
        missing = [int(i) + NUM_ROBOTS + 1 for i in np.flatnonzero(np.isnan(landmarks[:, 0]))]
        raise ValueError(f"{file('Landmark_Groundtruth.dat')}: missing landmarks {missing}")

    odometry, truth, measured = [], [], []
    for r in range(1, NUM_ROBOTS + 1):
        odometry.append(_read_table(file(f"Robot{r}_Odometry.dat"), 3))
        truth.append(_read_table(file(f"Robot{r}_Groundtruth.dat"), 4))
        measured.append(_read_table(file(f"Robot{r}_Measurement.dat"), 4, (1,)))

    t0 = max(max(o[0, 0], g[0, 0]) for o, g in zip(odometry, truth, strict=True))
    t_end = min(min(o[-1, 0], g[-1, 0]) for o, g in zip(odometry, truth, strict=True))
    steps = int(np.floor((t_end - t0) / dt))
    if steps < 1:
        raise ValueError(f"{path}: the robots' odometry and ground truth do not overlap by one step of {dt} s")
    grid = t0 + dt * np.arange(steps)

    odo = np.empty((steps, NUM_ROBOTS, 2))
    gt = np.empty((steps, NUM_ROBOTS, 3))
    for r in range(NUM_ROBOTS):
        odo[:, r] = _held_mean(odometry[r][:, 0], odometry[r][:, 1:3], grid, dt)
        t, pose = truth[r][:, 0], truth[r][:, 1:4]
        gt[:, r, 0] = np.interp(grid, t, pose[:, 0])
        gt[:, r, 1] = np.interp(grid, t, pose[:, 1])
        gt[:, r, 2] = _wrap(np.interp(grid, t, np.unwrap(pose[:, 2])))

    step_l, robot_l, subject_l, range_l, bearing_l = [], [], [], [], []
    dropped = 0
    for r in range(NUM_ROBOTS):
        rows = measured[r]
        subject = np.array([barcodes.get(int(c), 0) for c in rows[:, 1]], dtype=int)
        known = subject > 0
        dropped += int(np.count_nonzero(~known))
        k = np.rint((rows[:, 0] - t0) / dt).astype(np.int64)
        keep = known & (k >= 0) & (k < steps) & (subject != r + 1)
        step_l.append(k[keep])
        robot_l.append(np.full(np.count_nonzero(keep), r))
        subject_l.append(subject[keep])
        range_l.append(rows[keep, 2])
        bearing_l.append(rows[keep, 3])
    meas_step = np.concatenate(step_l)
    meas_robot = np.concatenate(robot_l)
    order = np.lexsort((meas_robot, meas_step))  # stable: file order within (step, robot)
    return MrclamData(
        path=path, dt=dt, t0=float(t0), time=dt * np.arange(steps), odometry=odo, groundtruth=gt,
        landmarks=landmarks, landmark_std=landmark_std, barcodes=barcodes,
        meas_step=meas_step[order], meas_robot=meas_robot[order],
        meas_subject=np.concatenate(subject_l)[order], meas_range=np.concatenate(range_l)[order],
        meas_bearing=np.concatenate(bearing_l)[order], dropped_unknown_barcode=dropped)


def _robust_std(values: np.ndarray) -> float:
    values = np.asarray(values, float)
    return float(1.4826 * np.median(np.abs(values - np.median(values))))


def calibrate_noise(d: MrclamData, seconds: float = 60.0) -> dict:
    """Noise standard deviations from the first ``seconds`` of ``d`` against the Vicon ground truth.

    Odometry noise: odometry minus the Vicon-derived (v, w) per step; range and bearing noise:
    measured minus Vicon-predicted values; each a robust standard deviation (1.4826 x median
    absolute deviation) so that misread barcodes do not inflate it.
    """
    from estimators.ukf_relay_se2 import observe

    k = max(2, min(d.steps - 1, int(round(seconds / d.dt))))
    gt = d.groundtruth[: k + 1]
    step = np.diff(gt[..., :2], axis=0)
    heading = gt[:-1, :, 2]
    v_gt = (step[..., 0] * np.cos(heading) + step[..., 1] * np.sin(heading)) / d.dt
    w_gt = _wrap(np.diff(gt[..., 2], axis=0)) / d.dt
    sel = d.meas_step < k
    pose = d.groundtruth[d.meas_step[sel], d.meas_robot[sel]]
    subject = d.meas_subject[sel]
    target = np.where((subject <= NUM_ROBOTS)[:, None],
                      d.groundtruth[d.meas_step[sel], np.clip(subject - 1, 0, NUM_ROBOTS - 1), :2],
                      d.landmarks[np.clip(subject - NUM_ROBOTS - 1, 0, NUM_LANDMARKS - 1)])
    predicted = observe(pose, target)
    return {
        "calibration_s": k * d.dt,
        "sigma_v": _robust_std(d.odometry[:k, :, 0] - v_gt),
        "sigma_w": _robust_std(d.odometry[:k, :, 1] - w_gt),
        "sigma_range": _robust_std(d.meas_range[sel] - predicted[:, 0]),
        "sigma_bearing": _robust_std(_wrap(d.meas_bearing[sel] - predicted[:, 1])),
        "calibration_measurements": int(np.count_nonzero(sel)),
    }


@functools.lru_cache(maxsize=4)
def _load_cached(path: str, dt: float) -> MrclamData:
    loaded = load(path, dt)
    for value in vars(loaded).values():
        if isinstance(value, np.ndarray):
            value.flags.writeable = False
    return loaded


def load_cached(data: str | os.PathLike | None = None, dt: float = 0.1) -> MrclamData:
    """:func:`load` memoized per (real path, dt); the arrays are read-only (shared between callers)."""
    return _load_cached(os.path.realpath(resolve_data_path(data)), float(dt))


def _wrap(angle):
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi
