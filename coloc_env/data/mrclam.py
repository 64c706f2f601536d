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

Time alignment on a fixed step ``dt`` (``load``):

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

The noise model fitted on these tables is in ``coloc_env.data.mrclam_noise``; the robots' own navigation
filters (odometry and landmark sightings only) in ``coloc_env.data.mrclam_navigation``.

Errors: a missing path, a folder that is not a dataset (missing file), a
malformed line (wrong number of fields, a non-number, a non-finite value,
bytes that are not text, time going backwards), an unknown or repeated
subject or barcode in ``Barcodes.dat`` or ``Landmark_Groundtruth.dat``, and a
physically impossible value raise ``coloc_env.config.BadInput`` (a ``ValueError``) naming the file
and line.
The physical bounds (``PHYSICAL_BOUNDS``) come from the dataset paper
(Leung et al. 2011: five iRobot Create robots in a 15 m x 8 m indoor
workspace, Vicon ground truth): |v| <= ``MAX_SPEED`` = 0.5 m/s (the Create's
top drive speed, 500 mm/s in its Open Interface), |w| <= ``MAX_TURN_RATE`` =
2 x 0.5 / 0.26 = 3.85 rad/s (both wheels at top speed in opposite directions,
wheel base 0.26 m), 0 < range <= ``MAX_RANGE`` = 20 m (beyond the workspace's
17 m diagonal), |bearing| <= pi, Vicon and landmark positions within
``MAX_POSITION`` = 20 m of the origin, headings within pi (+ the logs' rounding
to 4 decimals), landmark std >= 0, and a file spans at most ``MAX_SPAN`` = one
day (the datasets run for minutes to about an hour; a time of 1e308 would otherwise make a
step grid of 1e309 steps). Dataset 6's values lie well inside every bound.
The loader only reads.
"""

from __future__ import annotations

import functools
import os
import warnings
from dataclasses import dataclass

import numpy as np

from coloc_env.config import BadInput

__all__ = ["ENV_VAR", "NUM_LANDMARKS", "NUM_ROBOTS", "MrclamData", "load", "load_cached", "resolve_data_path"]

# Names that moved to the noise and navigation modules: still read here, with a DeprecationWarning, for one release
MOVED = {
    **{name: "coloc_env.data.mrclam_noise" for name in (
        "BASELINE_CALIBRATION_S", "CALIBRATION_FRACTION", "CALIBRATION_MIN_S", "GATE_999", "NOISE_MODELS",
        "NoiseModel", "calibrate_noise", "calibration_seconds", "fit_noise_scales")},
    **{name: "coloc_env.data.mrclam_navigation" for name in (
        "OWN_NAV_INITIAL_STD", "fix_std", "own_nav_predict", "own_nav_update", "own_navigation", "pseudo_fix")},
}


def __getattr__(name: str):
    if name in MOVED:
        import importlib

        warnings.warn(f"coloc_env.data.mrclam.{name} moved to {MOVED[name]}.{name}", DeprecationWarning,
                      stacklevel=2)
        return getattr(importlib.import_module(MOVED[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

ENV_VAR = "COLOC_MRCLAM_DATA"
NUM_ROBOTS = 5
NUM_LANDMARKS = 15  # subjects 6..20
NUM_SUBJECTS = NUM_ROBOTS + NUM_LANDMARKS

# Physical bounds of the recorded values (module docstring: the iRobot Create and the workspace of Leung et al.)
MAX_SPEED = 0.5  # m/s, the Create's top drive speed (500 mm/s)
MAX_TURN_RATE = 2 * MAX_SPEED / 0.26  # rad/s, wheels at +-0.5 m/s, wheel base 0.26 m: 3.85 rad/s
MAX_RANGE = 20.0  # m, beyond the 15 m x 8 m workspace's 17 m diagonal
MAX_POSITION = 20.0  # m from the Vicon origin, the workspace's centre
ANGLE_ROUNDING = 1e-3  # rad: headings are logged wrapped to [-pi, pi] and rounded (3.1416 > pi)
MAX_SPAN = 86_400.0  # s: one file covers at most a day (a dataset runs for minutes to about an hour)


@dataclass(frozen=True)
class Bound:
    """Column ``column`` of a file's rows lies in [low, high] (``(low, high]`` with ``low_open``)."""

    column: int
    low: float
    high: float
    what: str
    why: str
    low_open: bool = False

    def violated(self, table: np.ndarray) -> np.ndarray:
        values = table[:, self.column]
        above_low = values > self.low if self.low_open else values >= self.low
        return ~(above_low & (values <= self.high))


