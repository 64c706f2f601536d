"""The coloc command line end to end, on small runs."""

import json
import math
import os

import numpy as np
import pytest

from train.cli import main
from train.io import _atomic, read_json, write_json


def test_reproduce_zhao2020_writes_metrics_report_and_figures(tmp_path):
    assert main(["reproduce", "zhao2020", "--runs", "500", "--seed", "1", "--out", str(tmp_path)]) == 0
    folder = tmp_path / "zhao2020"
    metrics = json.loads((folder / "metrics.json").read_text())
    pairs = ["T1P1", "T1P2", "T1P3", "T2P1", "T3P1"]
    for key in ("cost_exact", "cost_bound", "cost_mc"):
        assert sorted(metrics[key]) == sorted(pairs)
    for pair in pairs:
        # exact covariance vs Monte Carlo within 3 %, and the bound above the exact cost
        assert abs(metrics["cost_mc"][pair] / metrics["cost_exact"][pair] - 1) < 0.03
        assert metrics["cost_bound"][pair] >= metrics["cost_exact"][pair]
    assert metrics["oracle_static_cost"] <= min(metrics["cost_exact"].values())
    assert metrics["greedy_cost"] < metrics["cost_exact"]["T1P1"]
    assert metrics["baselines"]["centralized_kf"] < metrics["oracle_static_cost"]
    for name in ("fig2_trajectories.png", "fig3_selection.png", "fig4_weights.png", "report.md"):
        assert (folder / name).stat().st_size > 1000
    report = (folder / "report.md").read_text()
    assert "P1 (uniform) is best" in report and "| T1P1 |" in report
    # the drift world's bound is exact (linear-Gaussian) and every pair reads no more than every node's
    # measurements: each pair's mean squared x, y error is at or above pcrb_centralized up to 3 standard errors of
    # its mean over the runs (a correct bound is crossed with probability about 0.1 %)
    block = metrics["pcrb"]
    assert block["local"] > block["centralized"] > 0 and block["delivered"] is None
    assert sorted(block["rows"]) == sorted(pairs)
    for pair, row in block["rows"].items():
        assert row["mse"] >= block["centralized"] ** 2 - 3 * row["mse_se"], pair
    assert "## Cramér–Rao bound" in report


def test_train_then_evaluate_a_saved_model(tmp_path, capsys):
    out = str(tmp_path)
    assert main(["train", "bandwidth_fusion", "--timesteps", "512", "--seed", "3", "--out", out]) == 0
    model = os.path.join(out, "bandwidth_fusion", "seed3", "model.zip")
    assert os.path.isfile(model)
    assert read_json(os.path.join(out, "bandwidth_fusion", "seed3", "model.json"))["scenario"] == "bandwidth_fusion"
    folder = os.path.join(out, "bandwidth_fusion", "seed3")
    curve = read_json(os.path.join(folder, "curve.json"))
    assert curve["points"][-1]["timesteps"] >= 512 and len(curve["points"]) >= 2
    assert os.path.isfile(os.path.join(folder, "learning_curve.png"))
    assert os.path.isfile(os.path.join(folder, "checkpoint.zip"))
    # off a terminal (capsys): no redrawn bar, one plain line per validation point, in the metric's unit
    printed = capsys.readouterr().out.splitlines()
    points = [line for line in printed if line.startswith("bandwidth_fusion seed 3: ")]
    assert len(points) == len(curve["points"]) and all(" (budget 512): validation error " in p for p in points)
    assert all(p.split(" m^2 (")[0].endswith(f"{q['mean_cost']:.4g} +- {q['ci95']:.3g}")
               for p, q in zip(points, curve["points"], strict=True))
    assert max(len(line) for line in printed) < 200
    assert main(["evaluate", "bandwidth_fusion", "--policy", model, "--episodes", "3", "--out", out]) == 0
    assert main(["evaluate", "bandwidth_fusion", "--policy", "paper", "--episodes", "3", "--out", out]) == 0
    table = read_json(os.path.join(out, "zhao2020", "leaderboard.json"))
    assert set(table) == {model, "paper"}
    assert table["paper"]["paper_cost"] == pytest.approx(table["paper"]["mean_cost"] + 1.44, abs=1e-12)
    assert "mean realized cost" in capsys.readouterr().out
    summary = (tmp_path / "leaderboard.md").read_text()
    assert "## zhao2020 (`bandwidth_fusion`)" in summary and "trained (mean of 1 seed)" in summary
    assert (tmp_path / "zhao2020" / "leaderboard.png").stat().st_size > 1000


