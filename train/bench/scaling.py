"""``coloc bench --scaling``: env-steps/s of compositions of the gps_denied world against the number of agents N,
at a fixed area and a fixed density, optionally beside another tree's."""

from __future__ import annotations

import contextlib
import inspect
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

from coloc_env.config import BadInput
from train.bench.against import export_commit, repository_root
from train.bench.measure import per_second
from train.io import save_figure, write_json, write_text

# --- coloc bench --scaling ---------------------------------------------------------------------------------------
# env-steps/s of vector_env(compose(gps_denied with N agents, network, backend), B copies) against N: every
# composition of the gps_denied world the current tree can run (and the UKFs over ``ideal`` too, where UKF-DCL
# computes UKF-CCL's numbers, and over ``gilbert_elliott``, bursty loss beside broadcast's: what its link chains
# cost), at a fixed start square and at a fixed density.
SCALING_SIZES = (5, 10, 20, 40, 80)
SCALING_BATCHES = (8, 64)
SCALING_DENSITY = 40.0  # UAVs per km^2: the default 500 m square at N = 10
SCALING_LAYOUTS = ("fixed area", "fixed density")
SCALING_EXTRA_NETWORKS = {"ukf_ccl": ("ideal", "gilbert_elliott"), "ukf_dcl": ("ideal", "gilbert_elliott")}
SCALING_CAP_S = 120.0  # per row and tree: the sizes not measured within it print "over cap"
SCALING_QUICK = {"sizes": (5, 10), "batches": (8,), "min_seconds": 0.05, "cap": 60.0}
_SCALING_PREAMBLE = "from __future__ import annotations\nimport gc\nimport json\nimport time\n\nimport numpy as np\n\n"


def scaling_world(num_agents: int, layout: str) -> dict:
    """The gps_denied world of one scaling cell as a plain dict (every version of the world takes it): the fixed
    density is given as the ``area`` (side) it implies, ``GpsDenied(density=...).side``, so that a tree without
    the ``density`` field draws the same episodes."""
    from coloc_env.worlds.gps_denied import GpsDenied

    if layout not in SCALING_LAYOUTS:
        raise BadInput(f"layout must be one of {SCALING_LAYOUTS}, got {layout!r}")
    world = {"name": "gps_denied", "num_agents": int(num_agents)}
    if layout == "fixed density":
        world["area"] = GpsDenied(num_agents=int(num_agents), density=SCALING_DENSITY).side
    return world


def scaling_compositions() -> list[tuple[str, str]]:
    """(backend, network) of every row: each backend that runs on gps_denied over broadcast, in the registry's
    order, then the UKFs over ideal and over gilbert_elliott (``SCALING_EXTRA_NETWORKS``)."""
    import coloc_env

    ok = [r["backend"] for r in coloc_env.compatibility() if r["world"] == "gps_denied"
          and r["network"] == "broadcast" and r["ok"]]
    pairs = [(b, "broadcast") for b in dict.fromkeys(ok)]
    pairs += [(b, net) for b in dict.fromkeys(ok) for net in SCALING_EXTRA_NETWORKS.get(b, ())]
    return pairs


def scaling_rate(coloc_env, world: dict, network: str, backend: str, batch: int, min_seconds: float) -> float:
    """Env-steps per second (copies x steps) of ``vector_env(compose(world, network, backend), num_envs=batch,
    seed=0)`` under random actions (a pool of 16 drawn from the action space seeded 0, cycled), timed by
    ``per_second`` after one step. Uses only its arguments, numpy and ``per_second``: ``--against`` runs this
    source in the reference tree's process."""
    spec = coloc_env.compose(world=world, network=network, backend=backend)
    venv = coloc_env.vector_env(spec, num_envs=batch, seed=0)
    try:
        venv.reset()
        venv.action_space.seed(0)
        pool = [np.stack([venv.action_space.sample() for _ in range(venv.num_envs)]) for _ in range(16)]
        box = {"k": 0}

        def step() -> None:
            venv.step(pool[box["k"] % len(pool)])
            box["k"] += 1

        return per_second(step, min_seconds) * batch
    finally:
        venv.close()


