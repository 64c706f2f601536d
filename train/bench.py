"""``coloc bench``: throughput of the estimator and the env (a first version).

Measures, per registered scenario that has a batched estimator step:
estimator steps per second at batch 1 and 1024, and env steps per second of
a Python loop over ``parallel_env``. Writes ``OUT/bench/bench.json``.
No test asserts a speed; this is where speed is reported.
"""

from __future__ import annotations

import os
import time

import numpy as np

from train.io import write_json


def _rate(fn, min_seconds: float) -> float:
    """Calls per second of ``fn`` over at least ``min_seconds`` (after one warm-up call)."""
    fn()
    count, start = 0, time.perf_counter()
    while True:
        fn()
        count += 1
        elapsed = time.perf_counter() - start
        if elapsed >= min_seconds:
            return count / elapsed


def bench_bandwidth_fusion(min_seconds: float) -> list[dict]:
    import agents
    import coloc_env
    import estimators.bandwidth_fusion as bf
    from coloc_env.config import build_config
    from coloc_env.scenarios.bandwidth_fusion import BandwidthFusionConfig, paper_selection, paper_weights

    config = build_config(BandwidthFusionConfig, {})
    model = config.fusion_model()
    selection, weights = paper_selection("T1"), paper_weights("P1")
    rows = []
    for batch in (1, 1024):
        state = bf.initial_state(model, np.asarray(config.initial_state), np.asarray(config.initial_cov), (batch,))
        y = np.random.default_rng(0).normal(size=(batch, config.num_uavs, 3))
        box = {"state": state}

        def one_step(box=box, y=y):
            box["state"] = bf.step(model, box["state"], y, selection, weights)

        rate = _rate(one_step, min_seconds)
        rows.append({"scenario": "bandwidth_fusion", "what": "estimator step (exact covariance)",
                     "batch": batch, "steps_per_s": rate * batch})
    env = coloc_env.parallel_env("bandwidth_fusion")
    policy = agents.make_policy("paper", env)
    obs, _ = env.reset(seed=0)
    actions = policy.act(obs)

    def env_step():
        if not env.agents:
            env.reset()
        env.step(actions)

    rows.append({"scenario": "bandwidth_fusion", "what": "parallel_env loop", "batch": 1,
                 "steps_per_s": _rate(env_step, min_seconds)})
    return rows


def run(out: str, quick: bool = False) -> list[dict]:
    from rich.console import Console
    from rich.table import Table

    min_seconds = 0.3 if quick else 2.0
    rows = bench_bandwidth_fusion(min_seconds)
    table = Table(title="coloc bench (env-steps/s: one copy advancing one step with all its agents)")
    for column in ("scenario", "what", "batch", "env-steps/s"):
        table.add_column(column)
    for row in rows:
        table.add_row(row["scenario"], row["what"], str(row["batch"]), f"{row['steps_per_s']:,.0f}")
    Console().print(table)
    write_json(os.path.join(out, "bench", "bench.json"), {"quick": quick, "rows": rows})
    return rows