def test_batched_model_evaluation_equals_the_env_loop(tmp_path):
    """run_model_batched (copies of the core) gives the parallel env's episode costs on the same seeds."""
    from stable_baselines3 import PPO

    import agents
    import coloc_env
    from train.evaluate import run_episodes, run_model_batched
    from train.training import train

    path = train("bandwidth_fusion", timesteps=256, seed=1, out=str(tmp_path), progress_bar=False, curve_points=0)
    batched = run_model_batched(PPO.load(path, device="cpu"), "bandwidth_fusion", 4, seed_base=77)
    looped = run_episodes("bandwidth_fusion", path, 4, seed_base=77)
    assert batched["mean_cost"] == pytest.approx(looped["mean_cost"], rel=1e-6)
    assert batched["communication_per_step"] == looped["communication_per_step"]
    model = PPO.load(path, device="cpu")
    sampled = [run_model_batched(model, "bandwidth_fusion", 4, seed_base=77, deterministic=False)["mean_cost"]
               for _ in range(2)]
    assert sampled[0] == sampled[1] != batched["mean_cost"]  # seeded sampling repeats, and it does sample
    assert agents.available_policies("bandwidth_fusion")[0] == "random"
    assert coloc_env.SCENARIOS


def test_evaluate_paper_matches_the_exact_cost():
    """Realized J_50 over seeded episodes agrees with the exact covariance within its 95 % interval (x1.5)."""
    import estimators.bandwidth_fusion as bf
    from coloc_env.scenarios.bandwidth_fusion import paper_selection, paper_weights
    from train.evaluate import run_episodes

    result = run_episodes("bandwidth_fusion", "paper", 60)
    import coloc_env

    model = coloc_env.parallel_env("bandwidth_fusion").config.fusion_model()
    exact, _ = bf.expected_cost(model, np.diag([0.19, 0.09, 0.08]), paper_selection("T1"), paper_weights("P1"), 50)
    assert abs(result["paper_cost"] - exact.sum()) < 1.5 * result["ci95"]


def test_bench_quick_runs_and_writes_json(tmp_path):
    assert main(["bench", "--quick", "--scenarios", "bandwidth_fusion", "--out", str(tmp_path)]) == 0
    rows = read_json(str(tmp_path / "bench" / "bench.json"))["rows"]
    ours = [r for r in rows if r["scenario"] == "bandwidth_fusion"]
    assert {r["what"] for r in ours} == {"parallel_env loop", "supersuit concat_vec_envs_v1", "vector_env",
                                         "estimator step", "pcrb, one episode"}
    assert {r["batch"] for r in ours if r["what"] == "vector_env"} == {1, 64, 1024}
    assert {r["batch"] for r in ours if r["what"] == "estimator step"} == {1, 64, 1024}
    assert all("env_time_over_estimator" in r for r in ours if r["what"] == "vector_env")
    assert all(r["env_steps_per_s"] > 0 and r["agent_steps_per_s"] == 4 * r["env_steps_per_s"] for r in ours)
    assert (tmp_path / "bench" / "throughput.png").stat().st_size > 1000


def test_cli_errors_are_clear(capsys):
    assert main(["evaluate", "no_such", "--policy", "paper"]) == 2
    assert "unknown scenario" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["reproduce", "zhao2020", "--runs", "0"])
    with pytest.raises(SystemExit):
        main(["train", "bandwidth_fusion", "--seeds", "3..1"])


def test_atomic_write_keeps_the_old_file_on_failure(tmp_path):
    path = str(tmp_path / "m.json")
    write_json(path, {"a": 1})

    def half_then_fail(fh):
        fh.write(b'{"a": 2, "b"')
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        _atomic(path, half_then_fail)
    assert read_json(path) == {"a": 1}
    assert os.listdir(tmp_path) == ["m.json"]


