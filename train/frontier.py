"""``coloc frontier``: error against messages for every policy family, the baseline frontier and the bounds.

For a preset or a composition (``world/network/backend``), every policy below plays the same seeded
episodes (episode e: ``reset(seed=S + e)``, S = ``--seed``, by default the evaluation seeds 10^6 + e of
``train.evaluate``), each one a point (messages per agent-step, the scenario's own per-episode metric):

| points          | what                                                                                    |
|-----------------|-----------------------------------------------------------------------------------------|
| baselines       | ``always``, ``silent``, ``random``, ``paper`` where the scenario has one, each          |
|                 | event-triggered family of ``agents.event_triggered`` over its knob grid, and over a     |
|                 | shared medium (``contention``) ``round_robin``, ``aloha`` and ``aloha:p`` over          |
|                 | ``ALOHA_PROBABILITIES`` (``agents.contention``)                                          |
| privileged      | ``greedy`` (it copies the core): drawn apart, never on the frontier                      |
| models          | every ``*.zip`` under ``--models DIR``: judged against the frontier; with ``--costs``    |
|                 | ``c1,c2,...`` each model at each cost, a point ``PATH.zip @ cost=c`` each (played in an   |
|                 | env built with ``communication_cost=c``, which its observation carries;                  |
|                 | ``train.evaluate.model_row`` names a model trained at a fixed cost so); a model that     |
|                 | samples its actions (``model.json``: ``train.hyperparams.ACTIONS``) plays them sampled,  |
|                 | ``PATH.zip @ cost=c (stochastic)``                                                       |

The knob grids (``--quick``: three of each) are fixed before the evaluation episodes are played:
``periodic`` over ``PERIODS`` (up to the horizon); ``uncertainty``, ``send_on_delta`` and ``value`` over
thresholds read from ``always`` and ``silent`` on validation episodes
(``train.evaluate.VALIDATION_SEED_BASE``): the 5th to 95th percentiles, evenly spaced in probability, of
what the rule compares with its knob (where its decisions change, from near ``always`` to near
``silent``), plus 0 (= ``always``) and inf (= ``silent``): ``uncertainty`` the covariance traces (m^2) of
both pooled. ``send_on_delta`` and ``value`` compare what grows since the reference transmission and is 0
right after one (under ``always`` it is 0 at nearly every decision), so their thresholds come from
``silent`` on the same validation episodes: for each s of ``PERIODS`` (``QUICK_PERIODS``) within the
horizon, the median over the agents and episodes of the positive displacements (m) or message values (m^2)
s steps into the episode, what an agent accumulates in s steps without sending, so that a threshold there
sends about every s steps. Nothing is tuned on the evaluation seeds.

The **baseline frontier** (``train.leaderboard.baseline_frontier``): at a message rate m, the lowest mean
error a time-share of baselines reaches with at most m messages per step; the lower convex hull of the
baseline points from the fewest messages up to the least error, flat after it (where the points turn back
up, as on a shared medium, sending less does better, so the frontier stays flat). A model is judged against
the frontier at its own message rate (``train.leaderboard.frontier_comparison``: paired over the episodes,
95 % interval, the leaderboard's verdict words).

Writes ``OUT/frontier/<name>/`` (name: the scenario, ``/`` as ``__``): ``metrics.json`` (every point:
``messages_per_agent_step``, ``communication_per_step``, ``mean_cost`` with ``ci95`` and
``per_episode_cost`` for pairing, ``rmse``, ``pcrb_centralized``, ``pcrb_local``, ``pcrb_delivered`` (m,
square roots of the bounds averaged over steps and agents, on the first ``--bound-episodes`` episodes,
``BOUND_EPISODES`` by default: a bound replays its episodes one env at a time; a point is judged by its
error, never by its bounds), NEES; the frontier's vertices; each judged
point's comparison), ``report.md`` and ``frontier.png``: left, the scenario's metric against messages per
agent-step, each family a line with its 95 % intervals, the baseline frontier drawn; right, the RMSE
against the same axis with the square roots of the centralized and local bounds as horizontal lines and,
under each point, its delivered bound (the gap between the point and its marker is the estimator's; the
gap from the marker to the centralized line is the network's and the schedule's). The bounds bound the
mean squared error, so they are drawn against the RMSE only, never against a mean distance.
"""

from __future__ import annotations

import glob
import itertools
import math
import os
import textwrap
from collections.abc import Callable

import numpy as np

from coloc_env.config import BadInput

