"""Only a refused input exits 2; anything else is an internal error, one line and exit 1 asking for a report; every
flag that takes a count, a seed or a folder refuses what it cannot use in one line (no traceback, no MemoryError,
no run that never ends)."""

from __future__ import annotations

import ast
import glob
import os
import re
import signal
import zipfile

import numpy as np
import pytest

from tests.train.test_cli_bad_input import COMMANDS, nothing_computes  # noqa: F401 - a fixture
from train.cli import BAD_INPUT, INTERNAL_ERROR, INTERRUPTED, MAX_RUNS, MAX_SEED, MAX_SEEDS, main

HUGE = "1" * 31


def _one_line(err: str) -> str:
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: c[0])
@pytest.mark.parametrize("out", ["", "  "])
def test_an_empty_out_is_refused_by_every_command(command, out, capsys, nothing_computes):  # noqa: F811
    with pytest.raises(SystemExit) as exit_info:
        main([*command, "--out", out])
    assert exit_info.value.code == BAD_INPUT
    assert f"argument --out: must be a non-empty folder path, got {out!r}" in capsys.readouterr().err


@pytest.mark.parametrize("argv, flag, bounds", [
    (["evaluate", "relay_ukf", "--episodes", HUGE], "--episodes", f"[2, {MAX_RUNS}]"),
    (["evaluate", "relay_ukf", "--episodes", "1"], "--episodes", f"[2, {MAX_RUNS}]"),
    (["study", "--world", "circles", "--network", "relay", "--backends", "ukf_dcl", "--episodes", "1"], "--episodes",
     f"[2, {MAX_RUNS}]"),
    (["reproduce", "zhao2020", "--runs", HUGE], "--runs", f"[1, {MAX_RUNS}]"),
    (["train", "relay_ukf", "--timesteps", HUGE], "--timesteps", "[1, 10000000000]"),
    (["train", "relay_ukf", "--timesteps", "1e5"], "--timesteps", "[1, 10000000000]"),
    (["train", "relay_ukf", "--seed", "-1"], "--seed", f"[0, {MAX_SEED}]"),
    (["train", "relay_ukf", "--curve-points", "-1"], "--curve-points", "[0, 1000]"),
    (["reproduce", "zhao2020", "--seed", HUGE], "--seed", f"[0, {MAX_SEED}]"),
    (["study", "--world", "circles", "--network", "relay", "--backends", "ukf_dcl", "--seed", "1.5"], "--seed",
     f"[0, {MAX_SEED}]"),
    (["study", "--world", "circles", "--network", "relay", "--backends", "ukf_dcl", "--horizon", HUGE],
     "--horizon", "[1, 1000000]"),
    (["bench", "--rounds", "21"], "--rounds", "[1, 20]"),
])
def test_a_count_or_seed_outside_its_range_names_the_flag_and_the_range(argv, flag, bounds, capsys,
                                                                         nothing_computes):  # noqa: F811
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == BAD_INPUT
    err = capsys.readouterr().err
    assert f"argument {flag}: must be an integer in {bounds}, got" in err and "Traceback" not in err


@pytest.mark.parametrize("text, message", [
    ("0..1000000000000", f"seeds must be in [0, {MAX_SEED}]"),
    (f"0..{MAX_SEEDS}", f"at most {MAX_SEEDS} seeds in one A..B, got {MAX_SEEDS + 1}"),
    (f"-3..{HUGE}", f"seeds must be in [0, {MAX_SEED}]"),
])
def test_a_seed_range_too_large_is_refused_before_it_is_built(text, message, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "relay_ukf", f"--seeds={text}"])
    assert exit_info.value.code == BAD_INPUT
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("scenario, policy, message", [
    ("relay_ukf", "paper:NOPE", "policy 'paper' of relay_ukf takes no variant, got 'paper:NOPE'"),
    ("gps_denied_nbp", "paper:NOPE", "policy 'paper' of gps_denied_nbp takes no variant"),
    ("nlos_horizon", "constant:abc", "constant's window (constant:N) must be an integer in [4, 30], got 'abc'"),
])
def test_a_bad_policy_variant_is_one_line_and_exit_2(scenario, policy, message, tmp_path, capsys):
    assert main(["evaluate", scenario, "--policy", policy, "--episodes", "2", "--out", str(tmp_path)]) == BAD_INPUT
    err = _one_line(capsys.readouterr().err)
    assert err.startswith(f"coloc evaluate: error: {message}"), err
    assert not os.listdir(tmp_path)


def test_bench_against_an_unknown_commit_is_one_line_and_exit_2(tmp_path, capsys, nothing_computes):  # noqa: F811
    assert main(["bench", "--against", "nosuchref", "--out", str(tmp_path)]) == BAD_INPUT
    err = _one_line(capsys.readouterr().err)
    assert re.match(r"coloc bench: error: --against 'nosuchref': no such commit in \S+", err), err


@pytest.mark.parametrize("exc, kind", [
    (lambda: np.reshape(np.zeros(3), (2, 2)), "ValueError"),  # numpy's ValueError: a bug, not the input
    (lambda: np.linalg.cholesky(-np.eye(2)), "LinAlgError"),
    (lambda: 1 / 0, "ZeroDivisionError"),
    (lambda: [][1], "IndexError"),
])
def test_an_internal_error_is_one_line_exit_1_asking_for_a_report(exc, kind, tmp_path, capsys, monkeypatch):
    import train.evaluate

    def failing(*args, **kwargs):
        exc()

    monkeypatch.setattr(train.evaluate, "evaluate_policy", failing)
    assert main(["evaluate", "relay_ukf", "--episodes", "2", "--out", str(tmp_path)]) == INTERNAL_ERROR
    err = _one_line(capsys.readouterr().err)
    assert err.startswith(f"coloc evaluate: internal error: {kind}: "), err
    assert "This is a bug in coloc, not in your input: please report it" in err