def test_a_model_save_interrupted_midway_keeps_the_previous_zip_and_leaves_no_temporary(tmp_path):
    """training's checkpoint / best / last saves go through save_model: Ctrl-C in the middle of SB3's zip write
    leaves the previous checkpoint as it was."""
    from stable_baselines3 import PPO

    from train.io import save_model

    model = PPO("MlpPolicy", "CartPole-v1", n_steps=64, batch_size=64, device="cpu", seed=0)
    path = str(tmp_path / "checkpoint.zip")
    save_model(path, model)
    before = open(path, "rb").read()

    class InterruptedMidway:
        def save(self, fh):
            model.save(fh)
            fh.flush()
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        save_model(path, InterruptedMidway())
    assert open(path, "rb").read() == before and os.listdir(tmp_path) == ["checkpoint.zip"]
    assert PPO.load(path, device="cpu").policy.state_dict().keys() == model.policy.state_dict().keys()


def test_map_tasks_reports_each_finished_unit_and_stops_at_a_failure():
    from train.executor import map_tasks

    finished = []
    assert map_tasks(pow, [(2, 1), (2, 2), (2, 3)], progress=lambda done, total: finished.append((done, total))) == [
        2, 4, 8]
    assert finished == [(1, 3), (2, 3), (3, 3)]
    finished.clear()
    with pytest.raises(ValueError, match="math domain error"):
        map_tasks(math.log, [(1.0,), (-1.0,), (2.0,)], progress=lambda done, total: finished.append(done))
    assert finished == [1]


@pytest.mark.slow  # Ray's start-up and its workers' imports: ~13 s of a 10-minute suite; run with -m slow
def test_ray_executor_equals_local(tmp_path):
    ray = pytest.importorskip("ray")
    import torch
    from stable_baselines3 import PPO

    from coloc_env.config import build_config
    from coloc_env.scenarios.bandwidth_fusion import BandwidthFusionConfig
    from train.executor import map_tasks
    from train.reproduce.zhao2020 import PAIRS, monte_carlo_block
    from train.training import train

    config = build_config(BandwidthFusionConfig, {"horizon": 10})
    blocks = [(pair, 20, 3, config) for pair in PAIRS[:2]]
    jobs = [("bandwidth_fusion", 256, seed, str(tmp_path / executor), "native", False, False, 0)
            for executor in ("local", "ray") for seed in (5,)]
    local = map_tasks(monte_carlo_block, blocks, "local")
    local_model = map_tasks(train, jobs[:1], "local")[0]
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    finished = []
    try:
        remote = map_tasks(monte_carlo_block, blocks, "ray",
                           progress=lambda done, total: finished.append((done, total)))
        remote_model = map_tasks(train, jobs[1:], "ray")[0]
    finally:
        ray.shutdown()
    assert finished == [(1, 2), (2, 2)]
    for a, b in zip(local, remote, strict=True):
        np.testing.assert_array_equal(a["per_run_cost"], b["per_run_cost"])
    weights_local = PPO.load(local_model, device="cpu").policy.state_dict()
    weights_ray = PPO.load(remote_model, device="cpu").policy.state_dict()
    assert all(torch.equal(weights_local[k], weights_ray[k]) for k in weights_local)
    with pytest.raises(ValueError, match="executor"):
        map_tasks(monte_carlo_block, blocks, "dask")


def test_native_and_supersuit_training_learn_the_same_weights(tmp_path):
    import torch
    from stable_baselines3 import PPO

    from train.training import train

    paths = [train("bandwidth_fusion", timesteps=256, seed=4, out=str(tmp_path / vec), vec=vec, progress_bar=False,
                   curve_points=0)
             for vec in ("native", "supersuit")]
    native, supersuit = (PPO.load(p, device="cpu").policy.state_dict() for p in paths)
    assert native.keys() == supersuit.keys()
    for key in native:
        assert torch.equal(native[key], supersuit[key]), key


def test_episode_metrics_follow_each_paper():
    """Default: a sum (J_K); lossy_fusion and relay_ukf: means; gps_denied_nbp: mean over faulty (step, UAV)."""
    import coloc_env
    from coloc_env.config import build_config

    def core(name):
        cls = coloc_env.scenario_class(name)
        return cls(build_config(cls.Config, {}), batch=1)

    errors = np.arange(12.0).reshape(3, 4)
    assert core("bandwidth_fusion").episode_error(errors) == 66.0
    assert core("relay_ukf").episode_error(errors) == 5.5
    fault = np.zeros((3, 4))
    fault[1, 2] = fault[2, 0] = 1.0
    assert core("gps_denied_nbp").episode_error(errors, fault) == (6.0 + 8.0) / 2
    assert core("gps_denied_nbp").episode_error(errors, np.zeros((3, 4))) == 0.0