PERIODS = (1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 128)
QUICK_PERIODS = (1, 2, 4)
UNCERTAINTY_LEVELS = 8  # a threshold family's thresholds between the two percentiles, plus 0 and inf
QUICK_LEVELS = 3
GRID_EPISODES = 4  # validation episodes of always and silent that place the thresholds
BOUND_EPISODES = 8  # the first episodes each point's bounds replay (train.evaluate.attach_bounds)
MAX_EPISODES = 100_000
FIGURE = "frontier.png"
BASELINE_NAMES = ("always", "silent", "random", "paper", "round_robin", "aloha")
# slotted ALOHA's transmit probability per slot (agents.contention), where the network is a shared medium
ALOHA_PROBABILITIES = (0.01, 0.02, 0.05, 0.1, 0.2, 0.5)
QUICK_ALOHA_PROBABILITIES = (0.05, 0.2)
PRIVILEGED = ("greedy",)


def folder_name(scenario: str) -> str:
    return scenario.replace("/", "__")


def _fixed_action_play(scenario: str, which: str, episodes: int, seed_base: int):
    """The batched core of ``episodes`` copies (copy e seeded ``seed_base + e``) playing ``always`` (``which`` =
    "maximum") or ``silent`` ("minimum"): yields the core after the reset, then after each step."""
    import coloc_env

    core = coloc_env.make_core(scenario, batch=episodes)
    core.reset([np.random.default_rng(seed_base + e) for e in range(episodes)])
    action = np.tile(core.action_vector(which), (episodes, core.num_agents, 1))
    yield core
    while not core.done().all():
        core.step(action)
        yield core


def _trace_values(scenario: str, which: str, episodes: int, seed_base: int) -> np.ndarray:
    """Every (step, agent) covariance trace (m^2) after each step of ``always`` (``which`` = "maximum") or
    ``silent`` ("minimum") over ``episodes`` episodes seeded ``seed_base + e``, on the batched core."""
    play = _fixed_action_play(scenario, which, episodes, seed_base)
    next(play)  # the reset: no step yet
    values = np.concatenate([np.asarray(core.info()["trace"], float).ravel() for core in play])
    return values[np.isfinite(values)]


def _silent_values(scenario: str, feature: str, episodes: int, seed_base: int) -> np.ndarray:
    """(K + 1, episodes, N): the observation feature ``feature`` at each step k of ``silent`` (``displacement``
    in m, ``message_value`` in m^2) over ``episodes`` episodes seeded ``seed_base + e``, on the batched core. Under
    ``silent`` no agent transmits, so step k is k steps after each agent's reference (the episode's start)."""
    from coloc_env.scenarios.composed import DISTANCE_SCALE

    scale = DISTANCE_SCALE if feature == "displacement" else 1.0
    play = _fixed_action_play(scenario, "minimum", episodes, seed_base)
    core = next(play)  # the reset: step 0
    index = core.feature_index(feature)

    def observed(core) -> np.ndarray:  # read at each yield: the generator steps one core object
        return np.asarray(core.observation()[..., index], float) * scale

    return np.array([observed(core), *(observed(core) for core in play)])


def _threshold_grid(pooled: np.ndarray, quick: bool) -> list[str]:
    """0, the 5th to 95th percentiles of ``pooled`` (``QUICK_LEVELS`` or ``UNCERTAINTY_LEVELS`` of them), inf."""
    levels = np.quantile(pooled, np.linspace(0.05, 0.95, QUICK_LEVELS if quick else UNCERTAINTY_LEVELS))
    return ["0"] + sorted({f"{v:.4g}" for v in levels if v > 0}, key=float) + ["inf"]


def _steps_grid(values: np.ndarray, steps: tuple[int, ...]) -> list[str]:
    """0, then for each s of ``steps`` within the episode the median of the positive values (K + 1, ...) at step s
    (what an agent accumulates over s steps without transmitting: a threshold there sends about every s steps),
    then inf."""
    levels = []
    for s in steps:
        if s < len(values):
            at = values[s][np.isfinite(values[s]) & (values[s] > 0)]
            if at.size:
                levels.append(float(np.median(at)))
    return ["0"] + sorted({f"{v:.4g}" for v in levels}, key=float) + ["inf"]


