"""Leaderboards: one table per paper (``OUT/<key>/leaderboard.json`` + a PNG dot-and-interval chart) and
``OUT/leaderboard.md`` gathering every scenario evaluated so far.

Each row is one policy (or reference filter) evaluated by ``coloc evaluate`` on the evaluation
seeds 10^6 + e; every row of a scenario plays the same episodes, so rows compare *paired*:
episode by episode, the difference d_e = cost_e(row) - cost_e(baseline), its mean and the 95 %
Student-t interval  dbar +- t_{0.975, n-1} s_d / sqrt(n)  (``paired_difference``). The
baseline is the scenario's strongest realizable one (``train.evaluate.baselines``: the best of
them by mean on these episodes), never a bound and not merely the paper's choice. A row
"beats" it only when that interval lies below zero; an interval that holds zero is "not
distinguishable (n episodes)", with the number of episodes a difference of this size would
need to resolve: the least n with t_{0.975, n-1} s_d / sqrt(n) < |dbar| (``episodes_needed``).
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

from coloc_env.config import BadInput, module_names
from train.io import read_json, save_figure, write_json, write_text

LOCK_NAME = ".leaderboard.lock"
STOCHASTIC = " (stochastic)"  # suffix of a model evaluated with sampled actions (``evaluate --stochastic``)

# A composition's episode metric and unit, and what its "communication" counts (a preset declares its own on its
# scenario class: ``metric``, ``metric_unit``, ``communication``).
COMPOSITION_METRIC = ("position error averaged over the steps and agents", "m")
COMPOSITION_COMMUNICATION = "messages sent"

# A composition's target (a combination of parts no paper ran): the error-communication trade-off against
# always and silent.
# "Lower error at equal messages" is judged against the time-sharing of the two (``tradeoff_comparison``),
# the only way always and silent reach a message rate between theirs.
COMPOSITION_TARGET = ("beat always and silent on the error-communication trade-off: a lower error than the better "
                      "of them, its error (paired interval within 2 %) with 30 % fewer messages, or a lower error "
                      "than always and silent mixed to send as many messages", 0.02, 0.30)

KINDS = {"random": "uniform random actions (seeded)", "always": "every transport decision at its maximum",
         "silent": "the least communication the scenario allows"}


def _preset_class(scenario: str):
    from coloc_env.scenarios import REGISTRY

    return REGISTRY.get(scenario)


def metric(scenario: str) -> tuple[str, str]:
    """(what the episode metric is, its unit) for a preset (its class's ``metric``, ``metric_unit``) or a
    composition."""
    cls = _preset_class(scenario)
    return COMPOSITION_METRIC if cls is None else (cls.metric, cls.metric_unit)


def communication(scenario: str) -> str:
    """What the ``communication`` info of a preset (its class's ``communication``) or a composition counts."""
    cls = _preset_class(scenario)
    return COMPOSITION_COMMUNICATION if cls is None else cls.communication


def target(scenario: str) -> tuple[str, float, float]:
    """The learned policies' target: (what it says, the largest |paired error difference| relative to the
    baseline's mean that counts as matching it, the communication saving a match needs); a preset's
    ``LEADERBOARD_TARGET`` in train/hyperparams/<preset>.py, ``COMPOSITION_TARGET`` for a composition."""
    from train import hyperparams

    if _preset_class(scenario) is None:
        return COMPOSITION_TARGET
    return hyperparams.setting(scenario, "LEADERBOARD_TARGET", COMPOSITION_TARGET)


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
            chart(table, os.path.join(out, key, "leaderboard.png"), key)
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
    the interval's ends and the episodes a difference of this size needs (``episodes_needed``)."""
    costs, reference = np.asarray(costs, float), np.asarray(reference, float)
    if costs.shape != reference.shape or costs.ndim != 1:
        raise BadInput(f"paired costs must be two 1-d arrays of one length, got {costs.shape} and {reference.shape}")
    if len(costs) < 2:
        raise BadInput(f"a paired interval needs at least 2 episodes, got {len(costs)}")
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
    the whole interval is within ``ROUNDING`` of zero, else "not distinguishable (n episodes)"."""
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
    """A trained model's row: ``PATH.zip``, sampled ``PATH.zip (stochastic)``, or at one communication cost
    ``PATH.zip @ cost=c ...`` (``train.evaluate.model_row``)."""
    return name.endswith(".zip") or name.endswith(".zip" + STOCHASTIC) or _at_cost(name)


def _trained_sampled(name: str) -> bool:
    """A sampled row ``PATH.zip (stochastic)`` of a model whose ``model.json`` records sampled actions."""
    from train.evaluate import model_actions

    return name.endswith(".zip" + STOCHASTIC) and model_actions(name[:-len(STOCHASTIC)]) == "sampled"


def _at_cost(name: str) -> bool:
    """A trained model's row at one communication cost (``train.evaluate.model_row``)."""
    return ".zip @ cost=" in name


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
    within each group. Bounds are not among them (``bound_rows``)."""
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
    _, tolerance, saving = target(scenario)
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
    ``paired_difference``'s dict with ``verdict`` and ``probability`` p; None where a row lacks paired
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


def baseline_frontier(points) -> list[int]:
    """The vertices of the baseline frontier of ``points`` [(messages per step, mean cost), ...], as indices in
    order of increasing messages.

    At a message rate m the frontier is the lowest expected cost a time-share of the points reaches with at most
    m messages per step: playing point a in a fraction 1 - w of the episodes and point b in the rest gives the
    expected (messages, cost) (1 - w) (m_a, c_a) + w (m_b, c_b), so every time-share lies in the convex hull of
    the points, and the least cost at messages <= m is the lower convex hull from the point of fewest messages
    up to the point of least cost, flat after it (a time-share that sends more than the least-cost point sends
    does no better than it). Ties in messages keep the lower cost; ties in cost the fewer messages."""
    pts = [(float(m), float(c), i) for i, (m, c) in enumerate(points) if math.isfinite(m) and math.isfinite(c)]
    if not pts:
        return []
    pts.sort()
    best = min(pts, key=lambda p: (p[1], p[0]))
    pts = [p for p in pts if p[0] <= best[0]]
    hull: list[tuple[float, float, int]] = []
    for p in pts:  # Andrew's monotone chain, lower half: drop a vertex that lies on or above the new chord
        if hull and hull[-1][0] == p[0]:
            continue  # the same messages, a higher cost (sorted): never on the lower hull
        while len(hull) >= 2:
            (m1, c1, _), (m2, c2, _) = hull[-2], hull[-1]
            if (m2 - m1) * (p[1] - c1) - (c2 - c1) * (p[0] - m1) <= 0:
                hull.pop()
            else:
                break
        hull.append(p)
    return [p[2] for p in hull]


def frontier_mix(rows_: list[dict], messages: float) -> tuple[dict, dict, float] | None:
    """The time-share of the baseline frontier of ``rows_`` at ``messages`` per step: (row a, row b, w), the
    frontier there being (1 - w) a + w b (w in [0, 1]; a = b at a vertex, below the fewest messages of any
    row (the frontier's first vertex: the row is compared with what sends more) and beyond the least-cost
    vertex). None without rows."""
    vertices = [rows_[i] for i in baseline_frontier([(r["communication_per_step"], r["mean_cost"]) for r in rows_])]
    if not vertices:
        return None
    if messages <= vertices[0]["communication_per_step"]:
        return vertices[0], vertices[0], 0.0
    for a, b in zip(vertices[:-1], vertices[1:], strict=True):
        ma, mb = a["communication_per_step"], b["communication_per_step"]
        if messages <= mb:
            return a, b, float((messages - ma) / (mb - ma))
    return vertices[-1], vertices[-1], 0.0


def frontier_comparison(row: dict, baseline_rows: list[dict]) -> dict | None:
    """The row's paired difference against the baseline frontier at the row's own message rate.

    The frontier (``baseline_frontier``) at m = the row's messages per step is the time-share (1 - w) a + w b of
    two baseline rows (``frontier_mix``); its cost in episode e is (1 - w) cost_e(a) + w cost_e(b), which
    ``tradeoff_comparison`` generalizes from always/silent to every baseline. The rows must share the
    seeds. Returns ``paired_difference``'s dict with ``verdict`` (the same words as ``verdict``), ``mix``
    ((a's policy, b's policy, w)) and ``frontier_cost`` (the frontier's mean cost at m); None where a row lacks
    per-episode costs, the seeds differ or no baseline is given."""
    candidates = [r for r in baseline_rows if _episodes(r) is not None and r.get("seed_base") == row.get("seed_base")]
    if _episodes(row) is None or not candidates:
        return None
    mix = frontier_mix(candidates, row["communication_per_step"])
    if mix is None:
        return None
    a, b, w = mix
    n = min(len(_episodes(r)) for r in (row, a, b))
    if n < 2:
        return None
    frontier = (1.0 - w) * np.asarray(_episodes(a)[:n], float) + w * np.asarray(_episodes(b)[:n], float)
    diff = paired_difference(_episodes(row)[:n], frontier)
    return dict(diff, verdict=verdict(diff), mix=(a["policy"], b["policy"], w), frontier_cost=float(frontier.mean()))


PRIVILEGED = ("greedy",)  # realizable in name only: it copies the core (a look-ahead no agent can run)


def frontier_baselines(scenario: str, table: dict) -> list[dict]:
    """The rows of ``table`` the baseline frontier is drawn through: every realizable fixed policy (a name of
    ``agents.available_policies``, a family at any knob) and the realizable reference filters, never a trained
    model, a bound or a privileged policy (``PRIVILEGED``)."""
    import agents
    from train.evaluate import baselines

    realizable = {name.partition(":")[0] for name in agents.available_policies(scenario)} - set(PRIVILEGED)
    return [r for name, r in table.items()
            if not _is_model(name) and not _is_bound(name)
            and (name.partition(":")[0] in realizable or name in baselines(scenario))]


def frontier_verdict(scenario: str, table: dict, name: str) -> dict | None:
    """``frontier_comparison`` of row ``name`` against the frontier of the table's other baselines (a baseline
    row is judged against the frontier of the others, so that a vertex is not compared with itself)."""
    others = [r for r in frontier_baselines(scenario, table) if r["policy"] != name]
    return frontier_comparison(table[name], others) if others else None


def target_verdict(scenario: str, table: dict) -> str | None:
    """One line: the target, judged per trained model against the strongest realizable baseline on paired
    episodes; "met" only when every trained model beats it (or matches it with the communication saving)."""
    # each model as it was trained to act: its deterministic row, or the sampled row of a model trained with
    # sampled actions (train.hyperparams.ACTIONS); another model's sampled row is shown only
    models = sorted(n for n in table if n.endswith(".zip") or _trained_sampled(n))
    if not models:
        return None
    text = target(scenario)[0]
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
        if _preset_class(scenario) is None and "always" in table and "silent" in table:
            mixed = tradeoff_comparison(table[name], table["always"], table["silent"])
            if mixed is not None:
                ok = ok or mixed["verdict"] == "beats"
                part += (f", against always and silent mixed to send as many messages (always in "
                         f"{100 * mixed['probability']:.0f} % of episodes): {mixed['verdict']} "
                         f"({mixed['mean']:+.4g} {unit}, 95 % [{mixed['low']:+.4g}, {mixed['high']:+.4g}])")
        against = frontier_verdict(scenario, table, name)
        if against is not None:
            a, b, w = against["mix"]
            at = a if a == b else f"{a} and {b} time-shared ({100 * w:.0f} % {b})"
            part += (f"; against the baseline frontier at its message rate ({at}): {against['verdict']} "
                     f"({against['mean']:+.4g} {unit}, 95 % [{against['low']:+.4g}, {against['high']:+.4g}])")
        met = met and ok
        parts.append(part)
    candidates = [n for n in baselines(scenario) if n in table]
    return (f"Target: {text}. Strongest realizable baseline: {baseline['policy']} {baseline['mean_cost']:.4g} {unit} "
            f"(best of {', '.join(candidates)}). " + "; ".join(parts) + f": {'**met**' if met else '**not met**'}.")


# --- output -------------------------------------------------------------------------------------------
VERDICT_STYLE = {  # marker colour and legend text of a row by its paired verdict against the strongest baseline
    "baseline": ("black", "s", "the strongest realizable baseline (the reference of the right panel)"),
    "beats": ("tab:green", "o", "beats it: paired 95 % interval below 0"),
    "worse": ("tab:red", "o", "worse: paired 95 % interval above 0"),
    "open": ("tab:blue", "o", "not distinguishable: the paired 95 % interval holds 0"),
    "equal": ("tab:purple", "D", "equal to rounding (the same decisions)"),
    "unpaired": ("0.55", "o", "not paired with the baseline (other seeds or no per-episode costs)"),
    "bound": ("0.45", "d", "bound: uses what the agents cannot have (not a result)"),
}
OFF_SCALE = 10.0  # a row whose mean exceeds this many times the median mean is drawn at the edge, its value written


def _style(scenario: str, row: dict, baseline: dict | None) -> str:
    if baseline is not None and row["policy"] == baseline["policy"]:
        return "baseline"
    if _is_bound(row["policy"]):
        return "bound"
    result = comparison(scenario, row, baseline)
    if result is None:
        return "unpaired"
    if result.get("equal"):
        return "equal"
    return "beats" if result["high"] < 0 else "worse" if result["low"] > 0 else "open"


def identical_rows(table: dict) -> list[tuple[str, str]]:
    """Pairs of rows (earlier, later in ``rows`` order) that played the same episodes to the last digit:
    equal per-episode costs on the same seeds and equal communication. Their bars would say nothing the
    other does not; the report says why they coincide (``IDENTICAL_BECAUSE``)."""
    entries = rows(table) + bound_rows(table)
    same = []
    for i, a in enumerate(entries):
        for b in entries[i + 1:]:
            ca, cb = _episodes(a), _episodes(b)
            if ca is None or cb is None or len(ca) != len(cb) or a.get("seed_base") != b.get("seed_base"):
                continue
            if np.array_equal(np.asarray(ca, float), np.asarray(cb, float)) and \
                    a["communication_per_step"] == b["communication_per_step"]:
                same.append((a["policy"], b["policy"]))
    return same


# Why two rows of a preset coincide, where the code makes them the same policy on purpose.
IDENTICAL_BECAUSE = {
    ("bandwidth_fusion", frozenset({"always", "silent"})):
        "with `exact_budget=True` (the paper's setting) every feasible selection takes exactly `budget` components "
        "per receiver, so the selection with the fewest components (`silent`) and the one with the most (`always`) "
        "are the same first selection in the budget's order, with the same weights P1: `silent` is the least the "
        "budget allows, not nothing (agents/generic.py). Set `exact_budget=False` to let them differ.",
}


def identical_note(scenario: str, pair: tuple[str, str]) -> str:
    """One sentence: the two rows coincide, and why where ``IDENTICAL_BECAUSE`` knows."""
    reason = IDENTICAL_BECAUSE.get((scenario, frozenset(pair)))
    return (f"`{pair[0]}` and `{pair[1]}` are identical episode by episode (same cost, same communication)"
            + (f": {reason}" if reason else "."))


def chart(table: dict, path: str, key: str) -> None:
    """Write ``leaderboard_figure`` to ``path`` (atomically)."""
    save_figure(path, leaderboard_figure(table, key))


def _off_scale(values: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Rows whose |value| exceeds ``OFF_SCALE`` x the median |value| (never a row of ``keep``)."""
    finite = np.abs(values[np.isfinite(values)])
    if finite.size < 2:
        return np.zeros(len(values), bool)
    limit = OFF_SCALE * max(float(np.median(finite)), 1e-300)
    return (np.abs(values) > limit) & ~keep


def leaderboard_figure(table: dict, key: str):
    """The leaderboard as a dot-and-interval figure on linear axes; returns the figure.

    One row per policy, reference filter, trained summary and bound (at the bottom, grey diamonds). Left:
    each row's mean episode error with its 95 % Student-t interval, the strongest baseline's mean as a
    dashed line. Right: the paired difference (episode by episode) to the strongest realizable baseline
    with its 95 % interval, zero marked; each dot's colour is the verdict, and the number, interval and
    verdict are written beside it. A row whose mean is more than ``OFF_SCALE`` x the median is drawn
    as an arrow at the right edge of both panels with its value written, so that it does not flatten the
    comparison of the others. Every marker is named in the legend under the panels.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from train.evaluate import baselines

    scenario = next(iter(table.values()))["scenario"]
    name, unit = metric(scenario)
    unit = unit.replace("^2", "\u00b2")
    baseline = strongest_baseline(scenario, table)
    # a model is drawn through its seeds' summary, a model at one communication cost as its own row
    shown = [r for r in rows(table) if not _is_model(r["policy"]) or _at_cost(r["policy"])] + bound_rows(table)
    count = len(shown)
    y = np.arange(count)[::-1].astype(float)
    means = np.array([r["mean_cost"] for r in shown], float)
    half = np.array([r["ci95"] for r in shown], float)
    is_base = np.array([baseline is not None and r["policy"] == baseline["policy"] for r in shown])
    off = _off_scale(means, is_base)
    styles = [_style(scenario, r, baseline) for r in shown]
    diffs = [None if baseline is None else comparison(scenario, r, baseline) for r in shown]
    paired_any = any(d is not None for d in diffs)

    fig, axes = plt.subplots(1, 2 if paired_any else 1, figsize=(11.5 if paired_any else 7.5, 1.9 + 0.42 * count),
                             sharey=True, layout="constrained", squeeze=False)
    axes = axes[0]
    ax = axes[0]

    def draw(axis, values, low, high, column_off):
        inside = ~column_off & np.isfinite(values)
        lo = np.nanmin(np.where(inside, low, np.nan)) if inside.any() else 0.0
        hi = np.nanmax(np.where(inside, high, np.nan)) if inside.any() else 1.0
        pad = 0.08 * max(hi - lo, 1e-12 * max(abs(hi), 1.0), 1e-300)
        if column_off.any():
            pad *= 2.5  # room for the arrows and their values
        axis.set_xlim(lo - pad, hi + pad)
        edge = hi + pad
        for i in range(count):
            colour, marker, _ = VERDICT_STYLE[styles[i]]
            if not np.isfinite(values[i]):
                continue
            if column_off[i]:
                axis.plot([edge], [y[i]], marker=">", color=colour, ms=8, clip_on=False, zorder=4)
                axis.annotate(f"{values[i]:.3g}", (edge, y[i]), xytext=(-10, 0), textcoords="offset points",
                              ha="right", va="center", fontsize=7, color=colour)
                continue
            axis.plot([low[i], high[i]], [y[i], y[i]], color=colour, lw=1.8, solid_capstyle="butt", zorder=2)
            axis.plot([values[i]], [y[i]], marker=marker, color=colour, ms=7,
                      mfc="white" if styles[i] == "bound" else colour, zorder=3)
        axis.grid(True, axis="x", color="0.9", lw=0.6)

    draw(ax, means, means - half, means + half, off)
    if baseline is not None:
        ax.axvline(baseline["mean_cost"], color="black", ls="--", lw=0.9, zorder=1)
    ax.set_yticks(y, [r["policy"] for r in shown], fontsize=8)
    ax.set_ylim(-0.7, count - 0.3)
    ax.set_xlabel(f"mean episode error [{unit}]", fontsize=9)
    ax.set_title(f"mean with 95 % interval ({shown[0]['episodes']} episodes)", fontsize=9)
    handles = []
    if paired_any:
        right = axes[1]
        d_mean = np.array([np.nan if d is None else d["mean"] for d in diffs], float)
        d_low = np.array([np.nan if d is None else d["low"] for d in diffs], float)
        d_high = np.array([np.nan if d is None else d["high"] for d in diffs], float)
        d_mean[is_base], d_low[is_base], d_high[is_base] = 0.0, 0.0, 0.0
        draw(right, d_mean, d_low, d_high, off)
        right.axvline(0.0, color="black", ls="--", lw=1.0, zorder=2.5)
        right.set_xlabel(f"paired difference to {baseline['policy']} [{unit}] (below 0: lower error)", fontsize=9)
        right.set_title("paired difference with 95 % interval, same episodes", fontsize=9)
        twin = right.twinx()
        twin.set_ylim(right.get_ylim())
        words = []
        for i, d in enumerate(diffs):
            if is_base[i]:
                words.append("reference")
            elif d is None:
                words.append("not paired")
            elif d.get("equal"):
                words.append("0 (equal to rounding)")
            else:
                text = d["verdict"].split(" (")[0]
                if styles[i] == "bound" and text == "beats":
                    text = "below (a bound, not a result)"
                words.append(f"{d['mean']:+.3g} [{d['low']:+.3g}, {d['high']:+.3g}] {text}")
        twin.set_yticks(y, words, fontsize=7)
        twin.tick_params(axis="y", length=0, pad=10)  # clear of the off-scale arrows at the edge
        twin.set_ylabel(f"paired difference [{unit}], 95 % interval, verdict", fontsize=8)
        handles.append(Line2D([], [], color="black", ls="--", lw=0.9, label="0: equal to the baseline (right); "
                              "the baseline's mean (left)"))
    elif baseline is not None:
        handles.append(Line2D([], [], color="black", ls="--", lw=0.9, label="the strongest baseline's mean"))
    for style in dict.fromkeys(styles):
        colour, marker, text = VERDICT_STYLE[style]
        if style == "baseline":
            candidates = [n for n in baselines(scenario) if n in table]
            text = (f"the strongest realizable baseline, {baseline['policy']}"
                    + (f" (best of {', '.join(candidates)})" if len(candidates) > 1 else "")
                    + "; a row that is not a designated baseline may beat it")
        handles.append(Line2D([], [], color=colour, marker=marker, lw=1.8, ms=7,
                              mfc="white" if style == "bound" else colour, label=text))
    if off.any():
        handles.append(Line2D([], [], color="0.3", marker=">", ls="", ms=8,
                              label=f"off scale (mean > {OFF_SCALE:g}x the median): value written beside the arrow"))
    identical = identical_rows(table)
    title = f"{key} ({scenario}): {name} [{unit}], lower is better"
    if identical:
        title += "\n" + "; ".join(f"{a} and {b} identical episode by episode (see leaderboard.md)"
                                   for a, b in identical)
    fig.suptitle(title, fontsize=9)
    fig.legend(handles=handles, loc="outside lower center", ncol=2, fontsize=7.5, frameon=False)
    return fig


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


def _frontier_cell(scenario: str, table: dict | None, row: dict) -> str:
    if table is None or row["policy"] not in table:
        return ""
    result = frontier_verdict(scenario, table, row["policy"])
    if result is None:
        return ""
    return f"{result['verdict']} ({result['mean']:+.3g}, 95 % [{result['low']:+.3g}, {result['high']:+.3g}])"


def _table(scenario: str, entries: list[dict], baseline: dict | None, show_initial: bool,
           table: dict | None = None) -> list[str]:
    _, unit = metric(scenario)
    comm = communication(scenario)
    versus = baseline["policy"] if baseline else "the strongest baseline"
    header = (f"| row | what it is | mean error [{unit}] | 95 % CI [{unit}] | paired difference vs {versus} "
              f"[{unit}] | its 95 % CI [{unit}] | verdict (paired) |"
              + (f" with the initial term [{unit}] |" if show_initial else "")
              + f" communication [{comm} / step] | vs the baseline frontier at its rate [{unit}] | episodes [n] |")
    lines = [header, "|" + "---|" * (header.count("|") - 1)]
    for r in entries:
        name = r["policy"] + (f" (seed means {r['spread'][0]:.4g}..{r['spread'][1]:.4g} {unit})" if "spread" in r
                              else "")
        diff, interval, text = _difference_cells(scenario, r, baseline)
        initial = f" {r['paper_cost']:.4g} |" if show_initial else ""
        lines.append(f"| {name} | {_kind(scenario, r, baseline)} | {r['mean_cost']:.4g} | ±{r['ci95']:.3g} | {diff} | "
                     f"{interval} | {text} |{initial} {r['communication_per_step']:.3g} | "
                     f"{_frontier_cell(scenario, table, r)} | {r['episodes']} |")
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
    poses = any(r.get("pose_nees") is not None for r in entries)
    if poses:  # an SE(2) backend: its pose NEES (3 degrees of freedom) beside the position's
        lines[-2] = lines[-2] + " pose NEES (3 if consistent) | per-step pose NEES in its band |"
        lines[-1] = lines[-1] + "---|---|"

    def in_band(r, key):
        band = r.get(f"{key}_band")
        return "-" if band is None else f"{100 * r[f'{key}_in_band']:.0f} % in [{band[0]:.3g}, {band[1]:.3g}]"

    for r in entries:
        bounds = " / ".join(number(r.get(f"pcrb_{k}")) for k in ("centralized", "delivered", "local"))
        line = (f"| {r['policy']} | {number(r['rmse'])} | {bounds} | {number(r.get('efficiency'), 3)} | "
                f"{number(r.get('nees'), 3)} | {in_band(r, 'nees')} |")
        if poses:
            line += f" {number(r.get('pose_nees'), 3)} | {in_band(r, 'pose_nees')} |"
        lines.append(line)
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
        lines += _table(scenario, rows(table), baseline, show_initial, table)
        lines.append("")
        lines += _bounds_table(rows(table))
        bounds = bound_rows(table)
        if bounds:
            lines += ["Bounds (not realizable: hindsight, the truth or information the agents lack; never a "
                      "baseline):", ""]
            lines += _table(scenario, bounds, baseline, show_initial, table)
            lines.append("")
        for pair in identical_rows(table):
            lines += [identical_note(scenario, pair), ""]
        budget = _training_budget(table)
        if budget:
            lines += [budget, ""]
        target = target_verdict(scenario, table)
        if target:
            lines += [target, ""]
    return "\n".join(lines)


def _per_preset(read) -> dict:
    from coloc_env.scenarios import REGISTRY

    return {scenario: read(scenario) for scenario in REGISTRY}


# the per-preset tables this module held before each preset declared them
__getattr__ = module_names(
    __name__, {"METRICS": lambda: _per_preset(metric), "COMMUNICATION": lambda: _per_preset(communication),
               "TARGETS": lambda: _per_preset(target)},
    deprecated=dict.fromkeys(("METRICS", "COMMUNICATION", "TARGETS"), "metric() and communication() read the "
                             "preset's class, target() its train/hyperparams module"))
