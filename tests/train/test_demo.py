"""``make demo``'s runner (``train.demo``): every scenario trained and evaluated once, two lanes, and a failed
stage stops only its own lane. The stages are replaced by a stub command here (the real ones take minutes)."""

import sys

from train import demo, hyperparams


def test_every_scenario_is_trained_and_evaluated_once_after_its_training():
    stages = [arguments for lane in demo.lanes("out") for _, arguments in lane]
    for scenario in hyperparams.presets_declaring("DEMO_RUN"):
        trains = [i for i, a in enumerate(stages) if a[:2] == ["train", scenario]]
        evaluates = [i for i, a in enumerate(stages) if a[:2] == ["evaluate", scenario] and "all" in a]
        assert len(trains) == 1 and len(evaluates) == 1 and trains[0] < evaluates[0], scenario
    assert sum(a[:2] == ["reproduce", "all"] for a in stages) == 1


def test_a_failed_stage_stops_its_lane_and_the_run_fails(tmp_path, capsys):
    stub = [sys.executable, "-c", "import sys; print('stub', sys.argv); sys.exit(3 if 'relay_ukf' in sys.argv else 0)"]
    code = demo.run(str(tmp_path), stub)
    assert code == 1
    done = [line.split(" ", 2)[2] for line in (tmp_path / demo.TIMES).read_text().splitlines()]
    lane1, lane2 = ([name for name, _ in lane] for lane in demo.lanes(str(tmp_path)))
    assert done.count("reproduce all --quick") == 1 and not any("relay_ukf" in name for name in done)
    assert set(lane2) <= set(done)  # the other lane ran to its end
    assert "exit status 3" in capsys.readouterr().err
    assert "stub" in (tmp_path / ".demo_lane1.log").read_text()