def knob_grids(scenario: str, horizon: int, quick: bool = False) -> dict[str, list[str]]:
    """Each applicable family's knobs (as the text after the colon), chosen without the evaluation seeds;
    ``quick``: ``QUICK_PERIODS`` and ``QUICK_LEVELS`` thresholds, for a first look."""
    import agents
    from train.evaluate import VALIDATION_SEED_BASE

    available = agents.available_policies(scenario)
    grids: dict[str, list[str]] = {}
    if "aloha" in available:  # p = 1 is always (every slot); the adaptive p = 1 / (neighbours + 1) is a baseline
        grids["aloha"] = [f"{p:g}" for p in (QUICK_ALOHA_PROBABILITIES if quick else ALOHA_PROBABILITIES)]
    if "periodic" in available:
        grids["periodic"] = [str(p) for p in (QUICK_PERIODS if quick else PERIODS) if p <= horizon] + ["inf"]
    if "uncertainty" in available:
        pooled = np.concatenate([_trace_values(scenario, which, GRID_EPISODES, VALIDATION_SEED_BASE)
                                 for which in ("maximum", "minimum")])
        grids["uncertainty"] = _threshold_grid(pooled, quick)
    for family, feature in (("send_on_delta", "displacement"), ("value", "message_value")):
        if family in available:
            values = _silent_values(scenario, feature, GRID_EPISODES, VALIDATION_SEED_BASE)
            grids[family] = _steps_grid(values, QUICK_PERIODS if quick else PERIODS)
    return grids


def cells(scenario: str, horizon: int, models: list[str], quick: bool = False,
          costs: list[float] | None = None) -> list[dict]:
    """The points to play: each a dict with ``policy`` (its name: make_policy's, or a model's row at a cost,
    `` (stochastic)`` after it for a model that samples its actions), ``kind`` (baseline, privileged or model),
    for a family ``family`` and ``knob``, for a model ``model`` (its path) and ``cost`` (each of ``costs``; None:
    ``train.evaluate.model_row``'s default)."""
    import agents
    from train.evaluate import model_actions, model_row
    from train.leaderboard import STOCHASTIC

    available = agents.available_policies(scenario)
    # the fixed policies, and the scenario's strongest baselines (nlos_horizon's best_constant, gps_denied_nbp's
    # threshold, ...); a name that builds the same policy as another of these plays once, under the other name
    # (round_robin is the contention preset's paper), but does play where its twin is not listed (nlos_horizon's
    # always is its constant)
    names = [n for n in dict.fromkeys([*BASELINE_NAMES, *agents.strongest_baselines(scenario)]) if n in available]
    repeated = agents.duplicates(scenario)
    out = [{"policy": name, "kind": "baseline"} for name in names if repeated.get(name) not in names]
    for family, knobs in knob_grids(scenario, horizon, quick).items():
        out += [{"policy": f"{family}:{knob}", "kind": "baseline", "family": family, "knob": knob} for knob in knobs]
    out += [{"policy": name, "kind": "privileged"} for name in PRIVILEGED if name in available]
    # a model's points at several costs share its path as their family: one line, the curve the model traces
    out += [{"policy": model_row(path, cost)[0] + (STOCHASTIC if model_actions(path) == "sampled" else ""),
             "kind": "model", "model": path, "cost": cost,
             **({"family": path} if costs else {})} for path in models for cost in (costs or [None])]
    return out


# what ``coloc train`` writes beside the model it keeps (model.zip, a copy of one of them): not models to judge
TRAINING_BYPRODUCTS = ("best.zip", "last.zip", "checkpoint.zip")


def find_models(folder: str | None) -> list[str]:
    """Every ``*.zip`` under ``folder`` (sorted), or none; a folder without one is a ``BadInput``. Where a folder
    holds ``model.zip`` (a ``coloc train`` folder), its ``TRAINING_BYPRODUCTS`` are left out."""
    if folder is None:
        return []
    if not os.path.isdir(folder):
        raise BadInput(f"--models must be a folder holding trained .zip models, got {folder!r}")
    found = sorted(path for path in glob.glob(os.path.join(folder, "**", "*.zip"), recursive=True)
                   if not (os.path.basename(path) in TRAINING_BYPRODUCTS
                           and os.path.isfile(os.path.join(os.path.dirname(path), "model.zip"))))
    if not found:
        raise BadInput(f"--models {folder!r} holds no .zip model")
    return found


def play(scenario: str, policy: str, episodes: int, seed: int, cost: float | None = None,
         bound_episodes: int = BOUND_EPISODES) -> dict:
    """One point: ``train.evaluate.evaluate_policy`` on episodes ``seed + e`` (a model at ``cost``), its bounds on
    the first ``bound_episodes`` of them."""
    from train.evaluate import evaluate_policy

    return evaluate_policy(scenario, policy, episodes, seed, bounds=True, cost=cost, bound_episodes=bound_episodes)


