"""Leaderboards: one table per paper (``OUT/<key>/leaderboard.json`` + a PNG bar chart) and
``OUT/leaderboard.md`` gathering every scenario evaluated so far.

Each row is one policy (or reference filter) evaluated by ``coloc evaluate`` on the evaluation
seeds 10^6 + e; every row of a scenario plays the same episodes, so rows compare *paired*:
episode by episode, the difference d_e = cost_e(row) - cost_e(baseline), its mean and the 95 %
Student-t interval  dbar +- t_{0.975, n-1} s_d / sqrt(n)  (:func:`paired_difference`). The
baseline is the scenario's strongest realizable one (``train.evaluate.baselines``: the best of
them by mean on these episodes), never a bound and not merely the paper's choice. A row
"beats" it only when that interval lies below zero; an interval that holds zero is "not
distinguishable (n episodes)", with the number of episodes a difference of this size would
need to resolve: the least n with t_{0.975, n-1} s_d / sqrt(n) < |dbar| (:func:`episodes_needed`).
Rows named ``bound_*`` use what the agents cannot have and are shown apart as bounds.

Trained models (policies given as a ``.zip`` path) are rows of their own, and are also
summarized as one "trained" row: the mean over training seeds (its paired difference uses the
per-episode mean over the seeds). ``record`` holds an exclusive ``fcntl.flock`` on
``OUT/.leaderboard.lock`` while it reads, merges and writes, so evaluations that finish at the
same time in several processes never lose a row.
"""

from __future__ import annotations

import contextlib
import fcntl
import glob
import math
import os

import numpy as np

from train.io import read_json, save_figure, write_json, write_text

LOCK_NAME = ".leaderboard.lock"
STOCHASTIC = " (stochastic)"  # suffix of a model evaluated with sampled actions (``evaluate --stochastic``)

# The episode metric (Scenario.episode_error) of each preset, its unit, and what "communication" counts.
METRICS = {
    "bandwidth_fusion": ("J_K: squared estimation error summed over the steps and receivers", "m^2"),
    "lossy_fusion": ("fused position MSE averaged over the slots", "m^2"),
    "relay_ukf": ("distance error averaged over the steps and platforms", "m"),
    "nlos_horizon": ("squared position error averaged over k >= 50 and the UAVs", "m^2"),
    "gps_denied_nbp": ("position error of the GPS-fault UAVs averaged over their (step, UAV)", "m"),
    "mrclam_relay": ("distance error against Vicon averaged over the steps and robots", "m"),
}
COMPOSITION_METRIC = ("position error averaged over the steps and agents", "m")
COMMUNICATION = {"bandwidth_fusion": "components received", "lossy_fusion": "messages transmitted",
                 "nlos_horizon": "packets", "relay_ukf": "relays", "gps_denied_nbp": "broadcasts",
                 "mrclam_relay": "messages delivered"}  # the words of train/cli.py's COMMUNICATION_UNITS

# Issue 15's target per scenario: (what it says, the largest |paired error difference| relative to the
# baseline's mean that counts as matching it, the communication saving a match needs).
TARGETS = {
    "bandwidth_fusion": ("beat the strongest baseline, or match it with 30 % less communication", 0.02, 0.30),
    "lossy_fusion": ("beat the strongest baseline, or match it with 30 % less communication", 0.02, 0.30),
    "relay_ukf": ("beat the strongest baseline, or match it with 30 % fewer hops", 0.02, 0.30),
    "nlos_horizon": ("beat the strongest baseline, or match it with 30 % fewer packets", 0.02, 0.30),
    "mrclam_relay": ("beat the strongest baseline, or match it with 30 % less communication", 0.02, 0.30),
    "gps_denied_nbp": ("the strongest baseline's error (within 5 %) with 30 % fewer broadcasts, or lower error",
                       0.05, 0.30),
}

# A composition's (issue 15's cross-combination): the error-communication trade-off against always and silent.
# "Lower error at equal messages" is judged against the time-sharing of the two (:func:`tradeoff_comparison`),
# the only way always and silent reach a message rate between theirs.
COMPOSITION_TARGET = ("beat always and silent on the error-communication trade-off: a lower error than the better "
                      "of them, its error (paired interval within 2 %) with 30 % fewer messages, or a lower error "
                      "than always and silent mixed to send as many messages", 0.02, 0.30)

KINDS = {"random": "uniform random actions (seeded)", "always": "every transport decision at its maximum",
         "silent": "the least communication the scenario allows"}


def metric(scenario: str) -> tuple[str, str]:
    """(what the episode metric is, its unit) for a preset or a composition."""
    return METRICS.get(scenario, COMPOSITION_METRIC)


# --- recording ---------------------------------------------------------------------------------------
@contextlib.contextmanager
def _locked(out: str):
    """An exclusive lock on ``out/.leaderboard.lock`` (held until the block ends, released if it raises)."""
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, LOCK_NAME), "a+") as handle:
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle.fileno(), fcntl.LOCK_UN)


def record(result: dict, out: str, key: str, draw: bool = True) -> str:
    """Merge ``result`` into ``out/<key>/leaderboard.json`` (keyed by policy), redraw its chart (``draw``)
    and the summary.

    The read-merge-write runs under an exclusive lock, so concurrent ``record`` calls (several
    ``coloc evaluate`` processes on one ``out``) keep every row; each file is still written atomically.
    The chart is drawn inside the lock too, so the last chart written shows the last table.
    """
    path = os.path.join(out, key, "leaderboard.json")
    with _locked(out):
        table = read_json(path, default={})
        table[result["policy"]] = result
        write_json(path, table)
        if draw:
            bar_chart(table, os.path.join(out, key, "leaderboard.png"), key)
        write_text(os.path.join(out, "leaderboard.md"), markdown(out))
    return path


# --- paired statistics ----------------------------------------------------------------------------------
def _t975(dof: int) -> float:
    from scipy import stats

    return float(stats.t.ppf(0.975, dof))


ROUNDING = 1e-9  # times the reference's mean cost (at least 1): a paired interval this close to 0 is float rounding


def episodes_needed(mean: float, sd: float, limit: int = 10**7) -> int | None:
    """The least n >= 2 with t_{0.975, n-1} sd / sqrt(n) < |mean|: the episodes a paired difference of this
    mean and spread needs before its 95 % interval excludes zero. None for a zero mean (never resolves)."""
    if mean == 0 or not math.isfinite(mean) or not math.isfinite(sd):
        return None
    if sd == 0:
        return 2
    n = max(2, math.floor((1.959963984540054 * sd / abs(mean)) ** 2))  # t > z, so the answer is at least this
    while _t975(n - 1) * sd / math.sqrt(n) >= abs(mean):
        n += 1
        if n > limit:
            return None
    return n


def paired_difference(costs, reference) -> dict:
    """Episode-by-episode differences ``costs - reference`` (same seeds): mean, 95 % t half-width, sd, n,
    the interval's ends and the episodes a difference of this size needs (:func:`episodes_needed`)."""
    costs, reference = np.asarray(costs, float), np.asarray(reference, float)
    if costs.shape != reference.shape or costs.ndim != 1:
        raise ValueError(f"paired costs must be two 1-d arrays of one length, got {costs.shape} and {reference.shape}")
    if len(costs) < 2:
        raise ValueError(f"a paired interval needs at least 2 episodes, got {len(costs)}")
    d = costs - reference
    mean, sd = float(d.mean()), float(d.std(ddof=1))
    half = _t975(len(d) - 1) * sd / math.sqrt(len(d))
    # two policies that play the same episodes differ by float rounding only (greedy = always on a composition
    # whose greedy choice is to send): no number of episodes resolves that, and it is no result
    equal = abs(mean) + half <= ROUNDING * max(1.0, float(np.abs(reference).mean()))
    return {"mean": mean, "ci95": half, "low": mean - half, "high": mean + half, "sd": sd, "episodes": len(d),
            "reference_mean": float(reference.mean()), "equal": equal,
            "episodes_needed": None if equal else episodes_needed(mean, sd)}


def verdict(diff: dict) -> str:
    """"beats" when the paired interval lies below zero (lower cost), "worse" above it, "equal to rounding" when
    the whole interval is within :data:`ROUNDING` of zero, else "not distinguishable (n episodes)"."""
    if diff.get("equal"):
        return "equal to rounding"
    if diff["high"] < 0:
        return "beats"
    if diff["low"] > 0:
        return "worse"
    return f"not distinguishable ({diff['episodes']} episodes)"


def _episodes(row: dict):
    return row.get("per_episode_cost")


def paired(row: dict, reference: dict) -> dict | None:
    """The paired difference of two leaderboard rows on their common episodes (same seed_base, the first
    min(n) episodes); None where either row has no per-episode costs or they ran on other seeds."""
    a, b = _episodes(row), _episodes(reference)
    if a is None or b is None or row.get("seed_base") != reference.get("seed_base"):
        return None
    n = min(len(a), len(b))
    if n < 2:
        return None
    return paired_difference(a[:n], b[:n])


# --- rows ---------------------------------------------------------------------------------------------
def _is_model(name: str) -> bool:
    return name.endswith(".zip") or name.endswith(".zip" + STOCHASTIC)


def _is_bound(name: str) -> bool:
    from train.evaluate import is_bound

    return is_bound(name)


def _trained_summary(table: dict, suffix: str = "") -> dict | None:
    models = [r for name, r in table.items() if name.endswith(".zip" + suffix)]
    if not models:
        return None
    means = np.array([r["mean_cost"] for r in models])
    label = "trained" + (", stochastic" if suffix else "")
    summary = {"policy": f"{label} (mean of {len(models)} seed{'s' if len(models) > 1 else ''})",
               "mean_cost": float(means.mean()), "ci95": float(np.mean([r["ci95"] for r in models])),
               "paper_cost": float(np.mean([r["paper_cost"] for r in models])),
               "communication_per_step": float(np.mean([r["communication_per_step"] for r in models])),
               "episodes": models[0]["episodes"], "spread": (float(means.min()), float(means.max())),
               "seed_base": models[0].get("seed_base")}
    per_episode = [r.get("per_episode_cost") for r in models]
    if all(p is not None for p in per_episode) and len({r.get("seed_base") for r in models}) == 1:
        n = min(len(p) for p in per_episode)
        summary["per_episode_cost"] = list(np.mean([p[:n] for p in per_episode], axis=0))
    return summary


def strongest_baseline(scenario: str, table: dict) -> dict | None:
    """The row of the strongest realizable baseline evaluated so far: among ``train.evaluate.baselines``, the
    lowest mean cost (on its paired episodes with the others, where they share seeds). None if none is there."""
    from train.evaluate import baselines

    names = baselines(scenario)
    candidates = [table[n] for n in names if n in table]
    if not candidates:
        return None
    return min(candidates, key=lambda r: r["mean_cost"])


def rows(table: dict) -> list[dict]:
    """Named policies and reference filters, each trained model, then the trained summaries; best first
    within each group. Bounds are not among them (:func:`bound_rows`)."""
    named = sorted((r for n, r in table.items() if not _is_model(n) and not _is_bound(n)),
                   key=lambda r: r["mean_cost"])
    models = sorted((r for n, r in table.items() if _is_model(n)), key=lambda r: r["mean_cost"])
    summaries = [_trained_summary(table, suffix) for suffix in ("", STOCHASTIC)]
    return named + models + [s for s in summaries if s]


def bound_rows(table: dict) -> list[dict]:
    """The ``bound_*`` rows, best first: what no agent can reach, shown apart."""
    return sorted((r for n, r in table.items() if _is_bound(n)), key=lambda r: r["mean_cost"])


def _kind(scenario: str, row: dict, baseline: dict | None) -> str:
    """What a row is, in words (the leaderboard's second column), with the names that build the same policy."""
    import agents

    also = sorted(n for n, same in agents.duplicates(scenario).items() if same == row["policy"])
    return _what(scenario, row, baseline) + (f" (also {', '.join(also)})" if also else "")


def _what(scenario: str, row: dict, baseline: dict | None) -> str:
    from train.evaluate import REFERENCE_FILTERS, baselines

    name = row["policy"]
    if baseline is not None and name == baseline["policy"]:
        return "strongest realizable baseline"
    if _is_bound(name):
        return "bound (uses what the agents cannot have)"
    if name.startswith("trained"):
        return "trained models, mean over training seeds"
    if _is_model(name):
        seed = os.path.basename(os.path.dirname(name)) or "model"
        return f"trained model ({seed}{', sampled actions' if name.endswith(STOCHASTIC) else ''})"
    if name in REFERENCE_FILTERS.get(scenario, {}):
        return "reference filter on the same episodes" + (", baseline" if name in baselines(scenario) else "")
    if name in baselines(scenario):
        return "realizable baseline"
    if name == "paper" or name.startswith("paper:"):
        return "the paper's policy"
    return KINDS.get(name, "hand-designed policy")


def comparison(scenario: str, row: dict, baseline: dict | None) -> dict | None:
    """The row's paired difference against the baseline with its verdict (and, for the target, whether it
    matches the baseline's error with less communication); None without a baseline or shared episodes."""
    if baseline is None or row["policy"] == baseline["policy"]:
        return None
    diff = paired(row, baseline)
    if diff is None:
        return None
    _, tolerance, saving = TARGETS.get(scenario, COMPOSITION_TARGET)
    within = abs(diff["low"]) <= tolerance * abs(diff["reference_mean"]) and \
        abs(diff["high"]) <= tolerance * abs(diff["reference_mean"])
    base_comm = baseline["communication_per_step"]
    less = base_comm > 0 and row["communication_per_step"] <= (1 - saving) * base_comm
    text = verdict(diff)
    if text != "beats" and within and less:
        text = f"matches with {100 * (1 - row['communication_per_step'] / base_comm):.0f} % less communication"
    return dict(diff, verdict=text)


def tradeoff_comparison(row: dict, always: dict, silent: dict) -> dict | None:
    """The row's paired difference against the mix of ``always`` and ``silent`` that sends as many messages.

    The mix plays ``always`` with probability p = (m - m_silent) / (m_always - m_silent) in each episode (m: the
    row's messages per step; p clipped to [0, 1]; m / m_always where silent sends nothing, as a composition's
    ``silent``) and ``silent`` otherwise, so its expected messages per step p m_always + (1 - p) m_silent are m
    and its expected error in episode e is p cost_e(always) + (1 - p) cost_e(silent). Beating it is "a lower
    error at equal messages" on the line that joins the two baselines' (messages, error) points. Returns
    :func:`paired_difference`'s dict with ``verdict`` and ``probability`` p; None where a row lacks paired
    episodes or ``always`` sends no more than ``silent``.
    """
    a, s, c = _episodes(always), _episodes(silent), _episodes(row)
    if a is None or s is None or c is None or len({r.get("seed_base") for r in (row, always, silent)}) != 1:
        return None
    span = always["communication_per_step"] - silent["communication_per_step"]
    if span <= 0:
        return None
    p = float(np.clip((row["communication_per_step"] - silent["communication_per_step"]) / span, 0.0, 1.0))
    n = min(len(a), len(s), len(c))
    if n < 2:
        return None
    mix = p * np.asarray(a[:n], float) + (1.0 - p) * np.asarray(s[:n], float)
    diff = paired_difference(c[:n], mix)
    return dict(diff, verdict=verdict(diff), probability=p)


def target_verdict(scenario: str, table: dict) -> str | None:
    """One line: the target, judged per trained model against the strongest realizable baseline on paired
    episodes; "met" only when every trained model beats it (or matches it with the communication saving)."""
    models = sorted(n for n in table if n.endswith(".zip"))  # deterministic models; sampled ones are shown only
    if not models:
        return None
    text = TARGETS.get(scenario, COMPOSITION_TARGET)[0]
    baseline = strongest_baseline(scenario, table)
    from train.evaluate import baselines

    if baseline is None:
        return f"Target: {text}. No baseline row ({', '.join(baselines(scenario))}) evaluated yet."
    unit = metric(scenario)[1]
    parts, met = [], True
    for name in models:
        result = comparison(scenario, table[name], baseline)
        seed = os.path.basename(os.path.dirname(name)) or name
        if result is None:
            parts.append(f"{seed}: not paired (evaluate it on the baseline's seeds)")
            met = False
            continue
        ok = result["verdict"] == "beats" or result["verdict"].startswith("matches")
        needed = ("" if not result["verdict"].startswith("not distinguishable") or result["episodes_needed"] is None
                  else f", ~{result['episodes_needed']} episodes would resolve a difference this size")
        part = (f"{seed}: {result['verdict']} (paired difference {result['mean']:+.4g} {unit}, 95 % "
                f"[{result['low']:+.4g}, {result['high']:+.4g}]{needed})")
        if scenario not in TARGETS and "always" in table and "silent" in table:
            mixed = tradeoff_comparison(table[name], table["always"], table["silent"])
            if mixed is not None:
                ok = ok or mixed["verdict"] == "beats"
                part += (f", against always and silent mixed to send as many messages (always in "
                         f"{100 * mixed['probability']:.0f} % of episodes): {mixed['verdict']} "
                         f"({mixed['mean']:+.4g} {unit}, 95 % [{mixed['low']:+.4g}, {mixed['high']:+.4g}])")
        met = met and ok
        parts.append(part)
    candidates = [n for n in baselines(scenario) if n in table]
    return (f"Target: {text}. Strongest realizable baseline: {baseline['policy']} {baseline['mean_cost']:.4g} {unit} "
            f"(best of {', '.join(candidates)}). " + "; ".join(parts) + f": {'**met**' if met else '**not met**'}.")


# --- output -------------------------------------------------------------------------------------------
def bar_chart(table: dict, path: str, key: str) -> None:
    """The leaderboard's bars with their 95 % intervals. Means spanning more than 10x (``random`` beside the
    filters) go on a log axis when all are positive; otherwise the bars above 10x the median are left out and
    named, with their values, in a note under the axes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenario = next(iter(table.values()))["scenario"]
    name, unit = metric(scenario)
    entries = [r for r in rows(table) if not _is_model(r["policy"])]
    bounds = bound_rows(table)
    shown = entries + bounds
    means = np.array([r["mean_cost"] for r in shown], dtype=float)
    finite = means[np.isfinite(means)]
    positive = finite.size > 0 and bool(np.all(finite > 0))
    wide = finite.size > 1 and (np.max(np.abs(finite)) > 10 * max(np.min(np.abs(finite)), 1e-300))
    log = positive and wide
    left_out = []
    if wide and not log:
        scale = 10 * max(float(np.median(np.abs(finite))), 1e-300)
        left_out = [r for r in shown if abs(r["mean_cost"]) > scale]
        shown = [r for r in shown if abs(r["mean_cost"]) <= scale]
    fig, ax = plt.subplots(figsize=(max(5, 1.3 * len(shown)), 4.2), layout="constrained")
    names = [r["policy"] for r in shown]
    colours = ["tab:green" if n.startswith("trained") else "tab:gray" if _is_bound(n) else "tab:blue" for n in names]
    heights = np.array([r["mean_cost"] for r in shown], dtype=float)
    half = np.array([r["ci95"] for r in shown], dtype=float)
    # on a log axis an interval reaching zero or below is drawn down to the axis' floor
    lower = np.minimum(half, heights * 0.999) if log else half
    ax.bar(range(len(shown)), heights, yerr=[lower, half], capsize=4, color=colours)
    if log:
        ax.set_yscale("log")
    baseline = strongest_baseline(scenario, table)
    if baseline is not None:
        ax.axhline(baseline["mean_cost"], color="k", ls="--", lw=1, label=f"strongest baseline ({baseline['policy']})")
        ax.legend(fontsize=8)
    ax.set_xticks(range(len(shown)), names, rotation=20, ha="right", fontsize=8)
    ax.set_ylabel(f"mean episode error [{unit}] (95 % CI){', log scale' if log else ''}")
    ax.set_title(f"{key}: {name} on the evaluation seeds (grey: bounds)", fontsize=9)
    if left_out:
        note = "not shown (off scale, > 10x the median): " + ", ".join(
            f"{r['policy']} {r['mean_cost']:.4g} {unit}" for r in left_out)
        fig.text(0.01, 0.0, note, fontsize=7, ha="left", va="top", wrap=True)
    save_figure(path, fig)


def _training_budget(table: dict) -> str | None:
    """The trained models' timesteps and training seeds, read from each model's ``model.json``."""
    budgets = []
    for name in table:
        meta = os.path.join(os.path.dirname(name), "model.json")
        if name.endswith(".zip") and os.path.isfile(meta):
            info = read_json(meta)
            budgets.append((info.get("timesteps"), info.get("seed"), info.get("env_config")))
    if not budgets:
        return None
    steps = sorted({b[0] for b in budgets if b[0] is not None})
    config = budgets[0][2]
    return (f"Trained models: {len(budgets)} training seed(s) ({', '.join(str(b[1]) for b in budgets)}), "
            f"{'/'.join(f'{s:,}' for s in steps)} timesteps each, training config {config}.")


def _difference_cells(scenario: str, row: dict, baseline: dict | None) -> tuple[str, str, str]:
    if baseline is not None and row["policy"] == baseline["policy"]:
        return "0 (reference)", "", ""
    result = comparison(scenario, row, baseline)
    if result is None:
        return "", "", ("" if baseline is None else "not paired (other seeds, or no per-episode costs)")
    needed = result["episodes_needed"]
    if _is_bound(row["policy"]) and result["verdict"] == "beats":
        result["verdict"] = "below the baseline (a bound, not a result)"
    return (f"{result['mean']:+.4g}", f"[{result['low']:+.4g}, {result['high']:+.4g}]",
            result["verdict"] + ("" if not result["verdict"].startswith("not distinguishable")
                                 else f"; ~{needed} episodes would resolve it" if needed
                                 else "; no number of episodes resolves a zero difference"))


def _table(scenario: str, entries: list[dict], baseline: dict | None, show_initial: bool) -> list[str]:
    _, unit = metric(scenario)
    comm = COMMUNICATION.get(scenario, "messages sent")
    versus = baseline["policy"] if baseline else "the strongest baseline"
    header = (f"| row | what it is | mean error [{unit}] | 95 % CI [{unit}] | paired difference vs {versus} "
              f"[{unit}] | its 95 % CI [{unit}] | verdict (paired) |"
              + (f" with the initial term [{unit}] |" if show_initial else "")
              + f" communication [{comm} / step] | episodes [n] |")
    lines = [header, "|" + "---|" * (header.count("|") - 1)]
    for r in entries:
        name = r["policy"] + (f" (seed means {r['spread'][0]:.4g}..{r['spread'][1]:.4g} {unit})" if "spread" in r
                              else "")
        diff, interval, text = _difference_cells(scenario, r, baseline)
        initial = f" {r['paper_cost']:.4g} |" if show_initial else ""
        lines.append(f"| {name} | {_kind(scenario, r, baseline)} | {r['mean_cost']:.4g} | ±{r['ci95']:.3g} | {diff} | "
                     f"{interval} | {text} |{initial} {r['communication_per_step']:.3g} | {r['episodes']} |")
    return lines


def _bounds_table(entries: list[dict]) -> list[str]:
    """RMSE of the 2-D position, the posterior Cramér-Rao bounds and NEES of the rows that have them
    (``train.evaluate.attach_bounds``)."""
    entries = [r for r in entries if r.get("rmse") is not None]
    if not entries:
        return []

    def number(value, digits=4):
        return "-" if value is None else f"{value:.{digits}g}"

    model_based = any(r.get("pcrb_model_based") for r in entries)
    lines = ["Estimation bounds (posterior Cramér-Rao, `coloc_env.pcrb` on the same episodes and actions"
             + ("; model-based: recorded data" if model_based else "") + ") and consistency:", "",
             "| row | RMSE [m] | sqrt PCRB centralized / delivered / local [m] | efficiency RMSE / sqrt PCRB_c | "
             "NEES (2 if consistent) | per-step NEES in its chi^2 95 % band |", "|---|---|---|---|---|---|"]
    for r in entries:
        band = r.get("nees_band")
        inside = "-" if band is None else f"{100 * r['nees_in_band']:.0f} % in [{band[0]:.3g}, {band[1]:.3g}]"
        bounds = " / ".join(number(r.get(f"pcrb_{k}")) for k in ("centralized", "delivered", "local"))
        lines.append(f"| {r['policy']} | {number(r['rmse'])} | {bounds} | {number(r.get('efficiency'), 3)} | "
                     f"{number(r.get('nees'), 3)} | {inside} |")
    return [*lines, ""]


def markdown(out: str) -> str:
    lines = ["# Leaderboard", "",
             "Each scenario's own episode metric (lower is better, named per table) on the evaluation seeds "
             "10^6 + e, every row on the same episodes. Each row: its mean with a 95 % Student-t interval, and "
             "the paired difference (episode by episode) against the scenario's strongest realizable baseline "
             "with its 95 % interval; \"beats\" needs that interval below zero, otherwise \"not distinguishable "
             "(n episodes)\" with the episodes a difference of this size would need. Bounds use what the agents "
             "cannot have and are listed apart. Communication as the scenario counts it. Written by "
             "`coloc evaluate`.", ""]
    for path in sorted(glob.glob(os.path.join(out, "*", "leaderboard.json"))):
        key = os.path.basename(os.path.dirname(path))
        table = read_json(path)
        scenario = next(iter(table.values()))["scenario"]
        name, unit = metric(scenario)
        baseline = strongest_baseline(scenario, table)
        show_initial = any(r.get("initial_cost", 0) for r in table.values())
        lines += [f"## {key} (`{scenario}`)", "", f"Episode metric: {name} [{unit}].", ""]
        lines += _table(scenario, rows(table), baseline, show_initial)
        lines.append("")
        lines += _bounds_table(rows(table))
        bounds = bound_rows(table)
        if bounds:
            lines += ["Bounds (not realizable: hindsight, the truth or information the agents lack; never a "
                      "baseline):", ""]
            lines += _table(scenario, bounds, baseline, show_initial)
            lines.append("")
        budget = _training_budget(table)
        if budget:
            lines += [budget, ""]
        target = target_verdict(scenario, table)
        if target:
            lines += [target, ""]
    return "\n".join(lines)
