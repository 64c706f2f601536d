"""Corrupted copies of real MRCLAM files: physically impossible values, bytes that are not text and repeated
barcodes are refused with a ValueError naming the file and the line (coloc_env.data.mrclam's bounds).

Each test writes a short excerpt of dataset 6 (a few seconds of every robot's files) into tmp_path, checks that
the excerpt loads, then damages one line of one file. The data are looked for where tests/conftest.py says
(``COLOC_MRCLAM_DATA``, else ../shared/data/mrclam/MRCLAM_Dataset6 beside the clone)."""

from __future__ import annotations

import os
import re

import numpy as np
import pytest

from coloc_env.data import mrclam
from tests.conftest import MRCLAM_DATASET6, MRCLAM_SKIP_REASON

DATASET6 = MRCLAM_DATASET6
WINDOW = (1248444191.5, 1248444197.0)  # seconds of dataset 6 in which every robot has odometry and ground truth
MEASUREMENT_LINES = 40  # the first sightings of each robot (those outside the window are dropped by the loader)


def _header_and_data(path: str) -> tuple[list[str], list[str]]:
    with open(path) as fh:
        lines = fh.readlines()
    return [line for line in lines if line.startswith("#")], [line for line in lines if not line.startswith("#")]


@pytest.fixture
def excerpt(tmp_path):
    """A loadable excerpt of dataset 6 in tmp_path/excerpt: {file name: (header lines, data lines)}."""
    if not os.path.isdir(DATASET6):
        pytest.skip(MRCLAM_SKIP_REASON)
    folder = tmp_path / "excerpt"
    folder.mkdir()
    files = {}
    for name in sorted(os.listdir(DATASET6)):
        header, data = _header_and_data(os.path.join(DATASET6, name))
        if name.endswith(("_Odometry.dat", "_Groundtruth.dat")) and name.startswith("Robot"):
            data = [line for line in data if WINDOW[0] <= float(line.split()[0]) <= WINDOW[1]]
        elif name.endswith("_Measurement.dat"):
            data = data[:MEASUREMENT_LINES]
        (folder / name).write_text("".join(header + data))
        files[name] = (header, data)
    return folder, files


def _replace(folder, files, name: str, index: int, line: str | bytes) -> int:
    """Data line ``index`` of ``name`` becomes ``line``; returns its line number in the file."""
    header, data = files[name]
    raw = [text.encode() for text in header + data]
    raw[len(header) + index] = (line if isinstance(line, bytes) else line.encode()) + b"\n"
    (folder / name).write_bytes(b"".join(raw))
    return len(header) + index + 1


def _fields(files, name: str, index: int) -> list[str]:
    return files[name][1][index].split()


def test_the_excerpt_loads(excerpt):
    folder, _ = excerpt
    d = mrclam.load(folder)
    assert d.steps >= 40 and np.isfinite(d.odometry).all() and np.isfinite(d.groundtruth).all()
    assert len(d.meas_step) > 0


def _odometry(files, index, v=None, w=None, t=None, name="Robot2_Odometry.dat"):
    time, speed, turn = _fields(files, name, index)
    return f"{t or time} \t {speed if v is None else v} \t {turn if w is None else w}"


@pytest.mark.parametrize(("change", "message"), [
    (dict(v="1e308"), r"forward velocity \[m/s\] 1e\+308 outside \[-0\.5, 0\.5\], physically impossible"),
    (dict(v="0.9"), r"forward velocity \[m/s\] 0\.9 outside \[-0\.5, 0\.5\]"),
    (dict(w="-5.0"), r"angular velocity \[rad/s\] -5 outside \[-3\.846, 3\.846\]"),
    (dict(w="inf"), r"non-finite value"),
    (dict(v="nan"), r"non-finite value"),
])
def test_impossible_odometry_is_refused_with_file_and_line(excerpt, change, message):
    folder, files = excerpt
    number = _replace(folder, files, "Robot2_Odometry.dat", 7, _odometry(files, 7, **change))
    with pytest.raises(ValueError, match=rf"Robot2_Odometry\.dat, line {number}: {message}"):
        mrclam.load(folder)


def test_a_time_far_beyond_the_run_is_refused(excerpt):
    """A last line at t = 1e308 keeps time monotone; it would make a grid of ~1e307 steps."""
    folder, files = excerpt
    last = len(files["Robot4_Odometry.dat"][1]) - 1
    number = _replace(folder, files, "Robot4_Odometry.dat", last,
                      _odometry(files, last, t="1e308", name="Robot4_Odometry.dat"))
    with pytest.raises(ValueError, match=rf"Robot4_Odometry\.dat, line {number}: time 1e\+308 is more than 86400 s"):
        mrclam.load(folder)


