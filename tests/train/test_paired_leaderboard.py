"""Paired leaderboard: the paired t-interval, its verdict, the strongest realizable baseline,
bounds apart, reference filters and rule runners on the env's own episodes, validation-only tuning and a
``record`` that keeps every row when several processes write at once."""

import math
import multiprocessing
import os

import numpy as np
import pytest
from scipy import stats

from train.evaluate import EVAL_SEED_BASE, SEED_RANGE, VALIDATION_SEED_BASE
from train.io import read_json, write_json
from train.leaderboard import (
    bound_rows,
    episodes_needed,
    markdown,
    paired_difference,
    record,
    rows,
    strongest_baseline,
    target_verdict,
    verdict,
)


def test_paired_interval_is_scipys_t_interval_on_the_differences():
    rng = np.random.default_rng(11)
    reference = rng.normal(10.0, 2.0, size=25)
    costs = reference + rng.normal(-0.4, 1.0, size=25)
    diff = paired_difference(costs, reference)
    d = costs - reference
    low, high = stats.t.interval(0.95, len(d) - 1, loc=d.mean(), scale=stats.sem(d))
    assert diff["low"] == pytest.approx(low, abs=1e-9) and diff["high"] == pytest.approx(high, abs=1e-9)
    assert diff["mean"] == pytest.approx(np.mean(costs) - np.mean(reference), abs=1e-12)
    assert diff["episodes"] == 25


def test_rounding_differences_are_equal_not_a_number_of_episodes_away():
    """Two policies playing the same episodes (greedy = always on a composition) differ by float rounding:
    'equal to rounding', not 'not distinguishable; ~5 episodes would resolve it'; a real difference of 1e-6
    relative still gets its verdict and its episode count."""
    reference = np.random.default_rng(4).uniform(0.5, 1.5, size=8)
    rounding = paired_difference(reference + np.array([2e-16, -1e-16, 3e-16, 0, 1e-16, 2e-16, 0, 4e-16]), reference)
    assert rounding["equal"] and verdict(rounding) == "equal to rounding" and rounding["episodes_needed"] is None
    small = paired_difference(reference + 1e-6 * np.linspace(0.5, 1.5, 8), reference)
    assert not small["equal"] and verdict(small) == "worse"


@pytest.mark.parametrize("seed", range(8))
def test_interval_excludes_zero_exactly_when_the_paired_t_test_rejects(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(5, 40))
    reference = rng.normal(5.0, 1.0, size=n)
    costs = reference + rng.normal(rng.uniform(-0.8, 0.8), rng.uniform(0.3, 2.0), size=n)
    diff = paired_difference(costs, reference)
    p_value = stats.ttest_rel(costs, reference).pvalue
    assert (p_value < 0.05) == (diff["high"] < 0 or diff["low"] > 0)
    assert (verdict(diff) == "beats") == (p_value < 0.05 and diff["mean"] < 0)


def test_verdict_flips_from_beats_to_not_distinguishable_as_noise_grows():
    z = np.random.default_rng(3).standard_normal(20)
    reference = np.full(20, 50.0)
    verdicts = [verdict(paired_difference(reference - 1.0 + scale * z, reference)) for scale in (0.1, 0.5, 2, 8, 30)]
    assert verdicts[0] == "beats"
    assert verdicts[-1] == "not distinguishable (20 episodes)"
    flipped = verdicts.index("not distinguishable (20 episodes)")
    assert all(v == "beats" for v in verdicts[:flipped]) and all(v != "beats" for v in verdicts[flipped:])


@pytest.mark.parametrize("mean, sd", [(0.5, 1.0), (0.05, 1.0), (-2.0, 3.0), (1.0, 0.2)])
def test_episodes_needed_is_the_least_n_whose_interval_resolves_the_difference(mean, sd):
    n = episodes_needed(mean, sd)
    assert stats.t.ppf(0.975, n - 1) * sd / math.sqrt(n) < abs(mean)
    if n > 2:
        assert stats.t.ppf(0.975, n - 2) * sd / math.sqrt(n - 1) >= abs(mean)
    assert episodes_needed(0.0, sd) is None


