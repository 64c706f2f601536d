"""``coloc bench``: the throughput rows of every preset (``bench_scenario``) and the run that prints, writes and
draws them (``run``); the package docstring lists the rows."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Callable

import numpy as np

from train import hyperparams
from train.bench.measure import BATCHES, PCRB_ROW, per_second
from train.bench.peers import PEERS, bench_vmas
from train.bench.replay import BACKEND_CALLS, ActionSource, replayed_estimator_step
from train.io import save_figure, write_json


def _gps_denied_nbp_episode(batch: int, num_particles: int = 100):
    """(model, episode arrays stacked over B copies, initial dNBP state, per-copy generators) at the defaults."""
    import estimators.dnbp as dn
    from coloc_env.config import build_config
    from coloc_env.scenarios.gps_denied_nbp import GpsDeniedNbpConfig
    from coloc_env.worlds.gps_denied import sample_episode
    from train.reproduce.wan2014 import dnbp_model

    config = build_config(GpsDeniedNbpConfig, {"num_particles": num_particles})
    model = dnbp_model(config)
    episodes = [sample_episode(config.parts()[0], np.random.default_rng([0, b])) for b in range(batch)]
    rngs = [np.random.default_rng([1, b]) for b in range(batch)]
    stack = {k: np.stack([getattr(e, k) for e in episodes]) for k in
             ("gps_normal", "gps_fix", "adjacency", "ranges", "accel")}
    state = dn.initial_state(model, rngs, "warm", np.stack([e.init_position for e in episodes]),
                             np.stack([e.init_velocity for e in episodes]), config.velocity_spread)
    return config, model, stack, state, rngs


def _gps_denied_nbp_inputs(stack: dict, k: int) -> tuple:
    """dNBP's per-step inputs of step k: (gps_normal, gps_fix, deliver over the adjacency, ranges, accel)."""
    from coloc_env.networks.blocks.broadcast_medium import BroadcastMedium

    return (stack["gps_normal"][:, k], stack["gps_fix"][:, k], BroadcastMedium().over(stack["adjacency"][:, k]),
            stack["ranges"][:, k], stack["accel"][:, k])


def _gps_denied_nbp_estimator_step(batch: int, num_particles: int = 100) -> Callable[[], None]:
    """One dNBP time step (``estimators.dnbp.step``, paper schedule) for B copies, cycling the episode."""
    import estimators.dnbp as dn

    config, model, stack, state, rngs = _gps_denied_nbp_episode(batch, num_particles)
    box = {"state": state, "k": 0}

    def step() -> None:
        k = box["k"] % config.horizon
        box["state"], _ = dn.step(model, box["state"], *_gps_denied_nbp_inputs(stack, k), rngs)
        box["k"] += 1

    return step


def _gps_denied_nbp_particle_rows(min_seconds: float, batch: int | None = None, steps: int | None = None
                                  ) -> list[dict]:
    """Time per fault-UAV step of dNBP (Table 1's unit) at M = 50, 100, 200, 300, over the first steps.

    B = 16 copies (the reproduction's batch) and 10 steps; 4 and 3 in quick mode.
    """
    import estimators.dnbp as dn

    quick = min_seconds < 1.0
    batch = batch or (4 if quick else 16)
    steps = steps or (3 if quick else 10)
    rows = []
    for M in (50, 100, 200, 300):
        config, model, stack, state, rngs = _gps_denied_nbp_episode(batch, M)
        dn.step(model, state, *_gps_denied_nbp_inputs(stack, 0), [np.random.default_rng(2) for _ in rngs])  # warm-up
        elapsed, fault_steps = 0.0, 0
        for k in range(steps):
            start = time.perf_counter()
            state, _ = dn.step(model, state, *_gps_denied_nbp_inputs(stack, k), rngs)
            elapsed += time.perf_counter() - start
            fault_steps += int((~stack["gps_normal"][:, k]).sum())
        rate = steps / elapsed
        rows.append({"scenario": "gps_denied_nbp", "what": f"dNBP step, M = {M}", "batch": batch,
                     "env_steps_per_s": rate * batch, "agent_steps_per_s": rate * batch * config.num_agents,
                     "time_per_fault_uav_step_s": elapsed / max(fault_steps, 1)})
    return rows


