"""``coloc bench --against REF``: the current tree and commit REF measured side by side, each tree's own
``bench_scenario`` in a subprocess with that tree first on ``sys.path`` (the package docstring)."""

from __future__ import annotations

import inspect
import json
import os
import subprocess
import sys
import tempfile

from train.bench import throughput
from train.bench.measure import BATCHES, per_second
from train.bench.throughput import _ONE_EPISODE_PREAMBLE, ONE_EPISODE, one_episode_rate
from train.io import write_json

# --- coloc bench --against REF ----------------------------------------------------------------------------------
# Run in a subprocess with a tree first on sys.path: that tree's bench_scenario over the given batches, rows to a file.
# Only names that every version of train.bench has are used (bench_scenario, SCENARIO_BATCHES, EXTRA_BENCHES), set on
# the module that defines bench_scenario (train/bench.py in older trees, train/bench/throughput.py here).
_DRIVER = """
import json, sys
spec = json.loads(sys.argv[1])
import train, train.bench as bench
home = sys.modules[bench.bench_scenario.__module__]  # the module whose settings bench_scenario reads
home.SCENARIO_BATCHES = {spec["name"]: tuple(spec["batches"])}
if not spec["extras"]:
    home.EXTRA_BENCHES = {}
rows = bench.bench_scenario(spec["name"], spec["min_seconds"], tuple(spec["batches"]))
if spec["name"] in spec["one_episode"] and not hasattr(home, "ONE_EPISODE_ROWS"):  # a tree before that row
    import coloc_env
    space = {}
    exec(spec["one_episode_source"], space)
    paper = bench.paper_actions(spec["name"])
    for batch in spec["batches"]:
        rate = space["one_episode_rate"](coloc_env, spec["name"], batch, paper, spec["min_seconds"])
        rows.append({"scenario": spec["name"], "what": spec["one_episode_label"], "batch": batch,
                     "env_steps_per_s": rate * batch, "agent_steps_per_s": rate * batch * paper.shape[0]})
with open(spec["out"], "w") as f:
    json.dump({"source": train.__file__, "rows": rows}, f)
"""


def repository_root() -> str:
    """The git work tree this package is imported from."""
    here = os.path.dirname(os.path.abspath(__file__))
    return subprocess.run(["git", "-C", here, "rev-parse", "--show-toplevel"], check=True, capture_output=True,
                          text=True).stdout.strip()


