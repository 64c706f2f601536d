"""Ctrl-C during a long command, with a real SIGINT: exit 130, one line on stderr naming the folder left
marked ``INCOMPLETE``, and nothing that was in the folder before is lost.

Each command runs as ``python -m train.cli`` in a subprocess (as in test_cli_bad_input.py), with a budget far larger
than the test waits for, so it is still computing when the signal comes: the test polls until the ``INCOMPLETE``
marker appears (the command has checked its input and is about to compute), then sends SIGINT.
"""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from train.cli import INTERRUPTED, main
from train.io import INCOMPLETE

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
STARTUP_TIMEOUT = 90  # s until the marker appears (the imports take ~2 s here; a loaded 2-core machine is slower)
EXIT_TIMEOUT = 60  # s from SIGINT to exit (~0.5 s here)
# 10**5 episodes of 100 steps, 10**8 PPO timesteps: hours of work, never finished before the signal
STUDY = ["study", "--world", "circles", "--network", "relay", "--backends", "ukf_dcl,dead_reckoning",
         "--episodes", "100000"]
STUDY_FOLDER = Path("study", "circles_relay")
TRAIN = ["train", "bandwidth_fusion", "--timesteps", "100000000", "--curve-points", "0"]
TRAIN_FOLDER = Path("bandwidth_fusion", "seed0")