_POSITION_WHY = f"the workspace is 15 m x 8 m, at most {MAX_POSITION:g} m from the origin"
_HEADING = (-np.pi - ANGLE_ROUNDING, np.pi + ANGLE_ROUNDING)
PHYSICAL_BOUNDS = {
    "Odometry": (Bound(1, -MAX_SPEED, MAX_SPEED, "forward velocity [m/s]", "the iRobot Create drives at most 0.5 m/s"),
                 Bound(2, -MAX_TURN_RATE, MAX_TURN_RATE, "angular velocity [rad/s]",
                       f"the iRobot Create turns at most {MAX_TURN_RATE:.2f} rad/s")),
    "Measurement": (Bound(2, 0.0, MAX_RANGE, "range [m]", f"a sighting is at a positive range within {MAX_RANGE:g} m "
                          "(the workspace)", low_open=True),
                    Bound(3, -np.pi, np.pi, "bearing [rad]", "a bearing lies in [-pi, pi]")),
    "Groundtruth": (Bound(1, -MAX_POSITION, MAX_POSITION, "x [m]", _POSITION_WHY),
                    Bound(2, -MAX_POSITION, MAX_POSITION, "y [m]", _POSITION_WHY),
                    Bound(3, *_HEADING, "orientation [rad]", "headings are logged wrapped to [-pi, pi]")),
    "Landmark_Groundtruth": (Bound(1, -MAX_POSITION, MAX_POSITION, "x [m]", _POSITION_WHY),
                             Bound(2, -MAX_POSITION, MAX_POSITION, "y [m]", _POSITION_WHY),
                             Bound(3, 0.0, MAX_POSITION, "x std-dev [m]", "a standard deviation is >= 0"),
                             Bound(4, 0.0, MAX_POSITION, "y std-dev [m]", "a standard deviation is >= 0")),
}


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
            raise BadInput(f"window [{start}, {start + steps}) must lie in [0, {self.steps}) with steps >= 1")
        keep = (self.meas_step >= start) & (self.meas_step < start + steps)
        return MrclamData(
            path=self.path, dt=self.dt, t0=self.t0 + start * self.dt, time=self.time[:steps].copy(),
            odometry=self.odometry[start:start + steps], groundtruth=self.groundtruth[start:start + steps],
            landmarks=self.landmarks, landmark_std=self.landmark_std, barcodes=self.barcodes,
            meas_step=self.meas_step[keep] - start, meas_robot=self.meas_robot[keep],
            meas_subject=self.meas_subject[keep], meas_range=self.meas_range[keep],
            meas_bearing=self.meas_bearing[keep], dropped_unknown_barcode=self.dropped_unknown_barcode)


def resolve_data_path(data: str | os.PathLike | None) -> str:
    """``data``, else ``$COLOC_MRCLAM_DATA``; BadInput when neither is set or the path is not a folder."""
    if data is None or str(data) == "":
        data = os.environ.get(ENV_VAR, "")
        if not data:
            raise BadInput(
                f"data: no MRCLAM dataset folder given; pass data=PATH (--data DIR) or set {ENV_VAR} to a "
                "folder such as MRCLAM_Dataset6 (download: http://asrl.utias.utoronto.ca/datasets/mrclam/)")
    path = os.fspath(data)
    if not os.path.isdir(path):
        raise BadInput(f"data: {path!r} is not a folder (expected an MRCLAM dataset folder, e.g. MRCLAM_Dataset6)")
    return path


def _data_lines(path: str) -> list[tuple[int, bytes]]:
    """(line number, raw line) of every data line: what is left before a ``#`` is not blank (np.loadtxt's rule)."""
    with open(path, "rb") as fh:
        raw = fh.read().splitlines()
    return [(number, line) for number, line in enumerate(raw, start=1) if line.split(b"#", 1)[0].strip()]


def _refuse_row(path: str, row: int, message: str):
    """BadInput naming ``path`` and the file line of data row ``row`` (0-based, comments and blanks skipped)."""
    number, line = _data_lines(path)[row]
    return BadInput(f"{path}, line {number}: {message}: {line.decode('utf-8', 'replace').strip()!r}")


