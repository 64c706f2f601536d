"""One table for all backends: RMSE, the three bounds, efficiencies and NEES of every generative composition.

    python -m train.bounds_table [--episodes 4] [--seed 0] [--jobs 1] [--out results/bounds_table] [--fresh]
                                 [--update-docs]

For every compatible composition of the generative worlds (``coloc_env.bounds.models.generative_worlds``) at
its defaults, under the policy ``always``: E seeded episodes (episode e reset with seed S + e, one batched
core, ``train.study.run_cell``), ``coloc_env.pcrb`` on the same episodes, and one row:

| column          | meaning                                                                             |
|-----------------|-------------------------------------------------------------------------------------|
| rmse            | sqrt of the mean squared 2-D position error over episodes, steps and agents (m)      |
| centralized, delivered, local | sqrt of each bound's mean over steps and agents (m; docs/bounds.md)   |
| eff_c           | rmse / centralized: how far estimator and network together are from the best         |
| eff_d           | rmse / delivered: how far the estimator is from what its delivered messages allow    |
| nees            | the mean 2-D position NEES (2 where the covariance is honest; "-" without one)       |
| in band         | the share of (step, agent) whose NEES averaged over the E episodes lies in the       |
|                 | chi^2(2E)/E 95 % band (``train.study.nees_metrics``)                                 |
| capped          | for an information-set bound, the share of the delivered readings that arrived more  |
|                 | than ``lag_cap`` steps after they were taken (credited earlier: the bound is lower   |
|                 | than the exact one there); "-" for the other delivered bounds                        |

Each row is kept as ``OUT/rows/WORLD_NETWORK_BACKEND.json`` (with its settings; a rerun with the same settings
reuses it, so an interrupted run resumes; ``--fresh`` computes every row again, as after a change to a backend),
the table is written to ``OUT/bounds_table.md`` and
``OUT/rows.json``, and ``--update-docs`` replaces the generated tables in docs/bounds.md and
docs/consistency.md (between their ``bounds-table`` markers). ``--jobs`` runs compositions in parallel
processes (the numbers do not depend on it).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed

import numpy as np

import coloc_env
from coloc_env.bounds.models import generative_worlds
from coloc_env.config import BadInput
from train.io import write_json, write_text
from train.study import cell_metrics, run_cell

POLICY = "always"
BEGIN, END = "<!-- bounds-table: begin -->", "<!-- bounds-table: end -->"


def compositions() -> list[str]:
    """Every compatible WORLD/NETWORK/BACKEND of the generative worlds, in ``compatibility()`` order."""
    worlds = set(generative_worlds())
    return [f"{r['world']}/{r['network']}/{r['backend']}" for r in coloc_env.compatibility()
            if r["ok"] and r["world"] in worlds]


def row(name: str, episodes: int, seed: int) -> dict:
    """The table's row of one composition (module docstring), with its wall time in seconds."""
    start = time.perf_counter()
    spec = coloc_env.composition_named(name)
    result = run_cell(spec, POLICY, episodes, seed, batched=True)
    bounds = coloc_env.pcrb(spec, episodes=episodes, seed=seed, policy=POLICY)
    metrics = cell_metrics(result, bounds)
    delivered = metrics["pcrb_delivered"]
    return {"name": name, "episodes": episodes, "seed": seed, "policy": POLICY,
            "rmse": metrics["rmse"], "centralized": metrics["pcrb_centralized"], "delivered": delivered,
            "local": metrics["pcrb_local"], "eff_c": metrics["efficiency"],
            "eff_d": metrics["rmse"] / delivered if delivered else None,
            "delivered_capped": bounds.get("delivered_capped"),
            "nees": metrics["nees"], "nees_in_band": metrics["nees_in_band"],
            "seconds": time.perf_counter() - start}