def test_paired_difference_refuses_unpaired_or_too_short_samples():
    with pytest.raises(ValueError, match="one length"):
        paired_difference([1.0, 2.0, 3.0], [1.0, 2.0])
    with pytest.raises(ValueError, match="at least 2 episodes"):
        paired_difference([1.0], [2.0])


def _row(policy, costs, comm=1.0, scenario="relay_ukf", seed_base=EVAL_SEED_BASE):
    costs = np.asarray(costs, float)
    return {"scenario": scenario, "policy": policy, "mean_cost": float(costs.mean()), "ci95": 0.1,
            "paper_cost": float(costs.mean()), "initial_cost": 0.0, "communication_per_step": comm,
            "episodes": len(costs), "seed_base": seed_base, "per_episode_cost": list(costs)}


def _relay_table(noise, shift=-0.05):
    """paper (full chain) and no_relay, a bound that is better than all, a trained model shift below paper."""
    rng = np.random.default_rng(0)
    paper = 1.5 + 0.1 * rng.standard_normal(30)
    return {"paper": _row("paper", paper, comm=3.0), "no_relay": _row("no_relay", paper + 0.3, comm=0.0),
            "nearest_local": _row("nearest_local", paper + 0.1, comm=2.0),
            "bound_truth": _row("bound_truth", paper - 0.5, comm=3.0),
            "/m/seed0/model.zip": _row("/m/seed0/model.zip", paper + shift + noise * rng.standard_normal(30),
                                       comm=3.0)}


def test_target_is_judged_paired_against_the_strongest_realizable_baseline_not_a_bound():
    table = _relay_table(noise=0.01)
    assert strongest_baseline("relay_ukf", table)["policy"] == "paper"  # the bound is lower but never a baseline
    line = target_verdict("relay_ukf", table)
    assert "Strongest realizable baseline: paper" in line and "seed0: beats" in line and "**met**" in line
    noisy = target_verdict("relay_ukf", _relay_table(noise=1.0))
    assert "seed0: not distinguishable (30 episodes)" in noisy and "**not met**" in noisy
    assert "episodes would resolve" in noisy
    # without the full chain, the strongest listed baseline is no_relay, and the model beats it clearly
    table.pop("paper")
    assert strongest_baseline("relay_ukf", table)["policy"] == "no_relay"


def test_matching_the_baseline_with_much_less_communication_meets_the_target():
    rng = np.random.default_rng(5)
    paper = 1.5 + 0.1 * rng.standard_normal(40)
    model = paper + 0.002 * rng.standard_normal(40)  # the same error to well within 2 %
    table = {"paper": _row("paper", paper, comm=3.0), "a/seed1/model.zip": _row("a/seed1/model.zip", model, comm=1.5)}
    assert "seed1: matches with 50 % less communication" in target_verdict("relay_ukf", table)
    table["a/seed1/model.zip"]["communication_per_step"] = 2.5  # only 17 % less: not enough
    assert "**not met**" in target_verdict("relay_ukf", table)


def test_rows_on_other_seeds_are_not_paired():
    table = _relay_table(noise=0.01)
    table["/m/seed0/model.zip"]["seed_base"] = VALIDATION_SEED_BASE
    assert "seed0: not paired" in target_verdict("relay_ukf", table)


def test_bounds_are_listed_apart_and_every_numeric_column_names_its_unit(tmp_path):
    table = _relay_table(noise=0.01)
    assert [r["policy"] for r in bound_rows(table)] == ["bound_truth"]
    assert "bound_truth" not in [r["policy"] for r in rows(table)]
    write_json(str(tmp_path / "wang2019" / "leaderboard.json"), table)
    text = markdown(str(tmp_path))
    assert "Episode metric: distance error averaged over the steps and platforms [m]." in text
    assert text.index("Bounds (not realizable") < text.index("| bound_truth |")
    headers = [line for line in text.splitlines() if line.startswith("| row |")]
    assert len(headers) == 2  # the table and the bounds
    for header in headers:
        cells = [c.strip() for c in header.strip("|").split("|")]
        assert cells[:2] == ["row", "what it is"]
        unitless = {"row", "what it is", "verdict (paired)"}
        assert all("[" in c and c.endswith("]") for c in cells if c not in unitless), cells
    assert "| paper | strongest realizable baseline (also always) |" in text
    assert "| /m/seed0/model.zip | trained model (seed0) |" in text