def _messages_per_agent(row: dict, num_agents: int) -> float:
    return float(row["communication_per_step"]) / num_agents


def summarize(scenario: str, plan: list[dict], results: list[dict], num_agents: int, episodes: int,
              seed: int) -> dict:
    """metrics.json: the points, the frontier and each judged point's comparison."""
    from train.leaderboard import baseline_frontier, communication, frontier_comparison, metric

    points = []
    for cell, row in zip(plan, results, strict=True):
        point = {key: row.get(key) for key in ("mean_cost", "ci95", "communication_per_step", "per_episode_cost",
                                               "rmse", "pcrb_centralized", "pcrb_local", "pcrb_delivered",
                                               "pcrb_episodes", "efficiency", "nees", "nees_in_band", "seed_base")}
        point.update(cell, messages_per_agent_step=_messages_per_agent(row, num_agents))
        points.append(point)
    baseline_rows = [dict(p, policy=p["policy"]) for p in points if p["kind"] == "baseline"]
    vertices = baseline_frontier([(p["communication_per_step"], p["mean_cost"]) for p in baseline_rows])
    judged = {}
    for p in points:
        if p["kind"] != "baseline":
            result = frontier_comparison(p, baseline_rows)
            if result is not None:
                judged[p["policy"]] = {k: result[k] for k in ("mean", "ci95", "low", "high", "verdict", "mix",
                                                              "frontier_cost", "episodes")}
    what, unit = metric(scenario)
    return {"scenario": scenario, "metric": what, "unit": unit,
            "communication": communication(scenario), "num_agents": num_agents,
            "episodes": episodes, "seed_base": seed, "episode_seeds": f"{seed} + e, e = 0..{episodes - 1}",
            "points": points, "frontier": [baseline_rows[i]["policy"] for i in vertices], "judged": judged}


def hull_by_rate(metrics: dict) -> dict[str, str]:
    """Which point forms the frontier at low, middle and high message rates (the thirds of the range the
    frontier spans, read at their centres)."""
    from train.leaderboard import frontier_mix

    baseline_rows = [p for p in metrics["points"] if p["kind"] == "baseline"]
    vertices = [p for p in baseline_rows if p["policy"] in metrics["frontier"]]
    if not vertices:
        return {}
    low = min(v["communication_per_step"] for v in vertices)
    high = max(v["communication_per_step"] for v in vertices)
    out = {}
    for label, fraction in (("low", 1 / 6), ("middle", 1 / 2), ("high", 5 / 6)):
        a, b, w = frontier_mix(baseline_rows, low + fraction * (high - low))
        out[label] = a["policy"] if w < 0.5 else b["policy"]
    return out


def report(metrics: dict, command: str) -> str:
    unit = metrics["unit"]
    lines = [f"# Communication frontier: {metrics['scenario']}", "", f"Command: `{command}`", "",
             f"Metric: {metrics['metric']} ({unit}); x: {metrics['communication']} per agent-step. "
             f"{metrics['episodes']} paired episodes (seeds {metrics['episode_seeds']}). Bounds: square roots of "
             f"the posterior Cramér-Rao bounds averaged over steps and agents (m), beside the RMSE (m).", "",
             f"Baseline frontier (vertices, fewest messages first): {', '.join(metrics['frontier'])}.", ""]
    by_rate = hull_by_rate(metrics)
    if by_rate:
        lines += ["Frontier at low / middle / high message rates: " +
                  ", ".join(f"{k}: {v}" for k, v in by_rate.items()) + ".", ""]
    lines += [f"| policy | kind | messages per agent-step | error ({unit}) | 95 % | RMSE (m) | √pcrb delivered (m) "
              f"| √pcrb centralized (m) | √pcrb local (m) | vs frontier |", "|" + "---|" * 10]

    def number(value, digits=4):
        return "-" if value is None else f"{value:.{digits}g}"

    for p in sorted(metrics["points"], key=lambda p: (p["kind"] != "baseline", p["messages_per_agent_step"])):
        judged = metrics["judged"].get(p["policy"])
        verdict = "vertex" if p["policy"] in metrics["frontier"] else ""
        if judged is not None:
            verdict = f"{judged['verdict']} ({judged['mean']:+.3g}, 95 % [{judged['low']:+.3g}, {judged['high']:+.3g}])"
        lines.append(f"| {p['policy']} | {p['kind']} | {p['messages_per_agent_step']:.4g} | {number(p['mean_cost'])} "
                     f"| ±{number(p['ci95'], 2)} | {number(p['rmse'])} | {number(p['pcrb_delivered'])} "
                     f"| {number(p['pcrb_centralized'])} | {number(p['pcrb_local'])} | {verdict} |")
    return "\n".join(lines) + "\n"