def scaling_cells(coloc_env, spec: dict) -> None:
    """One row of one tree: the sizes in order, each cell appended to ``spec["out"]`` as a JSON line as soon as it
    is measured (the caller kills the process at the row's cap and keeps what was written). A size the tree
    refuses (a ValueError, e.g. more agents than it allows) is written with its message."""
    for size, world in zip(spec["sizes"], spec["worlds"], strict=True):
        try:
            rate = scaling_rate(coloc_env, world, spec["network"], spec["backend"], spec["batch"],
                                spec["min_seconds"])
            cell = {"N": size, "env_steps_per_s": rate}
        except ValueError as exc:
            cell = {"N": size, "error": str(exc).splitlines()[0]}
        with open(spec["out"], "a") as f:
            f.write(json.dumps(cell) + "\n")


_SCALING_DRIVER = """
import json, sys
spec = json.loads(sys.argv[1])
space = {}
exec(spec["source"], space)
import coloc_env
space["scaling_cells"](coloc_env, spec)
"""


def _scaling_source() -> str:
    return _SCALING_PREAMBLE + "".join(inspect.getsource(f) for f in (per_second, scaling_rate, scaling_cells))


def scaling_row(tree: str, backend: str, network: str, layout: str, batch: int, sizes, min_seconds: float,
                cap: float, single_thread: bool = False) -> dict[int, dict]:
    """{N: cell} of one row measured in a subprocess with ``tree`` first on sys.path, killed after ``cap``
    seconds; a size with no cell is over the cap. ``single_thread``: BLAS, numba and dNBP's pool on one thread."""
    with tempfile.TemporaryDirectory(prefix="coloc-scaling-") as scratch:
        out = os.path.join(scratch, "cells.jsonl")
        spec = {"source": _scaling_source(), "backend": backend, "network": network, "batch": int(batch),
                "sizes": [int(n) for n in sizes], "worlds": [scaling_world(n, layout) for n in sizes],
                "min_seconds": float(min_seconds), "out": out}
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([tree, os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep),
                   MPLBACKEND="Agg")
        if single_thread:
            env.update({name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                                               "NUMBA_NUM_THREADS", "COLOC_THREADS")})
        error = None
        try:
            done = subprocess.run([sys.executable, "-c", _SCALING_DRIVER, json.dumps(spec)], cwd=tree, env=env,
                                  capture_output=True, text=True, timeout=cap)
            if done.returncode != 0:
                lines = (done.stderr or done.stdout).strip().splitlines()
                error = lines[-1] if lines else f"exit {done.returncode}"
        except subprocess.TimeoutExpired:
            pass
        cells = {}
        if os.path.exists(out):
            with open(out) as f:
                for line in f:
                    cell = json.loads(line)
                    cells[cell["N"]] = cell
    if error is not None:
        for n in sizes:
            cells.setdefault(n, {"N": n, "error": error})
    return cells


def growth_exponent(sizes, rates) -> float | None:
    """The least-squares slope of log(time per env-step) against log N over the measured sizes (time per step
    ~ N^slope); None with fewer than two."""
    points = [(n, r) for n, r in zip(sizes, rates, strict=True) if r is not None and r > 0]
    if len(points) < 2:
        return None
    n, r = np.array(points, float).T
    return float(np.polyfit(np.log(n), -np.log(r), 1)[0])


def _scaling_entry(cells: dict[int, dict], sizes) -> dict:
    rates = [cells.get(n, {}).get("env_steps_per_s") for n in sizes]
    status = ["ok" if r is not None else "refused" if "error" in cells.get(n, {}) else "over cap"
              for n, r in zip(sizes, rates, strict=True)]
    growth = (rates[sizes.index(20)] / rates[sizes.index(40)]
              if 20 in sizes and 40 in sizes and rates[sizes.index(20)] and rates[sizes.index(40)] else None)
    errors = {str(n): c["error"] for n, c in cells.items() if "error" in c}
    return {"env_steps_per_s": rates, "status": status, "exponent": growth_exponent(sizes, rates),
            "time_growth_20_to_40": growth, "errors": errors}


