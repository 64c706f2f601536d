"""The baseline frontier (the lower convex hull of the baselines' points, flat after its least error), the
judge against it, and ``coloc frontier``'s files."""

import json
import re

import numpy as np
import pytest

from train import frontier, plotting
from train.cli import main
from train.evaluate import evaluate_policy
from train.leaderboard import baseline_frontier, frontier_comparison, frontier_mix

SMALL = "drift/broadcast/kalman"


def test_the_frontier_is_the_lower_hull_up_to_the_least_error():
    points = [(0, 10), (1, 5), (2, 4.9), (3, 2), (4, 3), (2, 8)]
    assert baseline_frontier(points) == [0, 1, 3]  # (2, 4.9) lies above the chord (1, 5)-(3, 2); (4, 3) after it
    assert baseline_frontier([(0, 10), (1, 5), (2, 1), (3, 2)]) == [0, 1, 2]
    assert baseline_frontier([(1, 3), (1, 2), (0, 9)]) == [2, 1]  # equal messages: the lower cost only


def row(name, messages, costs):
    return {"policy": name, "communication_per_step": messages, "mean_cost": float(np.mean(costs)),
            "per_episode_cost": list(costs), "seed_base": 0}


def test_the_frontier_at_a_rate_between_two_vertices_is_their_time_share():
    rng = np.random.default_rng(0)
    a, b = row("silent", 0.0, 10 + rng.normal(size=50)), row("always", 4.0, 2 + rng.normal(size=50))
    first, second, w = frontier_mix([a, b], 1.0)
    assert (first["policy"], second["policy"]) == ("silent", "always") and w == pytest.approx(0.25)
    assert frontier_mix([a, b], 9.0)[:2] == (b, b)  # flat beyond the least error


@pytest.fixture(scope="module")
def played():
    """always, silent and periodic:2 of the small composition on the same 40 seeded episodes."""
    return {name: evaluate_policy(SMALL, name, 40, seed_base=5, bounds=False)
            for name in ("always", "silent", "periodic:2")}


def test_a_row_equal_to_a_vertex_is_not_beaten_by_it(played):
    baselines = [played["always"], played["silent"]]
    result = frontier_comparison(dict(played["always"], policy="copy of always"), baselines)
    assert result["verdict"] == "equal to rounding" and result["mean"] == 0.0


def test_a_time_shared_mix_of_two_vertices_lands_on_the_frontier(played):
    """Per episode, play always with probability 0.3 and silent otherwise (a seeded draw): the mix's messages and
    cost are those of a point of the chord, and the judge finds no difference its interval could resolve."""
    always, silent = played["always"], played["silent"]
    pick = np.random.default_rng(11).random(40) < 0.3
    costs = np.where(pick, always["per_episode_cost"], silent["per_episode_cost"])
    comms = np.where(pick, always["per_episode_communication"], silent["per_episode_communication"])
    mixed = {"policy": "mix", "per_episode_cost": list(costs), "communication_per_step": float(comms.mean()),
             "mean_cost": float(costs.mean()), "seed_base": always["seed_base"]}
    result = frontier_comparison(mixed, [always, silent])
    assert result["low"] <= 0.0 <= result["high"], result


def test_periodic_against_always_and_silent_is_judged_at_its_own_rate(played):
    result = frontier_comparison(played["periodic:2"], [played["always"], played["silent"]])
    assert result["mix"][:2] == ("silent", "always")
    assert result["mix"][2] == pytest.approx(played["periodic:2"]["communication_per_step"]
                                             / played["always"]["communication_per_step"])


def test_the_command_writes_metrics_report_and_figure(tmp_path, capsys):
    assert main(["frontier", SMALL, "--quick", "--episodes", "3", "--bound-episodes", "2", "--seed", "0",
                 "--out", str(tmp_path)]) == 0
    # printed to a pipe, where the bar draws nothing until the end: a line per tenth of the points
    done = re.findall(rf"frontier {SMALL}: (\d+) of (\d+) done", capsys.readouterr().out)
    assert len(done) == 10 and done[-1][0] == done[-1][1]
    folder = tmp_path / "frontier" / "drift__broadcast__kalman"
    metrics = json.loads((folder / "metrics.json").read_text())
    assert {"frontier.png", "report.md", "metrics.json"} <= {p.name for p in folder.iterdir()}
    names = {p["policy"] for p in metrics["points"]}
    assert {"always", "silent", "random", "periodic:1", "periodic:inf", "uncertainty:0", "uncertainty:inf",
            "send_on_delta:0", "send_on_delta:inf", "value:0", "value:inf"} <= names
    for family in ("uncertainty", "send_on_delta", "value"):  # thresholds between the ends (near-always to near-silent)
        assert sum(name.startswith(f"{family}:") for name in names) > 2, family
    silences = ("silent", "periodic:inf", "uncertainty:inf", "send_on_delta:inf", "value:inf")
    assert metrics["frontier"][0] in silences  # the fewest messages first
    by_name = {p["policy"]: p for p in metrics["points"]}
    assert by_name["periodic:1"]["per_episode_cost"] == by_name["always"]["per_episode_cost"]
    assert by_name["periodic:inf"]["messages_per_agent_step"] == 0.0
    assert all(p["pcrb_centralized"] is not None for p in metrics["points"])
    assert metrics["bound_episodes"] == 2 and "--bound-episodes 2" in metrics["command"]
    assert {p["pcrb_episodes"] for p in metrics["points"]} == {2}  # the errors on 3 episodes, the bounds on 2
    assert "greedy" in metrics["judged"]  # privileged: judged, never a vertex
    assert "greedy" not in metrics["frontier"]
    assert plotting.figure_problems(frontier.figure(metrics)) == []


