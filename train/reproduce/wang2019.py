"""Reproduce Wang et al. 2019 (``relay_ukf``): Figs. 5-8 and the paper's claims.

Writes ``OUT/wang2019/metrics.json`` with

* ``max_abs_diff_dcl_ccl``   largest |xhat_DCL - xhat_CCL| (metres) over all steps, runs, p and Q models
* ``mean_distance_error``    {"IL", "CCL", "DCL"}: the distance error ||xhat_i - x_i|| averaged over the
  800 measurement times, the 4 platforms and the runs (p = 0.5, the default Q with the heading term)
* ``error_vs_p``             {"0.05", "0.1", "0.25", "0.5", "1.0"} -> {"CCL", "IL"} (same average)
* ``max_abs_diff_ccl_filterpy`` CCL against filterpy's UnscentedKalmanFilter (JulierSigmaPoints,
  kappa = lambda) on the same reordered state and inputs, over one 800-step run
* ``paper_literal``          the same two tables with the paper's literal Q (speed noise only)
* ``nees_ccl``               mean NEES of each platform's own 2x2 block (expectation 2 for a consistent
  filter) at p = 0.5: default Q, the paper's Q, and a control without turn-rate noise
* ``truncated_chain``        hop budget 1: the paper's rule for unreached cross-covariances vs ours
* ``pcrb``                   {"default", "no_turn_rate_noise"} at p = ``measurement_probability``: the posterior
  Cramér–Rao bound of the ``relay_ukf`` preset under the paper's policy (``bound_block``,
  ``train.reproduce.bound_rows``) beside the RMSE of IL, CCL and DCL and their efficiency
* ``claims``                 each claim -> holds (bool)

plus ``report.md`` and PNG figures. The estimators are the composable backends on
the ``circles`` world (``Rig``): IL = ``dead_reckoning``, CCL = ``ukf_ccl`` over ``ideal``,
DCL = ``ukf_dcl`` over ``relay``; the filterpy comparison runs filterpy's update beside the
``ukf_ccl`` backend. Every Monte Carlo block draws its runs
from ``np.random.default_rng([seed, block])``; the same blocks are reused for
every p and Q model (common random numbers: the measurement schedules are
nested across p, because one uniform per step is compared with p).

``paper_policy_costs(seeds)`` gives this reproduction's per-episode number for UKF-DCL under the
paper's policy, with that policy's own generator, on the episodes ``env.reset(seed=s)`` draws
for each s in ``seeds`` (the scenario's own sampler), through the same backends as the
Monte Carlo above; a test checks that it equals what ``coloc evaluate`` reports for the
``paper`` policy on the same seeds.
"""

from __future__ import annotations

import dataclasses
import os
import warnings

import numpy as np

import coloc_env
import estimators.ukf_relay as ukf
from agents.relay_ukf import paper_actions
from coloc_env.backends import DeadReckoning, UkfCcl
from coloc_env.composition import compose
from coloc_env.config import BadInput, build_config
from coloc_env.networks import Ideal
from coloc_env.networks.blocks.relay_chain import STOP_REASONS
from coloc_env.scenarios.relay_ukf import RelayUKFConfig
from estimators.models import predict_joint
from train.executor import map_tasks
from train.io import save_figure, write_json, write_text
from train.reproduce.bound_rows import pcrb_block, report_section
from train.reproduce.common import block_sizes, ci95, claims_section, pyplot

KEY = "wang2019"
RUNS = 50
QUICK_RUNS = 10
PROBABILITIES = (0.05, 0.1, 0.25, 0.5, 1.0)
BLOCK_SIZE = 25
ESTIMATORS = ("IL", "CCL", "DCL")
BOUND_EPISODES = 4  # seeded episodes of the bound (at most the runs): 800 steps each, one recursion per episode


def _block_generators(seed: int, block: int, runs: int):
    rng = np.random.default_rng([seed, block])
    return rng.spawn(runs), rng.spawn(1)[0]


def composition_parts(config: RelayUKFConfig) -> tuple:
    """The composable parts this reproduction drives for ``config``: the ``circles`` world of the
    paper's Sec. 4 (4 platforms, no anchors; the relay_ukf preset's, ``RelayUKFConfig.parts``) and,
    per estimator of ``ESTIMATORS``, a
    (network, backend) pair: IL = ``dead_reckoning`` over ``ideal``, CCL = ``ukf_ccl`` over ``ideal``
    (every range reaches the fusion centre), DCL = ``ukf_dcl`` over ``relay`` with the config's links.
    """
    world, links, dcl = config.parts()  # the relay_ukf preset's parts
    pairs = {"IL": (Ideal(), DeadReckoning()),
             "CCL": (Ideal(), UkfCcl(ukf_lambda=config.ukf_lambda, motion=dcl.motion)),
             "DCL": (links, dcl)}
    return world, pairs