def run_scaling(out: str, quick: bool = False, against: str | None = None, cap: float | None = None,
                sizes=None, batches=None, compositions=None, layouts=SCALING_LAYOUTS,
                min_seconds: float | None = None, reference_tree: str | None = None,
                workers: int = 1) -> list[dict]:
    """``coloc bench --scaling``: env-steps/s against N (``SCALING_SIZES``) for every row of
    ``scaling_compositions`` x layout x B (``SCALING_BATCHES``), each row in its own subprocess stopped
    after ``cap`` seconds (the sizes left print "over cap"), with the growth exponent of each row (the log-log
    slope of time per step against N) and the growth of the time per step from N = 20 to 40. With ``against``
    REF, each row is measured for the current tree and for commit REF (exported by ``git archive``) one after
    the other, alternating which goes first, and each cell gets the ratio current / REF. ``reference_tree``: a
    folder holding REF's files instead of a git ref (``against`` then only labels it). ``workers`` > 1 runs that
    many rows at once, each process on one thread (BLAS, numba and dNBP's pool), for a machine with that many
    idle cores; the current and REF runs of a row then run side by side.
    Writes ``OUT/bench/scaling.json``, ``scaling.md`` and the log-log figure ``OUT/bench/scaling.png`` (atomic)."""
    from rich.console import Console
    from rich.table import Table

    sizes = tuple(sizes or (SCALING_QUICK["sizes"] if quick else SCALING_SIZES))
    batches = tuple(batches or (SCALING_QUICK["batches"] if quick else SCALING_BATCHES))
    cap = float(cap if cap is not None else SCALING_QUICK["cap"] if quick else SCALING_CAP_S)
    min_seconds = float(min_seconds if min_seconds is not None else SCALING_QUICK["min_seconds"] if quick else 1.0)
    pairs = list(compositions or scaling_compositions())
    console = Console(width=max(160, Console().width))  # the table is wide: never wrap its cells
    root = repository_root() if against and not reference_tree else \
        os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    rows: list[dict] = []
    commit = None
    against = against or (os.path.basename(os.path.normpath(reference_tree)) if reference_tree else None)
    with contextlib.ExitStack() as stack:
        trees = [("current", root)]
        if reference_tree:
            trees.append((against, os.path.abspath(reference_tree)))
        elif against:
            folder = stack.enter_context(tempfile.TemporaryDirectory(prefix="coloc-against-"))
            commit = export_commit(against, folder, root)
            trees.append((against, folder))
        status = stack.enter_context(console.status("benchmarking"))
        jobs = []  # (row, key, tree) in the alternating order
        for layout in layouts:
            for backend, network in pairs:
                for batch in batches:
                    row = {"layout": layout, "backend": backend, "network": network, "batch": batch}
                    order = trees if len(rows) % 2 == 0 else trees[::-1]
                    jobs += [(row, "current" if label == "current" else "reference", tree) for label, tree in order]
                    rows.append(row)

        def measure(job) -> None:
            row, key, tree = job
            status.update(f"{row['layout']}: {row['backend']} over {row['network']}, B = {row['batch']} ({key})")
            cells = scaling_row(tree, row["backend"], row["network"], row["layout"], row["batch"], sizes,
                                min_seconds, cap, single_thread=workers > 1)
            row[key] = _scaling_entry(cells, sizes)

        if workers > 1:
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(workers) as pool:
                list(pool.map(measure, jobs))
        else:
            for job in jobs:
                measure(job)
        for row in rows:
            if against:
                cur, ref = row["current"]["env_steps_per_s"], row["reference"]["env_steps_per_s"]
                row["ratio"] = [c / r if c and r else None for c, r in zip(cur, ref, strict=True)]
    table = Table(title="coloc bench --scaling: env-steps/s against N (gps_denied, random actions)"
                  + (f", ratio = current / {against}" if against else ""))
    for column in ("layout", "backend", "network", "B", "tree", *[f"N={n}" for n in sizes], "slope", "t40/t20"):
        table.add_column(column, justify="left" if column in ("layout", "backend", "network", "tree") else "right")

    def rate(value, state):
        return state if value is None else f"{value:,.1f}" if value < 100 else f"{value:,.0f}"

    def fmt(value, form):
        return "-" if value is None else form.format(value)

    for row in rows:
        entries = [("current", row["current"])] + ([(against, row["reference"])] if against else [])
        for label, entry in entries:
            table.add_row(row["layout"], row["backend"], row["network"], str(row["batch"]), label,
                          *[rate(v, s) for v, s in zip(entry["env_steps_per_s"], entry["status"], strict=True)],
                          fmt(entry["exponent"], "{:.2f}"), fmt(entry["time_growth_20_to_40"], "{:.1f}x"))
        if against:
            table.add_row(row["layout"], row["backend"], row["network"], str(row["batch"]), "ratio",
                          *[fmt(r, "{:.2f}x") for r in row["ratio"]], "", "")
    console.print(table)
    folder = os.path.join(out, "bench")
    write_text(os.path.join(folder, "scaling.md"), scaling_markdown(rows, sizes, against))
    write_json(os.path.join(folder, "scaling.json"),
               {"sizes": list(sizes), "batches": list(batches), "layouts": list(layouts), "cap_s": cap,
                "min_seconds": min_seconds, "density_per_km2": SCALING_DENSITY, "reference": against,
                "reference_commit": commit, "quick": quick, "cpu_count": os.cpu_count(), "rows": rows})
    _scaling_figure(rows, sizes, against, os.path.join(folder, "scaling.png"))
    return rows


