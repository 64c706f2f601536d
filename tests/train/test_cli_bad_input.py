"""Bad input to the command line and to the model loader: one clear line, the right exit code, nothing computed,
nothing lost."""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import subprocess
import sys
import time
import zipfile

import pytest

import agents
import coloc_env
from train.cli import INTERRUPTED, build_parser, main
from train.io import INCOMPLETE, check_output_folder

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
STUDY = ["study", "--world", "circles", "--network", "relay", "--backends", "ukf_dcl", "--episodes", "2"]
COMMANDS = [["reproduce", "zhao2020"], ["train", "bandwidth_fusion"], ["evaluate", "bandwidth_fusion"], ["bench"],
            STUDY]


@pytest.fixture
def nothing_computes(monkeypatch):
    """Every command's computing function fails the test if it is reached."""
    import train.bench
    import train.evaluate
    import train.reproduce.zhao2020
    import train.study
    import train.training

    def computed(*args, **kwargs):
        raise AssertionError("computing started before the output folder was checked")

    for module, name in ((train.reproduce.zhao2020, "run"), (train.training, "train"),
                         (train.evaluate, "evaluate_policy"), (train.bench, "run"), (train.study, "run_study")):
        monkeypatch.setattr(module, name, computed)


def _bad_outputs(tmp_path):
    a_file = tmp_path / "a_file"
    a_file.write_text("not a folder")
    return {"/proc/forbidden": r"output folder '/proc/forbidden.*' is not writable",
            str(a_file): rf"output folder '{a_file}(/\S+)?' (is an existing file, not a folder|cannot be created: "
                         rf"'{a_file}' is a file, not a folder)",
            str(a_file / "below"): rf"output folder '{a_file}/below.*' cannot be created: '{a_file}' is a file"}


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: c[0])
def test_an_unusable_out_fails_at_once_with_one_line_and_exit_2(command, tmp_path, capsys, nothing_computes):
    for out, message in _bad_outputs(tmp_path).items():
        assert main([*command, "--out", out]) == 2, out
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err, err
        assert err.startswith(f"coloc {command[0]}: error: ") and re.search(message, err), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_file"]  # nothing created anywhere


def test_the_installed_command_prints_no_traceback_and_exits_2_quickly():
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "train.cli", "reproduce", "zhao2020", "--out", "/proc/forbidden"],
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    elapsed = time.perf_counter() - start
    assert done.returncode == 2
    assert done.stderr.strip().count("\n") == 0 and "Traceback" not in done.stderr
    assert "output folder '/proc/forbidden/zhao2020' is not writable" in done.stderr
    assert elapsed < 30  # the import only: the reproduction itself takes far longer (26 s before the check)


def test_check_output_folder_creates_nothing_and_accepts_a_new_nested_folder(tmp_path):
    assert check_output_folder(str(tmp_path / "new" / "nested")) == str(tmp_path / "new" / "nested")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(ValueError, match="output folder must be a non-empty path, got ''"):
        check_output_folder("")


# --- Ctrl-C and result folders -------------------------------------------------------------------------------
def test_an_interrupt_mid_reproduction_leaves_the_folder_marked_and_prints_one_line(tmp_path, capsys, monkeypatch):
    """Ctrl-C between metrics.json and report.md: the folder says INCOMPLETE, exit 130."""
    import train.reproduce.zhao2020 as zhao2020

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(zhao2020, "write_text", interrupted)  # report.md is written after metrics.json
    folder = tmp_path / "zhao2020"
    assert main(["reproduce", "zhao2020", "--runs", "20", "--out", str(tmp_path)]) == INTERRUPTED == 130
    err = capsys.readouterr().err
    assert err == f"coloc reproduce: interrupted; {folder} marked {INCOMPLETE}\n"
    assert (folder / "metrics.json").is_file() and not (folder / "report.md").exists()
    marker = (folder / INCOMPLETE).read_text()
    assert "coloc reproduce zhao2020 --runs 20" in marker and "has not finished" in marker

    monkeypatch.undo()  # the same command, not interrupted, completes the folder and removes the marker
    assert main(["reproduce", "zhao2020", "--runs", "20", "--out", str(tmp_path)]) == 0
    assert (folder / "report.md").is_file() and not (folder / INCOMPLETE).exists()


