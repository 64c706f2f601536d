"""Reproduce Fu, Bi, Gao 2017 (``lossy_fusion``): Figs. 3-5 and the paper's claims, for L = 2 and L = 4 UAVs.

Every filter of ``estimators.lossy_fusion`` runs on the same simulated
runs (paired comparison). Writes ``OUT/fu2017/metrics.json`` with, per
setting ``L2`` / ``L4`` and filter (``naive_kf``, ``centralized``,
``centralized_paper_gain``, ``distributed``, ``informed_kf``,
``leader_only_kf``, ``ideal_kf``):

* ``mse``, ``mse_se``            position MSE (m^2, x+y+z), mean over runs and k = 0..99, and its standard error
* ``mse_late``, ``mse_late_se``  the same over k = 50..99
* ``claimed_late``               mean trace of the filter's own position covariance over k = 50..99
                                 (centralized, centralized_paper_gain, leader_only_kf, ideal_kf)
* ``own_covariance_late``        the same for every filter (mean over runs where it depends on the run)
* ``naive_divergence``           the naive filter's MSE over k = 40..49 and k = 90..99
* ``comparisons``                paired differences behind each claim (mean, standard error)
* ``claims``                     booleans from these numbers
* ``diagnostics``                per setting, filters outside the comparison proper (``DIAGNOSTICS``):
                                 ``mse``, ``mse_se``, ``mse_late``, ``mse_late_se``, ``own_covariance_late``
* ``readings``                   per setting, (B) under each reading of (29) (``READINGS``; ``reading`` of
                                 ``estimators.lossy_fusion.distributed_step``): ``mse``, ``mse_se``,
                                 ``mse_late``, ``own_covariance_late``, and ``versus``: the paired difference
                                 (reading minus reference; mean, se) against each of ``REFERENCES``
* ``pcrb``                       per setting, the posterior Cramér–Rao bound (``bound_block``,
                                 ``train.reproduce.bound_rows``) of the x, y components over k = 0..99
                                 and each filter's RMSE of x, y and efficiency
* ``runs``, ``seed``, ``steps``

plus ``report.md`` and PNG figures.

Every filter is a composition stepped batched over the runs (``filter_runs``): the ``lossy_fusion``
preset's world (``target_cv``: the truth and the measurements) and network (``bernoulli_delay``: the
followers' link outcomes, eq. 3) with the filter's backend (``filter_backend``: ``kalman``,
``centralized_lmmse`` or ``prediction_compensation``), every follower transmitting every slot; the
errors and the filters' own covariances are what the compositions report. Run r of setting L is seeded
``default_rng([seed, L, r])`` and every filter sees the same episodes and link outcomes (paired
comparisons). Monte Carlo blocks of at most ``BLOCK_RUNS`` runs are independent tasks, so a run's
numbers do not depend on the executor or on how many other runs there are.

``paper_policy_costs(seeds)`` gives this reproduction's per-episode number for algorithm (B),
the filter of the env's ``paper`` policy, on the episodes ``env.reset(seed=s)`` draws for each s
in ``seeds``, through the same path as the Monte Carlo above; a test checks that it equals what
``coloc evaluate`` reports for the ``paper`` policy on the same seeds.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

import coloc_env
import estimators.lossy_fusion as lf
from coloc_env.backends import CentralizedLmmse, Kalman
from coloc_env.backends.fusion import LEADER
from coloc_env.composition import compose
from coloc_env.config import BadInput, build_config
from coloc_env.scenarios.binding import PresetScenario
from coloc_env.scenarios.composed import ComposedScenario
from coloc_env.scenarios.lossy_fusion import LossyFusionConfig
from train.executor import map_tasks
from train.io import save_figure, write_json, write_text
from train.reproduce.bound_rows import pcrb_block, report_section
from train.reproduce.common import block_sizes, mean_se, pyplot

KEY = "fu2017"
RUNS = 500
QUICK_RUNS = 100
BLOCK_RUNS = 100
SETTINGS = {"L2": 2, "L4": 4}
CLAIMED = ("centralized", "centralized_paper_gain", "leader_only_kf", "ideal_kf")
LABELS = {
    "naive_kf": "general KF (received y as fresh)",
    "centralized": "(A) centralized, LMMSE gain",
    "centralized_paper_gain": "(A) centralized, paper gain (21)",
    "distributed": "(B) distributed (29)-(31)",
    "informed_kf": "KF knowing packet ages",
    "leader_only_kf": "leader-only KF",
    "ideal_kf": "ideal KF (no losses)",
}
# claim id -> (better filter, worse filter, what the paper says)
BEATS = {
    "centralized_beats_naive": ("centralized", "naive_kf",
                                "the centralized algorithm beats the general Kalman filter (Fig. 3)"),
    "distributed_beats_naive": ("distributed", "naive_kf",
                                "the distributed algorithm beats the general Kalman filter (Fig. 4)"),
    "centralized_beats_distributed": ("centralized", "distributed",
                                      "the centralized algorithm is more accurate than the distributed one (Fig. 5)"),
    "centralized_beats_leader_only": ("centralized", "leader_only_kf",
                                      "cooperation helps: (A) beats the leader alone (Sec. 1, implied)"),
    "distributed_beats_leader_only": ("distributed", "leader_only_kf",
                                      "cooperation helps: (B) beats the leader alone (Sec. 1, implied)"),
}
# not in the comparison proper: (B) under the other readings of (29) (estimators.lossy_fusion.READINGS: each
# held packet predicted forward by its possible ages, realizable; with (26)'s printed covariance, without the
# spread of the predictions; predicted forward by its known age, which needs time stamps), and (A) with the
# paper's gain (21) and its second moments exactly as printed (12)-(14), (20)
DIAGNOSTICS = ("distributed_forward", "distributed_forward_printed_covariance", "distributed_age_aware",
               "centralized_printed_moments")
# (B)'s readings side by side: row name -> (reading, forward_spread, what the leader needs)
READINGS = {
    "distributed": ("current", True, "nothing beyond the paper: the held packet as if current (as printed)"),
    "distributed_forward": ("forward", True, "nothing beyond the paper: predicted by each possible age (realizable)"),
    "distributed_forward_printed_covariance": ("forward", False, "as forward, covariance as (26) prints it"),
    "distributed_age_aware": ("age_aware", True, "time stamps: each packet's age"),
}
REFERENCES = ("informed_kf", "leader_only_kf", "centralized", "naive_kf")
DIAGNOSTIC_LABELS = {
    "distributed_forward": "(B), held packet predicted by each possible age",
    "distributed_forward_printed_covariance": "(B) forward, (26)'s covariance",
    "distributed_age_aware": "(B), held packet predicted by its known age",
    "centralized_printed_moments": "(A), paper gain and printed moments",
}
PAPER_FILTER = "distributed"  # the env's ``paper`` policy: (B), all transmit, weights (29)/(30)
SIGNIFICANCE = 2.0  # a difference counts when it exceeds this many standard errors
BOUND_EPISODES = 20  # seeded episodes of the delivered bound (the centralized and local ones do not depend on them)


def filter_backend(name: str, config: LossyFusionConfig):
    """The backend config that runs filter ``name`` (of ``estimators.lossy_fusion.FILTERS`` or
    ``DIAGNOSTICS``) at the leader:

    | filter                        | backend                                                         |
    |-------------------------------|-----------------------------------------------------------------|
    | ``naive_kf``, ``informed_kf``, | ``kalman`` (``variant`` naive, informed, leader_only, ideal)   |
    | ``leader_only_kf``, ``ideal_kf`` |                                                              |
    | ``centralized``               | ``centralized_lmmse`` (gain optimal)                            |
    | ``centralized_paper_gain``    | ``centralized_lmmse`` (gain paper, eq. 21)                      |
    | ``centralized_printed_moments`` | ``centralized_lmmse`` (gain paper, moments printed)           |
    | ``distributed`` and its       | the preset's ``prediction_compensation`` with the row's         |
    | readings (``READINGS``)   | ``reading`` and ``forward_spread``                              |
    """
    if name in READINGS:
        reading, spread, _ = READINGS[name]
        return dataclasses.replace(config.parts()[2], reading=reading, forward_spread=spread)
    backends = {
        "naive_kf": Kalman(variant="naive"),
        "informed_kf": Kalman(variant="informed"),
        "leader_only_kf": Kalman(variant="leader_only"),
        "ideal_kf": Kalman(variant="ideal"),
        "centralized": CentralizedLmmse(gain="optimal"),
        "centralized_paper_gain": CentralizedLmmse(gain="paper"),
        "centralized_printed_moments": CentralizedLmmse(gain="paper", moments="printed"),
    }
    if name not in backends:
        raise BadInput(f"unknown filter {name!r}; available: {[*lf.FILTERS, *DIAGNOSTICS]}")
    return backends[name]


class PairedComposition(ComposedScenario):
    """A composition whose copies draw their episodes by the ``lossy_fusion`` preset's rule
    (``coloc_env.scenarios.binding.PresetScenario.part_generators``: the world from the episode's
    generator itself, the network from its first child): reset with ``default_rng(s)``, every backend
    on the preset's world and network sees the episode and the link outcomes ``env.reset(seed=s)``
    draws."""

    part_generators = PresetScenario.part_generators


def filter_runs(config: LossyFusionConfig, seeds, names=(*lf.FILTERS, *DIAGNOSTICS)) -> dict:
    """Each filter of ``names`` on the episodes of ``seeds``, as a composition stepped batched.

    Filter f is the composition of the ``lossy_fusion`` preset's world (``target_cv``) and network
    (``bernoulli_delay``) with ``filter_backend`` ``(f)``, one copy per seed, reset with
    ``default_rng(seed)`` (``PairedComposition``: every filter on the same episodes and link
    outcomes, those of ``env.reset(seed=seed)``), every follower transmitting every slot and every
    decision at its paper default (the ``always`` action). Returns, per filter, ``errors`` (runs, K):
    the infos' ``error`` ||H (xhat(k|k) - x(k))||^2 (``ComposedScenario.target_error``) of the
    leader's estimate (shared by every agent), and ``own`` the trace of the position block of the
    filter's own covariance P(k|k) (the infos' ``trace`` over the world's metric, ``metric_traces``)
    (runs, K), or (K,) where it does not depend on the data (the same for every run); ``errors_xy`` (runs, K)
    the squared error of the leader's x, y (the world's ``position_index``, ``coloc_env.pcrb``'s
    coordinates); and ``delivered``
    the frequencies of the followers' link outcomes (on time, late, lost; eq. 3) the network drew.
    """
    seeds = list(seeds)
    world, network, _ = config.parts()
    errors, own, errors_xy, delivered = {}, {}, {}, None
    for name in names:
        spec = compose(world=world, network=network, backend=filter_backend(name, config), horizon=config.horizon)
        scenario = PairedComposition(spec, batch=len(seeds))
        scenario.reset([np.random.default_rng(s) for s in seeds])
        actions = np.broadcast_to(scenario.action_vector("maximum"), (len(seeds), scenario.num_agents,
                                                                      scenario.action_space().shape[0]))
        err, tr = np.empty((len(seeds), config.horizon)), np.empty((len(seeds), config.horizon))
        err_xy = np.empty((len(seeds), config.horizon))
        for k in range(config.horizon):
            scenario.step(actions)
            err[:, k] = scenario.target_error()[:, LEADER]
            tr[:, k] = scenario.metric_traces()[:, LEADER]
            err_xy[:, k] = scenario.position_error()[:, LEADER] ** 2
        errors[name], own[name] = err, (tr[0] if np.all(tr == tr[0]) else tr)
        errors_xy[name] = err_xy
        if delivered is None:
            outcome = scenario.network.slot_outcomes(range(config.horizon))[:, :, 1:, LEADER]
            delivered = np.bincount(outcome.ravel(), minlength=3) / outcome.size
    return {"errors": errors, "own": own, "errors_xy": errors_xy, "delivered": delivered}


def block_seeds(num_agents: int, runs: int, seed: int, block: int) -> list:
    """The episode seeds of one block: run r of block b is ``[seed, L, b * BLOCK_RUNS + r]``."""
    return [[seed, num_agents, block * BLOCK_RUNS + r] for r in range(runs)]


def monte_carlo_block(num_agents: int, runs: int, seed: int, block: int, config: LossyFusionConfig) -> dict:
    """``runs`` episodes with ``num_agents`` UAVs, every filter on the same episodes (``filter_runs`` on
    ``block_seeds``)."""
    config = dataclasses.replace(config, num_agents=num_agents)
    return {"num_agents": num_agents, "block": block,
            **filter_runs(config, block_seeds(num_agents, runs, seed, block))}


def paper_policy_costs(seeds, config: LossyFusionConfig | None = None) -> np.ndarray:
    """Per-episode MSE (mean over the slots of the squared position error) of ``PAPER_FILTER``,
    the filter the env's ``paper`` policy runs, on the episodes the env draws for ``seeds``
    (``filter_runs``: the preset's composition reset with ``default_rng(seeds[e])``), with
    ``config.num_agents`` UAVs (the env's default 2: setting L2).
    """
    config = config or build_config(LossyFusionConfig, {})
    return filter_runs(config, seeds, (PAPER_FILTER,))["errors"][PAPER_FILTER].mean(axis=1)


def _merge(blocks: list[dict]) -> dict:
    errors = {f: np.concatenate([b["errors"][f] for b in blocks]) for f in (*lf.FILTERS, *DIAGNOSTICS)}
    own = {}
    for f in (*lf.FILTERS, *DIAGNOSTICS):
        parts = [b["own"][f] for b in blocks]
        if any(p.ndim == 2 for p in parts):  # a block of one run reports its curve as (K,)
            own[f] = np.concatenate([np.broadcast_to(p, (len(b["errors"][f]), p.shape[-1]))
                                     for p, b in zip(parts, blocks, strict=True)])
        else:
            own[f] = parts[0]
    weights = np.array([len(b["errors"]["ideal_kf"]) for b in blocks], float)
    delivered = np.average([b["delivered"] for b in blocks], axis=0, weights=weights)
    errors_xy = {f: np.concatenate([b["errors_xy"][f] for b in blocks]) for f in (*lf.FILTERS, *DIAGNOSTICS)}
    return {"errors": errors, "own": own, "errors_xy": errors_xy, "delivered": delivered}


def bound_block(config: LossyFusionConfig, errors_xy: dict, seed: int, episodes: int = BOUND_EPISODES) -> dict:
    """The ``pcrb`` block of one setting: ``coloc_env.pcrb`` of the preset's world and network with the
    ``kalman`` backend (variant ``informed``, whose packets of the followers' readings define ``delivered``),
    beside each filter's error of the x, y components over k = 0..K-1 (``errors_xy`` {filter: (runs, K)}).

    ``target_cv`` is linear and Gaussian and every UAV reads at every step, so ``centralized`` (the ideal
    Kalman filter's covariance) and ``local`` (the leader alone) are the same for every episode: they are the
    bounds of this reproduction's runs. ``delivered`` (the leader's readings plus the followers' packets that
    arrived, each counted at its measurement step: the informed filter's covariance) depends on the link
    outcomes: it is the bound over ``episodes`` seeded episodes (episode e reset with seed + e), not over the
    runs (seeded ``[seed, L, r]``). Every filter uses no more than every UAV's readings, so its efficiency
    is >= 1 up to Monte Carlo noise; ``ideal_kf`` attains the centralized bound, ``informed_kf`` the delivered.
    """
    world, network, _ = config.parts()
    spec = compose(world=world, network=network, backend=Kalman(variant="informed"), horizon=config.horizon)
    bounds = coloc_env.pcrb(spec, episodes=episodes, seed=seed)
    note = (f"fu2017: centralized and local do not depend on the episode (linear-Gaussian, every UAV reads at every "
            f"step); delivered (the informed KF's information) over {episodes} seeded episodes of the preset's "
            "world and network, not the runs; x, y components, k = 0..99")
    return pcrb_block(bounds, {f: errors_xy[f].mean(axis=1) for f in lf.FILTERS}, episodes, seed, False, note)


def run(out: str, runs: int = RUNS, seed: int = 0, quick: bool = False, executor: str = "local",
        address: str | None = None, config: LossyFusionConfig | None = None, progress=None) -> dict:
    """Compute everything, write ``out/fu2017/``, return the metrics dict."""
    config = config or build_config(LossyFusionConfig, {})
    if runs < 2:
        raise BadInput(f"runs must be >= 2 for a standard error, got {runs}")
    K = config.horizon
    if K < 100:
        raise BadInput(f"the paper's windows need horizon >= 100 slots, got {K}")
    late = slice(K // 2, K)
    items = [(L, size, seed, block, config) for L in SETTINGS.values()
             for block, size in enumerate(block_sizes(runs, BLOCK_RUNS))]
    blocks = map_tasks(monte_carlo_block, items, executor, address)
    data = {key: _merge([b for b in blocks if b["num_agents"] == L]) for key, L in SETTINGS.items()}
    if progress:
        progress(f"Monte Carlo ({runs} runs x {len(SETTINGS)} settings) done")

    metrics: dict = {"runs": runs, "seed": seed, "steps": K}
    for key in ("mse", "mse_se", "mse_late", "mse_late_se", "claimed_late", "own_covariance_late",
                "naive_divergence", "comparisons", "claims", "diagnostics", "readings"):
        metrics[key] = {}
    for key, d in data.items():
        err, own = d["errors"], d["own"]
        metrics["mse"][key], metrics["mse_se"][key] = {}, {}
        metrics["mse_late"][key], metrics["mse_late_se"][key] = {}, {}
        for f in lf.FILTERS:
            metrics["mse"][key][f], metrics["mse_se"][key][f] = mean_se(err[f].mean(axis=1))
            metrics["mse_late"][key][f], metrics["mse_late_se"][key][f] = mean_se(err[f][:, late].mean(axis=1))
        metrics["own_covariance_late"][key] = {f: float(own[f][..., late].mean()) for f in lf.FILTERS}
        metrics["diagnostics"][key] = {}
        for f in DIAGNOSTICS:
            mse, se = mean_se(err[f].mean(axis=1))
            mse_late, se_late = mean_se(err[f][:, late].mean(axis=1))
            metrics["diagnostics"][key][f] = {"mse": mse, "mse_se": se, "mse_late": mse_late,
                                              "mse_late_se": se_late,
                                              "own_covariance_late": float(own[f][..., late].mean())}
        metrics["readings"][key] = {}
        for f in READINGS:
            mse, se = mean_se(err[f].mean(axis=1))
            versus = {}
            for ref in REFERENCES:
                diff, diff_se = mean_se(err[f].mean(axis=1) - err[ref].mean(axis=1))
                versus[ref] = {"difference": diff, "se": diff_se}
            metrics["readings"][key][f] = {"mse": mse, "mse_se": se, "mse_late": float(err[f][:, late].mean()),
                                           "own_covariance_late": float(own[f][..., late].mean()), "versus": versus}
        metrics["claimed_late"][key] = {f: metrics["own_covariance_late"][key][f] for f in CLAIMED}
        naive = err["naive_kf"]
        metrics["naive_divergence"][key] = {"mse_k40_49": float(naive[:, 40:50].mean()),
                                            "mse_k90_99": float(naive[:, 90:100].mean())}
        comparisons = {}
        for claim, (better, worse, _) in BEATS.items():
            diff, se = mean_se(err[better].mean(axis=1) - err[worse].mean(axis=1))
            comparisons[claim] = {"difference": diff, "se": se}
        for name in ("naive_kf", "ideal_kf"):
            diff, se = mean_se(err[name][:, 90:100].mean(axis=1) - err[name][:, 40:50].mean(axis=1))
            comparisons[f"{name}_growth_k90_99_minus_k40_49"] = {"difference": diff, "se": se}
        diff, se = mean_se(err["centralized"].mean(axis=1) - err["centralized_paper_gain"].mean(axis=1))
        comparisons["optimal_minus_paper_gain"] = {"difference": diff, "se": se}
        diff, se = mean_se(err["informed_kf"].mean(axis=1) - err["centralized"].mean(axis=1))
        comparisons["informed_minus_centralized"] = {"difference": diff, "se": se}
        metrics["comparisons"][key] = comparisons
        claims = {claim: bool(c["difference"] < -SIGNIFICANCE * c["se"])
                  for claim, c in comparisons.items() if claim in BEATS}
        growth = comparisons["naive_kf_growth_k90_99_minus_k40_49"]
        claims["naive_diverges"] = bool(growth["difference"] > SIGNIFICANCE * growth["se"])
        metrics["claims"][key] = {c: claims[c] for c in (
            "centralized_beats_naive", "distributed_beats_naive", "centralized_beats_distributed",
            "naive_diverges", "centralized_beats_leader_only", "distributed_beats_leader_only")}
    metrics["link_outcome_frequencies"] = {key: {"on_time": float(d["delivered"][0]), "late": float(d["delivered"][1]),
                                                 "lost": float(d["delivered"][2])} for key, d in data.items()}
    metrics["pcrb"] = {key: bound_block(dataclasses.replace(config, num_agents=L), data[key]["errors_xy"], seed)
                       for key, L in SETTINGS.items()}
    if progress:
        progress("Cramér–Rao bounds done")

    folder = os.path.join(out, KEY)
    write_json(os.path.join(folder, "metrics.json"), metrics)
    _figures(folder, data, config.period)
    write_text(os.path.join(folder, "report.md"), _report(metrics, config, quick))
    if progress:
        progress("figures and report written")
    return metrics


# line styles that keep curves apart where their values coincide: (A) with the paper's gain (21) lies on (A)
# with the LMMSE gain (same colour family), so it is a thin line with open markers over a thick one
STYLES = {"centralized": {"lw": 2.6, "alpha": 0.75},
          "centralized_paper_gain": {"lw": 1.0, "marker": "o", "markevery": 8, "ms": 4.5, "mfc": "none"}}
COLOURS = {**dict(zip(lf.FILTERS, ["tab:red", "tab:blue", "tab:cyan", "tab:orange", "tab:green", "tab:purple", "k"],
                      strict=True)),
           **dict(zip(DIAGNOSTICS, ["tab:brown", "tab:pink", "tab:olive", "tab:gray"], strict=True))}
FIGURES = {  # file -> (filters, title, with the filters' own covariance)
    "fig3_centralized_vs_naive.png": (("centralized", "centralized_paper_gain", "naive_kf"),
                                      "Fig. 3: centralized algorithm vs general Kalman filter", False),
    "fig4_distributed_vs_naive.png": (("distributed", "naive_kf"),
                                      "Fig. 4: distributed algorithm vs general Kalman filter", False),
    "fig5_centralized_vs_distributed.png": (("centralized", "distributed", "leader_only_kf"),
                                            "Fig. 5: centralized vs distributed (leader alone for reference)", False),
    "all_filters.png": (lf.FILTERS, "every filter on the same runs", False),
    "readings.png": ((*READINGS, "leader_only_kf", "centralized", "informed_kf"),
                     "(B) under each reading of (29), against the leader alone, (A) and the informed KF", False),
    "consistency.png": (("centralized", "centralized_paper_gain", "distributed", "naive_kf", "leader_only_kf",
                         "ideal_kf"), "consistency: measured MSE (solid) vs the filter's own covariance (dashed)",
                        True),
}


def curves_figure(data: dict, filters, title: str, period: float = 1.0, own: bool = False):
    """Position MSE against time, one panel per setting of ``data`` (``{setting: {"errors": {f: (runs, K)},
    "own": {f: (K,) or (runs, K)}}}``): per filter the mean over the runs at each slot with its 95 %
    Student-t band from the run-to-run spread, and with ``own`` the trace of the filter's own
    covariance (dashed, mean over runs). The legend, right of the panels, names every line, the band
    and the dashed curves, and says where two filters' curves coincide within the band."""
    plt = pyplot()
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from train.plotting import label, legend_outside, plain_log_ticks, t975

    labels = {**LABELS, **DIAGNOSTIC_LABELS}
    fig, axes = plt.subplots(1, len(data), figsize=(4.6 * len(data) + 3.2, 4), sharey=True, squeeze=False)
    axes = axes[0]
    stats = {}
    for ax, (key, d) in zip(axes, data.items(), strict=True):
        runs = d["errors"][filters[0]].shape[0]
        for f in filters:
            err = np.asarray(d["errors"][f], float)
            mean = err.mean(axis=0)
            half = t975(runs - 1) * err.std(axis=0, ddof=1) / np.sqrt(runs)
            stats[key, f] = (mean, half)
            ks = np.arange(err.shape[1]) * period
            ax.plot(ks, mean, color=COLOURS[f], **STYLES.get(f, {"lw": 1.3}))
            ax.fill_between(ks, np.maximum(mean - half, 1e-3 * mean), mean + half, color=COLOURS[f], alpha=0.18,
                            lw=0)
            if own:
                claimed = np.asarray(d["own"][f], float)
                claimed = claimed if claimed.ndim == 1 else claimed.mean(axis=0)
                ax.plot(ks, claimed, "--", color=COLOURS[f], lw=1.1)
        ax.set_yscale("log")
        ax.set_title(f"{key}: {runs} runs", fontsize=10)
        ax.set_xlabel(label("time kT", "s") + f", T = {period:g} s")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel(label("position MSE", "m²"))
    plain_log_ticks(axes[0])

    handles = []
    for index, f in enumerate(filters):
        text = labels[f]
        for g in filters[:index]:  # a curve that lies on an earlier one (within its band at every slot) says so
            if all(np.all(np.abs(stats[key, f][0] - stats[key, g][0]) <= stats[key, g][1]) for key in data):
                text += f":\n  on the curve of {labels[g]},\n  within its 95 % band at every slot"
                break
        handles.append(Line2D([], [], color=COLOURS[f], label=text, **STYLES.get(f, {"lw": 1.3})))
    handles.append(Patch(color="0.6", alpha=0.4, label="band: 95 % interval of the mean over the runs"))
    if own:
        handles.append(Line2D([], [], color="0.3", ls="--", lw=1.1,
                              label="dashed: trace of the filter's own\n  covariance P(k|k), colour of its filter"))
    legend_outside(axes[-1], handles=handles)
    fig.suptitle(title, fontsize=11)
    return fig


def _figures(folder: str, data: dict, period: float) -> None:
    for name, (filters, title, own) in FIGURES.items():
        save_figure(os.path.join(folder, name), curves_figure(data, filters, title, period, own))


def _fmt(value: float, se: float | None = None) -> str:
    return f"{value:.2f}" if se is None else f"{value:.2f} ± {se:.2f}"


def _report(metrics: dict, config: LossyFusionConfig, quick: bool) -> str:
    m = metrics
    lines = [
        "# fu2017: cooperative localization under Bernoulli delay and packet loss (reproduction)",
        "",
        "Fu, Bi, Gao 2017. Scenario `lossy_fusion`, estimators `estimators/lossy_fusion.py`. Target: 3-D "
        f"constant velocity, T = {config.period:g} s, q = {config.accel_noise:g}, r = {config.measurement_noise:g}; "
        f"followers' packets on time with probability {config.on_time_probability:g}, one slot late with "
        f"{config.late_probability:g}, else lost. Position MSE in m^2 (x+y+z), mean over runs and k = 0..99 "
        f"(late: k = 50..99) ± its standard error over runs. {m['runs']} Monte Carlo runs per setting, seed "
        f"{m['seed']}" + (" (quick mode)." if quick else ".") + " Every filter runs on the same runs.",
        "",
        "## The paper's claims",
        "",
        f"A filter beats another when the paired difference of their per-run MSE is below zero by more than "
        f"{SIGNIFICANCE:g} standard errors. 'The general KF diverges' is read as: its MSE over k = 90..99 exceeds "
        f"that over k = 40..49 by more than {SIGNIFICANCE:g} standard errors (paired).",
        "",
        "| claim | setting | our numbers | holds |",
        "|---|---|---|---|",
    ]
    for claim, (better, worse, text) in BEATS.items():
        for key in SETTINGS:
            c = m["comparisons"][key][claim]
            ours = (f"{better} {_fmt(m['mse'][key][better], m['mse_se'][key][better])} vs {worse} "
                    f"{_fmt(m['mse'][key][worse], m['mse_se'][key][worse])}; paired difference "
                    f"{_fmt(c['difference'], c['se'])}")
            lines.append(f"| {text} | {key} | {ours} | {'yes' if m['claims'][key][claim] else '**no**'} |")
    for key in SETTINGS:
        nd, g = m["naive_divergence"][key], m["comparisons"][key]["naive_kf_growth_k90_99_minus_k40_49"]
        ideal = m["comparisons"][key]["ideal_kf_growth_k90_99_minus_k40_49"]
        lines.append(f"| the general Kalman filter has convergence problems (Sec. 4) | {key} | MSE k=40..49 "
                     f"{nd['mse_k40_49']:.1f}, k=90..99 {nd['mse_k90_99']:.1f} (growth "
                     f"{_fmt(g['difference'], g['se'])}; ideal KF growth {_fmt(ideal['difference'], ideal['se'])}) | "
                     f"{'yes' if m['claims'][key]['naive_diverges'] else '**no**'} |")
    lines += ["", "## (B) against simply ignoring the followers", ""]
    for key in SETTINGS:
        c = m["comparisons"][key]["distributed_beats_leader_only"]
        b, lo = m["mse"][key]["distributed"], m["mse"][key]["leader_only_kf"]
        if c["difference"] > SIGNIFICANCE * c["se"]:
            verdict = f"**(B) is worse than the leader alone**: {b:.2f} vs {lo:.2f} m^2 ({b / lo:.1f} times)."
        elif m["claims"][key]["distributed_beats_leader_only"]:
            verdict = f"(B) beats the leader alone: {b:.2f} vs {lo:.2f} m^2."
        else:
            verdict = f"(B) and the leader alone do not differ significantly: {b:.2f} vs {lo:.2f} m^2."
        lines.append(f"* {key}: {verdict}")
    for key in SETTINGS:
        c = m["mse"][key]
        lines.append(f"* {key}: for scale, (A) {c['centralized']:.2f}, the informed KF (knows the ages) "
                     f"{c['informed_kf']:.2f}, the ideal KF {c['ideal_kf']:.2f} m^2.")
    lines += [
        "",
        "## (B) under each reading of (29)",
        "",
        "The paper's leader does not know a held packet's age. `distributed` weighs the held packet's entries as if "
        "current (the algorithm as printed); `distributed_forward` predicts its filtered estimate forward by each "
        "possible age 0, 1, 2 and weighs the predictions with (29)'s probabilities, its covariance including their "
        "spread (realizable: the derivation is in `estimators/lossy_fusion.py`); `..._printed_covariance` is the "
        "same estimate with (26)'s covariance; `distributed_age_aware` needs time stamps the paper's agents do not "
        "have. MSE in m^2 over k = 0..99 ± its standard error; the columns 'minus X' are paired differences "
        "(negative: the reading is better); **bold** where the difference exceeds "
        f"{SIGNIFICANCE:g} standard errors.",
        "",
        "| setting | reading | the leader needs | MSE | MSE k=50..99 | own covariance k=50..99 | "
        + " | ".join(f"minus {r}" for r in REFERENCES) + " |",
        "|---|---|---|---|---|---|" + "---|" * len(REFERENCES),
    ]
    for key in SETTINGS:
        for f, (_, _, needs) in READINGS.items():
            r = m["readings"][key][f]
            cells = []
            for ref in REFERENCES:
                v = r["versus"][ref]
                text = _fmt(v["difference"], v["se"])
                cells.append(f"**{text}**" if abs(v["difference"]) > SIGNIFICANCE * v["se"] else text)
            lines.append(f"| {key} | `{f}` | {needs} | {_fmt(r['mse'], r['mse_se'])} | {r['mse_late']:.2f} | "
                         f"{r['own_covariance_late']:.2f} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "## Every filter",
        "",
        "| setting | filter | MSE k=0..99 | MSE k=50..99 | own covariance k=50..99 | consistent |",
        "|---|---|---|---|---|---|",
    ]
    for key in SETTINGS:
        for f in lf.FILTERS:
            mse_l, se_l = m["mse_late"][key][f], m["mse_late_se"][key][f]
            claimed = m["own_covariance_late"][key][f]
            consistent = abs(mse_l - claimed) <= 3 * se_l
            verdict = "yes" if consistent else f"**no** (claims {claimed / mse_l:.2g} x the measured)"
            lines.append(f"| {key} | {LABELS[f]} | {_fmt(m['mse'][key][f], m['mse_se'][key][f])} | "
                         f"{_fmt(mse_l, se_l)} | {claimed:.2f} | {verdict} |")
    lines += [
        "",
        "Consistent: the measured late MSE is within 3 standard errors of the mean trace of the filter's own "
        "position covariance. For (A) the covariance is exact (derived in the estimator's docstring), for the "
        "Kalman filters it is the usual one under their own model (wrong for the general KF, which takes stale "
        "values as fresh), for (B) it is P0 = sum a_i^2 P_i of eq. (30), which treats the fused errors as "
        "independent and the held packets as current.",
        "",
        "## Notes",
        "",
    ]
    for key in SETTINGS:
        c = m["comparisons"][key]
        opt, inf = c["optimal_minus_paper_gain"], c["informed_minus_centralized"]
        lines.append(f"* {key}: LMMSE gain minus the paper's gain L = Phibar K (21): "
                     f"{_fmt(opt['difference'], opt['se'])} m^2 (exact own traces at k=50..99: "
                     f"{m['claimed_late'][key]['centralized']:.3f} vs "
                     f"{m['claimed_late'][key]['centralized_paper_gain']:.3f}); informed KF minus (A): "
                     f"{_fmt(inf['difference'], inf['se'])} m^2 (the bound must be below).")
    for key in SETTINGS:
        pm = m["diagnostics"][key]["centralized_printed_moments"]
        lines.append(f"* {key}: (A) with the paper's gain and its second moments exactly as printed (12)-(14): MSE "
                     f"{_fmt(pm['mse'], pm['mse_se'])} m^2 (late {_fmt(pm['mse_late'], pm['mse_late_se'])}, its own "
                     f"covariance claims {pm['own_covariance_late']:.2f}) against {m['mse'][key]['centralized']:.2f} "
                     f"with the derived moments and {m['mse'][key]['leader_only_kf']:.2f} for the leader alone.")
    freq = m["link_outcome_frequencies"]
    lines += [
        "* Link outcomes drawn for the followers: " + "; ".join(
            f"{key} on time {f['on_time']:.3f}, late {f['late']:.3f}, lost {f['lost']:.3f}" for key, f in freq.items())
        + ".",
        "* Departures from the printed equations (derivations in `estimators/lossy_fusion.py`): Cov(xi1, xi2) = "
        "-alpha1 alpha2 (exclusive outcomes) instead of the A1/A2/A3 weights of (13); the cross terms of "
        "E[dH X X^T dH^T] that (12) drops (as printed it depends on where the origin is); E[xi1 R xi1] = alpha1 R, "
        "not alpha1 R alpha1 (14), (20); P(k+1|k) derived for any gain instead of the printed (16).",
        "* The paper gives no numbers, only curves; 'holds' compares our own filters on our runs.",
    ]
    bounds = m["pcrb"]
    b2 = bounds["L2"]["rows"]
    lines += report_section(
        bounds,
        f"With L = 2, (B) is {b2['distributed']['efficiency']:.2f}x the centralized bound and "
        f"{b2['distributed']['rmse'] / bounds['L2']['local']:.2f}x the leader's own (local) bound: there is room, "
        f"and it is the estimator's. The ideal KF is {b2['ideal_kf']['efficiency']:.2f}x the centralized bound (it "
        "attains it up to Monte Carlo noise); the informed KF is "
        f"{b2['informed_kf']['rmse'] / bounds['L2']['delivered']:.2f}x the delivered bound, which averages the "
        "information over the link outcomes before the recursion and so lies below the mean of the per-episode "
        "covariances the informed KF attains.")
    return "\n".join(lines) + "\n"