# Scenarios too expensive per step for the default batches (dNBP: an M x M kernel per message): each preset's
# ``BENCH_BATCHES`` in train/hyperparams/<preset>.py.
SCENARIO_BATCHES: dict[str, tuple[int, ...]] = {name: tuple(batches) for name, batches
                                                in hyperparams.presets_declaring("BENCH_BATCHES").items()}
# Extra rows a scenario reports (name -> fn(min_seconds) -> rows).
CONTENTION_BENCH = {"num_agents": 40, "batch": 8, "backend": "range_ls"}


def _contention_rows(min_seconds: float) -> list[dict]:
    """A ``contention`` step against a ``broadcast`` step in one run: gps_denied with N = 40 UAVs at the scaling
    rows' density (``scaling_world``), B = 8 copies, one slot, the same backend (``range_ls``: its update is
    cheap, so the rows show the network's own cost; a UKF's step would hide it) and the same actions, one UAV
    transmitting per step (k mod N), with which the two networks deliver the same messages (nothing collides):
    the same backend work, and ``time_over_broadcast`` is the contention step's time over the broadcast one's.
    A second pair plays ``always`` (every UAV transmits: on contention everything collides, so the backend
    fuses less there)."""
    import coloc_env
    from train.bench.scaling import scaling_world

    N, B, backend = CONTENTION_BENCH["num_agents"], CONTENTION_BENCH["batch"], CONTENTION_BENCH["backend"]
    world = scaling_world(N, "fixed density")
    rows = []
    for schedule in ("one UAV per step", "always"):
        rates = {}
        for network in ("broadcast", {"name": "contention", "slots": 1}):
            venv = coloc_env.vector_env(coloc_env.compose(world=world, network=network, backend=backend),
                                        num_envs=B, seed=0)
            core = venv.scenario
            base = np.broadcast_to(core.action_vector("minimum" if schedule != "always" else "maximum"), (B, N, 1))
            box = {"k": 0}
            actions = [base.copy() for _ in range(N)]
            if schedule != "always":
                for k in range(N):
                    actions[k][:, k % N] = 1

            actions = [a.reshape(B * N, 1) for a in actions]  # the vec env's sub-envs: copies x agents

            def step(venv=venv, box=box, actions=actions) -> None:  # it resets a finished copy itself
                venv.step(actions[box["k"] % N])
                box["k"] += 1

            venv.reset()
            name = network if isinstance(network, str) else network["name"]
            rates[name] = per_second(step, min_seconds)
            venv.close()
        for name, rate in rates.items():
            row = {"scenario": "contention_localization",
                   "what": f"gps_denied/{name}/{backend} N = {N}, 1 slot, {schedule}", "batch": B,
                   "env_steps_per_s": rate * B, "agent_steps_per_s": rate * B * N}
            if name == "contention":
                row["time_over_broadcast"] = rates["broadcast"] / rate
            rows.append(row)
    return rows