def test_lossy_fusion_reference_filters_run_on_the_envs_own_episodes():
    """The reproduction's (B) on the episodes reference rows use equals the env's paper row, episode by episode."""
    from train.evaluate import reference_filter_costs, run_episodes, run_reference_filter

    costs, followers = reference_filter_costs("lossy_fusion", "distributed", 3, EVAL_SEED_BASE)
    env = run_episodes("lossy_fusion", "paper", 3, EVAL_SEED_BASE)
    np.testing.assert_allclose(costs, env["per_episode_cost"], rtol=1e-9, atol=1e-9)
    assert followers == 1.0
    centralized = run_reference_filter("lossy_fusion", "centralized_A", 3)
    assert centralized["communication_per_step"] == env["communication_per_step"] == 1.0
    with pytest.raises(ValueError, match="unknown reference filter 'kalman'"):
        run_reference_filter("lossy_fusion", "kalman", 3)


def test_batched_rules_equal_the_env_loop():
    """The validation sweeps' batched runners give the PettingZoo loop's episodes (nlos constant, gps threshold)."""
    import math as m

    from agents.gps_denied_nbp import threshold_actions
    from train.evaluate import run_episodes, run_rule_batched

    def constant(core):
        return core.encode_actions(np.full((core.batch, core.num_agents), 8))

    batched = run_rule_batched("nlos_horizon", "constant:8", constant, 2, 77, horizon=70)
    looped = run_episodes("nlos_horizon", "constant:8", 2, 77, horizon=70)
    np.testing.assert_allclose(batched["per_episode_cost"], looped["per_episode_cost"], rtol=1e-9, atol=1e-12)
    small = {"horizon": 4, "num_particles": 30}

    def threshold(core):
        return threshold_actions(core.observation(), 4.0, core.config.num_iterations)

    batched = run_rule_batched("gps_denied_nbp", "threshold:4", threshold, 2, 5, **small)
    looped = run_episodes("gps_denied_nbp", "threshold:4", 2, 5, **small)
    np.testing.assert_allclose(batched["per_episode_cost"], looped["per_episode_cost"], rtol=1e-9, atol=1e-12)
    assert batched["communication_per_step"] == pytest.approx(looped["communication_per_step"], abs=1e-12)
    assert m.isfinite(batched["mean_cost"])


def test_tuned_baselines_were_chosen_on_validation_seeds_disjoint_from_the_evaluation_seeds():
    from agents.gps_denied_nbp import THRESHOLD_VALIDATION
    from agents.nlos_horizon import BEST_CONSTANT_VALIDATION, BEST_CONSTANT_WINDOW
    from train.evaluate import check_not_evaluation_seeds, constant_horizon_sweep, threshold_sweep

    evaluation = range(EVAL_SEED_BASE, EVAL_SEED_BASE + SEED_RANGE)
    for chosen in (BEST_CONSTANT_VALIDATION, THRESHOLD_VALIDATION):
        seeds = range(chosen["seed_base"], chosen["seed_base"] + chosen["episodes"])
        assert not set(seeds) & set(evaluation[:1000]) and seeds.start >= evaluation.stop
        check_not_evaluation_seeds(chosen["seed_base"], chosen["episodes"], "test")
    low, high = BEST_CONSTANT_VALIDATION["windows"]
    assert low <= BEST_CONSTANT_WINDOW <= high
    with pytest.raises(ValueError, match="overlaps the evaluation seeds"):
        constant_horizon_sweep([12], episodes=2, seed_base=EVAL_SEED_BASE)
    with pytest.raises(ValueError, match="overlaps the evaluation seeds"):
        threshold_sweep([10.0], episodes=5, seed_base=EVAL_SEED_BASE - 3)