@pytest.mark.parametrize(("column", "value", "message"), [
    (2, "-1.5", r"range \[m\] -1\.5 outside \(0, 20\]"),
    (2, "0", r"range \[m\] 0 outside \(0, 20\]"),
    (2, "1e308", r"range \[m\] 1e\+308 outside \(0, 20\]"),
    (3, "4.0", r"bearing \[rad\] 4 outside \[-3\.142, 3\.142\]"),
])
def test_impossible_measurements_are_refused_with_file_and_line(excerpt, column, value, message):
    folder, files = excerpt
    fields = _fields(files, "Robot3_Measurement.dat", 5)
    fields[column] = value
    number = _replace(folder, files, "Robot3_Measurement.dat", 5, " \t ".join(fields))
    with pytest.raises(ValueError, match=rf"Robot3_Measurement\.dat, line {number}: {message}"):
        mrclam.load(folder)


@pytest.mark.parametrize(("column", "value", "message"), [
    (1, "1e308", r"x \[m\] 1e\+308 outside \[-20, 20\]"),
    (2, "-250.0", r"y \[m\] -250 outside \[-20, 20\]"),
    (3, "7.0", r"orientation \[rad\] 7 outside"),
])
def test_impossible_ground_truth_is_refused_with_file_and_line(excerpt, column, value, message):
    folder, files = excerpt
    fields = _fields(files, "Robot1_Groundtruth.dat", 11)
    fields[column] = value
    number = _replace(folder, files, "Robot1_Groundtruth.dat", 11, " \t ".join(fields))
    with pytest.raises(ValueError, match=rf"Robot1_Groundtruth\.dat, line {number}: {message}"):
        mrclam.load(folder)


def test_a_negative_landmark_std_is_refused(excerpt):
    folder, files = excerpt
    fields = _fields(files, "Landmark_Groundtruth.dat", 3)
    fields[3] = "-0.001"
    number = _replace(folder, files, "Landmark_Groundtruth.dat", 3, " \t ".join(fields))
    with pytest.raises(ValueError, match=rf"Landmark_Groundtruth\.dat, line {number}: x std-dev \[m\] -0\.001"):
        mrclam.load(folder)


@pytest.mark.parametrize("junk", [b"\x00\x01\x02\x03 binary", b"1248444192.000 \xff\xfe 0.1", b"\x89PNG\r"])
def test_binary_bytes_are_refused_with_the_line_not_a_byte_offset(excerpt, junk):
    folder, files = excerpt
    number = _replace(folder, files, "Robot5_Groundtruth.dat", 20, junk)
    with pytest.raises(ValueError, match=rf"Robot5_Groundtruth\.dat, line {number}: not text \((control )?byte 0x"):
        mrclam.load(folder)


def test_a_duplicate_barcode_names_both_lines(excerpt):
    folder, files = excerpt
    header, data = files["Barcodes.dat"]
    robot1_code = _fields(files, "Barcodes.dat", 0)[1]
    number = _replace(folder, files, "Barcodes.dat", 1, f"  2 \t  {robot1_code}")
    first = len(header) + 1
    with pytest.raises(ValueError, match=rf"Barcodes\.dat, line {number}: barcode {robot1_code} is already "
                                         rf"subject 1's \(line {first}\)"):
        mrclam.load(folder)


def test_a_subject_given_twice_is_refused(excerpt):
    folder, files = excerpt
    landmark_6 = files["Landmark_Groundtruth.dat"][1][0].rstrip("\n")
    number = _replace(folder, files, "Landmark_Groundtruth.dat", 1, landmark_6)
    with pytest.raises(ValueError, match=rf"Landmark_Groundtruth\.dat, line {number}: landmark 6 is given twice"):
        mrclam.load(folder)


def test_the_real_dataset_lies_inside_every_bound():
    """The bounds refuse only the impossible: every line of dataset 6 passes them (the full files)."""
    if not os.path.isdir(DATASET6):
        pytest.skip(MRCLAM_SKIP_REASON)
    for kind, bounds in mrclam.PHYSICAL_BOUNDS.items():
        names = [n for n in os.listdir(DATASET6) if re.fullmatch(rf"(Robot\d_)?{kind}\.dat", n)]
        assert names, kind
        for name in names:
            table = np.loadtxt(os.path.join(DATASET6, name), comments="#", ndmin=2)
            for bound in bounds:
                assert not bound.violated(table).any(), (name, bound.what)

