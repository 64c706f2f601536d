"""dNBP's covariance on the ``gps_denied_nbp`` preset with its ``paper`` policy: ``python -m train.dnbp_consistency``.

For the preset at its defaults, then each setting given (``FIELD=VALUE[,FIELD=VALUE...]``, keywords of
``GpsDeniedNbpConfig``), it plays the same E episodes on the batched core, copy e reset with
``default_rng(seed + e)`` (validation seeds by default, ``train.evaluate.VALIDATION_SEED_BASE``; the evaluation
seeds are refused), every UAV broadcasting whenever the schedule allows (the ``paper`` policy), and prints:

* the episode metric (the fault UAVs' mean position error, ``coloc evaluate``'s) with its 95 % t-interval and,
  against the defaults, the paired per-episode difference with its interval;
* the mean 2-D NEES of every (episode, step, UAV), the share of (step, UAV) whose mean over the E episodes lies
  in the chi^2(2E)/E 95 % band, above it (overconfident) and below it (conservative): the measure of
  ``coloc evaluate``'s ``nees`` / ``nees_in_band`` (``train.evaluate.attach_bounds``, the same numbers);
* the same over the first ``--block`` episodes (with the chi^2(2 block)/block band), and the share over every
  consecutive block of ``--block`` episodes: the range and the mean over blocks;
* for the GPS-normal and the GPS-fault UAVs apart (a group without cells is left out): the mean squared error,
  the mean tr P and the bulk factor, mean squared error / mean tr P (1 for an
  honest covariance; below 1 conservative), the median NEES / 1.386 (chi^2(2)'s median), and the tail: the
  share of NEES above 13.8 (chi^2(2)'s 99.9 % quantile: 0.1 % for an honest Gaussian covariance) and the share
  of the NEES sum those carry.

the share in band over blocks of 10, 20, 50 and E episodes (``--block`` 10); the largest share a factor on P
would put in band, fitted on these cells (``best_scales``: one factor, and one each for the GPS-normal and the
fault UAVs); and, as a reference, the NEES and the band share with the truth replaced by one draw from each
belief's density (``belief_draw``, from a generator of its own: the episodes are not changed): what a belief of
the same shape would read were it calibrated.

The decomposition is what docs/consistency.md ("The gps_denied_nbp preset") reads: a mean NEES near 2 can be a
conservative bulk and an overconfident tail that cancel, which a per-cell band over many episodes tells apart.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy import stats

import coloc_env
from train.evaluate import VALIDATION_SEED_BASE, _nees, check_not_evaluation_seeds, mean_ci95, reported_covariances

CHI2_2_MEDIAN = float(stats.chi2.ppf(0.5, 2))  # 1.386
TAIL = float(stats.chi2.ppf(0.999, 2))  # 13.8
CHUNK = 50  # copies of the batched core stepped at once


def play(episodes: int, seed: int, **config) -> dict[str, np.ndarray]:
    """E episodes of ``gps_denied_nbp`` (copy e seeded ``seed + e``) with the ``paper`` actions: per (episode,
    step, UAV) ``nees``, ``squared`` (2-D position error^2, m^2), ``trace`` (tr P, m^2), ``fault`` (GPS faulty),
    and per episode ``cost`` (the episode metric)."""
    check_not_evaluation_seeds(seed, episodes, "dnbp_consistency")
    parts: dict[str, list] = {key: [] for key in ("nees", "self_nees", "squared", "trace", "fault", "cost")}
    for start in range(0, episodes, CHUNK):
        count = min(CHUNK, episodes - start)
        core = coloc_env.make_core("gps_denied_nbp", batch=count, **config)
        core.reset([np.random.default_rng(seed + start + e) for e in range(count)])
        actions = np.ones((count, core.num_agents, core.config.num_iterations))  # the paper policy
        steps: dict[str, list] = {key: [] for key in ("nees", "self_nees", "squared", "trace", "fault", "error")}
        draw = np.random.default_rng([seed, start])  # the truth drawn from the belief: not the episodes' generators
        while not core.done().all():
            core.step(actions)
            info = core.info()
            error = (np.asarray(info["estimated_position"], float) - np.asarray(info["true_position"], float))[..., :2]
            cov, _ = reported_covariances(core)
            steps["nees"].append(_nees(error, cov))
            steps["self_nees"].append(_nees(belief_draw(core.backend, draw)
                                           - np.asarray(info["estimated_position"], float)[..., :2], cov))
            steps["squared"].append(np.sum(error**2, axis=-1))
            steps["trace"].append(np.trace(np.asarray(cov, float), axis1=-2, axis2=-1))
            steps["fault"].append(np.asarray(info["fault"], bool))
            steps["error"].append(np.asarray(info[core.metric_error_key], float))
        stacked = {key: np.stack(value, axis=1) for key, value in steps.items()}
        parts["cost"].append(core.episode_error(stacked.pop("error"), stacked["fault"].astype(float)))
        for key, value in stacked.items():
            parts[key].append(value)
    return {key: np.concatenate(value, axis=0) for key, value in parts.items()}


def belief_draw(backend, rng: np.random.Generator) -> np.ndarray:
    """One draw (B, N, 2) from each belief's density (``estimators.dnbp``, "Reported covariance"): a particle,
    plus N(0, h_rho^2 I2) where the belief is its prior's particle set."""
    points = backend.state.belief[..., :2]
    B, N, M = points.shape[:3]
    pick = rng.integers(M, size=(B, N))
    chosen = np.take_along_axis(points, pick[..., None, None], axis=2)[:, :, 0]
    return chosen + backend.belief_kernel[..., None] * rng.standard_normal((B, N, 2))


