"""``coloc bench``: throughput of every registered scenario, measured in one run.

Per scenario, in env-steps per second (one copy advancing one time step with
all its agents; agent-steps = env-steps x N):

* ``parallel_env``  a Python loop over the PettingZoo env (B = 1);
* ``supersuit``     SuperSuit's ``concat_vec_envs_v1`` over B copies;
* ``vector_env``    coloc's batched SB3 VecEnv at B = 1, 64, 1024;
* ``estimator``     the raw batched estimator step at the same B, where the
  scenario registers one in :data:`ESTIMATOR_STEPS` (so the env's overhead
  is the ratio of the two);
* ``vmas``          VMAS's batched ``simple_spread`` with 4 agents on the CPU at
  the same B, when ``vmas`` is installed (``pip install 'coloc[bench]'``).

Every env is driven by its ``paper`` policy's actions (computed once, tiled).
Writes ``OUT/bench/bench.json`` (atomic) and ``OUT/bench/throughput.png``.
No test asserts a speed: this is where speed is reported.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable

import numpy as np

from train.io import save_figure, write_json

BATCHES = (1, 64, 1024)


def _rate(fn: Callable[[], None], min_seconds: float) -> float:
    """Calls per second of ``fn`` over at least ``min_seconds`` (after one warm-up call)."""
    fn()
    count, start = 0, time.perf_counter()
    while True:
        fn()
        count += 1
        elapsed = time.perf_counter() - start
        if elapsed >= min_seconds:
            return count / elapsed


def _bandwidth_fusion_estimator_step(batch: int) -> Callable[[], None]:
    """One step of :func:`estimators.bandwidth_fusion.step` (with the exact covariance) for B copies."""
    import estimators.bandwidth_fusion as bf
    from coloc_env.config import build_config
    from coloc_env.scenarios.bandwidth_fusion import BandwidthFusionConfig, paper_selection, paper_weights

    config = build_config(BandwidthFusionConfig, {})
    model = config.fusion_model()
    selection, weights = paper_selection("T1"), paper_weights("P1")
    box = {"state": bf.initial_state(model, np.asarray(config.initial_state), np.asarray(config.initial_cov),
                                     (batch,))}
    y = np.random.default_rng(0).normal(size=(batch, config.num_uavs, 3)) + 10.0

    def step() -> None:
        box["state"] = bf.step(model, box["state"], y, selection, weights)

    return step


ESTIMATOR_STEPS: dict[str, Callable[[int], Callable[[], None]]] = {
    "bandwidth_fusion": _bandwidth_fusion_estimator_step,
}


def _paper_actions(name: str) -> np.ndarray:
    """The paper policy's actions at reset, (N, *action_shape), in agent order."""
    import agents
    import coloc_env

    env = coloc_env.parallel_env(name)
    observations, _ = env.reset(seed=0)
    actions = agents.make_policy("paper", env).act(observations)
    return np.stack([np.asarray(actions[a]) for a in env.possible_agents])


def bench_scenario(name: str, min_seconds: float, batches=BATCHES) -> list[dict]:
    import coloc_env
    from train.training import make_supersuit_vec_env, seed_supersuit_vec_env

    rows: list[dict] = []
    paper = _paper_actions(name)
    num_agents = paper.shape[0]

    def add(what: str, batch: int, calls_per_s: float) -> None:
        rows.append({"scenario": name, "what": what, "batch": batch, "env_steps_per_s": calls_per_s * batch,
                     "agent_steps_per_s": calls_per_s * batch * num_agents})

    env = coloc_env.parallel_env(name)
    env.reset(seed=0)
    actions = {a: paper[i] for i, a in enumerate(env.possible_agents)}

    def loop_step() -> None:
        if not env.agents:
            env.reset()
        env.step(actions)

    add("parallel_env loop", 1, _rate(loop_step, min_seconds))

    supersuit_batch = 64
    supersuit = make_supersuit_vec_env(name, supersuit_batch, {})
    seed_supersuit_vec_env(supersuit, 0)
    supersuit.reset()
    tiled = np.tile(paper, (supersuit_batch, *([1] * (paper.ndim - 1))))
    add("supersuit concat_vec_envs_v1", supersuit_batch, _rate(lambda: supersuit.step(tiled), min_seconds))
    supersuit.close()

    for batch in batches:
        venv = coloc_env.vector_env(name, num_envs=batch, seed=0)
        venv.reset()
        tiled = np.tile(paper, (batch, *([1] * (paper.ndim - 1))))
        add("vector_env", batch, _rate(lambda venv=venv, tiled=tiled: venv.step(tiled), min_seconds))
        if name in ESTIMATOR_STEPS:
            add("estimator step", batch, _rate(ESTIMATOR_STEPS[name](batch), min_seconds))
    return rows


def bench_vmas(min_seconds: float, batches=BATCHES) -> list[dict]:
    """VMAS's batched simple_spread (4 agents, CPU), the leading batched simulator, if installed."""
    try:
        import torch
        import vmas
    except ImportError:
        return []
    rows = []
    for batch in batches:
        env = vmas.make_env("simple_spread", num_envs=batch, device="cpu", continuous_actions=True, n_agents=4,
                            seed=0)
        env.reset()
        actions = [torch.zeros(batch, 2) for _ in range(4)]
        rate = _rate(lambda env=env, actions=actions: env.step(actions), min_seconds)
        rows.append({"scenario": "vmas simple_spread", "what": "vmas (torch, CPU)", "batch": batch,
                     "env_steps_per_s": rate * batch, "agent_steps_per_s": rate * batch * 4})
    return rows


def _figure(rows: list[dict], path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5))
    series: dict[tuple[str, str], list[tuple[int, float]]] = {}
    for row in rows:
        series.setdefault((row["scenario"], row["what"]), []).append((row["batch"], row["env_steps_per_s"]))
    for (scenario, what), points in series.items():
        points.sort()
        batches, rates = zip(*points, strict=True)
        style = "o-" if len(points) > 1 else "s"
        ax.loglog(batches, rates, style, label=f"{scenario}: {what}")
    ax.set_xlabel("batch B (copies)")
    ax.set_ylabel("env-steps / s")
    ax.set_title("coloc bench: throughput vs batch size (2-core CPU)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    save_figure(path, fig)


def run(out: str, quick: bool = False, scenarios: list[str] | None = None) -> list[dict]:
    from rich.console import Console
    from rich.table import Table

    import coloc_env

    min_seconds = 0.15 if quick else 1.5
    names = scenarios or list(coloc_env.SCENARIOS)
    console = Console()
    rows: list[dict] = []
    with console.status("benchmarking") as status:
        for name in names:
            status.update(f"benchmarking {name}")
            rows += bench_scenario(name, min_seconds)
        status.update("benchmarking vmas (if installed)")
        rows += bench_vmas(min_seconds)
    table = Table(title="coloc bench (env-step: one copy advancing one step with all its agents)")
    for column in ("scenario", "what", "B", "env-steps/s", "agent-steps/s"):
        table.add_column(column, justify="right" if column != "what" and column != "scenario" else "left")
    for row in rows:
        table.add_row(row["scenario"], row["what"], str(row["batch"]), f"{row['env_steps_per_s']:,.0f}",
                      f"{row['agent_steps_per_s']:,.0f}")
    console.print(table)
    folder = os.path.join(out, "bench")
    write_json(os.path.join(folder, "bench.json"), {"quick": quick, "cpu_count": os.cpu_count(), "rows": rows})
    _figure(rows, os.path.join(folder, "throughput.png"))
    return rows