def scaling_markdown(rows: list[dict], sizes, against: str | None = None) -> str:
    """The scaling table as Markdown: per row the current rates (env-steps/s), "over cap" or "refused" where
    none, the growth exponent and the time growth from N = 20 to 40; with ``against``, REF's row and the
    ratios current / REF below it."""
    def rate(value, state):
        return state if value is None else f"{value:,.1f}" if value < 100 else f"{value:,.0f}"

    def fmt(value, form):
        return "-" if value is None else form.format(value)

    head = ["layout", "backend", "network", "B", "tree", *[f"N = {n}" for n in sizes], "slope", "t(40) / t(20)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * 5 + ["---:"] * (len(sizes) + 2)) + "|"]
    for row in rows:
        entries = [("current", row["current"])] + ([(against, row["reference"])] if against else [])
        for label, entry in entries:
            cells = [rate(v, s) for v, s in zip(entry["env_steps_per_s"], entry["status"], strict=True)]
            lines.append("| " + " | ".join([row["layout"], f"`{row['backend']}`", row["network"], str(row["batch"]),
                                            str(label), *cells, fmt(entry["exponent"], "{:.2f}"),
                                            fmt(entry["time_growth_20_to_40"], "{:.1f}x")]) + " |")
        if against:
            lines.append("| " + " | ".join([row["layout"], f"`{row['backend']}`", row["network"], str(row["batch"]),
                                            "ratio", *[fmt(r, "{:.2f}x") for r in row["ratio"]], "", ""]) + " |")
    return "\n".join(lines) + "\n"


def _scaling_figure(rows: list[dict], sizes, against: str | None, path: str) -> None:
    """Time per env-step against N, log-log, one panel per (layout, B); the reference tree dashed; legends
    below the panels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter

    from train.plotting import label, plain_log_ticks

    panels = list(dict.fromkeys((r["layout"], r["batch"]) for r in rows))
    fig, axes = plt.subplots(1, max(1, len(panels)), figsize=(5.4 * max(1, len(panels)), 5.2), squeeze=False)
    for ax, (layout, batch) in zip(axes.flat, panels, strict=False):
        for k, row in enumerate(r for r in rows if (r["layout"], r["batch"]) == (layout, batch)):
            color = f"C{k % 10}"
            entries = [("", row["current"], "o-")] + ([(f" ({against})", row["reference"], "s--")] if against else [])
            for suffix, entry, style in entries:
                points = [(n, 1.0 / v) for n, v in zip(sizes, entry["env_steps_per_s"], strict=True) if v]
                if not points:
                    continue
                n, t = zip(*points, strict=True)
                slope = "" if entry["exponent"] is None else f", slope {entry['exponent']:.1f}"
                ax.loglog(n, t, style, color=color, markersize=4,
                          label=f"{row['backend']} / {row['network']}{suffix}{slope}")
        ax.set_title(f"{layout}, B = {batch}", fontsize=10)
        ax.set_xlabel(label("agents N", "agents"))
        ax.set_ylabel(label("time per env-step", "s"))
        ax.xaxis.set_major_locator(FixedLocator([n for n in sizes]))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _pos: f"{value:g}"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        plain_log_ticks(ax, "y")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6.5, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, frameon=False)
    fig.suptitle(f"coloc bench --scaling: gps_denied, random actions ({os.cpu_count()}-core CPU)")
    fig.tight_layout()
    save_figure(path, fig)