class Rig:
    """One ``circles`` world and several (network, backend) pairs stepped on the same readings.

    Each step is ``coloc_env.scenarios.composed.ComposedScenario.step``'s: the world's readings
    of time k, the network's link state of time k (true positions) and transport decisions, the
    backend's update of k (the posterior the errors score) and its prediction to k + 1, then the
    world moves. The world is reset with the caller's generators themselves (the draws of the
    ``relay_ukf`` scenario, in its order: the same odometry noise, schedules and range noise as
    ``env.reset(seed=...)``); each network and backend gets a child of the copy's generator.
    """

    def __init__(self, config: RelayUKFConfig, batch: int, names=ESTIMATORS):
        world, pairs = composition_parts(config)
        self.batch, self.num_agents = batch, config.num_agents
        self.world = None
        self.networks, self.backends = {}, {}
        for name in names:
            spec = compose(world=world, network=pairs[name][0], backend=pairs[name][1])
            if self.world is None:
                self.world = spec.world.build(batch, spec.episode_steps)
            network = spec.network.build(self.num_agents, batch, spec.backend.message_kind)
            self.networks[name] = network
            self.backends[name] = spec.backend.build(self.world, network, batch)

    def reset(self, copies: list) -> None:
        idx = np.arange(self.batch)
        self.world.reset(list(copies), idx)
        for name, network in self.networks.items():
            children = [rng.spawn(2) for rng in copies]
            network.reset([c[0] for c in children], idx)
            self.backends[name].reset([c[1] for c in children], idx)

    @property
    def schedule(self) -> np.ndarray:
        return self.world.schedule

    def distances(self) -> np.ndarray:
        p = self.world.positions()
        return np.linalg.norm(p[:, :, None, :] - p[:, None, :, :], axis=-1)

    def step(self, actions: np.ndarray, with_readings: bool = False):
        """One step under ``relay_ukf`` actions (B, N, 2) (whom to range with, whom to relay to; N = stop):
        the first is the world's sensing choice, the second the relay network's next hop. Returns the
        truth of time k (B, N, 2) (and the world's readings of k with ``with_readings``); each backend's
        ``posterior_position`` is its estimate of time k."""
        B, N = self.batch, self.num_agents
        actions = np.asarray(actions, np.int64)
        readings = self.world.readings(actions[..., :1])
        truth = self.world.positions().copy()
        none = np.zeros((B, N, 0), np.int64)
        for name, network in self.networks.items():
            transport = actions[..., 1:2] if network.transport_blocks() else none
            network.begin(self.world.k, truth, transport)
            self.backends[name].step(readings, none)
        self.world.advance()
        return (truth, readings) if with_readings else truth


def monte_carlo_block(block: int, runs: int, seed: int, config: RelayUKFConfig) -> dict:
    """``runs`` realizations under the paper's policy: IL, UKF-CCL and UKF-DCL on the same data.

    The three are the composable backends ``dead_reckoning``, ``ukf_ccl`` and ``ukf_dcl`` on one
    ``circles`` world (``Rig``). Errors are posterior ones, at each measurement time k = 0..K-1.
    """
    copies, policy_rng = _block_generators(seed, block, runs)
    return {"block": block, **simulate_runs(config, copies, policy_rng)}


def simulate_runs(config: RelayUKFConfig, copies: list, policy_rng: np.random.Generator) -> dict:
    """The runs of ``monte_carlo_block`` on given generators: copy r of the world reset with
    ``copies[r]``, the paper policy's random partners drawn from ``policy_rng`` (one call per step
    for all runs). ``per_run`` (3, runs): each run's error averaged over k = 0..K-1 and the platforms,
    rows ``ESTIMATORS``."""
    runs = len(copies)
    rig = Rig(config, runs)
    rig.reset(copies)
    K, N = config.horizon, config.num_agents
    il, ccl, dcl = (rig.backends[e] for e in ESTIMATORS)
    errors = np.zeros((3, K, runs, N))
    nees = np.zeros((K, runs, N))
    max_diff = 0.0
    chains = np.full((K, N), -1)
    tracks = np.zeros((2, K, N, 2))  # IL and DCL estimates of run 0
    for k in range(K):
        truth = rig.step(paper_actions(rig.distances(), rig.schedule[:, k], policy_rng))
        for e, backend in enumerate((il, ccl, dcl)):
            errors[e, k] = np.linalg.norm(backend.posterior_position - truth, axis=-1)
        max_diff = max(max_diff, float(np.abs(ccl.posterior_position - dcl.posterior_position).max()))
        residual = ccl.posterior_position - truth
        blocks = ccl.posterior_position_cov
        nees[k] = np.einsum("rni,rni->rn", residual, np.linalg.solve(blocks, residual[..., None])[..., 0])
        chain = rig.networks["DCL"].last_chain
        if chain is not None:
            chains[k] = chain.chain[0]
        tracks[0, k], tracks[1, k] = il.posterior_position[0], dcl.posterior_position[0]
    return {
        "per_run": errors.mean(axis=(1, 3)),  # (3, runs): time- and platform-averaged
        "per_run_squared": (errors**2).mean(axis=(1, 3)),  # (3, runs): each run's mean squared error
        "curves": errors.mean(axis=2),  # (3, K, N): mean over this block's runs
        "curves_sq": (errors**2).mean(axis=2),  # (3, K, N): mean square over this block's runs (for the spread)
        "runs": runs,
        "max_diff": max_diff,
        "nees": float(nees[1:].mean()),  # k = 0 is the known start
        "chains": chains,
        "tracks": tracks,
    }