# A fresh process building mrclam_relay at its defaults once the likelihood fit is cached on disk: the data's
# load, the moment rules' calibration and the cached fit's read (coloc_env.data.fit_cache), without the imports.
_CONSTRUCTION_DRIVER = """
import json, time
import coloc_env
from coloc_env.data import fit_cache
start = time.perf_counter()
env = coloc_env.parallel_env("mrclam_relay")
env.reset(seed=0)
print(json.dumps({"seconds": time.perf_counter() - start, "stats": dict(fit_cache.STATS)}))
"""
CONSTRUCTION_ROW = "construction, warm fit cache"
CONSTRUCTION_RUNS = 3
REPOSITORY = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _mrclam_relay_construction_rows(min_seconds: float) -> list[dict]:
    """``CONSTRUCTION_ROW``: the best of ``CONSTRUCTION_RUNS`` fresh processes' construction time (``construction_s``,
    and its inverse as the row's rate), after this process built the env (so the fit is in the disk cache); each
    process's cache counts (``fit_cache.STATS``) say whether it read the fit (``fits_read``) or ran it."""
    import coloc_env

    coloc_env.parallel_env("mrclam_relay").reset(seed=0)  # warms the disk cache if it was cold
    best, read = np.inf, True
    for _ in range(CONSTRUCTION_RUNS):
        done = subprocess.run([sys.executable, "-c", _CONSTRUCTION_DRIVER], capture_output=True, text=True,
                              check=True, cwd=REPOSITORY)
        report = json.loads(done.stdout.strip().splitlines()[-1])
        best = min(best, report["seconds"])
        read = read and report["stats"].get("computed", 0) == 0
    return [{"scenario": "mrclam_relay", "what": CONSTRUCTION_ROW, "batch": 1, "env_steps_per_s": 1.0 / best,
             "agent_steps_per_s": 1.0 / best, "construction_s": best, "fits_read": read}]


EXTRA_BENCHES: dict[str, Callable[[float], list[dict]]] = {"gps_denied_nbp": _gps_denied_nbp_particle_rows,
                                                           "contention_localization": _contention_rows,
                                                           "mrclam_relay": _mrclam_relay_construction_rows}
# Scenarios whose work per copy depends on the episode (dNBP: how many messages arrive, how many proposals the
# truncated kernel prunes): a vector_env of B copies plays episodes 0..B-1, so its rows at B = 1 and B = 4 time
# different work. These also get a row with every copy playing episode 0 (ONE_EPISODE), where only B changes
# (a preset's ``BENCH_ONE_EPISODE`` in train/hyperparams/<preset>.py).
ONE_EPISODE_ROWS = tuple(name for name, on in hyperparams.presets_declaring("BENCH_ONE_EPISODE").items() if on)
ONE_EPISODE = "vector_env, one episode"
# what one_episode_rate and per_second's sources need where --against runs them in a reference tree's process
_ONE_EPISODE_PREAMBLE = "from __future__ import annotations\nimport gc\nimport time\n\nimport numpy as np\n\n"


def one_episode_rate(coloc_env, name: str, batch: int, paper: np.ndarray, min_seconds: float) -> float:
    """Steps per second (``per_second``) of ``vector_env(name, num_envs=batch)`` with every copy seeded 0 (the same
    episode in each copy) and the paper actions ``paper`` (N, ...) tiled: constant actions only (gps_denied_nbp's).

    ``coloc bench --against`` also runs this source and ``per_second``'s in the reference tree's process, on that
    tree's coloc_env, for a tree whose bench has no such row: they use only their arguments, numpy, gc and time.
    It sets the env's ``_copy_seeds``, from which every version of the batched VecEnv reseeds copy b at reset."""
    venv = coloc_env.vector_env(name, num_envs=batch, seed=0)
    venv._copy_seeds = [0] * batch
    venv.reset()
    tiled = np.tile(paper, (batch, *([1] * (paper.ndim - 1))))
    try:
        return per_second(lambda: venv.step(tiled), min_seconds)
    finally:
        venv.close()


ESTIMATOR_STEPS: dict[str, Callable[[int], Callable[[], None]]] = {
    **{name: replayed_estimator_step(name) for name in BACKEND_CALLS},
    "gps_denied_nbp": _gps_denied_nbp_estimator_step,
}


def _supersuit_cores(venv) -> list:
    return [markov_env.par_env.scenario for markov_env in venv.venv.venv.vec_envs]


