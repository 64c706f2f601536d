"""The ``coloc`` command line: reproduce | train | evaluate | bench | study | list."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys

PAPERS = {"fu2017": "lossy_fusion", "zhao2020": "bandwidth_fusion", "wang2019": "relay_ukf", "gao2016": "nlos_horizon",
          "wan2014": "gps_denied_nbp"}
SCENARIO_TO_PAPER = {v: k for k, v in PAPERS.items()}


INTERRUPTED = 130  # the shell's exit status of a process ended by SIGINT (128 + 2)
INTERNAL_ERROR = 1  # a failure that is not the input's: a one-line report and a request to report it
BAD_INPUT = 2  # argparse's status for a bad flag; the same for every refused input

# The ranges of the counts and seeds the flags take (each flag's help states its own).
MAX_RUNS = 100_000  # --runs, --episodes
MAX_TIMESTEPS = 10**10  # --timesteps
MAX_SEED = 10**9  # --seed, and each seed of --seeds
MAX_SEEDS = 1_000  # seeds in one --seeds A..B
MAX_CURVE_POINTS = 1_000
MAX_HORIZON = 1_000_000


def _integer(text: str) -> int | None:
    """``text`` as an integer (decimal digits, an optional sign), None for anything else (1.5, 1e3, abc)."""
    text = text.strip()
    body = text[1:] if text[:1] in "+-" else text
    return int(text) if body.isascii() and body.isdigit() and len(body) <= 40 else None


def _count(low: int, high: int):
    """An argparse type: an integer in [low, high], refused in one line naming the range."""
    def parse(text: str) -> int:
        value = _integer(text)
        if value is None or not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must be an integer in [{low}, {high}], got {text!r}")
        return value
    parse.__name__ = f"integer in [{low}, {high}]"
    return parse


_positive = _count(1, MAX_RUNS)
_seed = _count(0, MAX_SEED)


def _out_folder(text: str) -> str:
    """An argparse type: a non-empty path (an empty --out would write into the current folder)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"must be a non-empty folder path, got {text!r}")
    return text


def _seed_range(text: str) -> list[int]:
    """``A..B`` (both included) or one seed ``S``, each in [0, MAX_SEED] and at most MAX_SEEDS of them; any other
    form is refused naming the ``A..B`` form."""
    start, dots, stop = text.partition("..")
    bounds = [_integer(start), _integer(stop)] if dots else [_integer(text)] * 2
    if None in bounds:
        raise argparse.ArgumentTypeError(f"expected A..B (e.g. 0..2, both included) or one integer S, "
                                         f"got {text!r}")
    first, last = bounds
    if first > last:
        raise argparse.ArgumentTypeError(f"A..B needs A <= B, got {text!r}")
    if first < 0 or last > MAX_SEED:
        raise argparse.ArgumentTypeError(f"seeds must be in [0, {MAX_SEED}], got {text!r}")
    if last - first + 1 > MAX_SEEDS:
        raise argparse.ArgumentTypeError(f"at most {MAX_SEEDS} seeds in one A..B, got {last - first + 1} ({text!r})")
    return list(range(first, last + 1))


def _number(text: str) -> float | None:
    """``text`` as a finite float (``0.5``, ``1e-2``), None for anything else (nan, inf, abc, an empty string)."""
    import math

    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _cost_range(text: str) -> tuple[float, float] | str:
    """``LO,HI`` with 0 <= LO <= HI <= the largest cost (log-uniform for LO > 0), or ``"none"`` (a fixed cost);
    anything else is refused naming the form and the range."""
    from coloc_env.composition import COST_LIMIT

    if text.strip().lower() == "none":
        return "none"
    parts = text.split(",")
    values = [_number(p) for p in parts] if len(parts) == 2 else [None]
    if None in values or not 0 <= values[0] <= values[1] <= COST_LIMIT:
        raise argparse.ArgumentTypeError(f"must be LO,HI with 0 <= LO <= HI <= {COST_LIMIT:g} (e.g. 0.05,50; "
                                         f"log-uniform for LO > 0, uniform on [0, HI] for LO = 0) or none, "
                                         f"got {text!r}")
    return values[0], values[1]