@pytest.mark.parametrize("name", ["bandwidth_fusion", "lossy_fusion", "relay_ukf", "nlos_horizon", "gps_denied_nbp",
                                  "mrclam_relay", "contention_localization"])
def test_every_scenario_has_a_raw_estimator_benchmark(name, request, monkeypatch):
    import coloc_env
    from train.bench import ESTIMATOR_STEPS

    if name == "mrclam_relay":
        monkeypatch.setenv("COLOC_MRCLAM_DATA", request.getfixturevalue("mrclam_dataset6"))
    assert set(ESTIMATOR_STEPS) == set(coloc_env.SCENARIOS)
    step = ESTIMATOR_STEPS[name](2)
    step()  # one batched step of two copies runs


def _logging(monkeypatch, targets, log):
    """Wrap each (module, attribute) so that its calls append (name, shapes of the array arguments, result)."""
    import importlib

    for module_name, attribute in targets:
        module = importlib.import_module(module_name)
        fn = getattr(module, attribute)

        def logged(*args, _fn=fn, _name=attribute, **kwargs):
            shapes = tuple(np.shape(a) if isinstance(a, np.ndarray) else None for a in args)
            out = _fn(*args, **kwargs)
            log.append((_name, shapes, out))
            return out

        monkeypatch.setattr(module, attribute, logged)


def test_the_relay_ukf_estimator_row_makes_the_envs_own_estimator_calls(monkeypatch):
    """The estimator row replays what the env's backend computes in a step: the same functions (the time update
    and the UKF-DCL range updates the driving actions trigger) on the same shapes, and the replayed time update
    gives the env's estimates bit for bit; the driving actions make every drawn measurement a complete chain."""
    import coloc_env
    from train import bench

    B, steps = 6, 24
    targets = [("estimators.ukf_relay", "range_updates"), ("coloc_env.backends.ukf", "predict_joint")]
    _, tape = bench.record_backend_calls("relay_ukf", B, steps=steps)
    assert len(tape.steps) == steps
    replayed, env_calls = [], []
    with monkeypatch.context() as patch:
        _logging(patch, targets, replayed)
        step = bench.replay_step(tape)
        for _ in range(steps):
            step()
    with monkeypatch.context() as patch:
        _logging(patch, targets, env_calls)
        source = bench.ActionSource("relay_ukf")
        venv = coloc_env.vector_env("relay_ukf", num_envs=B, seed=0)
        venv.reset()
        N = venv.scenario.num_agents
        for k in range(steps):
            venv.step(source([venv.scenario]))
            chain = venv.scenario.network.last_chain
            measured = venv.scenario.world.schedule[:, k] >= 0
            assert np.all(chain.length[measured] == N)  # ranged and relayed to every platform
    assert [(n, s) for n, s, _ in replayed] == [(n, s) for n, s, _ in env_calls]
    names = [n for n, _, _ in replayed]
    assert names.count("predict_joint") == steps and names.count("range_updates") > steps // 4
    assert np.array_equal(replayed[-1][2][0], venv.scenario.backend.mean)  # the last step's time update
    assert np.array_equal(replayed[-1][2][1], venv.scenario.backend.cov)


def test_the_mrclam_estimator_row_replays_the_envs_backend_state(monkeypatch, mrclam_dataset6):
    """mrclam_relay's estimator row: the stacked SE(2) updates and time updates its backend made, replayed on its
    own state arrays, end where the env's backend did (bit for bit), robot-robot chains included (the driving
    actions are the paper policy's of each data step, as PaperPolicy plays them)."""
    import agents
    import coloc_env
    from train import bench

    monkeypatch.setenv("COLOC_MRCLAM_DATA", mrclam_dataset6)
    source = bench.ActionSource("mrclam_relay")
    venv, tape = bench.record_backend_calls("mrclam_relay", 3, steps=30, source=source)
    step = bench.replay_step(tape)
    for _ in range(30):
        step()
    backend = venv.scenario.backend
    for name in ("estimate", "P_ii", "phi", "sigma"):
        assert np.array_equal(step.state[name], getattr(backend, name)), name
    chains = [args[1].shape[1] for calls in tape.steps for key, args, kwargs in calls
              if key[1] == "dcl_update_rows" and kwargs.get("measured_in_chain", True)]
    assert chains and max(chains) == backend.num_agents  # robot observations relayed along complete chains

    env = coloc_env.parallel_env("mrclam_relay")
    observations, _ = env.reset(seed=3)
    policy = agents.make_policy("paper", env)
    for _ in range(40):
        played = policy.act(observations)
        table = source([env.scenario])
        assert all(np.array_equal(played[a], table[i]) for i, a in enumerate(env.possible_agents))
        observations, *_ = env.step(played)