def bench_scenario(name: str, min_seconds: float, batches=BATCHES) -> list[dict]:
    import coloc_env
    from train.training import make_supersuit_vec_env, seed_supersuit_vec_env

    rows: list[dict] = []
    source = ActionSource(name)
    num_agents = source.num_agents
    batches = SCENARIO_BATCHES.get(name, batches)

    def add(what: str, batch: int, calls_per_s: float) -> None:
        rows.append({"scenario": name, "what": what, "batch": batch, "env_steps_per_s": calls_per_s * batch,
                     "agent_steps_per_s": calls_per_s * batch * num_agents})

    env = coloc_env.parallel_env(name)
    env.reset(seed=0)

    def loop_step() -> None:
        if not env.agents:
            env.reset()
        actions = source([env.scenario])
        env.step({a: actions[i] for i, a in enumerate(env.possible_agents)})

    add("parallel_env loop", 1, per_second(loop_step, min_seconds))

    supersuit_batch = min(64, max(batches))
    supersuit = make_supersuit_vec_env(name, supersuit_batch, {})
    seed_supersuit_vec_env(supersuit, 0)
    supersuit.reset()
    cores = _supersuit_cores(supersuit)
    add("supersuit concat_vec_envs_v1", supersuit_batch, per_second(lambda: supersuit.step(source(cores)), min_seconds))
    supersuit.close()

    for batch in batches:
        venv = coloc_env.vector_env(name, num_envs=batch, seed=0)
        venv.reset()
        core = [venv.scenario]
        add("vector_env", batch, per_second(lambda venv=venv, core=core: venv.step(source(core)), min_seconds))
        venv.close()
        if name in ONE_EPISODE_ROWS:
            add(ONE_EPISODE, batch, one_episode_rate(coloc_env, name, batch, source.paper, min_seconds))
        if name in ESTIMATOR_STEPS:
            add("estimator step", batch, per_second(ESTIMATOR_STEPS[name](batch), min_seconds))
        if name in PEERS:
            label, factory, ours, our_factory = PEERS[name]
            add(ours, batch, per_second(our_factory(batch), min_seconds))
            add(label, batch, per_second(factory(batch), min_seconds))
    # the posterior Cramér-Rao bound of one episode (coloc_env.pcrb: the play and the recursion), per env-step;
    # one warm-up call: a whole episode reaches every compiled kernel it uses, and each call takes seconds
    steps = coloc_env.make_core(name, batch=1).horizon
    add(PCRB_ROW, 1, steps * per_second(lambda: coloc_env.pcrb(name, episodes=1, seed=0), min_seconds, warm_up=1))
    if name in EXTRA_BENCHES:
        rows += EXTRA_BENCHES[name](min_seconds)
    return rows


REFERENCE_SCENARIOS = ("vmas simple_spread",)  # drawn in every panel as a grey reference, not a panel of its own