def _record_many(out: str, worker: int, count: int) -> None:
    for i in range(count):
        costs = [float(worker), float(i), 1.0]
        # the chart (matplotlib, inside the lock) only on the last record, to keep the test short
        record(_row(f"w{worker}-r{i}", costs, scenario="lossy_fusion"), out, "fu2017", draw=i == count - 1)


def test_concurrent_records_keep_every_row(tmp_path):
    out = str(tmp_path)
    context = multiprocessing.get_context("spawn")
    workers = [context.Process(target=_record_many, args=(out, w, 5)) for w in range(3)]
    for p in workers:
        p.start()
    for p in workers:
        p.join(900)  # generous: four fresh interpreters import numpy, scipy and the env on a loaded machine
    assert [p.exitcode for p in workers] == [0] * 3, "a worker failed or did not finish"
    table = read_json(os.path.join(out, "fu2017", "leaderboard.json"))
    assert set(table) == {f"w{w}-r{i}" for w in range(3) for i in range(5)}
    assert all(f"| w{w}-r{i} |" in (tmp_path / "leaderboard.md").read_text() for w in range(3) for i in range(5))


def test_policy_all_runs_realizable_policies_bounds_and_reference_filters():
    import agents
    from train.evaluate import all_rows, baselines

    for scenario in ("bandwidth_fusion", "lossy_fusion", "relay_ukf", "nlos_horizon", "gps_denied_nbp",
                     "mrclam_relay", "circles/relay/ukf_dcl"):
        names = all_rows(scenario)
        assert set(baselines(scenario)) <= set(names)  # every baseline gets its row
        assert not set(agents.duplicates(scenario)) & set(names)  # the same policy is not run twice
    lossy = all_rows("lossy_fusion")
    assert {"paper", "silent", "random", "leader_only_kf", "centralized_A", "bound_informed_kf"} <= set(lossy)
    assert agents.duplicates("lossy_fusion") == {"always": "paper"}
    assert agents.duplicates("relay_ukf") == {"always": "paper", "silent": "no_relay"}
    nlos = all_rows("nlos_horizon")
    assert {"best_constant", "bound_hindsight_constant"} <= set(nlos) and "oracle_constant" not in nlos
    assert len(nlos) == len(set(nlos))


def _composition_table(model_costs, model_comm):
    rng = np.random.default_rng(9)
    always = 1.0 + 0.05 * rng.standard_normal(60)
    silent = 3.0 + 0.2 * rng.standard_normal(60)
    scenario = "circles/broadcast/ukf_ccl"
    return {"always": _row("always", always, comm=2.4, scenario=scenario),
            "silent": _row("silent", silent, comm=0.0, scenario=scenario),
            "r/seed0/model.zip": _row("r/seed0/model.zip", model_costs(always, silent, rng), comm=model_comm,
                                      scenario=scenario)}, scenario


def test_a_composition_model_below_the_always_silent_line_meets_the_trade_off_target():
    """A model 10 % less accurate than always with 79 % fewer messages is worse than always and not a match,
    but far better than always and silent time-shared to send as many messages (always in 21 % of episodes)."""
    table, scenario = _composition_table(lambda a, s, rng: 1.1 * a + 0.01 * rng.standard_normal(60), 0.5)
    line = target_verdict(scenario, table)
    assert "seed0: worse" in line
    assert "mixed to send as many messages (always in 21 % of episodes): beats" in line and "**met**" in line


def test_a_model_on_the_always_silent_line_does_not_meet_the_trade_off_target():
    """The mix itself (its expected error in every episode, at its message rate) is no gain: equal to rounding."""
    p = 0.5 / 2.4
    table, scenario = _composition_table(lambda a, s, rng: p * a + (1 - p) * s, 0.5)
    line = target_verdict(scenario, table)
    assert "mixed to send as many messages (always in 21 % of episodes): equal to rounding" in line
    assert "**not met**" in line


def test_a_model_sending_more_than_always_is_compared_with_always_itself():
    table, scenario = _composition_table(lambda a, s, rng: a + 0.02 + 0.01 * rng.standard_normal(60), 3.0)
    line = target_verdict(scenario, table)
    assert "(always in 100 % of episodes): worse" in line and "**not met**" in line