def test_bad_input_is_refused_before_anything_is_written(tmp_path):
    assert main(["frontier", "drift/broadcast/nope", "--out", str(tmp_path)]) == 2
    assert main(["frontier", SMALL, "--models", str(tmp_path / "none"), "--out", str(tmp_path)]) == 2
    with pytest.raises(SystemExit) as refused:
        main(["frontier", SMALL, "--bound-episodes", "0", "--out", str(tmp_path)])
    assert refused.value.code == 2
    assert not (tmp_path / "frontier").exists()


def test_a_training_folder_gives_its_kept_model_only(tmp_path):
    """``coloc train``'s folder holds model.zip beside best.zip, last.zip and checkpoint.zip (model.zip is a copy
    of one of them): only model.zip is a model to judge; a .zip elsewhere, whatever its name, is one."""
    for name in ("model.zip", *frontier.TRAINING_BYPRODUCTS):
        (tmp_path / "s" / "seed0").mkdir(parents=True, exist_ok=True)
        (tmp_path / "s" / "seed0" / name).write_bytes(b"")
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "last.zip").write_bytes(b"")
    assert frontier.find_models(str(tmp_path)) == [str(tmp_path / "mine" / "last.zip"),
                                                   str(tmp_path / "s" / "seed0" / "model.zip")]


def test_a_shared_medium_adds_round_robin_and_slotted_aloha_over_its_probabilities():
    """Over ``contention`` the medium-access baselines are points too: round_robin (once: it is the preset's paper),
    the adaptive aloha and aloha:p over the probability grid; a network without a shared medium has none."""
    points = {cell["policy"]: cell for cell in frontier.cells("contention_localization", 30, [])}
    assert {"paper", "aloha", "always", "silent"} <= set(points) and "round_robin" not in points
    assert [name for name in points if name.startswith("aloha:")] == [f"aloha:{p:g}"
                                                                     for p in frontier.ALOHA_PROBABILITIES]
    assert all(points[f"aloha:{p:g}"]["family"] == "aloha" for p in frontier.ALOHA_PROBABILITIES)
    plain = frontier.cells(SMALL, 30, [], quick=True)
    assert not any(cell["policy"].startswith(("aloha", "round_robin")) for cell in plain)


def _point(policy, messages, error, rmse):
    return {"policy": policy, "kind": "baseline", "messages_per_agent_step": messages, "mean_cost": error,
            "ci95": 0.1 * error, "rmse": rmse, "pcrb_delivered": 1.0, "pcrb_centralized": 0.9, "pcrb_local": 2.0}


@pytest.mark.parametrize(("silent_error", "log"), [(1e4, True), (20.0, False)])
def test_a_panel_spanning_orders_of_magnitude_is_drawn_on_a_log_axis(silent_error, log):
    """Each panel's y axis is logarithmic where its values span more than frontier.WIDE_RANGE, linear otherwise."""
    metrics = {"scenario": "S", "episodes": 3, "metric": "error", "unit": "m^2", "communication": "messages",
               "frontier": ["silent", "always"],
               "points": [_point("silent", 0.0, silent_error, silent_error ** 0.5), _point("always", 1.0, 2.0, 1.5)]}
    fig = frontier.figure(metrics)
    left, right = fig.axes[:2]
    assert left.get_yscale() == ("log" if log else "linear")
    assert right.get_yscale() == ("log" if silent_error ** 0.5 > frontier.WIDE_RANGE * 0.9 else "linear")
    assert plotting.figure_problems(fig) == []


def test_the_fixed_points_are_the_fixed_policies_and_the_strongest_baselines_each_once():
    """A scenario's strongest baselines play beside always, silent, random and paper; a name that builds the same
    policy as another listed one plays once (lossy_fusion's always is its paper), and plays where its twin is not
    listed (nlos_horizon's always is its constant)."""
    def fixed(scenario):
        return [c["policy"] for c in frontier.cells(scenario, 30, [], quick=True) if c["kind"] == "baseline"
                and "family" not in c]

    assert fixed("nlos_horizon") == ["always", "silent", "random", "paper", "best_constant"]
    assert fixed("lossy_fusion") == ["silent", "random", "paper"]
    assert "threshold" in fixed("gps_denied_nbp") and "always" not in fixed("gps_denied_nbp")


def test_silents_features_are_read_at_each_step():
    """What the send_on_delta grid is read from: under silent the displacement since the episode's start is 0 at the
    reset and its mean over agents and episodes grows step by step (not the last step's value repeated)."""
    values = frontier._silent_values(SMALL, "displacement", 3, 2_000_000)
    means = values.mean(axis=(1, 2))
    assert means[0] == 0.0 and np.all(np.diff(means[:6]) > 0), means[:6]