MODEL_COLOURS = ("magenta", "lime", "darkblue", "gold", "darkred", "aqua")  # a model's line in the figure
WIDE_RANGE = 30.0  # a panel whose positive values span more than this factor is drawn on a log axis


def _log_axis_if_wide(ax, values) -> None:
    """A log y axis where the finite positive ``values`` span more than ``WIDE_RANGE`` (silence can cost orders of
    magnitude more than sending, and a linear axis then flattens every point near the frontier's low end)."""
    from train.plotting import plain_log_ticks

    values = np.asarray([v for v in values if v is not None and np.isfinite(v) and v > 0], float)
    if values.size and values.max() > WIDE_RANGE * values.min():
        ax.set_yscale("log")
        plain_log_ticks(ax)


def figure(metrics: dict):
    import matplotlib.pyplot as plt

    from train.plotting import legend_outside

    points = metrics["points"]
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.6))
    families: dict[str, list[dict]] = {}
    for p in points:
        families.setdefault(p.get("family") or p["policy"], []).append(p)
    models = [name for name, group in families.items() if group[0]["kind"] == "model"]
    # a model's label: its path below the folder its models share (seed0/model.zip), not the whole path
    shared = os.path.commonpath(models) if len(models) > 1 else None
    # the models draw from colours of their own, none near one of tab10's, which the other families draw from
    palettes = {False: itertools.cycle(plt.get_cmap("tab10").colors), True: itertools.cycle(MODEL_COLOURS)}
    for name, group in sorted(families.items()):
        colour = next(palettes[name in models])
        group = sorted(group, key=lambda p: p["messages_per_agent_step"])
        x = np.array([p["messages_per_agent_step"] for p in group])
        y = np.array([p["mean_cost"] for p in group])
        err = np.array([p["ci95"] if p["ci95"] is not None and math.isfinite(p["ci95"]) else 0.0 for p in group])
        kind = group[0]["kind"]
        style = dict(marker="o" if kind == "baseline" else "D" if kind == "model" else "x",
                     linestyle="-" if len(group) > 1 else "none", color=colour,
                     label=os.path.relpath(name, shared) if shared and name in models else name)
        left.errorbar(x, y, yerr=err, capsize=2, **style)
        rmse = np.array([np.nan if p["rmse"] is None else p["rmse"] for p in group])
        right.plot(x, rmse, **style)
        delivered = np.array([np.nan if p["pcrb_delivered"] is None else p["pcrb_delivered"] for p in group])
        right.plot(x, delivered, marker="_", markersize=12, linestyle="none", color=colour)
    baseline_rows = [p for p in points if p["kind"] == "baseline"]
    vertices = sorted((p for p in baseline_rows if p["policy"] in metrics["frontier"]),
                      key=lambda p: p["messages_per_agent_step"])
    if vertices:
        top = max(p["messages_per_agent_step"] for p in points)
        xs = [v["messages_per_agent_step"] for v in vertices] + [max(top, vertices[-1]["messages_per_agent_step"])]
        ys = [v["mean_cost"] for v in vertices] + [vertices[-1]["mean_cost"]]
        left.plot(xs, ys, color="black", linewidth=2.4, alpha=0.85, zorder=0, label="baseline frontier")
    for key, style in (("pcrb_centralized", "--"), ("pcrb_local", ":")):
        values = [p[key] for p in points if p.get(key) is not None]
        if values:
            right.axhline(float(np.mean(values)), color="black", linestyle=style,
                          label=f"√{key.replace('pcrb_', 'pcrb ')}")
    _log_axis_if_wide(left, [p["mean_cost"] for p in points])
    _log_axis_if_wide(right, [p.get(key) for p in points for key in ("rmse", "pcrb_delivered", "pcrb_centralized",
                                                                        "pcrb_local")])
    comm = metrics["communication"]
    left.set_xlabel(f"{comm} (per agent-step)")
    left.set_ylabel(textwrap.fill(f"{metrics['metric']} ({metrics['unit']})", 45))
    left.set_title("error against communication")
    right.set_xlabel(f"{comm} (per agent-step)")
    right.set_ylabel("position RMSE (m)")
    right.set_title("RMSE and bounds (— under a point: its √pcrb delivered)")
    handles, _ = left.get_legend_handles_labels()
    bound_handles = [h for h, label in zip(*right.get_legend_handles_labels(), strict=True) if label.startswith("√")]
    legend_outside(right, handles=handles + bound_handles)
    fig.suptitle(f"{metrics['scenario']}: {metrics['episodes']} paired episodes")
    fig.tight_layout()
    return fig