def _number(value, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "-"
    return f"{value:.{digits}g}"


def table(rows: list[dict]) -> str:
    lines = ["| composition | RMSE (m) | centralized | delivered | local | eff_c | eff_d | NEES | in band | capped |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        band = "-" if r["nees_in_band"] is None else f"{100 * r['nees_in_band']:.0f} %"
        capped = "-" if r.get("delivered_capped") is None else f"{100 * r['delivered_capped']:.0f} %"
        lines.append(f"| `{r['name']}` | {_number(r['rmse'])} | {_number(r['centralized'])} | "
                     f"{_number(r['delivered'])} | {_number(r['local'])} | {_number(r['eff_c'])} | "
                     f"{_number(r['eff_d'])} | {_number(r['nees'])} | {band} | {capped} |")
    return "\n".join(lines) + "\n"


def command(episodes: int, seed: int) -> str:
    return f"python -m train.bounds_table --episodes {episodes} --seed {seed} --fresh --update-docs"


def replace_generated(path: str, text: str) -> None:
    """The part of ``path`` between the markers replaced by ``text``; refused where the markers are missing."""
    with open(path) as fh:
        content = fh.read()
    if BEGIN not in content or END not in content:
        raise BadInput(f"{path}: no {BEGIN} ... {END} markers to replace")
    head, rest = content.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    write_text(path, f"{head}{BEGIN}\n{text}{END}{tail}")


def _cached(path: str, episodes: int, seed: int) -> dict | None:
    try:
        with open(path) as fh:
            data = json.load(fh)
    except (OSError, ValueError):
        return None
    return data if (data.get("episodes"), data.get("seed"), data.get("policy")) == (episodes, seed, POLICY) else None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m train.bounds_table", description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=4, help="E episodes per composition, 2..1000")
    parser.add_argument("--seed", type=int, default=0, help="S: episode e is seeded S + e, >= 0")
    parser.add_argument("--jobs", type=int, default=1, help="parallel processes, 1..64")
    parser.add_argument("--out", default=os.path.join("results", "bounds_table"), help="output folder")
    parser.add_argument("--only", default=None, help="comma-separated compositions (default: every one)")
    parser.add_argument("--fresh", action="store_true", help="compute every row again (no reuse of OUT/rows)")
    parser.add_argument("--update-docs", action="store_true",
                        help="replace the generated tables of docs/bounds.md and docs/consistency.md")
    args = parser.parse_args(argv)
    if not 2 <= args.episodes <= 1000:
        parser.error(f"--episodes must be in [2, 1000], got {args.episodes}")
    if args.seed < 0:
        parser.error(f"--seed must be >= 0, got {args.seed}")
    if not 1 <= args.jobs <= 64:
        parser.error(f"--jobs must be in [1, 64], got {args.jobs}")
    names = compositions()
    if args.only:
        wanted = args.only.split(",")
        unknown = sorted(set(wanted) - set(names))
        if unknown:
            parser.error(f"--only: not a compatible generative composition: {unknown}")
        names = [n for n in names if n in wanted]
    rows_dir = os.path.join(args.out, "rows")
    os.makedirs(rows_dir, exist_ok=True)
    paths = {n: os.path.join(rows_dir, n.replace("/", "_") + ".json") for n in names}
    rows = {n: None if args.fresh else _cached(paths[n], args.episodes, args.seed) for n in names}
    todo = [n for n in names if rows[n] is None]
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    start = time.perf_counter()
    with Progress(TextColumn("bounds table {task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn()) as bar:
        task = bar.add_task("", total=len(names), completed=len(names) - len(todo))

        def done(name: str, result: dict) -> None:
            rows[name] = result
            write_json(paths[name], result)
            bar.update(task, advance=1, description=name)

        if args.jobs == 1:
            for name in todo:
                done(name, row(name, args.episodes, args.seed))
        else:
            with ProcessPoolExecutor(args.jobs) as pool:
                futures = {pool.submit(row, name, args.episodes, args.seed): name for name in todo}
                for future in as_completed(futures):
                    done(futures[future], future.result())
    ordered = [rows[n] for n in names]
    text = table(ordered)
    write_json(os.path.join(args.out, "rows.json"), ordered)
    write_text(os.path.join(args.out, "bounds_table.md"), text)
    elapsed = time.perf_counter() - start
    print(f"wrote {args.out}/bounds_table.md ({len(ordered)} compositions, {len(todo)} computed in {elapsed:.0f} s; "
          f"{sum(r['seconds'] for r in ordered):.0f} s of row time in all)")
    if args.update_docs:
        generated = (f"Generated by `{command(args.episodes, args.seed)}` (policy `always`, defaults, episodes "
                     f"seeded {args.seed} + e, e < {args.episodes}; the rows took "
                     f"{sum(r['seconds'] for r in ordered):.0f} s of wall time in all):\n\n" + text)
        for path in (os.path.join("docs", "bounds.md"), os.path.join("docs", "consistency.md")):
            replace_generated(path, generated)
        print("updated docs/bounds.md and docs/consistency.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