def test_a_value_error_of_an_estimator_is_internal_and_a_bad_input_from_anywhere_is_not(tmp_path, capsys,
                                                                                       monkeypatch):
    import estimators.linear_models
    import train.evaluate
    from coloc_env.config import BadInput

    def estimator_fails(*args, **kwargs):
        estimators.linear_models.LinearGaussian(np.eye(2), np.zeros(3), np.eye(2))  # a bad drift: its own check

    monkeypatch.setattr(train.evaluate, "evaluate_policy", estimator_fails)
    assert main(["evaluate", "relay_ukf", "--episodes", "2", "--out", str(tmp_path)]) == INTERNAL_ERROR
    assert "internal error: ValueError" in capsys.readouterr().err

    def refused(*args, **kwargs):
        raise BadInput("backend.window_min must be >= 4")

    monkeypatch.setattr(train.evaluate, "evaluate_policy", refused)
    assert main(["evaluate", "relay_ukf", "--episodes", "2", "--out", str(tmp_path)]) == BAD_INPUT
    assert capsys.readouterr().err == "coloc evaluate: error: backend.window_min must be >= 4\n"


def test_the_checks_of_train_and_agents_raise_bad_input():
    """The command line reads a plain ValueError from train/ or agents/ as an internal error (exit 1), so each
    check there of what a user gave raises ``coloc_env.config.BadInput`` (exit 2), never a bare ValueError."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    plain = []
    for package in ("train", "agents"):
        for path in sorted(glob.glob(os.path.join(root, package, "**", "*.py"), recursive=True)):
            with open(path, encoding="utf-8") as handle:
                tree = ast.parse(handle.read())
            plain += [f"{os.path.relpath(path, root)}:{node.lineno}" for node in ast.walk(tree)
                      if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call)
                      and isinstance(node.exc.func, ast.Name) and node.exc.func.id == "ValueError"]
    assert not plain, f"checks raising a plain ValueError: {plain}"


def test_a_value_error_inside_train_that_no_check_raised_is_internal(tmp_path, capsys, monkeypatch):
    """A ValueError raised in train/ by something other than a check (here ``int`` of a malformed setting, its
    innermost frame in train/hyperparams) is a bug: exit 1 with the request to report it, not exit 2."""
    import train.evaluate
    import train.hyperparams
    import train.hyperparams.relay_ukf as settings

    monkeypatch.setattr(settings, "TIMESTEPS", "many")
    monkeypatch.setattr(train.evaluate, "evaluate_policy", lambda *a, **k: train.hyperparams.budget("relay_ukf", 1))
    assert main(["evaluate", "relay_ukf", "--episodes", "2", "--out", str(tmp_path)]) == INTERNAL_ERROR
    err = _one_line(capsys.readouterr().err)
    assert err.startswith("coloc evaluate: internal error: ValueError: invalid literal for int()"), err
    assert "train/hyperparams/__init__.py" in err


def test_a_folder_that_is_no_mrclam_dataset_is_one_line_and_exit_2(tmp_path, capsys):
    """The recorded-data loader's refusals are bad input too: a missing folder, a folder without the files."""
    (tmp_path / "empty").mkdir()
    for data, message in ((tmp_path / "nowhere", "is not a folder (expected an MRCLAM dataset folder"),
                          (tmp_path / "empty", "missing file Barcodes.dat: not an MRCLAM dataset folder")):
        out = tmp_path / "out"
        assert main(["reproduce", "mrclam", "--data", str(data), "--out", str(out)]) == BAD_INPUT
        err = _one_line(capsys.readouterr().err)
        assert err.startswith("coloc reproduce: error: ") and message in err, err
        assert not out.exists()


def test_an_interrupt_as_the_command_ends_prints_its_line_and_a_script_ignores_a_second_one(tmp_path, capsys,
                                                                                             monkeypatch):
    import train.evaluate

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(train.evaluate, "evaluate_policy", interrupted)
    monkeypatch.setattr("sys.argv", ["coloc", "evaluate", "relay_ukf", "--episodes", "2", "--out", str(tmp_path)])
    previous = signal.getsignal(signal.SIGINT)
    try:
        assert main() == INTERRUPTED
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN  # the line is out: nothing cuts the exit short
    finally:
        signal.signal(signal.SIGINT, previous)
    assert _one_line(capsys.readouterr().err).startswith("coloc evaluate: interrupted; nothing was left half written")


def test_a_garbage_policy_pth_is_one_line_naming_the_file(tmp_path):
    import agents
    import coloc_env
    from tests.train.test_cli_bad_input import _copy_model
    from train.training import train

    trained = train("bandwidth_fusion", timesteps=1, seed=0, out=str(tmp_path / "model"), progress_bar=False,
                    curve_points=0)
    path = _copy_model(trained, tmp_path / "garbage")
    with zipfile.ZipFile(trained) as source, zipfile.ZipFile(path, "w") as target:
        for name in source.namelist():
            target.writestr(name, b"not a torch file at all" if name == "policy.pth" else source.read(name))
    with pytest.raises(ValueError) as info:
        agents.make_policy(path, coloc_env.parallel_env("bandwidth_fusion"))
    message = str(info.value)
    assert message.startswith(f"model {path!r} cannot be loaded by stable-baselines3: ") and "\n" not in message