def _read_table(path: str, columns: int, integer_columns: tuple[int, ...] = (),
                time_column: int | None = 0, bounds: tuple[Bound, ...] = ()) -> np.ndarray:
    """Rows of ``columns`` finite numbers within ``bounds``; BadInput naming the file and the line otherwise.

    Fast path: ``np.loadtxt`` and vectorized checks; on any format failure the line-by-line
    parser re-reads the file to name the offending line, and a value out of its bounds is
    located by re-reading the line numbers (only then: the real files pass).
    """
    name = os.path.basename(path)
    if not os.path.isfile(path):
        raise BadInput(f"{path}: missing file {name}: not an MRCLAM dataset folder")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            table = np.loadtxt(path, comments="#", ndmin=2, dtype=float)
        ok = (table.shape[0] > 0 and table.shape[1] == columns and np.isfinite(table).all()
              and all(np.all(table[:, c] == np.round(table[:, c])) for c in integer_columns)
              and (time_column is None or np.all(np.diff(table[:, time_column]) >= 0)))
    except (ValueError, UserWarning, UnicodeDecodeError):
        ok = False
    if not ok:
        table = _read_table_lines(path, columns, integer_columns, time_column)
    for bound in bounds:
        bad = np.flatnonzero(bound.violated(table))
        if len(bad):
            value = table[bad[0], bound.column]
            interval = f"{'(' if bound.low_open else '['}{bound.low:.4g}, {bound.high:.4g}]"
            raise _refuse_row(path, int(bad[0]), f"{bound.what} {value:g} outside {interval}, physically "
                                                 f"impossible ({bound.why})")
    if time_column is not None:
        late = np.flatnonzero(table[:, time_column] - table[0, time_column] > MAX_SPAN)
        if len(late):
            raise _refuse_row(path, int(late[0]), f"time {table[late[0], time_column]:.17g} is more than "
                                                  f"{MAX_SPAN:g} s after the file's first line (a dataset runs "
                                                  "for minutes)")
    return table