def _figure(rows: list[dict], path: str) -> None:
    """One panel per preset (its env rows, estimator step and peers, each line labelled in the
    panel's own short legend, below the panel), VMAS as a dashed grey reference in every panel: a
    single axes with every series in one legend (26 entries) hid the lines it described."""
    import math

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    series: dict[str, dict[str, list[tuple[int, float]]]] = {}
    for row in rows:
        series.setdefault(row["scenario"], {}).setdefault(row["what"], []).append(
            (row["batch"], row["env_steps_per_s"]))
    panels = [name for name in series if name not in REFERENCE_SCENARIOS]
    references = {name: series[name] for name in REFERENCE_SCENARIOS if name in series}
    columns = min(3, max(1, len(panels)))
    lines = max(1, math.ceil(len(panels) / columns))
    from train.plotting import label, plain_log_ticks

    # one colour per series across panels (a series keeps its colour wherever it appears)
    names = list(dict.fromkeys(what for name in panels for what in series[name]))
    colour = {what: f"C{k % 10}" for k, what in enumerate(names)}
    fig, axes = plt.subplots(lines, columns, figsize=(5.2 * columns, 5.0 * lines), squeeze=False)
    for ax, name in zip(axes.flat, panels, strict=False):
        for what, points in series[name].items():
            points.sort()
            batches, rates = zip(*points, strict=True)
            # a single point (a dNBP size M, a peer at one B) as an open marker of its own colour, no line
            # (dNBP's sizes M, all at one B, as triangles: the colour cycle repeats past ten series)
            style = "o-" if len(points) > 1 else ("^" if what.startswith("dNBP step") else "D")
            ax.loglog(batches, rates, style, color=colour[what], label=what, markersize=4 if len(points) > 1 else 5,
                      markerfacecolor=None if len(points) > 1 else "none")
        for ref_name, whats in references.items():
            for what, points in whats.items():
                points.sort()
                batches, rates = zip(*points, strict=True)
                ax.loglog(batches, rates, "--", color="0.6", linewidth=1, label=f"{ref_name} ({what})")
        ax.set_title(name, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.set_xlabel(label("batch B", "copies"), fontsize=8)
        plain_log_ticks(ax, "x")
        plain_log_ticks(ax, "y")
        # below the panel, not on it: inside, the legend of a panel with five or more lines covered them
        ax.legend(fontsize=6.5, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2, frameon=False)
    for ax in axes.flat:
        ax.set_ylabel(label("throughput", "env-steps/s"), fontsize=8)
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    fig.suptitle(f"coloc bench: throughput vs batch size ({os.cpu_count()}-core CPU)")
    fig.tight_layout()
    save_figure(path, fig)


def add_overheads(rows: list[dict]) -> None:
    """On each vector_env row with an estimator row of the same scenario and batch: ``env_time_over_estimator``,
    the env's time per step over the estimator step's (the estimator's rate over the env's; 1 = no overhead)."""
    estimator = {(r["scenario"], r["batch"]): r["env_steps_per_s"] for r in rows if r["what"] == "estimator step"}
    for row in rows:
        key = (row["scenario"], row["batch"])
        if row["what"] == "vector_env" and key in estimator and row["env_steps_per_s"] > 0:
            row["env_time_over_estimator"] = estimator[key] / row["env_steps_per_s"]


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
    add_overheads(rows)
    table = Table(title="coloc bench (env-step: one copy advancing one step with all its agents; "
                        "env / est.: the vector_env's time per step over its estimator step's)")
    for column in ("scenario", "what", "B", "env-steps/s", "agent-steps/s", "env / est."):
        table.add_column(column, justify="right" if column != "what" and column != "scenario" else "left")
    for row in rows:
        overhead = row.get("env_time_over_estimator")
        table.add_row(row["scenario"], row["what"], str(row["batch"]), f"{row['env_steps_per_s']:,.0f}",
                      f"{row['agent_steps_per_s']:,.0f}", "" if overhead is None else f"{overhead:.2f}x")
    console.print(table)
    for row in rows:
        if "construction_s" in row:
            console.print(f"{row['scenario']} {row['what']}: {row['construction_s']:.2f} s per construction in a "
                          f"fresh process ({'the fit read from the disk cache' if row['fits_read'] else 'FITTED'})")
        if "time_over_broadcast" in row:
            console.print(f"{row['scenario']} {row['what']} (B = {row['batch']}): a contention step takes "
                          f"{row['time_over_broadcast']:.2f}x a broadcast step")
        if "time_per_fault_uav_step_s" in row:
            console.print(f"{row['scenario']} {row['what']} (B = {row['batch']}): "
                          f"{1e3 * row['time_per_fault_uav_step_s']:.1f} ms per fault-UAV step")
    folder = os.path.join(out, "bench")
    write_json(os.path.join(folder, "bench.json"), {"quick": quick, "cpu_count": os.cpu_count(), "rows": rows})
    _figure(rows, os.path.join(folder, "throughput.png"))
    return rows