def band_shares(nees: np.ndarray) -> dict[str, float]:
    """Shares of (step, UAV) whose mean NEES over the E episodes of ``nees`` (E, K, N) lies in the chi^2(2E)/E 95 %
    band, above it and below it, with the band."""
    E = nees.shape[0]
    low, high = (float(stats.chi2.ppf(q, 2 * E) / E) for q in (0.025, 0.975))
    mean = nees.mean(axis=0)
    return {"band": (low, high), "in": float(np.mean((mean >= low) & (mean <= high))),
            "above": float(np.mean(mean > high)), "below": float(np.mean(mean < low))}


def group_metrics(run: dict[str, np.ndarray], fault: bool) -> dict[str, float]:
    """Bulk factor and tail (module docstring) of the GPS-fault (``fault``) or GPS-normal UAVs' cells."""
    select = run["fault"] if fault else ~run["fault"]
    nees = run["nees"][select]
    if nees.size == 0:
        return dict.fromkeys(("nees", "mse", "trace", "mse_over_trace", "median_ratio", "tail_share", "tail_weight"),
                             float("nan"))
    tail = nees > TAIL
    mse_over_trace = run["squared"][select].mean() / run["trace"][select].mean()
    return {"nees": float(nees.mean()), "mse": float(run["squared"][select].mean()),
            "trace": float(run["trace"][select].mean()), "mse_over_trace": float(mse_over_trace),
            "median_ratio": float(np.median(nees) / CHI2_2_MEDIAN), "tail_share": float(tail.mean()),
            "tail_weight": float(nees[tail].sum() / nees.sum())}


SCALES = np.round(np.arange(0.6, 2.51, 0.05), 2)  # the factors on P searched by ``best_scales``


def best_scales(run: dict[str, np.ndarray]) -> dict[str, tuple]:
    """The largest share of cells in the E-episode band that a factor on the reported P reaches, fitted on these
    very cells (so optimistic): one factor for every UAV ``(share, c)``, and one for the GPS-normal and another for
    the fault UAVs ``(share, c_normal, c_fault)``, over ``SCALES``."""
    nees, fault = run["nees"], run["fault"]
    one = max((band_shares(nees / c)["in"], float(c)) for c in SCALES)
    two = max((band_shares(np.where(fault, nees / cf, nees / cn))["in"], float(cn), float(cf))
              for cn in SCALES for cf in SCALES)
    return {"one": one, "two": two}


def summary(run: dict[str, np.ndarray], block: int, reference: dict[str, np.ndarray] | None = None) -> dict:
    """The printed numbers of one setting (module docstring)."""
    mean, half = mean_ci95(run["cost"])
    out = {"error": (mean, half), "nees": float(run["nees"].mean()), **band_shares(run["nees"])}
    self_nees = run["self_nees"]
    out["self"] = {"nees": float(self_nees.mean()), "variance": float(self_nees.var()), **band_shares(self_nees)}
    E = run["nees"].shape[0]
    blocks = [band_shares(run["nees"][b:b + block])["in"] for b in range(0, E - block + 1, block)]
    out["blocks"] = blocks
    # the share in band as the episodes per mean grow: the mean over consecutive blocks of each size
    out["by_episodes"] = {size: float(np.mean([band_shares(run["nees"][b:b + size])["in"]
                                               for b in range(0, E - size + 1, size)]))
                          for size in (block, 2 * block, 5 * block, E) if 2 <= size <= E}
    if E >= block:
        out["first_block"] = {"nees": float(run["nees"][:block].mean()), **band_shares(run["nees"][:block])}
    out["normal"], out["fault"] = group_metrics(run, False), group_metrics(run, True)
    if reference is not None:
        out["paired"] = mean_ci95(run["cost"] - reference["cost"])
    return out