def test_an_interrupt_before_anything_is_written_leaves_nothing(tmp_path, capsys, monkeypatch):
    import train.training

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(train.training, "train", interrupted)
    assert main(["train", "bandwidth_fusion", "--seeds", "0..1", "--out", str(tmp_path / "runs")]) == 130
    assert capsys.readouterr().err == "coloc train: interrupted; nothing was left half written\n"
    assert list(tmp_path.iterdir()) == []


def test_refused_input_inside_a_marked_folder_leaves_no_marker(tmp_path, capsys):
    """train.training.train refuses a seed beyond its range after the folder was marked: the mark goes too."""
    assert main(["train", "bandwidth_fusion", "--seed", "100000", "--out", str(tmp_path)]) == 2
    assert "seed must be in [0, 100000)" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


# --- --help and argument forms --------------------------------------------------------------------------------
def _help(command: str) -> str:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
        main([command, "--help"])
    return out.getvalue()


def test_help_shows_defaults_scenarios_and_every_policy_name():
    train_help = " ".join(_help("train").split())
    assert "TIMESTEPS in train/hyperparams/<scenario>.py, 200000 where it sets none" in train_help
    assert "(default: results/train)" in train_help
    assert "(default: native)" in train_help and "(default: 10)" in train_help
    for scenario in coloc_env.SCENARIOS:
        assert scenario in train_help
    evaluate_help = _help("evaluate")
    assert "(default: 100)" in " ".join(evaluate_help.split())
    for scenario in coloc_env.SCENARIOS:
        line = next(line for line in evaluate_help.splitlines() if line.strip().startswith(scenario + " "))
        assert line.split(None, 1)[1].split(", ") == agents.available_policies(scenario)
    assert "constant:12" in evaluate_help and "PATH.zip" in evaluate_help
    study_help = " ".join(_help("study").split())
    assert "(default: 30)" in study_help and study_help.count("(default: always)") == 1
    assert "(default: None)" not in " ".join(_help(c) for c in ("reproduce", "train", "evaluate", "bench", "study"))


@pytest.mark.parametrize("text", ["0-2", "a..b", "1...3", "2..", ""])
def test_a_seed_range_in_another_form_names_the_a_dot_dot_b_form(text, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "bandwidth_fusion", "--seeds", text])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert f"argument --seeds: expected A..B (e.g. 0..2, both included) or one integer S, got {text!r}" in err
    assert "invalid _seed_range value" not in err


def test_a_seed_range_is_inclusive_and_ordered(capsys):
    args = build_parser().parse_args(["train", "bandwidth_fusion", "--seeds", "3..5"])
    assert args.seeds == [3, 4, 5]
    with pytest.raises(SystemExit):
        main(["train", "bandwidth_fusion", "--seeds", "3..1"])
    assert "A..B needs A <= B, got '3..1'" in capsys.readouterr().err


def test_printed_results_carry_units_and_the_initial_term_only_where_there_is_one(tmp_path, capsys):
    assert main(["evaluate", "bandwidth_fusion", "--policy", "paper", "--episodes", "2", "--out", str(tmp_path)]) == 0
    line = capsys.readouterr().out
    assert " m^2 (95 %, 2 episodes); with the initial term 1.44 m^2: " in line
    assert " components received per step -> " in line
    assert main(["evaluate", "relay_ukf", "--policy", "paper", "--episodes", "2", "--out", str(tmp_path)]) == 0
    line = capsys.readouterr().out
    assert " m (95 %, 2 episodes); communication " in line and "initial term" not in line
    assert " relays per step -> " in line


def test_output_to_a_pipe_is_not_wrapped_at_80_columns(tmp_path):
    done = subprocess.run([sys.executable, "-m", "train.cli", "evaluate", "bandwidth_fusion", "--policy", "silent",
                           "--episodes", "2", "--out", str(tmp_path / "a folder name long enough to pass 80 columns")],
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=300,
                          env={k: v for k, v in os.environ.items() if k != "COLUMNS"})
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stdout.splitlines() if line.startswith("bandwidth_fusion silent")]
    assert len(lines) == 1 and len(lines[0]) > 120 and lines[0].endswith("leaderboard.json")