def command_line(scenario, models, episodes, seed, quick, executor, address, out, costs=None,
                 bound_episodes=BOUND_EPISODES) -> str:
    args = ["coloc", "frontier", scenario, "--episodes", str(episodes), "--seed", str(seed)] + (["--quick"] if quick
                                                                                               else [])
    if bound_episodes != BOUND_EPISODES:
        args += ["--bound-episodes", str(bound_episodes)]
    if models:
        args += ["--models", models]
    if costs:
        args += ["--costs", ",".join(f"{c:g}" for c in costs)]
    if executor != "local":
        args += ["--executor", executor]
    if address:
        args += ["--address", address]
    return " ".join(args + ["--out", out])


def run_frontier(scenario: str, episodes: int = 30, seed: int | None = None, models: str | None = None,
                 quick: bool = False, executor: str = "local", address: str | None = None, out: str = "results",
                 progress: Callable[[int, int], None] | None = None, mark=None,
                 costs: list[float] | None = None, bound_episodes: int = BOUND_EPISODES) -> tuple[dict, str]:
    """Play every point (the module docstring) and write the three files; returns (metrics, folder). ``costs``
    (``--costs``): each model at each of these communication costs; it needs ``models``. ``bound_episodes``
    (``--bound-episodes``): each point's bounds on the first that many of its episodes."""
    import coloc_env
    from train.evaluate import EVAL_SEED_BASE, check_costs
    from train.executor import map_tasks
    from train.io import check_output_folder, result_folder, save_figure, write_json, write_text

    try:
        coloc_env.scenario_class(scenario)
    except ValueError as exc:
        raise BadInput(str(exc)) from exc
    if isinstance(episodes, bool) or not isinstance(episodes, (int, np.integer)) or not 2 <= episodes <= MAX_EPISODES:
        raise BadInput(f"episodes must be an integer in [2, {MAX_EPISODES}], got {episodes!r}")
    seed = EVAL_SEED_BASE if seed is None else seed
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed <= 2**62:
        raise BadInput(f"seed must be an integer in [0, 2**62], got {seed!r}")
    if executor not in ("local", "ray"):
        raise BadInput(f"executor must be 'local' or 'ray', got {executor!r}")
    if (isinstance(bound_episodes, bool) or not isinstance(bound_episodes, (int, np.integer))
            or not 1 <= bound_episodes <= MAX_EPISODES):
        raise BadInput(f"bound_episodes must be an integer in [1, {MAX_EPISODES}], got {bound_episodes!r}")
    if costs is not None:
        costs = check_costs(costs)
        if models is None:
            raise BadInput("--costs evaluates trained models at each cost: give them with --models DIR")
    found = find_models(models)
    folder = os.path.join(os.fspath(out), "frontier", folder_name(scenario))
    try:
        check_output_folder(folder)
    except ValueError as exc:
        raise BadInput(f"frontier folder not writable: {exc}") from exc
    core = coloc_env.make_core(scenario, batch=1)
    num_agents, horizon = core.num_agents, int(core.horizon)
    command = command_line(scenario, models, episodes, seed, quick, executor, address, os.fspath(out), costs,
                           bound_episodes)
    with result_folder(folder, command) if mark is None else mark(folder):
        plan = cells(scenario, horizon, found, quick, costs)
        tasks = [(scenario, cell.get("model", cell["policy"]), episodes, seed, cell.get("cost"), bound_episodes)
                 for cell in plan]
        results = map_tasks(play, tasks, executor, address, progress=progress)
        metrics = summarize(scenario, plan, results, num_agents, episodes, seed)
        metrics["command"] = command
        metrics["bound_episodes"] = min(int(bound_episodes), episodes)
        write_json(os.path.join(folder, "metrics.json"), metrics)
        write_text(os.path.join(folder, "report.md"), report(metrics, command))
        save_figure(os.path.join(folder, FIGURE), figure(metrics))
    return metrics, folder


__all__ = ["FIGURE", "PERIODS", "cells", "find_models", "folder_name", "hull_by_rate", "knob_grids", "run_frontier",
           "summarize"]