def test_bench_rows_put_the_env_beside_its_estimator(monkeypatch, mrclam_dataset6):
    """An estimator row beside every vector_env row of mrclam_relay (when its data is there), and the env's time
    over the estimator's on the vector_env row."""
    from train import bench

    monkeypatch.setenv("COLOC_MRCLAM_DATA", mrclam_dataset6)
    rows = bench.bench_scenario("mrclam_relay", 0.01, batches=(1, 2))
    bench.add_overheads(rows)
    env = {r["batch"]: r for r in rows if r["what"] == "vector_env"}
    estimator = {r["batch"]: r for r in rows if r["what"] == "estimator step"}
    assert set(env) == set(estimator) == {1, 2}
    for batch, row in env.items():
        assert row["env_time_over_estimator"] == estimator[batch]["env_steps_per_s"] / row["env_steps_per_s"]


def test_all_skips_a_scenario_whose_data_is_missing(monkeypatch, capsys):
    from rich.console import Console

    import coloc_env
    from train.cli import _runnable_scenarios

    monkeypatch.delenv("COLOC_MRCLAM_DATA", raising=False)
    names = _runnable_scenarios(Console())
    assert "mrclam_relay" not in names and set(names) == set(coloc_env.SCENARIOS) - {"mrclam_relay"}
    assert "mrclam_relay: skipped (data" in capsys.readouterr().out


def test_list_prints_every_composition_with_its_verdict(capsys):
    import coloc_env
    from train.cli import main

    assert main(["list"]) == 0
    out = capsys.readouterr().out
    rows = coloc_env.compatibility()
    assert f"compositions ({sum(r['ok'] for r in rows)} of {len(rows)} compatible)" in out
    for r in rows:
        verdict = "ok" if r["ok"] else "no: " + r["reason"]
        assert f"{r['world']}/{r['network']}/{r['backend']}" in out and verdict in out
    assert "relay_ukf          circles / relay / ukf_dcl  (coloc/relay_ukf-v2)" in out


def test_list_ok_and_part_filters_keep_only_their_rows(capsys):
    import coloc_env
    from train.cli import main

    rows = coloc_env.compatibility()
    assert main(["list", "--ok"]) == 0
    out = capsys.readouterr().out
    table = out.split("compositions (")[1].splitlines()[1:]
    ok_names = [f"{r['world']}/{r['network']}/{r['backend']}" for r in rows if r["ok"]]
    assert [line.split() for line in table] == [[name, "ok"] for name in ok_names]
    assert f"{len(ok_names)} shown (--ok)" in out
    assert main(["list", "--world", "circles", "--backend", "dnbp"]) == 0
    out = capsys.readouterr().out
    expected = [r for r in rows if r["world"] == "circles" and r["backend"] == "dnbp"]
    assert f"{len(expected)} shown (--world circles --backend dnbp)" in out
    for r in expected:
        assert f"circles/{r['network']}/dnbp" in out
    assert "drift/" not in out.split("compositions (")[1] and "/ukf_ccl" not in out.split("compositions (")[1]
    assert main(["list", "--network", "relay", "--world", "nope"]) == 2
    assert "--world must be one of drift" in capsys.readouterr().err