def _costs(text: str) -> list[float]:
    """``C1,C2,...``: one or more distinct costs, each in [0, the largest cost]."""
    from coloc_env.composition import COST_LIMIT

    values = [_number(p) for p in text.split(",")]
    if None in values or not all(0 <= v <= COST_LIMIT for v in values):
        raise argparse.ArgumentTypeError(f"must be C1,C2,... with each cost in [0, {COST_LIMIT:g}] (e.g. 0.1,1,10), "
                                         f"got {text!r}")
    if len(set(values)) != len(values):
        raise argparse.ArgumentTypeError(f"must not repeat a cost, got {text!r}")
    return values


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Every option's default in its help, except where there is none to show (None, a flag's False);
    descriptions and epilogs keep their line breaks (the tables of ``coloc study --help``)."""

    def _get_help_string(self, action):
        if action.default is None or action.default is False:
            return action.help
        return super()._get_help_string(action)


def _scenarios_help() -> str:
    import coloc_env

    return ("one of: " + ", ".join(coloc_env.SCENARIOS) + "; or a composition's name WORLD/NETWORK/BACKEND "
            "(coloc list), e.g. circles/broadcast/ukf_ccl")


def _result_key(scenario: str) -> str:
    """The folder of a scenario's leaderboard under OUT: the paper key of a preset (zhao2020), a composition's
    name with '_' for '/' (circles_broadcast_ukf_ccl)."""
    return SCENARIO_TO_PAPER.get(scenario, scenario.replace("/", "_"))


def _policies_epilog() -> str:
    """The policy names ``--policy`` accepts, per preset, from the registry (agents.available_policies)."""
    import agents
    import coloc_env
    from agents import generic

    lines = ["policies (--policy NAME, or NAME:VARIANT where a policy takes one: paper:T2P3 for bandwidth_fusion,",
             "constant:12 and paper:smoothed for nlos_horizon):"]
    width = max(len(name) for name in coloc_env.SCENARIOS)
    for name in coloc_env.SCENARIOS:
        lines.append(f"  {name:<{width}}  {', '.join(agents.available_policies(name))}")
    lines.append(f"  {'compositions':<{width}}  {', '.join(['random', *generic.POLICIES])}")
    lines.append("  any scenario: PATH.zip (a model saved by coloc train), or all (every name above and")
    lines.append("                the models under --models)")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="coloc", description=__doc__, formatter_class=_HelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    scenarios = _scenarios_help()
    papers = ", ".join(f"{paper} ({scenario})" for paper, scenario in PAPERS.items())

    rep = sub.add_parser("reproduce", help="reproduce a paper's figures and claims", formatter_class=_HelpFormatter,
                         description=f"Reproduce a paper's figures and claims into OUT/PAPER/. Papers: {papers}.")
    rep.add_argument("paper", choices=[*PAPERS, "all", "mrclam"],
                     help="a paper, all of them, or mrclam (real UTIAS MRCLAM data; needs --data, not part of all)")
    rep.add_argument("--runs", type=_positive, default=None,
                     help=f"Monte Carlo runs, 1..{MAX_RUNS} (default: the paper module's RUNS, or QUICK_RUNS with "
                          "--quick)")
    rep.add_argument("--seed", type=_seed, default=0, help=f"seed of the first Monte Carlo run, 0..{MAX_SEED}")
    rep.add_argument("--out", type=_out_folder, default="results", help="writes OUT/PAPER/")
    rep.add_argument("--quick", action="store_true", help="fewer Monte Carlo runs")
    rep.add_argument("--executor", choices=["local", "ray"], default="local", help="where the runs execute")
    rep.add_argument("--address", default=None, help="Ray cluster address (default: a local Ray)")
    rep.add_argument("--data", default=None,
                     help="mrclam: an MRCLAM dataset folder (default: $COLOC_MRCLAM_DATA)")

    tr = sub.add_parser("train", help="train a shared PPO policy with stable-baselines3",
                        formatter_class=_HelpFormatter)
    tr.add_argument("scenario", help=scenarios)
    tr.add_argument("--timesteps", type=_count(1, MAX_TIMESTEPS), default=None,
                    help=f"PPO timesteps (agent transitions), 1..{MAX_TIMESTEPS} (default: the scenario's TIMESTEPS in "
                         "train/hyperparams/<scenario>.py, 200000 where it sets none)")
    group = tr.add_mutually_exclusive_group()
    group.add_argument("--seed", type=_seed, default=None, help="one training seed S (default: 0)")
    group.add_argument("--seeds", type=_seed_range, default=None, metavar="A..B",
                       help=f"training seeds A to B, both included (e.g. 0..2: seeds 0, 1 and 2; at most "
                            f"{MAX_SEEDS})")
    tr.add_argument("--vec", choices=["native", "supersuit"], default="native",
                    help="native: coloc_env.vector_env (one batched numpy call); supersuit: SuperSuit's concat")
    tr.add_argument("--out", type=_out_folder, default="results/train", help="writes OUT/SCENARIO/seedS/")
    tr.add_argument("--executor", choices=["local", "ray"], default="local", help="where the seeds train")
    tr.add_argument("--address", default=None, help="Ray cluster address (default: a local Ray)")
    tr.add_argument("--tensorboard", action="store_true", help="also write TensorBoard logs (OUT/.../tb)")
    tr.add_argument("--curve-points", type=_count(0, MAX_CURVE_POINTS), default=10,
                    help=f"validation points of the learning curve, 0..{MAX_CURVE_POINTS} (0: none)")
    tr.add_argument("--cost-range", type=_cost_range, default=None, metavar="LO,HI",
                    help="cost-conditioned training: each episode draws its communication cost from [LO, HI] "
                         "(log-uniform for LO > 0; 0 <= LO <= HI <= 1e12) and the agents observe it; none: the fixed "
                         "communication_cost (default: COST_RANGE of train/hyperparams/<scenario>.py, none where it "
                         "sets none)")
    tr.add_argument("--paper-entries", default=None, metavar="NAME",
                    help="action entries the model leaves to the paper's rule (relay_ukf: partner, the paper's random "
                         "ranging partner; mrclam_relay: measurement, the paper's measurement choice); none: the model "
                         "decides every entry (default: PAPER_ENTRIES of "
                         "train/hyperparams/<scenario>.py, none where it sets none)")

    ev = sub.add_parser("evaluate", help="evaluate a policy over seeded episodes", formatter_class=_HelpFormatter,
                        epilog=_policies_epilog())
    ev.add_argument("scenario", help=f"{scenarios}, or all")
    ev.add_argument("--policy", default="paper",
                    help="a policy name of the scenario (listed below), PATH.zip, or all (every realizable policy, "
                         "the bounds, the reference filters and the trained models under --models)")
    ev.add_argument("--models", default="results/train", help="where --policy all looks for SCENARIO/seed*/model.zip")
    ev.add_argument("--episodes", type=_count(2, MAX_RUNS), default=100,
                    help=f"seeded evaluation episodes per policy, 2..{MAX_RUNS} (a confidence interval needs 2)")
    ev.add_argument("--stochastic", action="store_true",
                    help="trained models sample their actions (seeded) instead of taking the most likely "
                         "(default: as each model's model.json records; a model trained with ACTIONS = "
                         "'sampled' samples)")
    ev.add_argument("--costs", type=_costs, default=None, metavar="C1,C2,...",
                    help="evaluate each trained model at each communication cost (an env built with "
                         "communication_cost=C, which its observation carries), one row 'PATH.zip @ cost=C' per cost "
                         "(default: a cost-conditioned model at its range's median, any other at its training cost)")
    ev.add_argument("--out", type=_out_folder, default="results",
                    help="records into OUT/PAPER/leaderboard.json and OUT/leaderboard.md")

    be = sub.add_parser("bench", help="throughput of estimators and envs", formatter_class=_HelpFormatter)
    be.add_argument("--quick", action="store_true", help="shorter timing windows (noisier rates)")
    be.add_argument("--out", type=_out_folder, default="results", help="writes OUT/bench/")
    be.add_argument("--scenarios", nargs="+", default=None, help=f"only these scenarios (default: all); {scenarios}")
    be.add_argument("--against", metavar="REF", default=None,
                    help="also measure git commit REF (e.g. HEAD~3, a tag) side by side in the same run and print "
                         "both rates and the ratio current / REF (OUT/bench/against.json)")
    be.add_argument("--rounds", type=_count(1, 20), default=None,
                    help="with --against: alternating rounds per scenario, each row keeping its best rate (default "
                         "2; more on a machine whose speed wanders)")
    be.add_argument("--scaling", action="store_true",
                    help="env-steps/s against the number of agents N in 5..80 for every backend on gps_denied, at a "
                         "fixed area and a fixed density, B = 8 and 64, with each row's growth exponent "
                         "(OUT/bench/scaling.json, scaling.png); with --against REF side by side")
    be.add_argument("--cap", type=float, default=None, metavar="SECONDS",
                    help="with --scaling: time cap per row and tree (default 120, 60 with --quick); the sizes "
                         "not reached print 'over cap'")
    be.add_argument("--backends", nargs="+", default=None, metavar="BACKEND",
                    help="with --scaling: only the rows of these backends (default: every backend on gps_denied)")
    be.add_argument("--sizes", nargs="+", type=_count(2, 128), default=None, metavar="N",
                    help="with --scaling: these numbers of agents, 2..128 (default 5 10 20 40 80)")
    be.add_argument("--batches", nargs="+", type=_count(1, 4096), default=None, metavar="B",
                    help="with --scaling: these numbers of copies, 1..4096 (default 8 64)")

    _add_study_parser(sub)
    _add_frontier_parser(sub)

    ls = sub.add_parser("list", help="worlds, networks, backends, presets and the compatibility table",
                        formatter_class=_HelpFormatter,
                        description="The parts, the presets and one line per (world, network, backend): ok, or "
                                    "why that composition does not run. --ok and the part filters narrow the table.")
    ls.add_argument("--ok", action="store_true", help="only the compositions that run")
    ls.add_argument("--world", help="only compositions of this world")
    ls.add_argument("--network", help="only compositions over this network")
    ls.add_argument("--backend", help="only compositions with this backend")
    return parser


STUDY_EPILOG = """\
Every backend runs on the same seeded episodes (episode e: env.reset(seed=S + e), policy seeded S + e) for
each sweep value, so the backends compare on paired episodes. Writes OUT/study/NAME/ with
  metrics.json        {"world", "network", "reference", "backends": {BACKEND: {VALUE or "default":
                      {"position_error": {"mean", "ci95"}, "messages_per_step", "floats_per_step", "nees",
                      "per_episode_error"}}}, "paired": {BACKEND: {VALUE: {"mean", "ci95", "verdict"}}},
                      "config": {...}}  (errors in metres; paired = BACKEND - the first backend, per episode;
                      verdict lower | higher | no difference, from the 95 % t-interval; nees = mean of
                      e^T P^-1 e with the backend's 2x2 position covariance, null without one)
  report.md           a table per metric, the paired table, the command line
  position_error.png  error vs the swept value, one line per backend with 95 % bands (no sweep: bars)
Everything is checked before any episode runs (bad input: exit 2 and nothing written). While it runs the
folder holds an INCOMPLETE marker, removed after the last file; Ctrl-C prints one line and exits 130.
Example: coloc study --world circles --network relay --backends ukf_dcl,dead_reckoning \\
           --sweep network.loss_at_zero=0,0.2,0.4 --episodes 30
"""


def _add_study_parser(sub) -> None:
    st = sub.add_parser("study", help="compare backends on the same seeded episodes, optionally over a sweep",
                        description="Run every backend of one world and network on the same seeded episodes "
                                    "(see train/study.py).",
                        epilog=STUDY_EPILOG, formatter_class=_HelpFormatter)
    st.add_argument("--world", required=True, help="a world (coloc list), at its defaults")
    st.add_argument("--network", required=True, help="a network (coloc list), at its defaults")
    st.add_argument("--backends", required=True,
                    help="comma-separated backends, e.g. ukf_dcl,dead_reckoning; the first is the reference of "
                         "the paired differences")
    st.add_argument("--sweep", default=None, metavar="PART.FIELD=V1,V2,...",
                    help="PART in world|network|backend (for backend: every backend's field); values parse as "
                         "true/false, none, int, float (inf), else text. Without it: one run at the defaults, "
                         "key 'default'")
    st.add_argument("--policy", choices=["always", "silent", "random", "paper"], default="always",
                    help="always: every transport decision at its maximum; silent: nothing sent; random: "
                         "uniform, seeded S + e; paper: where the composition has one")
    st.add_argument("--episodes", type=_count(2, MAX_RUNS), default=30,
                    help=f"episodes per (backend, value), 2..{MAX_RUNS}")
    st.add_argument("--seed", type=_seed, default=0, help=f"S: episode e is seeded S + e, 0..{MAX_SEED}")
    st.add_argument("--horizon", type=_count(1, MAX_HORIZON), default=None,
                    help="steps per episode (compose(horizon=...); default: the world's)")
    st.add_argument("--batched", action="store_true",
                    help="run each cell's episodes as one batched core (always/silent/random only): faster, "
                         "equal to the default per-episode env run up to floating-point rounding")
    st.add_argument("--executor", choices=["local", "ray"], default="local",
                    help="ray: each (backend, value) cell is one Ray task, with the same numbers as local")
    st.add_argument("--address", default=None, help="Ray cluster address (default: a local Ray)")
    st.add_argument("--out", type=_out_folder, default="results", help="writes OUT/study/NAME/")
    st.add_argument("--name", default=None,
                    help="NAME (default: WORLD_NETWORK, plus _PART.FIELD with a sweep, e.g. "
                         "circles_relay_network.loss_at_zero)")


FRONTIER_EPILOG = """\
Writes OUT/frontier/NAME/ (NAME: the scenario, with / as __): metrics.json, report.md, frontier.png.
Every point plays the same episodes (seed S + e): always, silent, random, paper where the scenario has one,
and every event-triggered family over its knob grid (chosen on validation episodes), which form the baseline
frontier; greedy (privileged) and the models under --models are judged against it at their own message rate.
Example: coloc frontier circles/broadcast/ukf_ccl --episodes 30
"""


def _add_frontier_parser(sub) -> None:
    fr = sub.add_parser("frontier", help="error against messages: every policy family, the baseline frontier, "
                                         "the bounds", description="See train/frontier.py.",
                        epilog=FRONTIER_EPILOG, formatter_class=_HelpFormatter)
    fr.add_argument("scenario", help="a preset or a composition world/network/backend")
    fr.add_argument("--models", default=None, metavar="DIR", help="trained .zip models under DIR, judged against "
                                                                  "the frontier")
    fr.add_argument("--costs", type=_costs, default=None, metavar="C1,C2,...",
                    help="with --models: each model at each communication cost, a point 'PATH.zip @ cost=C' each")
    fr.add_argument("--episodes", type=_count(2, MAX_RUNS), default=30,
                    help=f"paired episodes per point, 2..{MAX_RUNS}")
    fr.add_argument("--bound-episodes", type=_positive, default=None, metavar="K",
                    help="each point's bounds on its first K episodes, 1..100000 (default: 8; a bound replays "
                         "its episodes one env at a time)")
    fr.add_argument("--quick", action="store_true", help="a first look: three knobs per family")
    fr.add_argument("--seed", type=_seed, default=None,
                    help="S: episode e is seeded S + e (default: the evaluation seeds 10^6 + e)")
    fr.add_argument("--executor", choices=["local", "ray"], default="local",
                    help="ray: each point is one Ray task, with the same numbers as local")
    fr.add_argument("--address", default=None, help="Ray cluster address (default: a local Ray)")
    fr.add_argument("--out", type=_out_folder, default="results", help="writes OUT/frontier/NAME/")


def _console():
    """A rich Console; on a terminal it fits the terminal, elsewhere (a pipe, a file) lines are never wrapped."""
    from rich.console import Console

    console = Console()
    if not console.is_terminal:
        console = Console(soft_wrap=True)
    return console


def _progress_callback(console, bar, task, label: str, steps: int = 10):
    """``progress(done, total)`` for a long run: it moves the bar; where the console is not a terminal (a log
    file, a pipe), where a bar draws nothing until the end, it also prints a line each time another tenth of the
    work is done."""
    printed = {"tenth": 0}

    def progress(done: int, total: int) -> None:
        bar.update(task, completed=done, total=total)
        if console.is_terminal or not total:
            return
        tenth = done * steps // total
        if tenth > printed["tenth"]:
            printed["tenth"] = tenth
            console.print(f"{label}: {done} of {total} done", highlight=False, soft_wrap=True)

    return progress


def _open(args, folder: str):
    """``train.io.result_folder`` for ``folder``, remembered on ``args`` so that an interrupt can name it."""
    from train.io import result_folder

    args.open_folders.append(folder)
    return result_folder(folder, "coloc " + " ".join(args.argv))


def cmd_reproduce(args) -> int:
    from train.io import check_output_folder

    console = _console()
    papers = list(PAPERS) if args.paper == "all" else [args.paper]
    for paper in papers:
        check_output_folder(os.path.join(args.out, paper))
    for paper in papers:
        module = __import__(f"train.reproduce.{paper}", fromlist=["run"])
        runs = args.runs or (module.QUICK_RUNS if args.quick else module.RUNS)
        extra = {"data": args.data} if paper == "mrclam" else {}
        with _open(args, os.path.join(args.out, paper)), \
                console.status(f"reproducing {paper} ({runs} Monte Carlo runs)") as status:
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


def _check_scenario(name: str) -> None:
    """``name`` is a preset or a composition's name, else a ``coloc_env.config.BadInput`` (exit 2)."""
    import coloc_env
    from coloc_env.config import BadInput

    try:
        coloc_env.scenario_class(name)
    except BadInput:
        raise
    except ValueError as exc:
        raise BadInput(str(exc)) from exc


def cmd_train(args) -> int:
    from train.executor import map_tasks
    from train.io import check_output_folder
    from train.training import FROM_SETTINGS, train, training_env_config

    _check_scenario(args.scenario)
    seeds = args.seeds or [0 if args.seed is None else args.seed]
    folders = [os.path.join(args.out, args.scenario, f"seed{s}") for s in seeds]
    for folder in folders:
        check_output_folder(folder)
    cost_range = {None: FROM_SETTINGS, "none": None}.get(args.cost_range, args.cost_range)
    training_env_config(args.scenario, cost_range)  # a refused cost range writes nothing
    paper_entries = {None: FROM_SETTINGS, "none": None}.get(args.paper_entries, args.paper_entries)
    if paper_entries is not None and paper_entries != FROM_SETTINGS:
        import agents

        agents.paper_entries(args.scenario, paper_entries)  # an unknown name writes nothing
    jobs = [(args.scenario, args.timesteps, s, args.out, args.vec, args.executor == "local", args.tensorboard,
             args.curve_points, cost_range, paper_entries) for s in seeds]
    with contextlib.ExitStack() as stack:
        for folder in folders:
            stack.enter_context(_open(args, folder))
        paths = map_tasks(train, jobs, args.executor, args.address)
    for path in paths:
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
            reason = str(exc).removeprefix(f"{name}: ")  # the preset's errors start with its name
            console.print(f"{name}: skipped ({reason})")
            continue
        names.append(name)
    return names


def _policies_for(scenario: str, policy: str, models: str) -> list[str]:
    """``all``: every realizable policy, the bounds, the reference filters and the trained models under ``models``."""
    import glob

    from train.evaluate import all_rows

    if policy != "all":
        return [policy]
    found = sorted(glob.glob(os.path.join(models, scenario, "seed*", "model.zip")))
    return all_rows(scenario) + found


def _evaluation_line(scenario: str, policy: str, result: dict, episodes: int, path: str) -> str:
    """One printed result, every number with its unit; the initial term only where the scenario's cost has one."""
    from train.leaderboard import communication, metric

    unit = metric(scenario)[1]
    line = (f"{scenario} {policy}: mean realized cost {result['mean_cost']:.3f} +- {result['ci95']:.3f} {unit} "
            f"(95 %, {episodes} episodes)")
    if result["initial_cost"] != 0:
        line += f"; with the initial term {result['initial_cost']:.2f} {unit}: {result['paper_cost']:.3f} {unit}"
    return line + f"; communication {result['communication_per_step']:.2f} {communication(scenario)} per step -> {path}"


def cmd_evaluate(args) -> int:
    from rich.progress import Progress

    from coloc_env.config import BadInput
    from train.evaluate import evaluate_policy
    from train.io import check_output_folder, read_json
    from train.leaderboard import frontier_verdict, metric, record

    console = _console()
    check_output_folder(args.out)
    if args.costs is not None and args.policy != "all" and not args.policy.endswith(".zip"):
        raise BadInput(f"--costs applies to trained models (--policy PATH.zip, or the models --policy all finds); "
                       f"{args.policy!r} does not read the communication cost")
    scenarios = _runnable_scenarios(console) if args.scenario == "all" else [args.scenario]
    for scenario in scenarios:
        _check_scenario(scenario)
        check_output_folder(os.path.join(args.out, _result_key(scenario)))
        runs = [(policy, cost) for policy in _policies_for(scenario, args.policy, args.models)
                for cost in (args.costs if args.costs is not None and policy.endswith(".zip") else [None])]
        for policy, cost in runs:
            with Progress(console=console, transient=True) as bar:
                task = bar.add_task(f"{scenario} / {policy}" + ("" if cost is None else f" @ cost={cost:g}"),
                                    total=args.episodes)
                result = evaluate_policy(scenario, policy, args.episodes,
                                         progress=lambda task=task: bar.advance(task),
                                         stochastic=True if args.stochastic else None, cost=cost)
            policy = result["policy"]
            path = record(result, args.out, _result_key(scenario))
            console.print(_evaluation_line(scenario, policy, result, args.episodes, path), highlight=False)
            against = frontier_verdict(scenario, read_json(path), result["policy"])
            if against is not None:
                console.print(f"  against the baseline frontier at its message rate (the fixed policies evaluated so "
                              f"far): {against['verdict']} ({against['mean']:+.4g} "
                              f"{metric(scenario)[1]}, 95 % [{against['low']:+.4g}, "
                              f"{against['high']:+.4g}])", highlight=False)
    return 0


def _check_commit(ref: str) -> str:
    """The commit ``ref`` names in this repository, else a one-line ``coloc_env.config.BadInput``."""
    import subprocess

    from coloc_env.config import BadInput
    from train.bench import repository_root

    try:
        root = repository_root()
    except Exception as exc:  # noqa: BLE001 - not in a git clone: say so in one line
        raise BadInput(f"--against {ref!r} needs a git clone of coloc: {exc}") from exc
    done = subprocess.run(["git", "-C", root, "rev-parse", "--verify", "--quiet", f"{ref}^{{commit}}"],
                          capture_output=True, text=True)
    if done.returncode != 0 or not done.stdout.strip():
        raise BadInput(f"--against {ref!r}: no such commit in {root} (a commit, tag or branch git knows)")
    return done.stdout.strip()


def cmd_bench(args) -> int:
    import coloc_env
    from coloc_env.config import BadInput
    from train.bench import run, run_against
    from train.io import check_output_folder

    check_output_folder(os.path.join(args.out, "bench"))
    for name in args.scenarios or []:
        if coloc_env.is_composition_name(name):  # its rows replay the paper policy's actions and raw backend step
            raise BadInput(f"coloc bench measures the presets ({', '.join(coloc_env.SCENARIOS)}), not a "
                           f"composition such as {name!r}")
        _check_scenario(name)
    if args.rounds is not None and not args.against:
        raise BadInput(f"--rounds {args.rounds} needs --against REF (the rounds alternate the two trees)")
    if args.cap is not None and not args.scaling:
        raise BadInput(f"--cap {args.cap} needs --scaling (it caps each row of the scaling table)")
    for flag in ("backends", "sizes", "batches"):
        if getattr(args, flag) is not None and not args.scaling:
            raise BadInput(f"--{flag} needs --scaling (it selects rows or columns of the scaling table)")
    if args.against:
        _check_commit(args.against)
    if args.scaling:
        from train.bench import run_scaling, scaling_compositions

        if args.scenarios:
            raise BadInput("--scenarios does not apply to --scaling (its rows are the backends on gps_denied)")
        if args.rounds is not None:
            raise BadInput("--rounds does not apply to --scaling (each row is measured once per tree)")
        if args.cap is not None and not 1.0 <= args.cap <= 86400.0:
            raise BadInput(f"--cap must be in [1, 86400] seconds, got {args.cap}")
        pairs = scaling_compositions()
        if args.backends is not None:
            known = list(dict.fromkeys(b for b, _ in pairs))
            unknown = [b for b in args.backends if b not in known]
            if unknown:
                raise BadInput(f"--backends must name backends that run on gps_denied ({', '.join(known)}), "
                               f"got {', '.join(map(repr, unknown))}")
            pairs = [(b, net) for b, net in pairs if b in args.backends]
        with _open(args, os.path.join(args.out, "bench")):
            run_scaling(args.out, quick=args.quick, against=args.against, cap=args.cap, compositions=pairs,
                        sizes=tuple(sorted(set(args.sizes))) if args.sizes else None,
                        batches=tuple(sorted(set(args.batches))) if args.batches else None)
        return 0
    scenarios = args.scenarios or _runnable_scenarios(_console())
    with _open(args, os.path.join(args.out, "bench")):
        if args.against:
            run_against(args.out, args.against, quick=args.quick, scenarios=scenarios, rounds=args.rounds or 2)
        else:
            run(args.out, quick=args.quick, scenarios=scenarios)
    return 0


def cmd_study(args) -> int:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    from train.io import check_output_folder
    from train.study import run_study

    check_output_folder(args.out)  # creates nothing: refused input leaves OUT as it was
    console = _console()
    with Progress(TextColumn("study {task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeRemainingColumn(), console=console, transient=True) as bar:
        task = bar.add_task(f"{args.world}/{args.network}", total=None)
        metrics, folder = run_study(
            args.world, args.network, args.backends, sweep=args.sweep, policy=args.policy, episodes=args.episodes,
            seed=args.seed, horizon=args.horizon, batched=args.batched, executor=args.executor,
            address=args.address, out=args.out, name=args.name,
            progress=_progress_callback(console, bar, task, f"study {args.world}/{args.network}"),
            mark=lambda folder: _open(args, folder))  # INCOMPLETE until the last file; named on Ctrl-C
    console.print(f"wrote {folder}/ (metrics.json, report.md, position_error.png)", soft_wrap=True)
    reference = metrics["reference"]
    for backend, cells in metrics["backends"].items():
        for key, cell in cells.items():
            line = (f"  {backend:<16} {key:>10}: error {cell['position_error']['mean']:.4g} "
                    f"+- {cell['position_error']['ci95']:.2g} m, {cell['messages_per_step']:.3g} messages and "
                    f"{cell['floats_per_step']:.3g} floats per agent-step")
            if cell.get("efficiency") is not None:  # RMSE over sqrt(pcrb_centralized): docs/bounds.md
                line += f"; RMSE {cell['rmse']:.3g} m = {cell['efficiency']:.3g} x the bound"
            if backend != reference:
                pair = metrics["paired"][backend][key]
                line += f"; vs {reference} {pair['mean']:+.3g} +- {pair['ci95']:.2g} m ({pair['verdict']})"
            console.print(line, highlight=False, soft_wrap=True)
    return 0


def cmd_frontier(args) -> int:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    from train.frontier import FIGURE, hull_by_rate, run_frontier
    from train.io import check_output_folder

    _check_scenario(args.scenario)
    check_output_folder(args.out)
    console = _console()
    with Progress(TextColumn("frontier {task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeRemainingColumn(), console=console, transient=True) as bar:
        task = bar.add_task(args.scenario, total=None)
        metrics, folder = run_frontier(
            args.scenario, episodes=args.episodes, seed=args.seed, models=args.models, quick=args.quick,
            executor=args.executor, costs=args.costs, address=args.address, out=args.out,
            **({} if args.bound_episodes is None else {"bound_episodes": args.bound_episodes}),
            progress=_progress_callback(console, bar, task, f"frontier {args.scenario}"),
            mark=lambda folder: _open(args, folder))
    console.print(f"wrote {folder}/ (metrics.json, report.md, {FIGURE})", soft_wrap=True)
    console.print(f"  baseline frontier: {', '.join(metrics['frontier'])}", highlight=False, soft_wrap=True)
    for label, name in hull_by_rate(metrics).items():
        console.print(f"  {label} message rates: {name}", highlight=False, soft_wrap=True)
    for name, result in metrics["judged"].items():
        console.print(f"  {name}: {result['verdict']} against the frontier ({result['mean']:+.4g} {metrics['unit']}, "
                      f"95 % [{result['low']:+.4g}, {result['high']:+.4g}])", highlight=False, soft_wrap=True)
    return 0


def cmd_list(args) -> int:
    """Print the parts, the presets (with their registered env ids) and one line per (world, network,
    backend): ok, or why not; ``--ok`` keeps the compatible rows, ``--world`` / ``--network`` / ``--backend``
    the rows of that part (a ``BadInput`` names the flag and the known names)."""
    import coloc_env
    from coloc_env.config import BadInput
    from coloc_env.registry import env_id

    filters = {part: getattr(args, part, None) for part in ("world", "network", "backend")}
    known = {"world": coloc_env.WORLDS, "network": coloc_env.NETWORKS, "backend": coloc_env.BACKENDS}
    for part, value in filters.items():
        if value is not None and value not in known[part]:
            raise BadInput(f"--{part} must be one of {', '.join(known[part])}; got {value!r}")
    only_ok = bool(getattr(args, "ok", False))
    print("worlds:   " + ", ".join(coloc_env.WORLDS))
    print("networks: " + ", ".join(coloc_env.NETWORKS))
    print("backends: " + ", ".join(coloc_env.BACKENDS))
    print("presets:")
    for name, spec in coloc_env.PRESETS.items():
        parts = [getattr(spec, part).name if getattr(spec, part) is not None else "(binding only)"
                 for part in ("world", "network", "backend")]
        print(f"  {name:<18} {' / '.join(parts)}  ({env_id(name)})")
    rows = coloc_env.compatibility()
    shown = [r for r in rows if (r["ok"] or not only_ok)
             and all(value is None or r[part] == value for part, value in filters.items())]
    narrowed = [f"--{part} {value}" for part, value in filters.items() if value is not None]
    if only_ok:
        narrowed.insert(0, "--ok")
    note = f"; {len(shown)} shown ({' '.join(narrowed)})" if narrowed else ""
    print(f"compositions ({sum(r['ok'] for r in rows)} of {len(rows)} compatible{note}):")
    width = max((len(f"{r['world']}/{r['network']}/{r['backend']}") for r in shown), default=0)
    for r in shown:
        label = f"{r['world']}/{r['network']}/{r['backend']}"
        print(f"  {label:<{width}}  {'ok' if r['ok'] else 'no: ' + r['reason']}")
    return 0


@contextlib.contextmanager
def _wide_output_when_not_a_terminal():
    """Rich sizes every Console it creates (train.bench's tables too) from ``COLUMNS``: when stdout is not a
    terminal and the user set none, make it wide enough that no line wraps at 80 columns and no table cell is
    truncated ("UnscentedKalmanFilt..."). Restored afterwards (main is also called in-process)."""
    previous = os.environ.get("COLUMNS")
    if previous is None and not sys.stdout.isatty():
        os.environ["COLUMNS"] = "400"
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop("COLUMNS", None)


# Where a plain ValueError (not a BadInput) still means bad input: raised by the recorded-data loader, whose
# checks name the data file the user gave. Anywhere else (numpy, an estimator, a backend's step) it is an
# internal error; the checks of the command line and of the policies raise BadInput.
INPUT_LAYERS = (os.path.join("coloc_env", "data"),)
PACKAGE_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def is_bad_input(exc: BaseException) -> bool:
    """A refusal of the user's input (exit 2), as opposed to an internal error (exit 1): a
    ``coloc_env.config.BadInput`` (every check raises one), or a ``ValueError`` raised by code of
    ``INPUT_LAYERS`` itself (its innermost frame)."""
    from coloc_env.config import BadInput

    if isinstance(exc, BadInput):
        return True
    if type(exc) is not ValueError or exc.__traceback__ is None:
        return False
    tb = exc.__traceback__
    while tb.tb_next is not None:
        tb = tb.tb_next
    path = os.path.abspath(tb.tb_frame.f_code.co_filename)
    relative = os.path.relpath(path, PACKAGE_ROOT)
    return not relative.startswith("..") and relative.startswith(tuple(layer + os.sep for layer in INPUT_LAYERS))


def _internal_error(command: str, exc: BaseException) -> str:
    """One line for an internal error: what failed and where, and that it is worth a report (no traceback;
    ``COLOC_TRACEBACK=1`` prints it)."""
    tb = exc.__traceback__
    where = ""
    while tb is not None:
        where = f" at {os.path.relpath(tb.tb_frame.f_code.co_filename, PACKAGE_ROOT)}:{tb.tb_lineno}"
        tb = tb.tb_next
    message = " ".join(str(exc).split()) or "(no message)"
    return (f"coloc {command}: internal error: {type(exc).__name__}: {message}{where}. This is a bug in coloc, "
            "not in your input: please report it with the command line (COLOC_TRACEBACK=1 shows the traceback)")


def main(argv: list[str] | None = None) -> int:
    """Run one command and return its exit status.

    | status | when                                                                                   |
    |--------|----------------------------------------------------------------------------------------|
    | 0      | done                                                                                   |
    | 1      | an internal error (``is_bad_input`` is False): one line naming it, no traceback    |
    | 2      | bad input (a flag, a config value, a policy, a file; ``is_bad_input``): one line,   |
    |        | checked before any computing                                                           |
    | 130    | Ctrl-C: one line naming the folders left marked ``INCOMPLETE``                         |

    Called as the ``coloc`` script (``argv`` None), a second Ctrl-C after the message is ignored, so the
    process always ends with its line and its status, and a Ctrl-C that Python would drop is delivered again
    (``redeliver_ignored_interrupt``).
    """
    as_script = argv is None
    if as_script:
        sys.unraisablehook = redeliver_ignored_interrupt
    argv = sys.argv[1:] if argv is None else list(argv)
    command = next((a for a in argv if not a.startswith("-")), "")
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        for name, value in vars(args).items():  # argparse reads --flag=-- as an empty list, never typed
            if isinstance(value, list) and not value:
                parser.error(f"argument --{name.replace('_', '-')}: expected a value, got '--'")
        args.argv, args.open_folders = argv, []
        command = args.command
        handlers = {"reproduce": cmd_reproduce, "train": cmd_train, "evaluate": cmd_evaluate, "bench": cmd_bench,
                    "study": cmd_study, "frontier": cmd_frontier, "list": cmd_list}
        try:
            with _wide_output_when_not_a_terminal():
                return handlers[args.command](args)
        except Exception as exc:  # noqa: BLE001 - every failure ends in one line and a status
            if os.environ.get("COLOC_TRACEBACK"):
                import traceback

                traceback.print_exception(exc, file=sys.stderr)
            if is_bad_input(exc):
                print(f"coloc {args.command}: error: {' '.join(str(exc).split())}", file=sys.stderr)
                return BAD_INPUT
            print(_internal_error(args.command, exc), file=sys.stderr)
            return INTERNAL_ERROR
    except KeyboardInterrupt:
        return _interrupted(command, locals().get("args"), as_script)
    finally:
        if as_script:  # the status is decided: a Ctrl-C from here to the exit would end it without a line
            import signal

            signal.signal(signal.SIGINT, signal.SIG_IGN)


def redeliver_ignored_interrupt(unraisable) -> None:
    """``sys.unraisablehook`` of the script: a Ctrl-C whose KeyboardInterrupt was raised inside a callback whose
    exceptions Python ignores (a weakref's, such as the import system's module-lock cleanup) would be lost and
    the command would run on; it is delivered again to the main thread (``_thread.interrupt_main``) from a timer
    thread 10 ms later, once the callback has returned (delivered from inside it, it would be ignored again;
    should it land in such a callback again, this hook delivers it once more). Every other unraisable exception
    goes to Python's default hook."""
    if unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt):
        import _thread
        import threading

        timer = threading.Timer(0.01, _thread.interrupt_main)
        timer.daemon = True
        timer.start()
        return
    sys.__unraisablehook__(unraisable)


def _forget_unhandled_keyboard_interrupt() -> None:
    """Clear CPython's record of an unhandled Ctrl-C, which would turn this script's status 130 into a death by
    SIGINT (status -2 to a parent) under ``python -m``.

    CPython marks a KeyboardInterrupt that leaves a string ``exec`` / ``eval`` (``PyRun_String``: dataclasses and
    namedtuples build their methods that way, so a Ctrl-C during a lazy import often lands there) as unhandled even
    when a caller catches it; ``Py_RunMain`` then re-raises SIGINT after the interpreter exits, whatever status the
    script chose. Every string ``exec`` clears that mark as it starts, so one trivial ``exec`` after the interrupt
    has been caught forgets it; on an interpreter without the mark it does nothing."""
    exec("pass", {})  # noqa: S102 - a constant string, run for its side effect on the interpreter's flag


def _interrupted(command: str, args, as_script: bool) -> int:
    """The line of an interrupt (the folders left marked) and status 130; a script ignores a further Ctrl-C."""
    import signal

    if as_script:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        _forget_unhandled_keyboard_interrupt()
    from train.io import INCOMPLETE

    folders = getattr(args, "open_folders", [])
    marked = [f for f in folders if os.path.exists(os.path.join(f, INCOMPLETE))]
    where = f"; {', '.join(marked)} marked {INCOMPLETE}" if marked else "; nothing was left half written"
    print(f"coloc {command or 'command'}: interrupted{where}", file=sys.stderr)
    return INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())


def _preset_fields(field: str) -> dict:
    from coloc_env.scenarios import REGISTRY

    return {scenario: getattr(cls, field) for scenario, cls in REGISTRY.items()}


def __getattr__(name: str):
    """The per-preset unit tables this module held before each preset declared them (deprecated)."""
    from coloc_env.config import module_names  # imported here: `coloc --help` imports no part

    return module_names(__name__, {"METRIC_UNITS": lambda: _preset_fields("metric_unit"),
                                   "COMMUNICATION_UNITS": lambda: _preset_fields("communication")},
                        deprecated=dict.fromkeys(("METRIC_UNITS", "COMMUNICATION_UNITS"),
                                                 "a preset's class declares metric_unit and communication"),
                        stacklevel=3)(name)