def _read_table_lines(path: str, columns: int, integer_columns: tuple[int, ...],
                      time_column: int | None) -> np.ndarray:
    name = os.path.basename(path)
    rows = []
    try:
        with open(path, "rb") as fh:
            lines = fh.read().splitlines()
    except OSError as exc:
        raise BadInput(f"{path}: cannot read {name}: {exc}") from exc
    previous = -np.inf
    for number, raw in enumerate(lines, start=1):
        try:
            line = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise BadInput(f"{path}, line {number}: not text (byte 0x{raw[exc.start]:02x} at column "
                             f"{exc.start + 1}): a binary or damaged file") from exc
        data = line.split("#", 1)[0]
        control = [c for c in data if ord(c) < 32 and c not in "\t\f\v"]
        if control:
            raise BadInput(f"{path}, line {number}: not text (control byte 0x{ord(control[0]):02x} at column "
                             f"{data.index(control[0]) + 1}): a binary or damaged file")
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        fields = text.split()
        if len(fields) != columns:
            raise BadInput(f"{path}, line {number}: expected {columns} fields, got {len(fields)}: {text!r}")
        try:
            values = [float(f) for f in fields]
        except ValueError as exc:
            raise BadInput(f"{path}, line {number}: not a number: {text!r}") from exc
        if not all(np.isfinite(values)):
            raise BadInput(f"{path}, line {number}: non-finite value: {text!r}")
        for c in integer_columns:
            if values[c] != int(values[c]):
                raise BadInput(f"{path}, line {number}: field {c + 1} must be an integer: {text!r}")
        if time_column is not None:
            if values[time_column] < previous:
                raise BadInput(f"{path}, line {number}: time goes backwards ({values[time_column]} < {previous})")
            previous = values[time_column]
        rows.append(values)
    if not rows:
        raise BadInput(f"{path}: {name} holds no data lines")
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
        raise BadInput(f"dt must be a positive number of seconds, got {dt!r}")
    dt = float(dt)
    path = resolve_data_path(data)
    file = functools.partial(os.path.join, path)

    barcode_file = file("Barcodes.dat")
    barcode_rows = _read_table(barcode_file, 2, (0, 1), time_column=None)
    barcodes: dict[int, int] = {}
    barcode_row: dict[int, int] = {}
    subject_row: dict[int, int] = {}
    for row, (subject, code) in enumerate(barcode_rows.astype(int)):
        subject, code = int(subject), int(code)
        if not 1 <= subject <= NUM_SUBJECTS:
            raise _refuse_row(barcode_file, row, f"subject {subject} outside 1..{NUM_SUBJECTS}")
        if code in barcode_row:
            first = _data_lines(barcode_file)[barcode_row[code]][0]
            raise _refuse_row(barcode_file, row, f"barcode {code} is already subject {barcodes[code]}'s "
                                                 f"(line {first}); each barcode names one subject")
        if subject in subject_row:
            first = _data_lines(barcode_file)[subject_row[subject]][0]
            raise _refuse_row(barcode_file, row, f"subject {subject} already has a barcode (line {first})")
        barcodes[code], barcode_row[code], subject_row[subject] = subject, row, row
    if sorted(barcodes.values()) != list(range(1, NUM_SUBJECTS + 1)):
        missing = sorted(set(range(1, NUM_SUBJECTS + 1)) - set(barcodes.values()))
        raise BadInput(f"{barcode_file}: must map each subject 1..{NUM_SUBJECTS} to one distinct barcode; "
                         f"no barcode for subjects {missing}")

    landmark_file = file("Landmark_Groundtruth.dat")
    landmark_rows = _read_table(landmark_file, 5, (0,), time_column=None,
                                bounds=PHYSICAL_BOUNDS["Landmark_Groundtruth"])
    landmarks = np.full((NUM_LANDMARKS, 2), np.nan)
    landmark_std = np.full((NUM_LANDMARKS, 2), np.nan)
    for index, row in enumerate(landmark_rows):
        subject = int(row[0])
        if not NUM_ROBOTS < subject <= NUM_SUBJECTS:
            raise _refuse_row(landmark_file, index, f"subject {subject} is not a landmark "
                                                    f"({NUM_ROBOTS + 1}..{NUM_SUBJECTS})")
        if not np.isnan(landmarks[subject - NUM_ROBOTS - 1, 0]):
            raise _refuse_row(landmark_file, index, f"landmark {subject} is given twice")
        landmarks[subject - NUM_ROBOTS - 1] = row[1:3]
        landmark_std[subject - NUM_ROBOTS - 1] = row[3:5]
    if np.isnan(landmarks).any():
        missing = [int(i) + NUM_ROBOTS + 1 for i in np.flatnonzero(np.isnan(landmarks[:, 0]))]
        raise BadInput(f"{file('Landmark_Groundtruth.dat')}: missing landmarks {missing}")

    odometry, truth, measured = [], [], []
    for r in range(1, NUM_ROBOTS + 1):
        odometry.append(_read_table(file(f"Robot{r}_Odometry.dat"), 3, bounds=PHYSICAL_BOUNDS["Odometry"]))
        truth.append(_read_table(file(f"Robot{r}_Groundtruth.dat"), 4, bounds=PHYSICAL_BOUNDS["Groundtruth"]))
        measured.append(_read_table(file(f"Robot{r}_Measurement.dat"), 4, (1,), bounds=PHYSICAL_BOUNDS["Measurement"]))

    t0 = max(max(o[0, 0], g[0, 0]) for o, g in zip(odometry, truth, strict=True))
    t_end = min(min(o[-1, 0], g[-1, 0]) for o, g in zip(odometry, truth, strict=True))
    steps = int(np.floor((t_end - t0) / dt))
    if steps < 1:
        raise BadInput(f"{path}: the robots' odometry and ground truth do not overlap by one step of {dt} s")
    grid = t0 + dt * np.arange(steps)

    odo = np.empty((steps, NUM_ROBOTS, 2))
    gt = np.empty((steps, NUM_ROBOTS, 3))
    for r in range(NUM_ROBOTS):
        odo[:, r] = _held_mean(odometry[r][:, 0], odometry[r][:, 1:3], grid, dt)
        t, pose = truth[r][:, 0], truth[r][:, 1:4]
        gt[:, r, 0] = np.interp(grid, t, pose[:, 0])
        gt[:, r, 1] = np.interp(grid, t, pose[:, 1])
        gt[:, r, 2] = wrap_angle(np.interp(grid, t, np.unwrap(pose[:, 2])))

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


@functools.lru_cache(maxsize=4)
def _load_cached(path: str, dt: float) -> MrclamData:
    loaded = load(path, dt)
    for value in vars(loaded).values():
        if isinstance(value, np.ndarray):
            value.flags.writeable = False
    return loaded


def load_cached(data: str | os.PathLike | None = None, dt: float = 0.1) -> MrclamData:
    """``load`` memoized per (real path, dt); the arrays are read-only (shared between callers)."""
    return _load_cached(os.path.realpath(resolve_data_path(data)), float(dt))


def wrap_angle(angle):
    """``angle`` wrapped to [-pi, pi)."""
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi
