"""The ``coloc`` command line: reproduce | train | evaluate | bench | list."""

from __future__ import annotations

import argparse
import os
import sys

PAPERS = {"fu2017": "lossy_fusion", "zhao2020": "bandwidth_fusion", "wang2019": "relay_ukf", "gao2016": "nlos_horizon",
          "wan2014": "gps_denied_nbp"}
SCENARIO_TO_PAPER = {v: k for k, v in PAPERS.items()}


def _seed_range(text: str) -> list[int]:
    if ".." in text:
        a, b = text.split("..")
        if int(b) < int(a):
            raise argparse.ArgumentTypeError(f"--seeds A..B needs A <= B, got {text}")
        return list(range(int(a), int(b) + 1))
    return [int(text)]


def _positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="coloc", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    rep = sub.add_parser("reproduce", help="reproduce a paper's figures and claims")
    rep.add_argument("paper", choices=[*PAPERS, "all", "mrclam"],
                     help="a paper, all of them, or mrclam (real UTIAS MRCLAM data; needs --data, not part of all)")
    rep.add_argument("--runs", type=_positive, default=None,
                     help="Monte Carlo runs (default: the paper module's RUNS, or QUICK_RUNS with --quick)")
    rep.add_argument("--seed", type=int, default=0)
    rep.add_argument("--out", default="results")
    rep.add_argument("--quick", action="store_true", help="fewer Monte Carlo runs")
    rep.add_argument("--executor", choices=["local", "ray"], default="local")
    rep.add_argument("--address", default=None, help="Ray cluster address (default: a local Ray)")
    rep.add_argument("--data", default=None,
                     help="mrclam: an MRCLAM dataset folder (default: $COLOC_MRCLAM_DATA)")

    tr = sub.add_parser("train", help="train a shared PPO policy with stable-baselines3")
    tr.add_argument("scenario")
    tr.add_argument("--timesteps", type=_positive, default=200_000)
    group = tr.add_mutually_exclusive_group()
    group.add_argument("--seed", type=int, default=None)
    group.add_argument("--seeds", type=_seed_range, default=None, help="A..B")
    tr.add_argument("--vec", choices=["native", "supersuit"], default="native",
                    help="native: coloc_env.vector_env (one batched numpy call); supersuit: SuperSuit's concat")
    tr.add_argument("--out", default="results/train")
    tr.add_argument("--executor", choices=["local", "ray"], default="local")
    tr.add_argument("--address", default=None, help="Ray cluster address (default: a local Ray)")
    tr.add_argument("--tensorboard", action="store_true")
    tr.add_argument("--curve-points", type=int, default=10, help="validation points of the learning curve (0: none)")

    ev = sub.add_parser("evaluate", help="evaluate a policy over seeded episodes")
    ev.add_argument("scenario")
    ev.add_argument("--policy", default="paper",
                    help="paper | random | greedy | oracle_* | PATH.zip | all (every named policy and the "
                         "trained models under --models)")
    ev.add_argument("--models", default="results/train", help="where --policy all looks for SCENARIO/seed*/model.zip")
    ev.add_argument("--episodes", type=_positive, default=100)
    ev.add_argument("--stochastic", action="store_true",
                    help="trained models sample their actions (seeded) instead of taking the most likely")
    ev.add_argument("--out", default="results")

    be = sub.add_parser("bench", help="throughput of estimators and envs")
    be.add_argument("--quick", action="store_true")
    be.add_argument("--out", default="results")
    be.add_argument("--scenarios", nargs="+", default=None, help="only these scenarios (default: all)")

    sub.add_parser("list", help="worlds, networks, backends, presets and the compatibility table")
    return parser


def cmd_reproduce(args) -> int:
    from rich.console import Console

    console = Console()
    papers = list(PAPERS) if args.paper == "all" else [args.paper]
    for paper in papers:
        module = __import__(f"train.reproduce.{paper}", fromlist=["run"])
        runs = args.runs or (module.QUICK_RUNS if args.quick else module.RUNS)
        extra = {"data": args.data} if paper == "mrclam" else {}
        with console.status(f"reproducing {paper} ({runs} Monte Carlo runs)") as status:
            metrics = module.run(args.out, runs=runs, seed=args.seed, quick=args.quick,
                                 executor=args.executor, address=args.address, **extra,
                                 progress=lambda msg, status=status, paper=paper: status.update(f"{paper}: {msg}"))
        console.print(f"[bold]{paper}[/bold]: wrote {os.path.join(args.out, paper)}/")
        for claim, holds in metrics.get("claims", {}).items():
            # claims may be grouped by setting (fu2017: per number of UAVs)
            for name, value in (holds.items() if isinstance(holds, dict) else [(None, holds)]):
                label = claim if name is None else f"{claim}.{name}"
                console.print(f"  {label}: {'holds' if value else '[red]does not hold[/red]'}")
    return 0


def cmd_train(args) -> int:
    import coloc_env
    from train.executor import map_tasks
    from train.training import train

    coloc_env.scenario_class(args.scenario)
    seeds = args.seeds or [0 if args.seed is None else args.seed]
    jobs = [(args.scenario, args.timesteps, s, args.out, args.vec, args.executor == "local", args.tensorboard,
             args.curve_points) for s in seeds]
    for path in map_tasks(train, jobs, args.executor, args.address):
        print(f"saved {path} (learning curve beside it)")
    return 0


def _runnable_scenarios(console) -> list[str]:
    """Every registered scenario whose default config builds here; the others are named and skipped
    (``mrclam_relay`` needs a dataset folder: ``COLOC_MRCLAM_DATA``)."""
    import coloc_env

    names = []
    for name in coloc_env.SCENARIOS:
        try:
            coloc_env.parallel_env(name).close()
        except ValueError as exc:
            console.print(f"{name}: skipped ({exc})")
            continue
        names.append(name)
    return names


def _policies_for(scenario: str, policy: str, models: str) -> list[str]:
    import glob

    import agents

    if policy != "all":
        return [policy]
    found = sorted(glob.glob(os.path.join(models, scenario, "seed*", "model.zip")))
    return agents.available_policies(scenario) + found


def cmd_evaluate(args) -> int:
    from rich.console import Console
    from rich.progress import Progress

    import coloc_env
    from train.evaluate import evaluate_policy
    from train.leaderboard import record

    console = Console()
    scenarios = _runnable_scenarios(console) if args.scenario == "all" else [args.scenario]
    for scenario in scenarios:
        coloc_env.scenario_class(scenario)
        for policy in _policies_for(scenario, args.policy, args.models):
            with Progress(console=console, transient=True) as bar:
                task = bar.add_task(f"{scenario} / {policy}", total=args.episodes)
                result = evaluate_policy(scenario, policy, args.episodes,
                                         progress=lambda task=task: bar.advance(task),
                                         stochastic=args.stochastic and policy.endswith(".zip"))
            path = record(result, args.out, SCENARIO_TO_PAPER.get(scenario, scenario))
            console.print(
                f"{scenario} {policy}: mean realized cost {result['mean_cost']:.3f} "
                f"+- {result['ci95']:.3f} (95 %, {args.episodes} episodes); with the initial term "
                f"{result['initial_cost']:.2f}: {result['paper_cost']:.3f}; "
                f"communication {result['communication_per_step']:.2f} per step -> {path}")
    return 0


def cmd_bench(args) -> int:
    from rich.console import Console

    import coloc_env
    from train.bench import run

    for name in args.scenarios or []:
        coloc_env.scenario_class(name)
    run(args.out, quick=args.quick, scenarios=args.scenarios or _runnable_scenarios(Console()))
    return 0


def cmd_list(args) -> int:
    """Print the parts, the presets and one line per (world, network, backend): ok, or why not."""
    import coloc_env

    print("worlds:   " + ", ".join(coloc_env.WORLDS))
    print("networks: " + ", ".join(coloc_env.NETWORKS))
    print("backends: " + ", ".join(coloc_env.BACKENDS))
    print("presets:")
    for name, spec in coloc_env.PRESETS.items():
        parts = [getattr(spec, part).name if getattr(spec, part) is not None else "(binding only)"
                 for part in ("world", "network", "backend")]
        print(f"  {name:<18} {' / '.join(parts)}")
    rows = coloc_env.compatibility()
    print(f"compositions ({sum(r['ok'] for r in rows)} of {len(rows)} compatible):")
    width = max(len(f"{r['world']}/{r['network']}/{r['backend']}") for r in rows)
    for r in rows:
        label = f"{r['world']}/{r['network']}/{r['backend']}"
        print(f"  {label:<{width}}  {'ok' if r['ok'] else 'no: ' + r['reason']}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    handlers = {"reproduce": cmd_reproduce, "train": cmd_train, "evaluate": cmd_evaluate, "bench": cmd_bench,
                "list": cmd_list}
    try:
        return handlers[args.command](args)
    except ValueError as exc:
        print(f"coloc {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