# --- damaged model files --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    from train.training import train

    path = train("bandwidth_fusion", timesteps=1, seed=0, out=str(tmp_path_factory.mktemp("model")),
                 progress_bar=False, curve_points=0)
    return path


def _copy_model(trained, folder, zip_bytes=None, json_text=None):
    folder.mkdir(exist_ok=True)
    zip_path = folder / "model.zip"
    with open(trained, "rb") as fh:
        zip_path.write_bytes(fh.read() if zip_bytes is None else zip_bytes)
    with open(os.path.splitext(trained)[0] + ".json") as fh:
        (folder / "model.json").write_text(fh.read() if json_text is None else json_text)
    return str(zip_path)


def test_an_intact_copy_loads(trained, tmp_path):
    policy = agents.make_policy(_copy_model(trained, tmp_path / "ok"), coloc_env.parallel_env("bandwidth_fusion"))
    assert policy.model.action_space.shape == (13,)


def test_a_truncated_model_zip_names_the_file(trained, tmp_path):
    with open(trained, "rb") as fh:
        data = fh.read()
    env = coloc_env.parallel_env("bandwidth_fusion")
    for cut in (len(data) // 2, len(data) - 30, 10):
        path = _copy_model(trained, tmp_path / f"cut{cut}", zip_bytes=data[:cut])
        damaged = (rf"model '{re.escape(path)}' (is not a readable zip|is damaged|"
                   r"is not a complete stable-baselines3 model \(truncated)")
        with pytest.raises(ValueError, match=damaged):
            agents.make_policy(path, env)


def test_a_damaged_member_names_the_file_and_the_member(trained, tmp_path):
    with open(trained, "rb") as fh:
        data = bytearray(fh.read())
    with zipfile.ZipFile(trained) as archive:
        info = archive.getinfo("policy.pth")
    start = info.header_offset + 30 + len(info.filename) + len(info.extra)  # the member's stored bytes
    data[start + info.compress_size // 2] ^= 0xFF
    path = _copy_model(trained, tmp_path / "flipped", zip_bytes=bytes(data))
    damaged = rf"model '{re.escape(path)}' is damaged: member 'policy\.pth'"
    with pytest.raises(ValueError, match=damaged):
        agents.make_policy(path, coloc_env.parallel_env("bandwidth_fusion"))


def test_a_zip_without_policy_pth_names_the_file_and_the_member(trained, tmp_path):
    folder = tmp_path / "nopolicy"
    path = _copy_model(trained, folder)
    with zipfile.ZipFile(trained) as source, zipfile.ZipFile(path, "w") as target:
        for name in source.namelist():
            if name != "policy.pth":
                target.writestr(name, source.read(name))
    missing = rf"model '{re.escape(path)}' is not a complete stable-baselines3 model .*: the zip has no policy\.pth"
    with pytest.raises(ValueError, match=missing):
        agents.make_policy(path, coloc_env.parallel_env("bandwidth_fusion"))


@pytest.mark.parametrize(("text", "message"), [
    ('{"scenario": "bandwidth_fu', r"is not valid JSON \(truncated\?\): Unterminated string .* line 1 column 14"),
    ("", r"is not valid JSON \(truncated\?\): Expecting value at line 1 column 1"),
    ('["bandwidth_fusion"]', r"must hold a JSON object, got list"),
])
def test_a_damaged_model_json_names_the_file(trained, tmp_path, text, message):
    path = _copy_model(trained, tmp_path / "meta", json_text=text)
    meta = os.path.splitext(path)[0] + ".json"
    with pytest.raises(ValueError, match=rf"model metadata '{re.escape(meta)}' {message}"):
        agents.make_policy(path, coloc_env.parallel_env("bandwidth_fusion"))


def test_cli_evaluate_of_a_damaged_model_is_one_line_and_exit_2(trained, tmp_path, capsys):
    path = _copy_model(trained, tmp_path / "meta", json_text=json.dumps({"scenario": "x"})[:7])
    assert main(["evaluate", "bandwidth_fusion", "--policy", path, "--episodes", "2", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"model metadata '{os.path.splitext(path)[0]}.json' is not valid JSON" in err