def _value(text: str):
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def parse_setting(text: str) -> dict:
    """``FIELD=VALUE[,FIELD=VALUE...]`` -> {FIELD: VALUE} (VALUE an int, a float, else the text)."""
    setting = {}
    for item in text.split(","):
        field, sep, value = item.partition("=")
        if not sep or not field:
            raise SystemExit(f"a setting is FIELD=VALUE[,FIELD=VALUE...], got {text!r}")
        setting[field.strip()] = _value(value.strip())
    return setting


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="python -m train.dnbp_consistency", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("settings", nargs="*", metavar="FIELD=VALUE[,FIELD=VALUE...]",
                        help="gps_denied_nbp keywords of one setting, e.g. num_particles=200,fault_message_power=0.25")
    parser.add_argument("--episodes", type=int, default=100, help="E episodes per setting (default: 100)")
    parser.add_argument("--seed", type=int, default=VALIDATION_SEED_BASE,
                        help=f"episode e is seeded SEED + e (default: {VALIDATION_SEED_BASE}, the validation seeds)")
    parser.add_argument("--block", type=int, default=10, help="episodes per block (default: 10)")
    args = parser.parse_args(argv)
    if args.episodes < 2:
        raise SystemExit(f"--episodes must be >= 2, got {args.episodes}")
    settings = [{}] + [parse_setting(text) for text in args.settings]
    reference = None
    for config in settings:
        run = play(args.episodes, args.seed, **config)
        s = summary(run, args.block, reference)
        reference = reference or run
        low, high = s["band"]
        line = (f"{config or 'defaults'}: error {s['error'][0]:.3f} +- {s['error'][1]:.3f} m, NEES {s['nees']:.3f}, "
                f"in band [{low:.3f}, {high:.3f}] {s['in']:.1%} (above {s['above']:.1%}, below {s['below']:.1%})")
        if "paired" in s:
            line += f", paired {s['paired'][0]:+.3f} +- {s['paired'][1]:.3f} m"
        print(line, flush=True)
        print("  in band over E episodes (the mean over blocks of E): "
              + ", ".join(f"E = {size}: {share:.1%}" for size, share in s["by_episodes"].items()))
        scales = best_scales(run)
        print(f"  P scaled to fit these cells: one factor at most {scales['one'][0]:.1%} in band "
              f"(P x {scales['one'][1]}); normal and fault apart {scales['two'][0]:.1%} "
              f"(x {scales['two'][1]}, x {scales['two'][2]})", flush=True)
        own = s["self"]
        print(f"  truth drawn from the belief: NEES {own['nees']:.3f} (variance {own['variance']:.2f}; chi^2(2): 4), "
              f"in band {own['in']:.1%}", flush=True)
        if "first_block" in s:
            first = s["first_block"]
            print(f"  first {args.block} episodes: NEES {first['nees']:.3f}, in band [{first['band'][0]:.3f}, "
                  f"{first['band'][1]:.3f}] {first['in']:.1%}; {args.block}-episode blocks: in band "
                  f"{min(s['blocks']):.1%} .. {max(s['blocks']):.1%}, mean {np.mean(s['blocks']):.1%}, "
                  f"{sum(b >= 0.8 for b in s['blocks'])} of {len(s['blocks'])} >= 80 %")
        for name in ("normal", "fault"):
            g = s[name]
            if np.isnan(g["nees"]):
                continue
            print(f"  GPS-{name}: NEES {g['nees']:.2f}, mse {g['mse']:.3f} m^2 / mean tr P {g['trace']:.3f} m^2 = "
                  f"{g['mse_over_trace']:.3f}, median NEES / 1.386 "
                  f"{g['median_ratio']:.3f}, NEES > 13.8: {g['tail_share']:.2%} of cells, "
                  f"{g['tail_weight']:.1%} of the sum",
                  flush=True)


if __name__ == "__main__":
    main()