def paper_policy_costs(seeds, config: RelayUKFConfig | None = None) -> np.ndarray:
    """Per-episode mean distance error of UKF-DCL under the paper's policy (the env's ``paper``: random
    partner, nearest-not-yet-reached relay until the chain is complete) on the episodes the env plays
    for ``seeds``: the error at each measurement time k = 0..K-1 after its update, averaged over the
    steps and platforms (this reproduction's ``mean_distance_error`` of one run).

    Episode e is the world reset with ``default_rng(seeds[e])``, as ``env.reset(seed=seeds[e])`` resets the
    scenario. The paper policy draws its partners, one draw per step, from the generator ``coloc evaluate``
    gives it for that episode (``agents.base.episode_generator(seeds[e])``, restarted for each episode).
    """
    from agents.base import episode_generator

    config = config or build_config(RelayUKFConfig, {})
    dcl = ESTIMATORS.index("DCL")
    return np.array([simulate_runs(config, [np.random.default_rng(s)], episode_generator(s))["per_run"][dcl, 0]
                     for s in seeds])


def filterpy_ccl_update(estimate: np.ndarray, cov: np.ndarray, measuring: int, measured: int, z: float,
                        range_var: float, lam: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The CCL range update done by filterpy's ``UnscentedKalmanFilter`` (one copy).

    The state is reordered with m, n first (eq. 17), sigma points are
    ``JulierSigmaPoints(2N, kappa=lambda)`` (lower-Cholesky columns, w_0 =
    lambda/(2N+lambda)). filterpy's ``update()`` uses the sigma points left by
    ``predict()``, so they are set from (x, P) directly, which is what a
    predict with the identity transition and Q = 0 would leave.
    """
    from filterpy.kalman import JulierSigmaPoints, UnscentedKalmanFilter

    N = estimate.shape[0]
    L = 2 * N
    order = ukf.reorder_first(N, np.array(measuring), np.array(measured))
    index = (2 * order[:, None] + np.arange(2)).ravel()
    points = JulierSigmaPoints(L, kappa=lam)
    filt = UnscentedKalmanFilter(dim_x=L, dim_z=1, dt=1.0, points=points, fx=lambda s, dt: s,
                                 hx=lambda s: np.array([np.hypot(s[0] - s[2], s[1] - s[3])]))
    filt.x = estimate.reshape(-1)[index].copy()
    filt.P = cov[np.ix_(index, index)].copy()
    filt.R = np.array([[range_var]])
    filt.sigmas_f = points.sigma_points(filt.x, filt.P)
    filt.update(np.array([z]))
    inverse = np.argsort(index)
    return filt.x[inverse].reshape(N, 2), filt.P[np.ix_(inverse, inverse)]


def ccl_filterpy_difference(config: RelayUKFConfig, seed: int) -> float:
    """Largest |CCL - filterpy| position difference over one run of the paper's policy: the ``ukf_ccl``
    backend on the ``circles`` world (``Rig``) and filterpy's update on the same ranges, each
    from the same start (the linear time update of the filterpy side is the world's motion model)."""
    copies, policy_rng = _block_generators(seed, 0, 1)
    rig = Rig(config, 1, names=("CCL",))
    rig.reset(copies)
    ccl = rig.backends["CCL"]
    fx, fP = ccl.mean[0].copy(), ccl.cov[0].copy()
    worst = 0.0
    for k in range(config.horizon):
        _, readings = rig.step(paper_actions(rig.distances(), rig.schedule[:, k], policy_rng), with_readings=True)
        for m, n in np.argwhere(readings.range_valid[0]):
            fx, fP = filterpy_ccl_update(fx, fP, int(m), int(n), float(readings.range[0, m, n]),
                                         config.range_noise_var, config.ukf_lambda)
        worst = max(worst, float(np.abs(ccl.posterior_position[0] - fx).max()))
        fx, fP = predict_joint(rig.world.motion_model, fx, fP, readings.inputs[0])
    return worst


def truncated_chain_study(config: RelayUKFConfig, seed: int, copies: int = 8, max_hops: int = 1) -> dict:
    """Smallest eigenvalue of P per step with a hop budget, for the paper's rule and ours (the ``ukf_dcl``
    backend over a ``relay`` network with that budget)."""
    out = {"max_hops": max_hops, "copies": copies}
    for rule in ("paper", "consistent"):
        cfg = dataclasses.replace(config, max_hops=max_hops, truncation=rule)
        generators, policy_rng = _block_generators(seed, 10_000, copies)
        with warnings.catch_warnings():  # the paper's rule is studied here on purpose
            warnings.simplefilter("ignore", UserWarning)
            rig = Rig(cfg, copies, names=("DCL",))
        rig.reset(generators)
        smallest, failed = [], None
        for k in range(cfg.horizon):
            try:
                rig.step(paper_actions(rig.distances(), rig.schedule[:, k], policy_rng))
            except np.linalg.LinAlgError:
                failed = k
                break
            smallest.append(float(np.linalg.eigvalsh(rig.backends["DCL"].cov).min()))
        negative = [k for k, v in enumerate(smallest) if v < 0]
        out[rule] = {
            "min_eigenvalue": float(min(smallest)) if smallest else float("nan"),
            "first_indefinite_step": negative[0] + 1 if negative else None,
            "cholesky_failed_at_step": failed,
            "min_eigenvalue_per_step": smallest,
        }
    return out


def run(out: str, runs: int = RUNS, seed: int = 0, quick: bool = False, executor: str = "local",
        address: str | None = None, config: RelayUKFConfig | None = None, progress=None) -> dict:
    """Compute everything, write ``out/wang2019/``, return the metrics dict."""
    config = config or build_config(RelayUKFConfig, {})
    if runs < 2:
        raise BadInput(f"runs must be >= 2 for a confidence interval, got {runs}")
    folder = os.path.join(out, KEY)
    sizes = block_sizes(runs, BLOCK_SIZE)
    variants = {"default": {}, "paper_literal": {"heading_noise": False}}
    cases = [(name, p) for name in variants for p in PROBABILITIES]
    cases.append(("no_turn_rate_noise", config.measurement_probability))
    items, labels = [], []
    for name, p in cases:
        overrides = variants.get(name, {"turn_rate_noise_std": 0.0})
        cfg = dataclasses.replace(config, measurement_probability=p, **overrides)
        cfg.validate()
        for block, size in enumerate(sizes):
            items.append((block, size, seed, cfg))
            labels.append((name, p))
    results = map_tasks(monte_carlo_block, items, executor, address)
    if progress:
        progress(f"Monte Carlo ({runs} runs x {len(cases)} settings) done")
    merged = {}
    for (name, p), result in zip(labels, results, strict=True):
        merged.setdefault((name, p), []).append(result)
    summary = {key: _merge(blocks) for key, blocks in merged.items()}

    filterpy_diff = ccl_filterpy_difference(config, seed)
    truncation = truncated_chain_study(config, seed)
    if progress:
        progress("filterpy comparison and truncated chains done")

    p0 = config.measurement_probability
    main = summary[("default", p0)] if ("default", p0) in summary else summary[("default", 0.5)]
    metrics = {
        "max_abs_diff_dcl_ccl": max(s["max_diff"] for s in summary.values()),
        "mean_distance_error": {e: main["mean"][e] for e in ESTIMATORS},
        "error_vs_p": {str(p): {"CCL": summary[("default", p)]["mean"]["CCL"],
                                "IL": summary[("default", p)]["mean"]["IL"]} for p in PROBABILITIES},
        "max_abs_diff_ccl_filterpy": filterpy_diff,
        "paper_literal": {
            "mean_distance_error": {e: summary[("paper_literal", p0)]["mean"][e] for e in ESTIMATORS},
            "error_vs_p": {str(p): {"CCL": summary[("paper_literal", p)]["mean"]["CCL"],
                                    "IL": summary[("paper_literal", p)]["mean"]["IL"]} for p in PROBABILITIES},
        },
        "mean_distance_error_ci95": {e: main["ci95"][e] for e in ESTIMATORS},
        "nees_ccl": {"default": main["nees"], "paper_literal": summary[("paper_literal", p0)]["nees"],
                     "no_turn_rate_noise": summary[("no_turn_rate_noise", p0)]["nees"],
                     "p": p0, "expected": 2.0},
        "truncated_chain": {k: v for k, v in truncation.items() if k not in ("paper", "consistent")}
        | {rule: {k: v for k, v in truncation[rule].items() if k != "min_eigenvalue_per_step"}
           for rule in ("paper", "consistent")},
        "runs": runs,
        "seed": seed,
        "horizon": config.horizon,
        "heading_term_max": config.dt**4 * config.speed**2 * config.horizon * config.turn_rate_noise_std**2,
        "speed_term": config.dt**2 * config.speed_noise_std**2,
        "measurement_probability": p0,
    }
    claims = _claims(metrics, summary)
    metrics["claims"] = {c["id"]: c["holds"] for c in claims}
    episodes = min(runs, BOUND_EPISODES)
    worlds = {"default": {}, "no_turn_rate_noise": {"turn_rate_noise_std": 0.0}}
    metrics["pcrb"] = {name: bound_block(dataclasses.replace(config, measurement_probability=p0, **worlds[name]),
                                         summary[(name, p0)], seed, episodes) for name in worlds}
    if progress:
        progress("Cramér–Rao bounds done")
    write_json(os.path.join(folder, "metrics.json"), metrics)
    _figures(folder, summary, truncation, config)
    write_text(os.path.join(folder, "report.md"), _report(metrics, claims, quick))
    return metrics


def bound_block(config: RelayUKFConfig, merged: dict, seed: int, episodes: int) -> dict:
    """The ``pcrb`` block of one setting: ``coloc_env.pcrb`` of the ``relay_ukf`` preset with ``config``
    under the env's ``paper`` policy (seeded ``seed + e`` for episode e), beside the RMSE of IL, CCL and DCL
    (``merged`` one setting's ``_merge``, errors at k = 0..K-1 after each update, the bound's steps).

    The circles bound depends on the episode (which ranges the random partners took): it is the bound over
    ``episodes`` seeded episodes of the preset (episode e reset with seed + e), not over the runs (drawn from
    ``default_rng([seed, block])``). Each estimator uses no more than every odometry and range reading, and
    the circles bound model is the world's problem (the integrated heading in its state), so every
    efficiency is >= 1 up to Monte Carlo noise, with or without turn-rate noise.
    """
    from agents import make_policy

    flat = {f.name: getattr(config, f.name) for f in dataclasses.fields(config)}
    acts = [make_policy("paper", coloc_env.parallel_env("relay_ukf", **flat), seed=seed + e).act
            for e in range(episodes)]
    bounds = coloc_env.pcrb("relay_ukf", episodes=episodes, seed=seed, policy=acts, **flat)
    note = (f"wang2019: the bound over {episodes} seeded episodes of the relay_ukf preset under the paper's policy "
            "(not the runs' episodes); errors after each update, k = 0..799")
    rows = {e: merged["per_run_squared"][i] for i, e in enumerate(ESTIMATORS)}
    return pcrb_block(bounds, rows, episodes, seed, False, note)


def _merge(blocks: list[dict]) -> dict:
    per_run = np.concatenate([b["per_run"] for b in blocks], axis=1)  # (3, runs)
    weights = np.array([b["runs"] for b in blocks], float)
    curves = np.einsum("b,bekn->ekn", weights / weights.sum(), np.stack([b["curves"] for b in blocks]))
    squares = np.einsum("b,bekn->ekn", weights / weights.sum(), np.stack([b["curves_sq"] for b in blocks]))
    runs = int(weights.sum())
    spread = np.sqrt(np.maximum(squares - curves**2, 0.0) * runs / max(runs - 1, 1))  # sample sd over the runs
    half = 1.96 * per_run.std(axis=1, ddof=1) / np.sqrt(per_run.shape[1])
    return {
        "per_run": per_run,
        "per_run_squared": np.concatenate([b["per_run_squared"] for b in blocks], axis=1),
        "mean": {e: float(per_run[i].mean()) for i, e in enumerate(ESTIMATORS)},
        "ci95": {e: float(half[i]) for i, e in enumerate(ESTIMATORS)},
        "curves": curves,
        "curves_sd": spread,
        "max_diff": max(b["max_diff"] for b in blocks),
        "nees": float(np.average([b["nees"] for b in blocks], weights=weights)),
        "chains": blocks[0]["chains"],
        "tracks": blocks[0]["tracks"],
    }


def _claims(metrics: dict, summary: dict) -> list[dict]:
    p0 = metrics["measurement_probability"]
    key = ("default", p0) if ("default", p0) in summary else ("default", 0.5)
    per_run = summary[key]["per_run"]
    gain = per_run[0] - per_run[2]  # IL - DCL per run
    gain_ci = ci95(gain)
    err = metrics["mean_distance_error"]
    claims = [{
        "id": "dcl_equals_ccl",
        "claim": "UKF-DCL has the same localization performance as UKF-CCL: the error curves coincide (Fig. 6)",
        "ours": f"largest abs(xhat_DCL - xhat_CCL) over all steps, runs, p and Q models: "
                f"{metrics['max_abs_diff_dcl_ccl']:.2e} m",
        "criterion": "below 1e-9 m",
        "holds": bool(metrics["max_abs_diff_dcl_ccl"] < 1e-9),
    }, {
        "id": "cooperation_beats_il",
        "claim": "UKF-DCL is much closer to the truth than independent localization (Figs. 5-6)",
        "ours": f"mean distance error at p = {p0}: IL {err['IL']:.3f} m, CCL {err['CCL']:.3f} m, "
                f"DCL {err['DCL']:.3f} m; IL - DCL = {gain.mean():.3f} +- {gain_ci:.3f} m (95 %), "
                f"DCL better in {int(np.sum(gain > 0))} of {len(gain)} runs",
        "criterion": "the 95 % interval of IL - DCL (per run) lies above 0",
        "holds": bool(gain.mean() - gain_ci > 0),
    }]
    for name, label in (("default", "with the heading term in Q"), ("paper_literal", "with the paper's Q")):
        table = metrics["error_vs_p"] if name == "default" else metrics["paper_literal"]["error_vs_p"]
        ccl = [table[str(p)]["CCL"] for p in PROBABILITIES]
        claims.append({
            "id": f"error_falls_with_p_{name}",
            "claim": f"the average error falls as relative measurements become more frequent (Fig. 7), {label}",
            "ours": "CCL: " + ", ".join(f"p={p}: {v:.3f} m" for p, v in zip(PROBABILITIES, ccl, strict=True)),
            "criterion": "strictly decreasing in p",
            "holds": bool(np.all(np.diff(ccl) < 0)),
        })
    literal = [metrics["paper_literal"]["error_vs_p"][str(p)]["CCL"] for p in PROBABILITIES]
    claims.append({
        "id": "literal_q_error_rises_again",
        "claim": "with the paper's Q the error rises again when range measurements are frequent",
        "ours": f"paper's Q, CCL: p=1.0 {literal[-1]:.3f} m vs the smallest over p {min(literal):.3f} m",
        "criterion": "the error at p = 1.0 exceeds the smallest error over p",
        "holds": bool(literal[-1] > min(literal)),
    })
    nees = metrics["nees_ccl"]
    claims.append({
        "id": "heading_term_makes_filter_consistent",
        "claim": "the paper's Q makes the filter overconfident; the heading term in Q fixes it",
        "ours": f"mean NEES of each platform's own block at p = {nees['p']} (2 if consistent): default Q "
                f"{nees['default']:.2f}, paper's Q {nees['paper_literal']:.2f}, control without turn-rate "
                f"noise {nees['no_turn_rate_noise']:.2f}",
        "criterion": "paper's Q NEES > 2.5 and default-Q NEES within [1.5, 2.5]",
        "holds": bool(nees["paper_literal"] > 2.5 and 1.5 <= nees["default"] <= 2.5),
    })
    trunc = metrics["truncated_chain"]
    claims.append({
        "id": "truncated_chain_consistent_update",
        "claim": "on truncated chains the paper's rule (P_RU unchanged) makes P indefinite; the "
                 "consistent update P_RU - K_R P_zU keeps it positive definite",
        "ours": f"hop budget {trunc['max_hops']}, {trunc['copies']} runs: paper's rule first indefinite at step "
                f"{trunc['paper']['first_indefinite_step']}, Cholesky failed at step "
                f"{trunc['paper']['cholesky_failed_at_step']}; consistent rule smallest eigenvalue over 800 steps "
                f"{trunc['consistent']['min_eigenvalue']:.3g}",
        "criterion": "the paper's rule goes indefinite and ours stays > 0 for the whole run",
        "holds": bool(trunc["paper"]["first_indefinite_step"] is not None
                      and trunc["consistent"]["min_eigenvalue"] > 0
                      and trunc["consistent"]["cholesky_failed_at_step"] is None),
    })
    claims.append({
        "id": "ccl_matches_filterpy",
        "claim": "our UKF-CCL is the textbook UKF (filterpy's UnscentedKalmanFilter on the reordered state)",
        "ours": f"largest position difference over one 800-step run: {metrics['max_abs_diff_ccl_filterpy']:.2e} m",
        "criterion": "below 1e-9 m",
        "holds": bool(metrics["max_abs_diff_ccl_filterpy"] < 1e-9),
    })
    return claims


def trajectories_figure(truth: np.ndarray, tracks: np.ndarray, p: float):
    """Fig. 5: each platform's true track with the IL and UKF-DCL estimates of one run (``truth`` (K, N, 2),
    ``tracks`` (2, K, N, 2): IL, DCL), the start marked; the legend right of the map."""
    plt = pyplot()
    from train.plotting import label, legend_outside

    fig, ax = plt.subplots(figsize=(8.2, 6.2))
    il, dcl = tracks
    for i in range(truth.shape[1]):
        ax.plot(truth[:, i, 0], truth[:, i, 1], "k-", lw=1.5, label="truth" if i == 0 else None)
        ax.plot(il[:, i, 0], il[:, i, 1], "r-", lw=0.8, label="IL (independent)" if i == 0 else None)
        ax.plot(dcl[:, i, 0], dcl[:, i, 1], "g-", lw=0.8, label="UKF-DCL" if i == 0 else None)
        ax.plot(*truth[0, i], "ko", ms=5, label="start" if i == 0 else None)
        ax.annotate(f"A{i + 1}", truth[0, i], textcoords="offset points", xytext=(6, 6))
    ax.set_aspect("equal")
    ax.set_xlabel(label("x", "m"))
    ax.set_ylabel(label("y", "m"))
    ax.set_title(f"Fig. 5: trajectories (one run, p = {p})", fontsize=10)
    legend_outside(ax)
    return fig


def platform_errors_figure(main: dict, runs: int, dt: float, p: float):
    """Fig. 6: each platform's distance error against time, mean over the runs with its 95 % band (the
    run-to-run spread, ``main["curves_sd"]``), for IL, UKF-CCL and UKF-DCL; the legend under the panels
    says how far apart CCL and DCL are."""
    plt = pyplot()
    from matplotlib.patches import Patch

    from train.plotting import label, t975

    curves, spread = main["curves"], main["curves_sd"]
    K, N = curves.shape[1], curves.shape[2]
    times = np.arange(K) * dt
    fig, axes = plt.subplots(2, (N + 1) // 2, figsize=(11, 6.8), sharex=True, squeeze=False)
    styles = (("r-", 1.0, 1.0, "IL (independent)"), ("b-", 2.4, 0.5, "UKF-CCL"), ("g--", 1.0, 1.0, "UKF-DCL"))
    half = t975(runs - 1) * spread / np.sqrt(runs)
    for i, ax in enumerate(axes.ravel()[:N]):
        for e, (style, lw, alpha, name) in enumerate(styles):
            ax.plot(times, curves[e, :, i], style, lw=lw, alpha=alpha, label=name)
            if e < 2:  # DCL's band is CCL's
                ax.fill_between(times, curves[e, :, i] - half[e, :, i], curves[e, :, i] + half[e, :, i],
                                color=style[0], alpha=0.15, lw=0)
        ax.set_title(f"A{i + 1}", fontsize=9)
        ax.set_ylabel(label("distance error", "m"))
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[N:]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel(label("time", "s"))
    handles, texts = axes[0, 0].get_legend_handles_labels()
    gap = float(np.abs(curves[1] - curves[2]).max())
    texts[2] += f" (on UKF-CCL: mean curves {gap:.1e} m apart at most)"
    handles.append(Patch(color="0.5", alpha=0.3))
    texts.append(f"band: 95 % interval of the mean over {runs} runs")
    fig.legend(handles, texts, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=2, fontsize=8, frameon=False)
    fig.suptitle(f"Fig. 6: distance error per platform, mean over runs (p = {p})", fontsize=10)
    fig.tight_layout()
    return fig


def error_vs_p_figure(summary: dict):
    """Fig. 7: the mean distance error against p with 95 % t-interval bars over the runs, for UKF-CCL with the
    heading term in Q (filled) and the paper's literal Q (open markers, dashed), and IL; the legend says how
    close the two UKF-CCL curves are, since at this scale they coincide."""
    plt = pyplot()
    from train.plotting import label, legend_outside, t975

    def stats(name, row):
        per_run = [np.asarray(summary[(name, p)]["per_run"][row], float) for p in PROBABILITIES]
        mean = np.array([v.mean() for v in per_run])
        half = np.array([t975(len(v) - 1) * v.std(ddof=1) / np.sqrt(len(v)) for v in per_run])
        return mean, half, len(per_run[0])

    fig, ax = plt.subplots(figsize=(8.6, 4))
    ccl = ESTIMATORS.index("CCL")
    heading, heading_half, runs = stats("default", ccl)
    literal, literal_half, _ = stats("paper_literal", ccl)
    il, il_half, _ = stats("default", ESTIMATORS.index("IL"))
    x = np.array(PROBABILITIES)
    gap = float(np.abs(heading - literal).max())
    ax.errorbar(x, heading, yerr=heading_half, fmt="o-", color="tab:blue", capsize=3, ms=6,
                label="UKF-CCL, Q with heading term")
    ax.errorbar(x * 1.03, literal, yerr=literal_half, fmt="s--", color="tab:orange", mfc="none", capsize=3, ms=7,
                label=f"UKF-CCL, paper's Q (drawn 3 % right):\nwithin {gap:.3f} m of the heading-term curve")
    ax.errorbar(x, il, yerr=il_half, fmt="rs-", capsize=3, label="IL (independent)")
    ax.set_xscale("log")
    from train.plotting import plain_log_ticks

    plain_log_ticks(ax, "x")
    ax.set_xlabel(label("probability p of a relative measurement per step", "-"))
    ax.set_ylabel(label("mean distance error", "m"))
    ax.set_title(f"Fig. 7: average error vs measurement probability; bars: 95 % over {runs} runs", fontsize=10)
    ax.grid(alpha=0.3)
    legend_outside(ax)
    return fig


def topology_figure(chains: np.ndarray, dt: float, p: float):
    """Fig. 8: the relay chain of each measurement of one run (``chains`` (K, N): platform at each place of
    the chain, -1 where none), coloured by the place in the chain."""
    plt = pyplot()
    from coloc_env.rendering import AGENT_COLOURS
    from train.plotting import label

    N = chains.shape[1]
    fig, ax = plt.subplots(figsize=(11, 3.5))
    for k in np.flatnonzero(chains[:, 0] >= 0):
        hops = chains[k][chains[k] >= 0]
        ax.plot(np.full(len(hops), k * dt), hops + 1, "-", color="0.7", lw=0.8)
        for place, platform in enumerate(hops):
            ax.plot(k * dt, platform + 1, "o", ms=6 if place == 0 else 4,
                    color=AGENT_COLOURS[place % len(AGENT_COLOURS)])
    handles = [plt.Line2D([], [], marker="o", ls="", color=AGENT_COLOURS[i], label=lab)
               for i, lab in enumerate(["m (measuring)", "n (measured)", "3rd", "4th", *[
                   f"{j}th" for j in range(5, N + 1)]][:N])]
    handles.append(plt.Line2D([], [], color="0.7", lw=0.8, label="one chain"))
    ax.legend(handles=handles, fontsize=8, ncol=N + 1, loc="upper center", bbox_to_anchor=(0.5, -0.2),
              frameon=False)
    ax.set_yticks(range(1, N + 1), [f"A{i}" for i in range(1, N + 1)])
    ax.set_ylabel("platform")
    ax.set_xlabel(label("time", "s"))
    ax.set_title(f"Fig. 8: relay chain of each measurement (one run, p = {p}): colour = place in the chain",
                 fontsize=10)
    return fig


def truncated_chain_figure(truncation: dict, dt: float):
    """The smallest eigenvalue of P per step on truncated chains, for the paper's rule and the consistent one."""
    plt = pyplot()
    from train.plotting import label, legend_outside

    fig, ax = plt.subplots(figsize=(8.4, 4))
    for rule in ("paper", "consistent"):
        values = np.array(truncation[rule]["min_eigenvalue_per_step"])
        failed = truncation[rule].get("cholesky_failed_at_step")
        ax.plot(np.arange(1, len(values) + 1) * dt, values,
                label=f"{rule} rule" + ("" if failed is None else f" (Cholesky fails at step {failed}: ends)"))
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_yscale("symlog", linthresh=1e-4)
    ax.set_xlabel(label("time", "s"))
    ax.set_ylabel(label("smallest eigenvalue of P (positions)", "m²"))
    ax.set_title(f"truncated chains (hop budget {truncation['max_hops']}): unreached cross-covariances",
                 fontsize=10)
    ax.grid(alpha=0.3)
    legend_outside(ax)
    return fig


def _figures(folder: str, summary: dict, truncation: dict, config: RelayUKFConfig) -> None:
    truth = Rig(config, 1, names=("IL",)).world.truth
    p0 = config.measurement_probability
    main = summary.get(("default", p0), summary[("default", 0.5)])
    runs = main["per_run"].shape[1]
    dt = config.dt
    save_figure(os.path.join(folder, "fig5_trajectories.png"), trajectories_figure(truth, main["tracks"], p0))
    save_figure(os.path.join(folder, "fig6_platform_errors.png"), platform_errors_figure(main, runs, dt, p0))
    save_figure(os.path.join(folder, "fig7_error_vs_p.png"), error_vs_p_figure(summary))
    save_figure(os.path.join(folder, "fig8_topology.png"),
                topology_figure(summary[("default", PROBABILITIES[0])]["chains"], dt, PROBABILITIES[0]))
    save_figure(os.path.join(folder, "truncated_chain.png"), truncated_chain_figure(truncation, dt))


def _report(metrics: dict, claims: list[dict], quick: bool) -> str:
    err, ci = metrics["mean_distance_error"], metrics["mean_distance_error_ci95"]
    lit = metrics["paper_literal"]
    lines = [
        "# wang2019: UKF cooperative localization over relay chains (reproduction)",
        "",
        "Wang, Cui, Kong, Zhao, Trans. Nanjing Univ. Aero. Astro. 36(2), 2019. Scenario `relay_ukf`, "
        "estimator `estimators/ukf_relay.py`. Four platforms on circles (Sec. 4, Table 1), 400 s at 0.5 s, "
        "one range per step with probability p, the paper's policy: random partner, then the nearest "
        "platform not yet reached until everyone is reached. Distance error ||xhat_i - x_i|| averaged over "
        "the 800 measurement times (posterior), the 4 platforms and the runs.",
        "",
        f"Monte Carlo: {metrics['runs']} runs per setting, seed {metrics['seed']}"
        + (" (quick mode)." if quick else ".") + " Stop reasons of a chain: " + ", ".join(STOP_REASONS) + ".",
        "",
    ]
    lines += claims_section(claims)
    lines += [
        "",
        f"## Mean distance error at p = {metrics['measurement_probability']} (m, 95 % interval over runs)",
        "",
        "| estimator | Q with heading term (default) | paper's Q |",
        "|---|---|---|",
    ]
    for e in ESTIMATORS:
        lines.append(f"| {e} | {err[e]:.3f} +- {ci[e]:.3f} | {lit['mean_distance_error'][e]:.3f} |")
    lines += ["", "## Error vs p (m)", "", "| p | IL | CCL (default Q) | CCL (paper's Q) |", "|---|---|---|---|"]
    for p in PROBABILITIES:
        row = metrics["error_vs_p"][str(p)]
        lines.append(f"| {p} | {row['IL']:.3f} | {row['CCL']:.3f} | {lit['error_vs_p'][str(p)]['CCL']:.3f} |")
    nees = metrics["nees_ccl"]
    lines += [
        "",
        "## Notes",
        "",
        f"* Consistency. Mean NEES of each platform's own block (2 for a consistent filter) at p = {nees['p']}: "
        f"{nees['default']:.2f} with the heading term, {nees['paper_literal']:.2f} with the paper's Q, "
        f"{nees['no_turn_rate_noise']:.2f} in a control run without turn-rate noise. The heading term adds the "
        "per-step marginal variance of the heading error (a random walk); its effect on the position is "
        "correlated in time, which a white position-only Q cannot carry, so the term is small: at most "
        f"dt^2 V^2 K dt^2 sigma_omega^2 = {metrics['heading_term_max']:.2g} m^2 per step against "
        f"dt^2 sigma_v^2 = {metrics['speed_term']:.2g} m^2 from the speed noise.",
        "* IL does not depend on p (no measurements): its row is the same dead-reckoning error in every column.",
        "* Ranges observe only the relative geometry: a common translation or rotation of all four estimates "
        "is unobservable, so even p = 1 leaves the dead-reckoning drift of the formation as a whole.",
        "* UKF-DCL departs from the printed equations where they are typos (signs of (11) and (23), the "
        "missing Pz^-1 in (22), the '-' sigma points of (18), the own columns in (20)); see the estimator's "
        "docstring.",
    ]
    bounds = metrics["pcrb"]
    lit, default = bounds["no_turn_rate_noise"], bounds["default"]
    lines += report_section(
        {"default": default, "no turn-rate noise": lit},
        f"Without turn-rate noise CCL (= DCL) is {lit['rows']['CCL']['efficiency']:.2f}x the centralized bound "
        f"and IL {lit['rows']['IL']['efficiency']:.2f}x; with it (the default) CCL is "
        f"{default['rows']['CCL']['efficiency']:.2f}x and IL {default['rows']['IL']['efficiency']:.2f}x: the "
        f"relayed ranges take the estimate {'most' if lit['rows']['CCL']['efficiency'] < 1.5 else 'part'} of the "
        "way from dead reckoning to the best any estimator could do with every reading. The bound carries the "
        "integrated heading's error in its state (docs/bounds.md); the paper's filter does not.")
    return "\n".join(lines) + "\n"
