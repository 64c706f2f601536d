"""``make demo``: every paper reproduced in quick mode and a short PPO run per simulated scenario, on both cores.

``python -m train.demo [--out results] [--coloc COMMAND]`` runs the stages below in two lanes side by side,
one process per lane at a time, each single-threaded (BLAS, numba and torch: two lanes of one thread fill
two cores without oversubscribing them; numbers do not depend on the thread count beyond the last bits
of a BLAS sum). Each stage is a ``coloc`` command; its output goes to ``OUT/.demo_lane<L>.log`` and this
process prints one line as each stage starts and ends. Each stage also appends ``START END STAGE``
(Unix seconds) to ``OUT/.demo_times``, which ``train.demo_summary`` reads, then prints the summary.

The lanes are balanced by the stage times of a quiet 2-core machine (the training budgets, each preset's
``DEMO_RUN`` in train/hyperparams/<preset>.py, are reduced: one seed, a few rollouts; the full budgets are in
docs/learning.md;
so are the evaluation episodes of the two slow scenarios). Stages of one lane run in order;
a failed stage stops its lane (the other lane goes on), and the run ends with status 1 and the tail of
the failed stage's log. ``coloc evaluate`` merges its rows under a lock (``train.leaderboard.record``),
so the two lanes may write the same ``leaderboard.md``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import threading
import time

from train import hyperparams

TIMES = ".demo_times"
SINGLE_THREAD = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                                         "NUMBA_NUM_THREADS")}


def _scenario_stages(scenario: str, out: str) -> list[tuple[str, list[str]]]:
    steps, episodes = hyperparams.setting(scenario, "DEMO_RUN")  # (training timesteps, evaluation episodes)
    models = os.path.join(out, "train")
    return [
        (f"train {scenario} ({steps} timesteps)",
         ["train", scenario, "--timesteps", str(steps), "--seed", "0", "--out", models, "--curve-points", "2"]),
        (f"evaluate {scenario} ({episodes} episodes)",
         ["evaluate", scenario, "--policy", "all", "--models", models, "--episodes", str(episodes), "--out", out]),
    ]


def lanes(out: str) -> list[list[tuple[str, list[str]]]]:
    """The two lanes: (stage name, ``coloc`` arguments) in the order each lane runs them. A preset with a
    ``DEMO_RUN`` that the balanced lanes below do not name is trained and evaluated at the end of the first."""
    balanced = [
        [("reproduce all --quick", ["reproduce", "all", "--quick", "--out", out]),
         *_scenario_stages("bandwidth_fusion", out), *_scenario_stages("relay_ukf", out)],
        [*_scenario_stages("nlos_horizon", out),
         ("evaluate nlos_horizon constant:6",
          ["evaluate", "nlos_horizon", "--policy", "constant:6", "--episodes", "6", "--out", out]),
         *_scenario_stages("gps_denied_nbp", out), *_scenario_stages("lossy_fusion", out)],
    ]
    named = {arguments[1] for lane in balanced for _, arguments in lane if arguments[0] == "train"}
    for scenario in hyperparams.presets_declaring("DEMO_RUN"):
        if scenario not in named:
            balanced[0] += _scenario_stages(scenario, out)
    return balanced


def _clock(seconds: float) -> str:
    return f"{int(seconds) // 60}:{int(seconds) % 60:02d}"


def run(out: str, coloc: list[str]) -> int:
    """Runs both lanes to the end; 0 when every stage passed."""
    os.makedirs(out, exist_ok=True)
    times = os.path.join(out, TIMES)
    if os.path.exists(times):
        os.remove(times)
    env = {**os.environ, "MPLBACKEND": "Agg", **SINGLE_THREAD}
    lock, failed, began = threading.Lock(), [], time.time()

    def say(line: str) -> None:
        with lock:
            print(f"[{_clock(time.time() - began)}] {line}", flush=True)

    def lane(index: int, stages) -> None:
        log = os.path.join(out, f".demo_lane{index}.log")
        with open(log, "w") as handle:
            for name, arguments in stages:
                say(f"lane {index}: {name} ...")
                start = time.time()
                handle.write(f"\n$ coloc {' '.join(arguments)}\n")
                handle.flush()
                code = subprocess.run([*coloc, *arguments], stdout=handle, stderr=subprocess.STDOUT, env=env,
                                      stdin=subprocess.DEVNULL).returncode
                end = time.time()
                if code != 0:
                    failed.append((name, code, log))
                    say(f"lane {index}: {name} FAILED (exit {code}); this lane stops, see {log}")
                    return
                with lock, open(times, "a") as stamp:
                    stamp.write(f"{int(start)} {int(end)} {name}\n")
                say(f"lane {index}: {name} done in {_clock(end - start)}")

    threads = [threading.Thread(target=lane, args=(i + 1, stages)) for i, stages in enumerate(lanes(out))]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for name, code, log in failed:
        with open(log) as handle:
            tail = handle.read().splitlines()[-30:]
        print(f"\n{name} failed with exit status {code}; the end of {log}:\n" + "\n".join(tail), file=sys.stderr)
    return 1 if failed else 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m train.demo", description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results", help="the folder every stage writes under")
    parser.add_argument("--coloc", default=None, help="the coloc command (default: this Python's -m train.cli)")
    args = parser.parse_args(argv)
    coloc = args.coloc.split() if args.coloc else [sys.executable, "-m", "train.cli"]
    code = run(args.out, coloc)
    from train import demo_summary

    demo_summary.main([args.out])
    return code


if __name__ == "__main__":
    sys.exit(main())


def __getattr__(name: str):
    """The table of demo budgets this module held before each preset's hyperparameters declared them
    (deprecated)."""
    from coloc_env.config import module_names  # imported here: `coloc --help` imports no part

    return module_names(__name__, {"DEMO_RUNS": lambda: hyperparams.presets_declaring("DEMO_RUN")},
                        deprecated={"DEMO_RUNS": "DEMO_RUN in train/hyperparams/<preset>.py"}, stacklevel=3)(name)
