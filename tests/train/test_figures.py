"""The figures (reproductions, leaderboard, learning curves, studies, preset frames, bench), built from small
synthetic inputs, checked for layout properties."""

from __future__ import annotations

import itertools
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter  # noqa: E402

import coloc_env  # noqa: E402
from coloc_env.config import build_config  # noqa: E402
from coloc_env.scenarios.nlos_horizon import NlosHorizonConfig  # noqa: E402
from train import demo_summary, plotting  # noqa: E402
from train.reproduce import gao2016, wan2014  # noqa: E402


def _overlap(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


@pytest.fixture
def wan_metrics():
    rng = np.random.default_rng(0)
    T = 30

    def point():
        return {method: {"err_fault": float(rng.uniform(4, 9)), "err_fault_run_std": float(rng.uniform(0.5, 2)),
                         "err_fault_t": list(rng.uniform(2, 12, T)), "err_fault_t_ci95": list(rng.uniform(0.5, 2, T))}
                for method in ("dnbp", "ls", "dr")}

    # errors between 4 and 9 m: less than a decade, where a log axis showed one or two labels
    m = {"runs": 3, "default": point()}
    for key, (_field, values) in wan2014.SWEEPS.items():
        m[key] = {f"{v:g}": point() for v in values}
    return m


def test_wan2014_fig6_panels_do_not_overlap_and_carry_error_bars(wan_metrics):
    fig = wan2014.fig6_sweeps(wan_metrics)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    boxes = [ax.get_tightbbox(renderer) for ax in fig.axes]
    assert len(boxes) == 4
    for a, b in itertools.combinations(boxes, 2):
        assert not _overlap(a, b), (a, b)
    assert plotting.figure_problems(fig) == []
    from scipy import stats

    t = stats.t.ppf(0.975, wan_metrics["runs"] - 1)
    for ax, (key, _, _) in zip(fig.axes, wan2014.FIG6_PANELS, strict=True):
        assert ax.get_yscale() == "linear" and ax.get_ylim()[0] == 0
        assert len(ax.containers) == 3  # one errorbar container per method
        _, _, (bars,) = ax.containers[0]  # dNBP: its 95 % t-interval from the run-to-run spread
        half = [0.5 * (seg[1, 1] - seg[0, 1]) for seg in bars.get_segments()]
        runs = wan_metrics["runs"]
        expected = [t * p["dnbp"]["err_fault_run_std"] / np.sqrt(runs) for p in wan_metrics[key].values()]
        np.testing.assert_allclose(half, expected, rtol=1e-9)
    plt.close(fig)


def test_wan2014_figures_follow_the_conventions(wan_metrics):
    from coloc_env.scenarios.gps_denied_nbp import GpsDeniedNbpConfig

    config = build_config(GpsDeniedNbpConfig, {})
    history = [np.random.default_rng(n).normal(200, 50, (6, 40, 2)) for n in range(3)]
    case = {"spread_after_iteration": [[10.0] * 6] * 3, "error_after_iteration": [[5.0] * 6] * 3}
    for fig in (wan2014.fig4_case_study(case, history), wan2014.fig5_error_vs_time(wan_metrics, config),
                wan2014.tradeoff(wan_metrics)):
        assert plotting.figure_problems(fig) == []
        plt.close(fig)
    fig = wan2014.tradeoff(wan_metrics)
    (ax,) = fig.axes
    assert "particles" in ax.get_xlabel() and "time" not in ax.get_xlabel()
    assert [float(t) for t in ax.get_xticks()] == [50.0, 100.0, 200.0, 300.0]
    plt.close(fig)


def test_gao2016_fig6_legend_is_outside_the_data_area():
    config = build_config(NlosHorizonConfig, {"num_agents": 1})
    rng = np.random.default_rng(1)
    R, K, S = 3, config.horizon, 30
    res = {"afge": {"known": rng.uniform(0.1, 1, (R, K))}, "dfir": {"known": rng.uniform(0.1, 1, (R, K, S))},
           "kf": {"known": rng.uniform(0.1, 1, (R, K)), "blind": rng.uniform(1, 10, (R, K))},
           "kf_matched": {"known": rng.uniform(0.1, 1, (R, K))}}
    fig = gao2016.fig6_rmse_over_time(res, 5, config)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    (ax,) = fig.axes
    legend = ax.get_legend()
    assert legend is not None
    assert len(legend.get_texts()) == 7  # five series, the band and the turns' shading
    assert not _overlap(legend.get_window_extent(renderer), ax.get_window_extent(renderer))
    plt.close(fig)


def _capture(monkeypatch, module, name="save_figure"):
    saved = {}
    monkeypatch.setattr(module, name, lambda path, fig: saved.update(path=path, fig=fig))
    return saved


def test_learning_curve_bands_are_labelled(monkeypatch, tmp_path):
    import train.evaluate
    import train.io
    from train import training

    monkeypatch.setattr(training, "_play", lambda *args, **kwargs: {"mean_cost": 3.0, "ci95": 0.4})
    saved = _capture(monkeypatch, train.io)
    training.write_learning_curve(str(tmp_path), "bandwidth_fusion", [(100, 5.0, 1.0), (200, 4.0, 0.5)], "t")
    labels = [t.get_text() for t in saved["fig"].axes[0].get_legend().get_texts()]
    n = training.CURVE_EPISODES
    interval = [s for s in labels if f"95 % interval over {n} validation episodes" in s]
    assert len(interval) == 2, labels  # the trained policy's band and the paper policy's
    assert any(s.startswith("paper policy") and "3" in s for s in labels), labels
    assert os.path.isfile(tmp_path / "curve.json")
    ax = saved["fig"].axes[0]
    assert "J_K" in ax.get_ylabel() and ax.get_ylabel().endswith("[m\u00b2]"), ax.get_ylabel()
    assert len(ax.containers) == 1  # the points carry error bars
    assert plotting.figure_problems(saved["fig"]) == []
    plt.close(saved["fig"])


def _row(policy, mean, ci=0.1):
    return {"policy": policy, "scenario": "bandwidth_fusion", "mean_cost": mean, "ci95": ci, "episodes": 4,
            "seed_base": 0, "per_episode_cost": [mean] * 4, "paper_cost": mean, "communication_per_step": 1.0}


def test_leaderboard_is_linear_dots_and_intervals_with_an_outlier_at_the_edge(monkeypatch):
    from train import leaderboard

    table = {p: _row(p, v) for p, v in (("random", 500.0), ("paper", 2.0), ("oracle_static", 1.5),
                                         ("always", 1.8))}
    fig = leaderboard.leaderboard_figure(table, "zhao2020")
    assert plotting.figure_problems(fig) == []
    means, diffs = fig.axes[0], fig.axes[1]
    for ax in (means, diffs):
        assert ax.get_xscale() == "linear" and ax.get_yscale() == "linear"
        assert ax.get_xlim()[1] < 100  # random (500) does not set the scale
    assert "[m\u00b2]" in means.get_xlabel() and "oracle_static" in diffs.get_xlabel()
    assert any(t.get_text() == "500" for t in means.texts), [t.get_text() for t in means.texts]
    assert [t.get_text() for t in means.get_yticklabels()] == ["oracle_static", "always", "paper", "random"]
    legend = fig.legends[0].get_texts()
    assert any("off scale" in t.get_text() for t in legend)
    assert any("strongest realizable baseline, oracle_static" in t.get_text() for t in legend)
    plt.close(fig)


def test_leaderboard_says_why_identical_rows_coincide(tmp_path):
    from train import leaderboard

    for policy, mean in (("always", 2.0), ("silent", 2.0), ("oracle_static", 1.5)):
        leaderboard.record(_row(policy, mean), str(tmp_path), "zhao2020", draw=False)
    table = leaderboard.read_json(str(tmp_path / "zhao2020" / "leaderboard.json"))
    assert leaderboard.identical_rows(table) == [("always", "silent")]
    text = (tmp_path / "leaderboard.md").read_text()
    assert "`always` and `silent` are identical episode by episode" in text and "exact_budget" in text
    fig = leaderboard.leaderboard_figure(table, "zhao2020")
    assert "always and silent identical" in fig._suptitle.get_text()
    plt.close(fig)


def test_figure_problems_finds_a_missing_unit_a_sparse_log_axis_and_a_legend_over_the_data():
    fig, (a, b) = plt.subplots(1, 2)
    a.plot(np.linspace(0, 1, 50), np.linspace(0, 1, 50), label="a line through the legend's corner")
    a.legend(loc="upper left")
    a.set_xlabel("time")  # no unit
    b.plot([1, 2], [4.0, 9.0])
    b.set_yscale("log")
    b.set_ylim(4.0, 9.0)
    b.yaxis.set_major_locator(FixedLocator([5.0]))  # one labelled tick inside
    b.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    b.yaxis.set_minor_formatter(NullFormatter())
    b.set_xlabel("x [m]")
    b.set_ylabel("error [m]")
    problems = plotting.figure_problems(fig)
    assert any("'time' names no unit" in p for p in problems), problems
    assert any("y axis without a label" in p for p in problems), problems
    assert any("log y axis with" in p for p in problems), problems
    assert any("legend covers" in p for p in problems), problems
    plotting.plain_log_ticks(b)
    a.set_xlabel("time [s]")
    a.set_ylabel("error [m]")
    plotting.legend_outside(a)
    assert plotting.figure_problems(fig) == []
    plt.close(fig)


def test_demo_summary_on_an_empty_folder_says_what_is_missing(tmp_path):
    text = demo_summary.summary(str(tmp_path))
    for paper in demo_summary.PAPERS:
        assert f"missing: {tmp_path / paper}/" in text
    assert f"missing: {tmp_path / 'leaderboard.md'}" in text
    assert f"missing: {tmp_path / '.demo_times'}" in text


def test_demo_summary_reads_claims_verdicts_and_stage_times(tmp_path, capsys):
    import json

    (tmp_path / "zhao2020").mkdir()
    (tmp_path / "zhao2020" / "metrics.json").write_text(json.dumps({"claims": {"a": True, "b": False}}))
    (tmp_path / "fu2017").mkdir()
    (tmp_path / "fu2017" / "metrics.json").write_text(json.dumps({"claims": {"n3": {"x": True, "y": True}}}))
    (tmp_path / "gao2016").mkdir()
    (tmp_path / "gao2016" / "report.md").write_text(
        "# r\n\n| claim | our numbers | criterion | holds |\n|---|---|---|---|\n| c1 | 1 | < 2 | yes |\n"
        "| c2 | 3 | < 2 | **no** |\n\nafter\n")
    (tmp_path / "leaderboard.md").write_text(
        "# Leaderboard\n\n## bandwidth_fusion (`bandwidth_fusion`)\n\nTarget: beat it. seed0: beats: **met**.\n\n"
        "## relay_ukf (`relay_ukf`)\n\nTarget: beat it. seed0: worse: **not met**.\n\n## x (`x`)\n\nno target\n")
    (tmp_path / ".demo_times").write_text("100 130 reproduce all --quick\n130 205 train relay_ukf\nbad line\n"
                                          "110 150 train nlos_horizon\n")
    demo_summary.main([str(tmp_path)])
    text = capsys.readouterr().out
    assert "zhao2020  1 held, 1 failed; failed: b" in text
    assert "fu2017    2 held, 0 failed" in text
    assert "gao2016   1 held, 1 failed; failed: c2" in text
    assert "missing: " + str(tmp_path / "wan2014") in text
    # a report's table is what is counted, and a metrics.json listing fewer of its claims is pointed out
    (tmp_path / "wan2014").mkdir()
    (tmp_path / "wan2014" / "metrics.json").write_text(json.dumps({"claims": {"c1": True}}))
    (tmp_path / "wan2014" / "report.md").write_text(
        "| claim | our numbers | criterion | holds |\n|---|---|---|---|\n| c1 | 1 | < 2 | yes |\n"
        "| c2 | 3 | < 2 | **no** |\n| c3 | 3 | < 2 | **no** |\n")
    (tmp_path / "fu2017" / "report.md").write_text(
        "| claim | setting | our numbers | holds |\n|---|---|---|---|\n| c1 | n3 | 1 | yes |\n"
        "| c1 | n5 | 2 | **no** |\n")
    assert demo_summary.paper_claims(str(tmp_path), "fu2017")[0] == [("c1 (n3)", True), ("c1 (n5)", False)]
    assert demo_summary.paper_claims(str(tmp_path), "wan2014") == (
        [("c1", True), ("c2", False), ("c3", False)],
        f"{tmp_path / 'wan2014' / 'report.md'}; metrics.json lists 1 of its 3 claims")
    lines = text.splitlines()
    assert any("bandwidth_fusion (`bandwidth_fusion`)" in s and "target met" in s for s in lines)
    assert any("relay_ukf (`relay_ukf`)" in s and "target not met" in s for s in lines)
    assert any(s.strip().startswith("reproduce all --quick") and s.strip().endswith("30 s") for s in lines)
    assert any(s.strip().startswith("train relay_ukf") and s.strip().endswith("1 min 15 s") for s in lines)
    assert any(s.strip().startswith("total of the stages") and s.strip().endswith("2 min 25 s") for s in lines)
    assert any(s.strip().startswith("wall clock") and s.strip().endswith("1 min 45 s") for s in lines)


def test_gao2016_figure6_is_a_moving_mean_with_its_interval_band_and_follows_the_conventions():
    """Each curve is the square root of the run-mean of the per-run moving mean of the squared error, and its band
    the 95 % t-interval of that run-mean (square roots of its ends, cut at the axis where it reaches 0)."""
    config = build_config(NlosHorizonConfig, {"num_agents": 1})
    rng = np.random.default_rng(3)
    R, K = 5, config.horizon
    res = {"afge": {"known": rng.gamma(2.0, 2.0, (R, K))}, "dfir": {"known": rng.gamma(2.0, 2.0, (R, K, 10))},
           "kf": {"known": rng.gamma(2.0, 2.0, (R, K)), "blind": rng.gamma(4.0, 2.0, (R, K))},
           "kf_matched": {"known": rng.gamma(2.0, 2.0, (R, K))}}
    fig = gao2016.fig6_rmse_over_time(res, 5, config)
    assert plotting.figure_problems(fig) == []
    (ax,) = fig.axes
    smooth = gao2016.moving_mse(res["afge"]["known"])
    window = gao2016.SMOOTHING_STEPS
    assert np.allclose(smooth[:, 50], res["afge"]["known"][:, 50 - window // 2:50 + window // 2 + 1].mean(axis=1),
                       rtol=1e-12)
    afge = next(line for line in ax.get_lines() if line.get_label() == "AFGE")
    assert np.allclose(afge.get_ydata(), np.sqrt(smooth.mean(axis=0)), rtol=1e-12)
    band = ax.collections[0].get_paths()[0].vertices
    upper = np.sqrt(smooth.mean(axis=0) + plotting.t975(R - 1) * smooth.std(axis=0, ddof=1) / np.sqrt(R))
    assert np.isclose(band[:, 1].max(), upper.max(), rtol=1e-12)
    plt.close(fig)


def test_gao2016_fig6_log_ticks_are_plain():
    config = build_config(NlosHorizonConfig, {"num_agents": 1})
    rng = np.random.default_rng(2)
    R, K = 2, config.horizon
    res = {"afge": {"known": rng.uniform(1, 4, (R, K))}, "dfir": {"known": rng.uniform(1, 4, (R, K, 10))},
           "kf": {"known": rng.uniform(1, 4, (R, K)), "blind": rng.uniform(4, 9, (R, K))},
           "kf_matched": {"known": rng.uniform(1, 4, (R, K))}}
    fig = gao2016.fig6_rmse_over_time(res, 5, config)
    fig.canvas.draw()
    (ax,) = fig.axes
    major = [t.get_text() for t in ax.get_yticklabels() if t.get_text()]
    assert len(major) >= 2 and all("times" not in s for s in major), major
    assert not [t.get_text() for t in ax.get_yticklabels(minor=True) if t.get_text()]
    plt.close(fig)


@pytest.mark.parametrize("name", [s for s in coloc_env.SCENARIOS if s != "mrclam_relay"])
def test_every_preset_frame_follows_the_figure_conventions(name):
    """One frame of each simulated preset (MRCLAM needs data; tests/coloc_env/test_frames.py draws it): metre
    axes labelled with their unit and the legend clear of every panel's data."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    import agents
    from coloc_env.rendering import draw_scene

    env = coloc_env.parallel_env(name)
    observations, _ = env.reset(seed=0)
    policy = agents.make_policy("paper", env)
    for _ in range(4):
        observations, *_ = env.step(policy.act(observations))
    figure = Figure(figsize=(9.6, 6.0), dpi=100)
    FigureCanvasAgg(figure)
    draw_scene(env.unwrapped.scenario.scene(0), figure, env.possible_agents)
    assert plotting.figure_problems(figure) == []
    env.close()


def _fu2017_data(runs=5, K=30, seed=3):
    from train.reproduce import fu2017

    rng = np.random.default_rng(seed)
    names = (*fu2017.lf.FILTERS, *fu2017.DIAGNOSTICS)
    data = {}
    for key in ("L2", "L4"):
        errors = {f: rng.gamma(2.0, 5.0 * (1 + i), (runs, K)) for i, f in enumerate(names)}
        errors["centralized_paper_gain"] = errors["centralized"] * 1.001  # on the LMMSE curve
        data[key] = {"errors": errors, "own": {f: np.full(K, 10.0 * (1 + i)) for i, f in enumerate(names)}}
    return data


def test_fu2017_curves_follow_the_conventions_with_bands_and_every_line_in_the_legend():
    from matplotlib.collections import PolyCollection

    from train.reproduce import fu2017

    data = _fu2017_data()
    for filters, title, own in fu2017.FIGURES.values():
        fig = fu2017.curves_figure(data, filters, title, 1.0, own)
        assert plotting.figure_problems(fig) == [], title
        left = fig.axes[0]
        bands = [c for c in left.collections if isinstance(c, PolyCollection)]
        assert len(bands) == len(filters)  # every mean with its 95 % band
        texts = [t.get_text() for t in fig.axes[-1].get_legend().get_texts()]
        assert len(texts) == len(filters) + 1 + own  # the filters, the band, the dashed own covariances
        assert any("95 %" in t for t in texts)
        if own:
            assert any("own" in t and "covariance" in t for t in texts)
        if "centralized_paper_gain" in filters:
            assert any(t.startswith(fu2017.LABELS["centralized_paper_gain"]) and "on the curve of (A) centralized, "
                       "LMMSE gain" in t for t in texts), texts
        plt.close(fig)
    # the band is the Student-t interval of the mean over the runs at each slot
    fig = fu2017.curves_figure(data, ("ideal_kf",), "t", 1.0)
    err = data["L2"]["errors"]["ideal_kf"]
    (band,) = [c for c in fig.axes[0].collections if isinstance(c, PolyCollection)]
    top = band.get_paths()[0].vertices[:, 1].max()
    half = plotting.t975(err.shape[0] - 1) * err.std(axis=0, ddof=1) / np.sqrt(err.shape[0])
    np.testing.assert_allclose(top, (err.mean(axis=0) + half).max(), rtol=1e-9)
    plt.close(fig)


def test_plain_log_ticks_labels_a_range_of_many_decades_without_moving_its_limits():
    fig, ax = plt.subplots()
    ax.semilogy(np.arange(51), np.logspace(0, 9, 51))
    ax.set_xlabel("k [step]")
    ax.set_ylabel("J [m²]")
    before = ax.get_ylim()
    plotting.plain_log_ticks(ax)
    assert ax.get_ylim() == before  # not widened: matplotlib drops sub-decade ticks there, the decades remain
    assert plotting.figure_problems(fig) == []
    plt.close(fig)


def test_zhao2020_figures_follow_the_conventions():
    from train.reproduce import zhao2020

    rng = np.random.default_rng(4)
    K, N = 20, 4
    truth = np.cumsum(rng.normal(0.5, 0.2, (K + 1, 3)), axis=0)
    estimate = truth[:, None, :] + rng.normal(0, 0.3, (K + 1, N, 3))
    estimate[:, :, 1] = estimate[:, :1, 1]  # every node the same on y
    fig = zhao2020.trajectory_error_figure(truth, estimate)
    assert plotting.figure_problems(fig) == []
    x, y, z = fig.axes
    np.testing.assert_allclose(x.get_lines()[1].get_ydata(), estimate[:, 0, 0] - truth[:, 0], rtol=1e-12)
    assert "identical" in y.get_title() and "identical" not in z.get_title()
    plt.close(fig)

    pairs = ("T1P1", "T2P1", "T3P1")
    exact = {p: rng.uniform(0.5, 1.0, K + 1) for p in pairs}
    bound = {p: np.exp(np.linspace(0, 12, K + 1)) for p in pairs}  # the bound grows over many decades
    mc = {p: {"mean_curve": exact[p] * 1.01, "cumulative_sd": np.linspace(0.1, 2, K + 1), "runs": 50}
          for p in pairs}
    fig = zhao2020.cost_figure(exact, bound, mc, pairs, ("T1", "T2", "T3"), "t")
    assert plotting.figure_problems(fig) == []
    assert len(fig.axes[0].containers) == 3  # the Monte Carlo means carry error bars
    plt.close(fig)

    curves = {"paper T1P1": exact["T1P1"], "greedy (P1)": exact["T2P1"]}
    fig = zhao2020.policies_figure(curves, "oracle_static", exact["T3P1"])
    assert plotting.figure_problems(fig) == []
    (ax,) = fig.axes
    assert not any(len(set(line.get_ydata())) == 1 and len(line.get_ydata()) > 1 for line in ax.get_lines())
    star = [line for line in ax.get_lines() if line.get_marker() == "*"]
    assert len(star) == 1 and list(star[0].get_xdata()) == [K]  # J_K of the oracle at k = K, not a line
    assert star[0].get_ydata()[0] == pytest.approx(exact["T3P1"].sum(), rel=1e-12)
    plt.close(fig)


def test_zhao2020_oracle_static_curve_sums_to_its_searched_cost():
    from agents.bandwidth_fusion import oracle_static_search
    from coloc_env.scenarios.bandwidth_fusion import BandwidthFusionConfig, BandwidthFusionScenario
    from train.reproduce import zhao2020

    config = build_config(BandwidthFusionConfig, {"horizon": 10})
    best = oracle_static_search(BandwidthFusionScenario(config, batch=1))[0]
    curve = zhao2020.oracle_static_curve(best, config)
    assert curve.shape == (11,)
    assert curve.sum() == pytest.approx(best.cost, rel=1e-9)


def _study_metrics(sweep=True):
    rng = np.random.default_rng(5)
    backends = ("ukf_ccl", "ukf_dcl", "dead_reckoning")
    keys = ["0", "0.3", "0.6"] if sweep else ["default"]

    def cell(mean):
        return {"position_error": {"mean": mean, "ci95": 0.1}, "rmse": mean * 1.2, "pcrb_centralized": 0.9}

    same = {k: float(rng.uniform(0.7, 0.9)) for k in keys}
    cells = {"ukf_ccl": {k: cell(same[k]) for k in keys}, "ukf_dcl": {k: cell(same[k]) for k in keys},
             "dead_reckoning": {k: cell(3.4) for k in keys}}  # ukf_ccl and ukf_dcl equal: the dodge keeps them apart
    paired = {b: {k: {"mean": cells[b][k]["position_error"]["mean"] - same[k], "ci95": 0.05, "verdict": "x"}
                  for k in keys} for b in backends[1:]}
    compositions = {b: {k: {"world": {"name": "circles"}, "network": {"name": "relay"}, "backend": {"name": b}}
                        for k in keys} for b in backends}
    config = {"policy": "always", "episodes": 4, "compositions": compositions,
              "sweep": {"part": "network", "field": "loss_at_zero", "values": [0, 0.3, 0.6], "keys": keys}
              if sweep else None}
    return {"world": "circles", "network": "relay", "reference": "ukf_ccl", "backends": cells, "paired": paired,
            "config": config}


@pytest.mark.parametrize("sweep", [True, False])
def test_study_figure_is_dots_with_intervals_a_paired_panel_and_a_legend_off_the_data(sweep):
    from train import study

    fig = study.figure(_study_metrics(sweep))
    assert plotting.figure_problems(fig) == []
    errors, diffs = fig.axes
    assert len(errors.containers) == 3 and len(diffs.containers) == 2  # every mean with its error bar
    assert errors.get_legend() is None and diffs.get_legend() is not None
    assert any("pcrb_centralized" in t.get_text() for t in diffs.get_legend().get_texts())
    assert "[m]" in errors.get_ylabel() and "ukf_ccl" in diffs.get_ylabel()
    if sweep:
        assert errors.get_xlabel() == "network.loss_at_zero [-]"
        ccl, dcl = (c.lines[0].get_xdata() for c in errors.containers[:2])
        assert np.all(np.asarray(dcl) > np.asarray(ccl))  # equal values drawn side by side, not on top
    plt.close(fig)


def test_study_sweep_axis_unit_comes_from_the_parts_table():
    from train.study import field_unit

    assert field_unit("network", "relay", "loss_at_zero") == "-"
    assert field_unit("network", "relay", "comm_range") == "m"
    assert field_unit("world", "circles", "speed") == "m/s"
    assert field_unit("world", "circles", "horizon") == "step"
    assert field_unit("backend", "dnbp", "num_particles") == "count"
    assert field_unit("network", "no_such_network", "x") == "as documented"


def _wang_summary(runs=4, K=30, N=4, seed=6):
    from train.reproduce import wang2019

    rng = np.random.default_rng(seed)
    summary = {}
    for name in ("default", "paper_literal"):
        for p in wang2019.PROBABILITIES:
            per_run = np.stack([rng.uniform(3.5, 4.5, runs), rng.uniform(1.0, 3.0, runs), rng.uniform(1.0, 3.0, runs)])
            curves = rng.uniform(0.5, 5.0, (3, K, N))
            curves[2] = curves[1] + 1e-13
            chains = np.full((K, N), -1)
            chains[::3] = [rng.permutation(N) for _ in range(len(chains[::3]))]
            summary[name, p] = {"per_run": per_run, "curves": curves, "curves_sd": np.full((3, K, N), 0.5),
                                "chains": chains, "tracks": rng.normal(0, 50, (2, K, N, 2))}
    return summary


def test_wang2019_figures_follow_the_conventions():
    from train.reproduce import wang2019

    summary = _wang_summary()
    main = summary["default", 0.5]
    truncation = {"max_hops": 1,
                  "paper": {"min_eigenvalue_per_step": [1e-2, 1e-3, -1e-2], "cholesky_failed_at_step": 4},
                  "consistent": {"min_eigenvalue_per_step": [1e-2] * 6, "cholesky_failed_at_step": None}}
    figures = [wang2019.trajectories_figure(np.random.default_rng(0).normal(0, 50, (30, 4, 2)), main["tracks"], 0.5),
               wang2019.platform_errors_figure(main, 4, 0.5, 0.5), wang2019.error_vs_p_figure(summary),
               wang2019.topology_figure(main["chains"], 0.5, 0.05), wang2019.truncated_chain_figure(truncation, 0.5)]
    for fig in figures:
        assert plotting.figure_problems(fig) == [], fig.axes[0].get_title()
        plt.close(fig)


def test_wang2019_fig7_carries_interval_bars_over_the_runs_and_names_the_coinciding_curves():
    from train.reproduce import wang2019

    summary = _wang_summary()
    fig = wang2019.error_vs_p_figure(summary)
    (ax,) = fig.axes
    assert len(ax.containers) == 3
    _, _, (bars,) = ax.containers[0]  # UKF-CCL with the heading term: t-interval of the mean over the runs
    half = [0.5 * (seg[1, 1] - seg[0, 1]) for seg in bars.get_segments()]
    runs = [summary["default", p]["per_run"][1] for p in wang2019.PROBABILITIES]
    expected = [plotting.t975(len(v) - 1) * v.std(ddof=1) / np.sqrt(len(v)) for v in runs]
    np.testing.assert_allclose(half, expected, rtol=1e-9)
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any("of the heading-term curve" in t for t in texts), texts
    assert ax.get_xlabel().endswith("[-]")
    plt.close(fig)


def test_bench_throughput_figure_follows_the_conventions_with_one_colour_per_series(monkeypatch, tmp_path):
    from train.bench import throughput

    rows = [{"scenario": s, "what": w, "batch": b, "env_steps_per_s": 100.0 * b ** 0.7 * (k + 1)}
            for s in ("bandwidth_fusion", "relay_ukf") for k, w in enumerate(("vector_env", "estimator step"))
            for b in (1, 64, 1024)]
    rows += [{"scenario": "relay_ukf", "what": f"dNBP step, M = {m}", "batch": 4, "env_steps_per_s": 1e4 / m}
             for m in (50, 100)]
    drawn = {}
    monkeypatch.setattr(throughput, "save_figure", lambda path, fig: drawn.setdefault("fig", fig))
    throughput._figure(rows, str(tmp_path / "throughput.png"))
    fig = drawn["fig"]
    assert plotting.figure_problems(fig) == []
    colours = {}
    for ax in fig.axes:
        for line in ax.get_lines():
            colours.setdefault(line.get_label(), set()).add(line.get_color())
    assert all(len(c) == 1 for c in colours.values()), colours
    plt.close(fig)


def test_bench_scaling_figure_follows_the_conventions(monkeypatch):
    """coloc bench --scaling's log-log figure: units on both axes, the sizes as plain x ticks, plain y ticks, the
    legend below the panels."""
    from train.bench import scaling

    saved = _capture(monkeypatch, scaling)
    sizes = (5, 10, 20, 40, 80)
    rows = [{"layout": layout, "batch": 8, "backend": backend, "network": "broadcast",
             "current": {"env_steps_per_s": [rate / n ** slope for n in sizes], "exponent": slope},
             "reference": {"env_steps_per_s": [rate / 2 / n ** slope for n in sizes[:3]] + [None, None],
                           "exponent": slope}}
            for layout in ("fixed area", "fixed density")
            for backend, rate, slope in (("ukf_ccl", 2e4, 2.5), ("range_ls", 5e4, 1.0))]
    scaling._scaling_figure(rows, sizes, "REF", "scaling.png")
    fig = saved["fig"]
    assert plotting.figure_problems(fig) == []
    for ax in fig.axes:
        assert [t.get_text() for t in ax.get_xticklabels() if t.get_text()] == ["5", "10", "20", "40", "80"]
    plt.close(fig)