def export_commit(ref: str, folder: str, root: str | None = None) -> str:
    """Write the tree of commit ``ref`` into ``folder`` (``git archive``: the repository is only read);
    returns the full commit id."""
    root = root or repository_root()
    commit = subprocess.run(["git", "-C", root, "rev-parse", "--verify", f"{ref}^{{commit}}"], check=True,
                            capture_output=True, text=True).stdout.strip()
    archive = subprocess.run(["git", "-C", root, "archive", "--format=tar", commit], check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", folder], input=archive, check=True)
    return commit


def bench_tree(tree: str, name: str, min_seconds: float, batches, extras: bool = True,
               timeout: float | None = None) -> dict:
    """Rows of ``tree``'s ``bench_scenario(name)`` measured in a subprocess with ``tree`` first on sys.path.

    Returns {"rows": [...], "source": the imported train/__init__.py} or {"error": text} when that tree
    cannot run the scenario (e.g. it did not exist there)."""
    with tempfile.TemporaryDirectory(prefix="coloc-bench-") as scratch:
        out = os.path.join(scratch, "rows.json")
        spec = {"name": name, "min_seconds": min_seconds, "batches": list(batches), "extras": extras, "out": out,
                "one_episode": list(throughput.ONE_EPISODE_ROWS), "one_episode_label": ONE_EPISODE,
                "one_episode_source": _ONE_EPISODE_PREAMBLE + inspect.getsource(per_second)
                + inspect.getsource(one_episode_rate)}
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([tree, os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep),
                   MPLBACKEND="Agg")
        try:
            done = subprocess.run([sys.executable, "-c", _DRIVER, json.dumps(spec)], cwd=tree, env=env,
                                  capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            return {"error": f"timed out after {timeout} s"}
        if done.returncode != 0 or not os.path.exists(out):
            lines = (done.stderr or done.stdout).strip().splitlines()
            return {"error": lines[-1] if lines else f"exit {done.returncode}"}
        with open(out) as f:
            result = json.load(f)
    if not os.path.abspath(result["source"]).startswith(os.path.abspath(tree) + os.sep):
        raise RuntimeError(f"the bench of {tree} imported {result['source']} instead")
    return result


def compare_rows(current: list[dict], reference: list[dict]) -> list[dict]:
    """Join rows on (scenario, what, batch): both env-step rates and the ratio current / reference."""
    ref = {(r["scenario"], r["what"], r["batch"]): r["env_steps_per_s"] for r in reference}
    cur = {(r["scenario"], r["what"], r["batch"]): r["env_steps_per_s"] for r in current}
    keys = list(cur) + [k for k in ref if k not in cur]
    return [{"scenario": k[0], "what": k[1], "batch": k[2], "reference_env_steps_per_s": ref.get(k),
             "current_env_steps_per_s": cur.get(k),
             "ratio": cur[k] / ref[k] if k in cur and k in ref and ref[k] > 0 else None} for k in keys]


def _best(rounds: list[list[dict]]) -> list[dict]:
    """Per (scenario, what, batch) the row with the highest rate over the rounds (the least disturbed one)."""
    best: dict[tuple, dict] = {}
    for rows in rounds:
        for row in rows:
            key = (row["scenario"], row["what"], row["batch"])
            if key not in best or row["env_steps_per_s"] > best[key]["env_steps_per_s"]:
                best[key] = row
    return list(best.values())


def run_against(out: str, ref: str, quick: bool = False, scenarios: list[str] | None = None,
                min_seconds: float | None = None, extras: bool = True, rounds: int = 2) -> list[dict]:
    """``coloc bench --against REF``: the current tree and commit REF measured side by side (see the module doc).

    Per scenario the two trees are measured in ``rounds`` alternating rounds (current, REF, REF, current, ...:
    a load that drifts during the run affects both alike) and each row keeps its best rate."""
    from rich.console import Console
    from rich.table import Table

    import coloc_env

    min_seconds = min_seconds if min_seconds is not None else (0.15 if quick else 1.5)
    names = scenarios or list(coloc_env.SCENARIOS)
    root = repository_root()
    console = Console()
    rows: list[dict] = []
    errors: dict[str, dict[str, str]] = {}
    with tempfile.TemporaryDirectory(prefix="coloc-against-") as folder:
        commit = export_commit(ref, folder, root)
        with console.status("benchmarking") as status:
            for name in names:
                batches = throughput.SCENARIO_BATCHES.get(name, BATCHES)
                measured: dict[str, list[list[dict]]] = {"current": [], ref: []}
                for k in range(rounds):
                    order = [("current", root), (ref, folder)]
                    for label, tree in order if k % 2 == 0 else order[::-1]:
                        status.update(f"benchmarking {name} ({label}, round {k + 1} of {rounds})")
                        result = bench_tree(tree, name, min_seconds, batches, extras)
                        if "error" in result:
                            errors.setdefault(name, {})[label] = result["error"]
                        measured[label].append(result.get("rows", []))
                rows += compare_rows(_best(measured["current"]), _best(measured[ref]))
    table = Table(title=f"coloc bench --against {ref} ({commit[:7]}): env-steps/s, ratio = current / {ref}")
    for column in ("scenario", "what", "B", ref, "current", "ratio"):
        table.add_column(column, justify="left" if column in ("scenario", "what") else "right")

    def rate(value):
        return "-" if value is None else f"{value:,.1f}" if value < 100 else f"{value:,.0f}"

    for row in rows:
        table.add_row(row["scenario"], row["what"], str(row["batch"]), rate(row["reference_env_steps_per_s"]),
                      rate(row["current_env_steps_per_s"]), "-" if row["ratio"] is None else f"{row['ratio']:.2f}x")
    console.print(table)
    for name, failed in errors.items():
        for label, text in failed.items():
            console.print(f"{name} ({label}): not measured: {text}")
    write_json(os.path.join(out, "bench", "against.json"),
               {"reference": ref, "reference_commit": commit, "quick": quick, "min_seconds": min_seconds,
                "rounds": rounds, "cpu_count": os.cpu_count(), "rows": rows, "errors": errors})
    return rows