def _default_sigint():
    """In the child, before exec: SIGINT back to its default, so that Python installs its KeyboardInterrupt handler
    (a process started from a non-interactive shell's background job inherits SIGINT ignored, and Python then
    leaves it ignored)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def interrupt(command: list[str], out: Path, folder: Path) -> tuple[int, str, str]:
    """Start ``coloc COMMAND --out OUT``, wait until ``OUT/FOLDER/INCOMPLETE`` exists, send SIGINT; (rc, out, err)."""
    marker = out / folder / INCOMPLETE
    proc = subprocess.Popen([sys.executable, "-m", "train.cli", *command, "--out", str(out)], cwd=REPO_ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_default_sigint)
    try:
        deadline = time.monotonic() + STARTUP_TIMEOUT
        while not marker.exists():
            if proc.poll() is not None:
                stdout, stderr = proc.communicate()
                pytest.fail(f"coloc {command[0]} exited ({proc.returncode}) before marking {marker}:\n{stdout}{stderr}")
            if time.monotonic() > deadline:
                pytest.fail(f"{marker} did not appear within {STARTUP_TIMEOUT} s")
            time.sleep(0.02)
        assert proc.poll() is None, "the command finished before it could be interrupted"
        proc.send_signal(signal.SIGINT)
        try:
            stdout, stderr = proc.communicate(timeout=EXIT_TIMEOUT)
        except subprocess.TimeoutExpired:
            pytest.fail(f"coloc {command[0]} did not exit within {EXIT_TIMEOUT} s of SIGINT")
        return proc.returncode, stdout, stderr
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


def snapshot(root: Path) -> dict[str, str]:
    """Every file under ``root`` (relative path -> sha256), the marker left out."""
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file() and p.name != INCOMPLETE}


def earlier_files(out: Path, folder: Path) -> dict[str, str]:
    """An unrelated file beside OUT and one in the result folder (from an earlier run, say); their snapshot."""
    (out / folder).mkdir(parents=True)
    (out / "notes.txt").write_text("mine, not coloc's\n")
    (out / folder / "earlier.json").write_bytes(b'{"from": "an earlier run"}\n')
    return snapshot(out)


@pytest.mark.parametrize(("command", "folder"), [(STUDY, STUDY_FOLDER), (TRAIN, TRAIN_FOLDER)],
                         ids=["study", "train"])
def test_sigint_exits_130_with_one_line_and_leaves_the_folder_marked(tmp_path, command, folder):
    before = earlier_files(tmp_path, folder)
    rc, _, err = interrupt(command, tmp_path, folder)
    assert rc == INTERRUPTED == 130, err
    assert err == f"coloc {command[0]}: interrupted; {tmp_path / folder} marked {INCOMPLETE}\n"
    marker = (tmp_path / folder / INCOMPLETE).read_text()
    assert marker.startswith(f"coloc {' '.join(command)} --out {tmp_path}\n") and "has not finished" in marker
    after = snapshot(tmp_path)
    assert {name: after.get(name) for name in before} == before  # nothing lost or changed
    # training saves a checkpoint from its first step, so a signal that comes late finds one: whole, never a
    # temporary or half-written file beside it
    new = set(after) - set(before)
    assert new <= {str(folder / "checkpoint.zip")}, new
    assert all(zipfile.is_zipfile(tmp_path / name) for name in new)


def test_sigint_before_a_new_study_folder_holds_anything_leaves_nothing(tmp_path):
    """A study writes its files after the last episode: interrupted while computing into a new folder, it removes
    the marker and the folders it created, and says that nothing was left half written."""
    (tmp_path / "notes.txt").write_text("mine\n")
    rc, _, err = interrupt(STUDY, tmp_path, STUDY_FOLDER)
    assert rc == 130, err
    assert err == "coloc study: interrupted; nothing was left half written\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]
    assert (tmp_path / "notes.txt").read_text() == "mine\n"


SMALL_STUDY = ["study", "--world", "circles", "--network", "relay", "--backends", "ukf_dcl,dead_reckoning",
               "--episodes", "2", "--horizon", "5"]


def test_a_study_interrupted_between_its_files_keeps_the_written_ones_and_the_mark(tmp_path, capsys, monkeypatch):
    """Ctrl-C while the figure is saved (after metrics.json and report.md): both kept, the folder marked; the same
    command run again completes the folder and removes the mark."""
    import train.io

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(train.io, "save_figure", interrupted)
    folder = tmp_path / STUDY_FOLDER
    assert main([*SMALL_STUDY, "--out", str(tmp_path)]) == INTERRUPTED
    assert capsys.readouterr().err == f"coloc study: interrupted; {folder} marked {INCOMPLETE}\n"
    assert sorted(p.name for p in folder.iterdir()) == [INCOMPLETE, "metrics.json", "report.md"]
    assert "coloc study --world circles --network relay" in (folder / INCOMPLETE).read_text()

    monkeypatch.undo()
    assert main([*SMALL_STUDY, "--out", str(tmp_path)]) == 0
    assert sorted(p.name for p in folder.iterdir()) == ["metrics.json", "position_error.png", "report.md"]


def test_run_study_marks_its_folder_while_computing(tmp_path, monkeypatch):
    """Called as a library too, the folder holds the marker from the first episode to the last file."""
    from train import study

    seen = []
    run_cell = study.run_cell

    def watched(*args, **kwargs):
        seen.append(sorted(p.name for p in (tmp_path / "study" / "mine").iterdir()))
        return run_cell(*args, **kwargs)

    monkeypatch.setattr(study, "run_cell", watched)
    _, folder = study.run_study("circles", "relay", "dead_reckoning", episodes=2, horizon=5, out=str(tmp_path),
                                name="mine")
    assert seen == [[INCOMPLETE]]
    assert sorted(os.listdir(folder)) == ["metrics.json", "position_error.png", "report.md"]


def test_a_study_folder_that_cannot_be_created_is_refused_before_any_episode(tmp_path, capsys, monkeypatch):
    """``--out`` itself is fine but OUT/study is a file: exit 2, one line, nothing computed, nothing written."""
    from train import study

    def no_computing(*args, **kwargs):
        raise AssertionError("an episode ran before the study folder was checked")

    monkeypatch.setattr(study, "run_cell", no_computing)
    (tmp_path / "study").write_text("a file")
    assert main([*SMALL_STUDY, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("coloc study: error: ") and "is a file, not a folder" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["study"]


def test_a_ctrl_c_python_ignores_in_a_callback_is_delivered_again(monkeypatch):
    """A KeyboardInterrupt raised in a weakref callback is "ignored" by Python (as when SIGINT lands in the import
    system's module-lock cleanup); the script's hook delivers it again, so the command still ends."""
    import signal
    import weakref

    from train.cli import redeliver_ignored_interrupt

    monkeypatch.setattr(sys, "unraisablehook", redeliver_ignored_interrupt)
    # interrupt_main raises only under Python's own SIGINT handler: another test of this worker may have left
    # SIGINT ignored (a script's second Ctrl-C is, once it reports an interrupt)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)

    class Target:
        pass

    def interrupted(_):
        raise KeyboardInterrupt

    target = Target()
    ref = weakref.ref(target, interrupted)
    with pytest.raises(KeyboardInterrupt):
        try:
            del target  # the callback runs here and its KeyboardInterrupt is ignored ...
            for _ in range(5000):  # ... and delivered again on a later bytecode (5 s at most on a loaded machine)
                time.sleep(0.001)
        finally:
            signal.signal(signal.SIGINT, previous)
    assert ref() is None


INTERRUPTED_IN_A_STRING_EXEC = """
import sys
import train.cli
import train.io  # imported first, as the command has by the time it computes (an import runs string execs)


def interrupted_in_a_string_exec(args):
    args.open_folders = []
    exec("raise KeyboardInterrupt", {})  # where a Ctrl-C lands while a dataclass builds its methods


train.cli.cmd_list = interrupted_in_a_string_exec
sys.exit(train.cli.main())
"""


def test_a_ctrl_c_caught_from_a_string_exec_still_exits_130_under_python_m(tmp_path):
    """CPython records a KeyboardInterrupt that leaves a string ``exec`` as unhandled even once it is caught, and
    ``python -m`` then ends the process by SIGINT (-2) after the script chose 130; the script forgets that record."""
    (tmp_path / "interrupted_in_a_string_exec.py").write_text(INTERRUPTED_IN_A_STRING_EXEC)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), REPO_ROOT])}
    done = subprocess.run([sys.executable, "-m", "interrupted_in_a_string_exec", "list"], cwd=REPO_ROOT, env=env,
                          capture_output=True, text=True, timeout=EXIT_TIMEOUT)
    assert (done.returncode, done.stderr) == (INTERRUPTED, "coloc list: interrupted; nothing was left half written\n")


def test_other_ignored_exceptions_go_to_pythons_hook(monkeypatch):
    from train.cli import redeliver_ignored_interrupt

    seen = []
    monkeypatch.setattr(sys, "__unraisablehook__", seen.append)
    unraisable = type("Unraisable", (), {"exc_type": RuntimeError})()
    redeliver_ignored_interrupt(unraisable)
    assert seen == [unraisable]


WRITER = """
import sys, time
from train.io import _atomic

def write(fh):
    fh.write(b"half a figure")
    fh.flush()
    time.sleep(600)  # killed here, mid-write

_atomic(sys.argv[1], write)
"""


def test_a_rerun_clears_the_temporary_a_killed_writer_left(tmp_path):
    """A writer killed with SIGKILL mid-write leaves its ``.tmp-...`` file (no handler runs); the next run into the
    same result folder removes it, and only it: the results, other dotfiles and subfolders stay."""
    from train.io import result_folder, write_text

    folder = tmp_path / "zhao2020"
    folder.mkdir()
    (folder / ".keep").write_text("")
    (folder / "sub").mkdir()
    (folder / "sub" / ".tmp-other").write_text("")  # a subfolder's own business
    child = subprocess.Popen([sys.executable, "-c", WRITER, str(folder / "trajectories.png")], cwd=REPO_ROOT)
    deadline = time.monotonic() + STARTUP_TIMEOUT
    while not list(folder.glob(".tmp-*")) and time.monotonic() < deadline and child.poll() is None:
        time.sleep(0.05)
    child.send_signal(signal.SIGKILL)
    child.wait(EXIT_TIMEOUT)
    left = list(folder.glob(".tmp-*"))
    assert [p.name.endswith("trajectories.png") for p in left] == [True]  # what the kill left behind
    with result_folder(str(folder), "coloc reproduce zhao2020"):
        write_text(str(folder / "trajectories.png"), "the figure")
    assert sorted(p.name for p in folder.iterdir()) == [".keep", "sub", "trajectories.png"]
    assert (folder / "sub" / ".tmp-other").exists()
