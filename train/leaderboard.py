"""Leaderboards: one table per paper (``OUT/<key>/leaderboard.json`` + a PNG bar chart) and
``OUT/leaderboard.md`` gathering every scenario evaluated so far.

Each row is one policy evaluated by ``coloc evaluate`` on the evaluation
seeds. Trained models (policies given as a ``.zip`` path) are also summarized
as one "trained" row: the mean over training seeds of their mean errors.
"""

from __future__ import annotations

import glob
import os

import numpy as np

from train.io import read_json, save_figure, write_json, write_text


def record(result: dict, out: str, key: str) -> str:
    """Merge ``result`` into ``out/<key>/leaderboard.json`` (keyed by policy), redraw its chart and the summary."""
    path = os.path.join(out, key, "leaderboard.json")
    table = read_json(path, default={})
    table[result["policy"]] = result
    write_json(path, table)
    bar_chart(table, os.path.join(out, key, "leaderboard.png"), key)
    write_text(os.path.join(out, "leaderboard.md"), markdown(out))
    return path


STOCHASTIC = " (stochastic)"  # suffix of a model evaluated with sampled actions (``evaluate --stochastic``)


def _is_model(name: str) -> bool:
    return name.endswith(".zip") or name.endswith(".zip" + STOCHASTIC)


def _trained_summary(table: dict, suffix: str = "") -> dict | None:
    models = [r for name, r in table.items() if name.endswith(".zip" + suffix)]
    if not models:
        return None
    means = np.array([r["mean_cost"] for r in models])
    label = "trained" + (", stochastic" if suffix else "")
    return {"policy": f"{label} (mean of {len(models)} seed{'s' if len(models) > 1 else ''})",
            "mean_cost": float(means.mean()), "ci95": float(np.mean([r["ci95"] for r in models])),
            "paper_cost": float(np.mean([r["paper_cost"] for r in models])),
            "communication_per_step": float(np.mean([r["communication_per_step"] for r in models])),
            "episodes": models[0]["episodes"], "spread": (float(means.min()), float(means.max()))}


# Issue 10's target per scenario: (what it says, the reference policies, whether the trained policy must
# also use no more communication than the paper policy, the relative margin below the reference).
TARGETS = {
    "bandwidth_fusion": ("reach the best static selection (oracle_static)", ("oracle_static",), False, 0.0),
    "lossy_fusion": ("at least 10 % below the paper's fixed fusion weights", ("paper",), True, 0.10),
    "relay_ukf": ("the full chain's (paper) error with fewer hops", ("paper",), True, 0.0),
    "nlos_horizon": ("at or below the best constant horizon (constant:N rows)", ("constant",), False, 0.0),
    "gps_denied_nbp": ("the paper's error with fewer broadcasts", ("paper",), True, 0.0),
}


def target_verdict(scenario: str, table: dict) -> str | None:
    """One line: the scenario's target, the trained mean against the reference, met or not.

    "met" needs the trained mean at or below the reference times (1 - margin); "within noise" means the
    gap is smaller than the larger of the two 95 % half-widths (not distinguishable on these episodes).
    """
    if scenario not in TARGETS or _trained_summary(table) is None:
        return None
    text, references, fewer_messages, margin = TARGETS[scenario]
    trained = _trained_summary(table)
    candidates = [r for name, r in table.items() if not _is_model(name)
                  and any(name == ref or name.startswith(ref + ":") for ref in references)]
    if not candidates:
        return f"Target: {text}. No reference row evaluated yet."
    reference = min(candidates, key=lambda r: r["mean_cost"])
    goal = reference["mean_cost"] * (1 - margin)
    gap = trained["mean_cost"] / reference["mean_cost"] - 1
    paper = table.get("paper")
    comm_ok = not fewer_messages or paper is None or \
        trained["communication_per_step"] <= paper["communication_per_step"] * (1 + 1e-9)
    if trained["mean_cost"] <= goal and comm_ok:
        verdict = "**met**"
    elif trained["mean_cost"] - goal <= max(trained["ci95"], reference["ci95"]) and comm_ok:
        verdict = "**not met, within noise**"
    else:
        verdict = "**not met**"
    comm = (f"; communication {trained['communication_per_step']:.3g} vs the paper's "
            f"{paper['communication_per_step']:.3g} per step" if fewer_messages and paper else "")
    return (f"Target: {text}. Trained {trained['mean_cost']:.4g} vs {reference['policy']} "
            f"{reference['mean_cost']:.4g} ({100 * gap:+.1f} %){comm}: {verdict}.")


def rows(table: dict) -> list[dict]:
    """Named policies, each trained model, then the trained summary; best first within each group."""
    named = sorted((r for n, r in table.items() if not _is_model(n)), key=lambda r: r["mean_cost"])
    models = sorted((r for n, r in table.items() if _is_model(n)), key=lambda r: r["mean_cost"])
    summaries = [_trained_summary(table, suffix) for suffix in ("", STOCHASTIC)]
    return named + models + [s for s in summaries if s]


def bar_chart(table: dict, path: str, key: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    entries = [r for r in rows(table) if not _is_model(r["policy"])]
    fig, ax = plt.subplots(figsize=(max(5, 1.3 * len(entries)), 4))
    names = [r["policy"] for r in entries]
    ax.bar(range(len(entries)), [r["mean_cost"] for r in entries], yerr=[r["ci95"] for r in entries],
           capsize=4, color=["tab:green" if n.startswith("trained") else "tab:blue" for n in names])
    if "paper" in table:
        ax.axhline(table["paper"]["mean_cost"], color="k", ls="--", lw=1, label="paper")
        ax.legend()
    ax.set_xticks(range(len(entries)), names, rotation=20, ha="right", fontsize=8)
    ax.set_ylabel("mean episode error (95 % CI)")
    ax.set_title(f"{key}: policies on the evaluation seeds", fontsize=10)
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
    steps = sorted({b[0] for b in budgets})
    config = budgets[0][2]
    return (f"Trained models: {len(budgets)} training seed(s) ({', '.join(str(b[1]) for b in budgets)}), "
            f"{'/'.join(f'{s:,}' for s in steps)} timesteps each, training config {config}.")


def markdown(out: str) -> str:
    lines = ["# Leaderboard", "",
             "Mean episode estimation error (each scenario's own metric, lower is better) with its 95 % "
             "interval over the evaluation seeds, and communication per step as the scenario counts it. "
             "Written by `coloc evaluate`.", ""]
    for path in sorted(glob.glob(os.path.join(out, "*", "leaderboard.json"))):
        key = os.path.basename(os.path.dirname(path))
        table = read_json(path)
        scenario = next(iter(table.values()))["scenario"]
        paper = table.get("paper")
        lines += [f"## {key} (`{scenario}`)", "",
                  "| policy | mean error | 95 % CI | vs paper | paper's cost | communication / step | episodes |",
                  "|---|---|---|---|---|---|---|"]
        for r in rows(table):
            versus = f"{100 * (r['mean_cost'] / paper['mean_cost'] - 1):+.1f} %" if paper else ""
            name = r["policy"] + (f" (seeds {r['spread'][0]:.3f}..{r['spread'][1]:.3f})" if "spread" in r else "")
            lines.append(f"| {name} | {r['mean_cost']:.4g} | ±{r['ci95']:.3g} | {versus} | {r['paper_cost']:.4g} | "
                         f"{r['communication_per_step']:.3g} | {r['episodes']} |")
        lines.append("")
        budget = _training_budget(table)
        if budget:
            lines += [budget, ""]
        verdict = target_verdict(scenario, table)
        if verdict:
            lines += [verdict, ""]
    return "\n".join(lines)
