"""Consistency of the joint UKF's motion models on ``circles``: ``python -m train.consistency``.

For each backend (``ukf_ccl``, ``ukf_dcl``) and motion model (``heading``: the heading error in the
state, ``estimators.heading_models.OdometryHeadingError``; ``displacement``: wang2019's
position-only model) it plays E seeded episodes (copy e reset with ``default_rng(seed + e)``, the
``always`` actions, the ``ideal`` network) and prints: the mean NEES of each agent's own position
(expectation 2), the fraction of (step, agent) values whose E-episode mean lies in the chi-square(2E)/E
95 % band, the same after the first ``transient`` steps with the count of misses Binomial(count, 0.05)
allows at 99.9 %, the position RMSE, and the paired difference of the per-episode mean squared error
(heading minus displacement) with its 95 % t-interval. ``--world`` takes ``FIELD=VALUE`` overrides of
the ``circles`` world (e.g. ``turn_rate_noise_std=0``).

Independent checks (``band_checks``): per-step values of one set of episodes are correlated (a heading
or dead-reckoning error is a random walk), so their misses are not Binomial. Check j instead looks at one
step k_j = spacing (j + 1) and one agent (cycling) on its OWN E episodes (seeds seed + j E ..); no two
checks share an episode, so for a consistent filter the number of checks whose mean NEES lies outside the
chi-square(2E)/E 95 % band is Binomial(J, 0.05), 99.9 % quantile 7 of 40.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy import stats

import coloc_env
from coloc_env.scenarios.composed import ComposedScenario


def play(backend: str, motion: str, episodes: int, seed: int, world: dict | None = None,
         horizon: int | None = None):
    """Own-position NEES (K, E, N) and squared position errors (K, E, N) of E seeded episodes."""
    spec = coloc_env.compose(world={"name": "circles", **(world or {})}, network="ideal",
                             backend={"name": backend, "motion": motion},
                             **({} if horizon is None else {"horizon": horizon}))
    core = ComposedScenario(spec, batch=episodes)
    core.reset([np.random.default_rng(seed + e) for e in range(episodes)])
    one = core.action_vector("maximum")
    actions = np.broadcast_to(one, (episodes, core.num_agents, one.size))
    nees, squared = [], []
    while not core.done().all():
        core.step(actions)
        info = core.info()
        diff = info["estimated_position"] - info["true_position"]
        cov = core.backend.posterior_position_cov
        nees.append(np.einsum("kna,knab,knb->kn", diff, np.linalg.inv(cov), diff))
        squared.append(np.sum(diff**2, axis=-1))
    return np.array(nees), np.array(squared)


def band_checks(backend: str, motion: str, world: dict | None = None, episodes: int = 20, checks: int = 40,
                spacing: int = 3, seed: int = 300) -> tuple[np.ndarray, np.ndarray, int]:
    """(J,) mean own-position NEES of the independent checks (module docstring), the chi-square(2E)/E 95 %
    band (2,) and the 99.9 % quantile of Binomial(J, 0.05): the number of checks outside chance allows."""
    spec = coloc_env.compose(world={"name": "circles", **(world or {})}, network="ideal",
                             backend={"name": backend, "motion": motion}, horizon=spacing * checks + 1)
    core = ComposedScenario(spec, batch=episodes * checks)
    core.reset([np.random.default_rng(seed + c) for c in range(episodes * checks)])
    one = core.action_vector("maximum")
    actions = np.broadcast_to(one, (core.batch, core.num_agents, one.size))
    steps = spacing * (np.arange(checks) + 1)
    agent = np.arange(checks) % core.num_agents
    means = np.zeros(checks)
    for k in range(steps[-1] + 1):
        core.step(actions)
        for j in np.flatnonzero(steps == k):
            rows = slice(j * episodes, (j + 1) * episodes)
            info = core.info()
            e = info["estimated_position"][rows, agent[j]] - info["true_position"][rows, agent[j]]
            P = core.backend.posterior_position_cov[rows, agent[j]]
            means[j] = np.einsum("ea,eab,eb->e", e, np.linalg.inv(P), e).mean()
    band = stats.chi2.ppf([0.025, 0.975], 2 * episodes) / episodes
    return means, band, int(stats.binom.ppf(0.999, checks, 0.05))


def summary(nees: np.ndarray, squared: np.ndarray, transient: int) -> dict:
    E = nees.shape[1]
    lo, hi = stats.chi2.ppf([0.025, 0.975], 2 * E) / E
    mean = nees.mean(axis=1)
    inside = (mean >= lo) & (mean <= hi)
    late = inside[transient:]
    return {"nees": float(nees.mean()), "in_band": float(inside.mean()), "in_band_late": float(late.mean()),
            "misses_late": int(late.size - late.sum()), "allowed_late": int(stats.binom.ppf(0.999, late.size, 0.05)),
            "rmse": float(np.sqrt(squared.mean()))}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=100)
    parser.add_argument("--horizon", type=int, default=None)
    parser.add_argument("--transient", type=int, default=50)
    parser.add_argument("--backends", default="ukf_ccl,ukf_dcl")
    parser.add_argument("--world", nargs="*", default=[], help="circles overrides FIELD=VALUE")
    args = parser.parse_args(argv)
    world = {k: float(v) if v not in ("True", "False") else v == "True"
             for k, v in (item.split("=", 1) for item in args.world)}
    print(f"circles {world or 'defaults'}, {args.episodes} episodes from seed {args.seed}, network ideal, "
          f"policy always; band chi-square(2E)/E 95 %; late = after {args.transient} steps")
    print("| backend | motion | mean NEES (d = 2) | in band | in band, late (misses / allowed) | RMSE [m] | "
          "independent checks outside / allowed |")
    print("|---|---|---|---|---|---|---|")
    for backend in args.backends.split(","):
        mse = {}
        for motion in ("heading", "displacement"):
            nees, squared = play(backend, motion, args.episodes, args.seed, world, args.horizon)
            s = summary(nees, squared, args.transient)
            mse[motion] = squared.mean(axis=(0, 2))
            means, (lo, hi), allowed = band_checks(backend, motion, world)
            outside = int(np.sum((means < lo) | (means > hi)))
            print(f"| {backend} | {motion} | {s['nees']:.2f} | {100 * s['in_band']:.1f} % | "
                  f"{100 * s['in_band_late']:.1f} % ({s['misses_late']} / {s['allowed_late']}) | {s['rmse']:.4f} | "
                  f"{outside} / {allowed} (mean {means.mean():.2f}) |")
        diff = mse["heading"] - mse["displacement"]
        half = stats.t.ppf(0.975, len(diff) - 1) * diff.std(ddof=1) / np.sqrt(len(diff))
        print(f"| {backend} | paired MSE heading - displacement | {diff.mean():+.4f} m^2, 95 % CI "
              f"[{diff.mean() - half:+.4f}, {diff.mean() + half:+.4f}] | | | | |")


if __name__ == "__main__":
    main()