def test_a_composition_trains_and_evaluates_by_its_name(tmp_path, capsys, monkeypatch):
    """``coloc train WORLD/NETWORK/BACKEND`` (a cross-combination of parts) uses the composition's settings
    module (train/hyperparams/circles__broadcast__ukf_ccl.py), and ``coloc evaluate --policy all`` judges its
    model against always and silent in OUT/circles_broadcast_ukf_ccl/. ``all`` is every row of
    ``train.evaluate.all_rows`` plus the models found; the rows played here are always and silent (random, the
    event-triggered families and greedy, which take minutes on 800-step episodes, are played by their own
    tests: tests/agents/test_event_triggered.py, tests/train/test_frontier.py)."""
    import train.evaluate
    from train.cli import _policies_for

    name, out = "circles/broadcast/ukf_ccl", str(tmp_path)
    assert main(["train", name, "--timesteps", "64", "--curve-points", "0", "--out", out]) == 0
    model = os.path.join(out, *name.split("/"), "seed0", "model.zip")
    meta = read_json(os.path.join(os.path.dirname(model), "model.json"))
    assert meta["scenario"] == name and meta["env_config"] == {"reward": "trace", "communication_cost": 0.5,
                                                               "cost_range": [0.05, 50.0]}
    assert meta["cost_range"] == [0.05, 50.0]  # the settings' COST_RANGE: cost-conditioned by default
    every_row = train.evaluate.all_rows(name)
    assert {"always", "silent", "random", "greedy", "periodic", "uncertainty"} <= set(every_row)
    assert _policies_for(name, "all", out) == every_row + [model]
    monkeypatch.setattr(train.evaluate, "all_rows", lambda scenario: ["always", "silent"])
    assert main(["evaluate", name, "--policy", "all", "--models", out, "--episodes", "2", "--out", out]) == 0
    table = read_json(os.path.join(out, "circles_broadcast_ukf_ccl", "leaderboard.json"))
    assert {"always", "silent", model} <= set(table)
    summary = (tmp_path / "leaderboard.md").read_text()
    assert f"## circles_broadcast_ukf_ccl (`{name}`)" in summary and "error-communication trade-off" in summary
    capsys.readouterr()
    assert main(["evaluate", "circles/telepathy/ukf_ccl", "--out", out]) == 2
    assert "unknown network 'telepathy'" in capsys.readouterr().err
    assert main(["bench", "--quick", "--scenarios", name, "--out", out]) == 2  # the bench replays presets only
    assert "coloc bench measures the presets (bandwidth_fusion" in capsys.readouterr().err


def test_a_maskable_ppo_model_trains_loads_and_never_plays_a_masked_choice(tmp_path, monkeypatch):
    """ALGORITHM = "maskable_ppo" in a settings module trains sb3-contrib's MaskablePPO on the vector env's masks;
    model.json names it, make_policy loads it as such (also without model.json), its env-loop actions respect the
    infos' masks, and the batched evaluation (which hands it the core's masks) equals the env loop."""
    from sb3_contrib import MaskablePPO

    import agents
    import coloc_env
    import train.hyperparams.relay_ukf as settings
    from train.evaluate import run_episodes, run_model_batched
    from train.training import train

    monkeypatch.setattr(settings, "ALGORITHM", "maskable_ppo", raising=False)
    path = train("relay_ukf", timesteps=256, seed=2, out=str(tmp_path), progress_bar=False, curve_points=0)
    assert read_json(os.path.join(os.path.dirname(path), "model.json"))["algorithm"] == "maskable_ppo"
    env = coloc_env.parallel_env("relay_ukf", horizon=40)
    policy = agents.make_policy(path, env)
    assert isinstance(policy.model, MaskablePPO)
    observations, infos = env.reset(seed=5)
    masked_somewhere = False
    while env.agents:
        actions = policy.act(observations)
        for agent, action in actions.items():
            nvec = env.action_space(agent).nvec
            mask = np.split(np.asarray(infos[agent]["action_mask"], bool).ravel(), np.cumsum(nvec)[:-1])
            masked_somewhere |= not all(m.all() for m in mask)
            assert all(mask[i][int(choice)] for i, choice in enumerate(action))
        observations, _, _, _, infos = env.step(actions)
    assert masked_somewhere  # the check above had masks to respect
    batched = run_model_batched(policy.model, "relay_ukf", 3, seed_base=91, horizon=40,
                               paper_entries=policy.paper_entries)
    looped = run_episodes("relay_ukf", path, 3, seed_base=91, horizon=40)
    assert batched["per_episode_cost"] == pytest.approx(looped["per_episode_cost"], rel=1e-9)
    os.remove(os.path.join(os.path.dirname(path), "model.json"))
    assert isinstance(agents.make_policy(path, env).model, MaskablePPO)  # read from the zip's policy class
    monkeypatch.setattr(settings, "ALGORITHM", "a2c")
    with pytest.raises(ValueError, match=r"ALGORITHM of train/hyperparams/relay_ukf.py must be one of"):
        train("relay_ukf", timesteps=1, seed=0, out=str(tmp_path), progress_bar=False, curve_points=0)
