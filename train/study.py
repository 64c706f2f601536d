"""``coloc study``: every backend on the same seeded episodes of one world and network, per sweep value.

>>> from train.study import run_study
>>> metrics, folder = run_study("circles", "relay", ["ukf_dcl", "dead_reckoning"],
...                             sweep="network.loss_at_zero=0,0.2,0.4", episodes=30, seed=0)

Arguments (``coloc study --help`` says the same)
-------------------------------------------------
| argument        | default      | meaning                                                                  |
|-----------------|--------------|--------------------------------------------------------------------------|
| ``--world``     | (required)   | a name of ``coloc_env.WORLDS``, at its defaults                          |
| ``--network``   | (required)   | a name of ``coloc_env.NETWORKS``, at its defaults                        |
| ``--backends``  | (required)   | ``a,b,c``: names of ``coloc_env.BACKENDS``; the first is the reference   |
|                 |              | of the paired differences                                                |
| ``--sweep``     | none         | ``PART.FIELD=v1,v2,...``, PART one of world, network, backend; each      |
|                 |              | value sets that field of that part (of every backend for PART=backend).  |
|                 |              | Values parse as bool (true/false), None (none/null), int, float          |
|                 |              | (inf too), else a string; an int given to a float field becomes a float. |
|                 |              | Without it every backend runs once at its defaults, key ``"default"``    |
| ``--policy``    | ``always``   | always / silent / random (``agents.make_policy``), or paper where the    |
|                 |              | composition has one                                                      |
| ``--episodes``  | 30           | E >= 2 episodes per (backend, value)                                     |
| ``--seed``      | 0            | S: episode e is ``env.reset(seed=S + e)`` and the policy is              |
|                 |              | ``make_policy(P, env, seed=S + e)``: the same truth and sensor readings  |
|                 |              | for every backend and value (paired episodes)                            |
| ``--horizon``   | the world's  | steps per episode (``compose(horizon=...)``)                             |
| ``--batched``   | off          | run a cell's E episodes as one batched core (``ComposedScenario`` with   |
|                 |              | batch E; always / silent / random only): much faster, and equal to the   |
|                 |              | default per-episode run up to floating-point rounding (~1e-14 m on the   |
|                 |              | UKFs; a particle backend can drift further where rounding flips a        |
|                 |              | resampling draw). Off: each episode steps ``coloc_env.parallel_env``     |
|                 |              | itself, bit-identical to a user's own env loop                           |
| ``--executor``  | ``local``    | local, or ray: each (backend, value) cell is one Ray task                |
|                 |              | (``train.executor``), bit-identical to local                          |
| ``--address``   | a local Ray  | Ray cluster address                                                      |
| ``--out``       | ``results``  | the study goes to ``OUT/study/<name>/``                                  |
| ``--name``      | see below    | ``<name>``; default ``{world}_{network}``, plus ``_{PART}.{FIELD}`` with |
|                 |              | a sweep (``circles_relay_network.loss_at_zero``)                         |

Every input is checked (compositions composed, policies built, the output
folder probed for writing) before any episode runs; a bad one is a
``ValueError`` naming it, and nothing is written.

From the first episode to the last file, the folder holds an ``INCOMPLETE``
file (``train.io.result_folder``): a study interrupted (Ctrl-C: ``coloc
study`` prints one line and exits 130) or failed half way leaves it there,
beside the files written so far and those already in the folder (a folder
that held nothing else is removed again); a study that completes removes it.

Metrics of each (backend, value) cell, over the E episodes
------------------------------------------------------------
| key                 | meaning                                                                          |
|---------------------|----------------------------------------------------------------------------------|
| position_error      | ``{"mean": m, "ci95": h}``: each episode's mean over steps and agents of          |
|                     | ``infos[agent]["position_error"]`` (m), then the mean over episodes and the       |
|                     | half-width of its 95 % Student-t interval                                         |
| messages_per_step   | mean of ``infos[agent]["messages_sent"]`` over episodes, steps and agents         |
| floats_per_step     | the same for ``floats_sent``                                                      |
| rmse                | sqrt of the mean over episodes, steps and agents of position_error^2 (m)         |
| pcrb_centralized,   | sqrt of the mean over steps and agents of ``coloc_env.pcrb``'s bound of that name |
| pcrb_local,         | on the cell's episodes and policy (m); null where the bound is not defined        |
| pcrb_delivered      | (delivered: where the backend's messages carry readings; docs/bounds.md)          |
| efficiency          | rmse / pcrb_centralized (>= 1 up to Monte Carlo noise)                            |
| nees                | mean over episodes, steps and agents of e^T P^-1 e (e: estimate - truth, P:       |
|                     | ``backend.posterior_position_cov``, 2 x 2; about 2 for a consistent filter);      |
|                     | null where the backend has no covariance                                          |
| nees_band           | [lo, hi]: the chi^2(2 E) / E 95 % band of a NEES averaged over the E episodes at  |
|                     | one step (null without a covariance)                                              |
| nees_in_band        | the share of (step, agent) whose NEES averaged over the episodes lies in it (a   |
|                     | consistent filter: about 0.95)                                                    |
| per_episode_error   | the E episode means behind ``position_error`` (m), in seed order                  |

``paired[b][value]`` for every backend b after the first (the reference):
the per-episode difference ``error_b - error_reference`` (m) over the same
seeds, ``{"mean", "ci95", "verdict"}`` with verdict "lower" (the interval is
below 0: b is more accurate), "higher", or "no difference" (the interval
contains 0, or both ends lie within 1e-9 m of it: numerically equal backends).

Outputs in ``OUT/study/<name>/`` (each written atomically, ``train.io``)
--------------------------------------------------------------------------
| file                 | contents                                                                      |
|----------------------|-------------------------------------------------------------------------------|
| metrics.json         | ``{"world", "network", "reference", "backends": {b: {value: cell}}, "paired",  |
|                      | "config": {seed, episodes, policy, sweep, horizon, batched, compositions}}``  |
| report.md            | one markdown table per metric (backends x values; RMSE with efficiency, the   |
|                      | three bounds, NEES with its share in band), the paired table, the command line|
| position_error.png   | error vs the swept value (or per backend without a sweep): each mean as a dot |
|                      | with its 95 % interval, the RMSE (x) beside its bound sqrt(pcrb_centralized)  |
|                      | (dashed), which compares with the RMSE, not the mean; with two or more        |
|                      | backends a second panel with the paired difference to the first and its 95 % |
|                      | interval                                                                      |

``metrics.json`` depends only on the inputs that change numbers (not on
``--out``, ``--executor`` or ``--address``): the same command reproduces it
byte for byte.
"""

from __future__ import annotations

import math
import os
import re
import shlex
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from typing import Any

import numpy as np

from coloc_env.config import BadInput

PARTS = ("world", "network", "backend")
POLICIES = ("always", "silent", "random", "paper")
BATCHABLE_POLICIES = ("always", "silent", "random")  # their actions never read the env's state
MAX_EPISODES = 1_000_000
MAX_SEED = 2**62  # S + e must stay a valid numpy seed
EQUAL_TOLERANCE = 1e-9  # m: a paired interval within this of 0 is "no difference" (rounding, not a result)
FIGURE = "position_error.png"


# --- argument parsing and checks --------------------------------------------------------------------------
def parse_value(token: str) -> Any:
    """A sweep value from its text: bool, None, int, float, else the string itself."""
    text = token.strip()
    if not text:
        raise BadInput("--sweep has an empty value; give PART.FIELD=v1,v2,...")
    lower = text.lower()
    if lower in ("true", "false"):
        return lower == "true"
    if lower in ("none", "null"):
        return None
    if re.fullmatch(r"[+-]?\d+", text):
        return int(text)
    try:
        return float(text)
    except ValueError:
        return text


def parse_sweep(sweep: str | None) -> tuple[str, str, list[str], list[Any]] | None:
    """``"PART.FIELD=v1,v2"`` -> (part, field, value texts, parsed values); None for no sweep."""
    if sweep is None:
        return None
    if not isinstance(sweep, str) or "=" not in sweep:
        raise BadInput(f"--sweep must look like PART.FIELD=v1,v2,... (PART one of {list(PARTS)}), got {sweep!r}")
    target, _, values = sweep.partition("=")
    part, dot, field = target.strip().partition(".")
    if part not in PARTS or not dot:
        raise BadInput(f"--sweep PART must be one of {list(PARTS)} (as PART.FIELD=...), got {target.strip()!r}")
    if not field.isidentifier():
        raise BadInput(f"--sweep FIELD must be a field name of the {part}, got {field!r}")
    if field == "name":
        raise BadInput(f"--sweep cannot change {part}.name; choose the part with --{part}"
                       f"{'s' if part == 'backend' else ''}")
    texts = [t.strip() for t in values.split(",")]
    parsed = [parse_value(t) for t in texts]
    seen = []
    for text, value in zip(texts, parsed, strict=True):
        if any(value == v and type(value) is type(v) for v in seen):
            raise BadInput(f"--sweep {part}.{field} lists the value {text!r} twice")
        seen.append(value)
    return part, field, texts, parsed


def _coerce(value: Any, default: Any) -> Any:
    """An int given to a float field becomes a float; a field whose default is a string keeps the text."""
    if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def _check_int(name: str, value: Any, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not low <= value <= high:
        raise BadInput(f"{name} must be an integer in [{low}, {high}], got {value!r}")
    return int(value)


def _backend_list(backends: str | Sequence[str]) -> list[str]:
    if isinstance(backends, str):
        backends = backends.split(",")
    if isinstance(backends, (bytes, dict)) or not isinstance(backends, Sequence):
        raise BadInput(f"backends must be a comma-separated string or a list of names, got {backends!r}")
    names = [b.strip() if isinstance(b, str) else b for b in backends]
    if not names or any(not isinstance(b, str) or not b for b in names):
        raise BadInput(f"backends must be one or more backend names (a,b,c), got {backends!r}")
    duplicated = sorted({b for b in names if names.count(b) > 1})
    if duplicated:
        raise BadInput(f"backends lists {duplicated} more than once")
    return names


def _check_name(name: str) -> str:
    if (not isinstance(name, str) or not name or name in (".", "..") or "/" in name or "\\" in name
            or name != name.strip()):
        raise BadInput(f"name must be a non-empty folder name without path separators, got {name!r}")
    return name


def study_name(world: str, network: str, sweep: tuple | None) -> str:
    """The default ``<name>``: ``{world}_{network}``, plus ``_{PART}.{FIELD}`` with a sweep."""
    base = f"{world}_{network}"
    return base if sweep is None else f"{base}_{sweep[0]}.{sweep[1]}"


def build_cells(world: str, network: str, backends: list[str], sweep: tuple | None, horizon: int | None):
    """``{(backend, value key): Composition}``, composing every cell (so that every ValueError comes first)."""
    import coloc_env
    from coloc_env.parts import BACKENDS, NETWORKS, WORLDS

    registries = {"world": WORLDS, "network": NETWORKS, "backend": BACKENDS}
    for kind, name in (("world", world), ("network", network), *(("backend", b) for b in backends)):
        registries[kind]._class(name)  # "unknown world 'x'; available: [...]"
    options = {} if horizon is None else {"horizon": horizon}
    cells = {}
    for backend in backends:
        names = {"world": world, "network": network, "backend": backend}
        if sweep is None:
            cells[backend, "default"] = coloc_env.compose(**names, **options)
            continue
        part, field, texts, values = sweep
        cls = registries[part][names[part]]
        default = getattr(cls, field, None)
        for text, value in zip(texts, values, strict=True):
            parts = dict(names)
            parts[part] = {"name": names[part], field: _coerce(value, default)}
            try:
                cells[backend, text] = coloc_env.compose(**parts, **options)
            except ValueError as exc:
                raise BadInput(f"--sweep {part}.{field}={text} with backend {backend}: {exc}") from exc
    return cells


# --- running one cell: E paired episodes of one composition --------------------------------------------------
def _nees(error: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """e^T P^-1 e over the leading axes of ``error`` (..., 2) and ``cov`` (..., 2, 2); pinv where P is singular."""
    try:
        solved = np.linalg.solve(cov, error[..., None])[..., 0]
    except np.linalg.LinAlgError:
        solved = np.einsum("...ij,...j->...i", np.linalg.pinv(cov), error)
    return np.einsum("...i,...i->...", error, solved)


def _episode_summary(errors: list, messages: list, floats: list, nees: list | None) -> tuple:
    """One episode's (mean error, mean messages, mean floats, mean NEES or nan, mean squared error, per-step NEES
    (K, N) or None) from per-step (N,) rows."""
    errors = np.array(errors, dtype=float)
    steps = None if nees is None else np.array(nees, dtype=float)
    return (float(np.mean(errors)), float(np.mean(np.array(messages, dtype=float))),
            float(np.mean(np.array(floats, dtype=float))),
            float("nan") if nees is None else float(np.mean(steps)), float(np.mean(errors**2)), steps)


def run_cell(spec, policy: str, episodes: int, seed: int, batched: bool = False,
             progress: Callable[[], None] | None = None) -> dict[str, np.ndarray]:
    """E episodes of ``spec``; episode e is ``env.reset(seed=seed + e)`` with ``make_policy(policy, env,
    seed=seed + e)``. Returns per-episode arrays ``error``, ``messages``, ``floats``, ``nees`` (nan
    without a covariance) and ``squared_error`` (the mean of position_error^2), and ``nees_steps`` (E, K, N)
    the NEES of every step and agent (None without a covariance). ``progress()`` is called once per
    episode (per cell if batched)."""
    run = _run_batched if batched else _run_env
    rows = run(spec, policy, episodes, seed, progress)
    columns = list(zip(*rows, strict=True))
    error, messages, floats, nees, squared = (np.array(column, dtype=float) for column in columns[:5])
    steps = None if columns[5][0] is None else np.stack(columns[5])
    return {"error": error, "messages": messages, "floats": floats, "nees": nees, "squared_error": squared,
            "nees_steps": steps}


def _run_env(spec, policy_name, episodes, seed, progress):
    import agents
    import coloc_env

    env = coloc_env.parallel_env(spec)
    agents_order = env.possible_agents
    rows = []
    for e in range(episodes):
        policy = agents.make_policy(policy_name, env, seed=seed + e)
        observations, _ = env.reset(seed=seed + e)
        errors, messages, floats, nees = [], [], [], []
        while env.agents:
            observations, _, _, _, infos = env.step(policy.act(observations))
            info = [infos[a] for a in agents_order]
            errors.append([i["position_error"] for i in info])
            messages.append([i["messages_sent"] for i in info])
            floats.append([i["floats_sent"] for i in info])
            cov = env.scenario.backend.posterior_position_cov
            if cov is None:
                nees = None
            elif nees is not None:
                diff = np.array([i["estimated_position"] for i in info]) - np.array([i["true_position"] for i in info])
                nees.append(_nees(diff, cov[0]))
        rows.append(_episode_summary(errors, messages, floats, nees))
        if progress:
            progress()
    env.close()
    return rows


def _run_batched(spec, policy_name, episodes, seed, progress):
    import agents
    import coloc_env
    from coloc_env.scenarios.composed import ComposedScenario

    view = coloc_env.parallel_env(spec)  # the policies' action spaces (B = 1); never stepped
    policies = [agents.make_policy(policy_name, view, seed=seed + e) for e in range(episodes)]
    core = ComposedScenario(spec, batch=episodes)
    core.reset([np.random.default_rng(seed + e) for e in range(episodes)])
    order = view.possible_agents
    blind = dict.fromkeys(order)  # these policies never read observations
    errors, messages, floats, nees = [], [], [], []
    while not core.done().all():
        actions = np.stack([np.stack([np.asarray(act[a], dtype=float) for a in order])
                            for act in (p.act(blind) for p in policies)])
        core.step(actions)
        info = core.info()
        errors.append(info["position_error"])
        messages.append(info["messages_sent"])
        floats.append(info["floats_sent"])
        cov = core.backend.posterior_position_cov
        if cov is None:
            nees = None
        elif nees is not None:
            nees.append(_nees(info["estimated_position"] - info["true_position"], cov))
    view.close()
    if progress:
        progress()
    return [_episode_summary([x[e] for x in errors], [x[e] for x in messages], [x[e] for x in floats],
                             None if nees is None else [x[e] for x in nees]) for e in range(episodes)]


# --- statistics --------------------------------------------------------------------------------------------
def mean_ci95(values: np.ndarray) -> tuple[float, float]:
    """Mean and the half-width of its 95 % Student-t interval (n >= 2)."""
    from scipy import stats

    values = np.asarray(values, dtype=float)
    half = stats.t.ppf(0.975, len(values) - 1) * values.std(ddof=1) / math.sqrt(len(values))
    return float(values.mean()), float(half)


def verdict(mean: float, half: float) -> str:
    """"lower" / "higher" where the 95 % interval excludes 0 (beyond rounding), else "no difference"."""
    if abs(mean) + half <= EQUAL_TOLERANCE:
        return "no difference"
    if mean + half < 0:
        return "lower"
    if mean - half > 0:
        return "higher"
    return "no difference"


NEES_DOF = 2  # the position block: 2 DOF


def nees_band(episodes: int, dof: int = NEES_DOF) -> tuple[float, float]:
    """The 95 % band of a NEES averaged over ``episodes`` independent episodes at one step: chi^2(E d) / E quantiles
    (Bar-Shalom, Li, Kirubarajan, Sec. 5.4.2). The per-step average is tested against it, not the mean over steps
    (the steps of an episode are correlated, which would make the band of that mean meaningless)."""
    from scipy import stats

    return (float(stats.chi2.ppf(0.025, episodes * dof) / episodes),
            float(stats.chi2.ppf(0.975, episodes * dof) / episodes))


def nees_metrics(steps: np.ndarray | None) -> dict[str, Any]:
    """``nees_band`` [lo, hi] and ``nees_in_band`` (the share of (step, agent) whose NEES averaged over the E
    episodes lies in it) from the per-step NEES (E, K, N); None without a covariance."""
    if steps is None:
        return {"nees_band": None, "nees_in_band": None}
    low, high = nees_band(steps.shape[0])
    per_step = steps.mean(axis=0)
    return {"nees_band": [low, high], "nees_in_band": float(np.mean((per_step >= low) & (per_step <= high)))}


def bound_metrics(bounds: dict | None, rmse: float) -> dict[str, Any]:
    """sqrt of each PCRB's mean over steps and agents (m) and efficiency = RMSE / sqrt(pcrb_centralized)."""
    if bounds is None:
        return {"pcrb_centralized": None, "pcrb_local": None, "pcrb_delivered": None, "efficiency": None}
    out = {f"pcrb_{key}": (float(np.sqrt(np.mean(bounds[key]))) if key in bounds else None)
           for key in ("centralized", "local", "delivered")}
    out["efficiency"] = float(rmse / out["pcrb_centralized"]) if out["pcrb_centralized"] > 0 else None
    return out


def cell_metrics(result: dict[str, np.ndarray], bounds: dict | None = None) -> dict[str, Any]:
    mean, half = mean_ci95(result["error"])
    nees = result["nees"]
    rmse = float(np.sqrt(np.mean(result["squared_error"])))
    return {"position_error": {"mean": mean, "ci95": half},
            "rmse": rmse,
            **bound_metrics(bounds, rmse),
            "messages_per_step": float(result["messages"].mean()),
            "floats_per_step": float(result["floats"].mean()),
            "nees": float(nees.mean()) if not np.any(np.isnan(nees)) else None,
            **nees_metrics(result.get("nees_steps")),
            "per_episode_error": [float(x) for x in result["error"]]}


def cell_bounds(spec, policy: str, episodes: int, seed: int) -> dict:
    """``coloc_env.pcrb`` of one cell on its episodes: the named policy where the bound's core plays it
    identically (always, silent), else the study's own per-episode policies (``make_policy(policy, env,
    seed=seed + e)``) as callables."""
    import coloc_env

    if policy in ("always", "silent"):
        return coloc_env.pcrb(spec, episodes=episodes, seed=seed, policy=policy)
    import agents

    acts = []
    for e in range(episodes):
        env = coloc_env.parallel_env(spec)
        acts.append(agents.make_policy(policy, env, seed=seed + e).act)
    return coloc_env.pcrb(spec, episodes=episodes, seed=seed, policy=acts)


def paired_metrics(results: dict, backends: list[str], keys: list[str]) -> dict[str, dict]:
    reference = backends[0]
    paired = {}
    for backend in backends[1:]:
        paired[backend] = {}
        for key in keys:
            mean, half = mean_ci95(results[backend, key]["error"] - results[reference, key]["error"])
            paired[backend][key] = {"mean": mean, "ci95": half, "verdict": verdict(mean, half)}
    return paired


# --- outputs -----------------------------------------------------------------------------------------------
def _finite(value: Any) -> Any:
    """JSON-safe: non-finite floats as strings ("inf"), recursively."""
    if isinstance(value, dict):
        return {str(k): _finite(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple, set, frozenset)):
        return [_finite(v) for v in (sorted(value, key=repr) if isinstance(value, (set, frozenset)) else value)]
    if isinstance(value, (float, np.floating)) and not math.isfinite(value):
        return str(float(value))
    return value


def command_line(world, network, backends, sweep_text, policy, episodes, seed, horizon, batched, executor,
                 address, out, name) -> str:
    args = ["coloc", "study", "--world", world, "--network", network, "--backends", ",".join(backends)]
    if sweep_text is not None:
        args += ["--sweep", sweep_text]
    args += ["--policy", policy, "--episodes", str(episodes), "--seed", str(seed)]
    if horizon is not None:
        args += ["--horizon", str(horizon)]
    if batched:
        args.append("--batched")
    args += ["--executor", executor]
    if address:
        args += ["--address", address]
    return shlex.join([*args, "--out", out, "--name", name])


def _table(title: str, backends, keys, cell: Callable[[str, str], str], header: str) -> list[str]:
    lines = [f"## {title}", "", f"| backend | {' | '.join(keys)} |", "|---|" + "---|" * len(keys)]
    lines += [f"| {b} | {' | '.join(cell(b, k) for k in keys)} |" for b in backends]
    return [*lines, "", header, ""] if header else [*lines, ""]


def _bound_text(value) -> str:
    return "-" if value is None else f"{value:.4g}"


def report(metrics: dict, command: str) -> str:
    backends = list(metrics["backends"])
    keys = list(metrics["backends"][backends[0]])
    sweep = metrics["config"]["sweep"]
    column = "default" if sweep is None else f"{sweep['part']}.{sweep['field']}"
    cells = metrics["backends"]
    config = metrics["config"]
    lines = [f"# coloc study: {metrics['world']} over {metrics['network']}", "",
             f"Backends {', '.join(backends)}; policy `{config['policy']}`; {config['episodes']} episodes per cell, "
             f"episode e seeded {config['seed']} + e (the same episodes for every backend and value); columns: "
             f"{column}.", ""]
    lines += _table("Position error (m), mean ± 95 % interval over episodes", backends, keys,
                    lambda b, k: f"{cells[b][k]['position_error']['mean']:.4g} ± "
                                 f"{cells[b][k]['position_error']['ci95']:.2g}", "")
    lines += _table("RMSE (m) and efficiency = RMSE / sqrt(pcrb_centralized)", backends, keys,
                    lambda b, k: f"{cells[b][k]['rmse']:.4g}" + ("" if cells[b][k]["efficiency"] is None
                                                                 else f" ({cells[b][k]['efficiency']:.3g})"),
                    "")
    lines += _table("Posterior Cramér-Rao bounds, sqrt of the mean over steps and agents (m): centralized / "
                    "delivered / local (- where not defined)" + (" [model-based]" if config.get("pcrb_model_based")
                                                                 else ""), backends, keys,
                    lambda b, k: " / ".join(_bound_text(cells[b][k][f"pcrb_{n}"])
                                            for n in ("centralized", "delivered", "local")),
                    "The centralized bound holds every reading fused centrally; delivered what the network carried to "
                    "each agent (where its messages are readings); local each agent's own readings only "
                    "(coloc_env.pcrb, docs/bounds.md).")
    lines += _table("Messages per agent per step", backends, keys,
                    lambda b, k: f"{cells[b][k]['messages_per_step']:.4g}", "")
    lines += _table("Floats per agent per step", backends, keys,
                    lambda b, k: f"{cells[b][k]['floats_per_step']:.4g}", "")
    band = next((cells[b][k]["nees_band"] for b in backends for k in keys if cells[b][k]["nees_band"]), None)
    lines += _table("NEES (mean of e^T P^-1 e, 2 for a consistent 2-D estimate; - without a covariance) and the "
                    "share of (step, agent) whose NEES averaged over the episodes lies in the chi^2 95 % band"
                    + ("" if band is None else f" [{band[0]:.3g}, {band[1]:.3g}]"),
                    backends, keys, lambda b, k: "-" if cells[b][k]["nees"] is None
                    else f"{cells[b][k]['nees']:.3g} ({100 * cells[b][k]['nees_in_band']:.0f} % in band)",
                    "")
    if len(backends) > 1:
        paired = metrics["paired"]
        lines += _table(f"Paired difference in position error against {backends[0]} (m, backend - "
                        f"{backends[0]}, same episodes)", backends[1:], keys,
                        lambda b, k: f"{paired[b][k]['mean']:+.4g} ± {paired[b][k]['ci95']:.2g} "
                                     f"({paired[b][k]['verdict']})", "")
    lines += ["## Command", "", "```", command, "```", ""]
    return "\n".join(lines)


_UNIT_TOKEN = re.compile(r"(?<![\w^/])(m\^2/s\^4|m/s\^2|m\^2|m/s|rad/s|deg/s|dBm|dB|Hz|rad|deg|metres|steps?|hops?|s|m)"
                         r"(?![\w^/])")
_RANGE = re.compile(r"^\s*[\[(]\s*([-+0-9.e]+)\s*,\s*([-+0-9.e]+)\s*[\])]")
_INTEGERS = re.compile(r"^\s*-?\d+\s*\.\.\s*\w+")


def field_unit(kind: str, name: str, field: str) -> str:
    """The unit of part field ``field`` of the registered ``kind`` part ``name`` (``"network"``, ``"relay"``,
    ``"loss_at_zero"``), read from the "allowed" column of the part's documented table: the first unit
    written there (m, s, m/s, rad, dB, steps, ...), ``"-"`` for a range inside [0, 1] without one (a
    probability or a fraction), ``"count"`` for an integer range ``a..b``; ``"as documented"`` where the
    table says none of these."""
    import sys

    import coloc_env.parts as parts

    registry = getattr(parts, kind.upper() + "S", None)
    try:
        cls = registry._class(name)
    except (AttributeError, KeyError, ValueError):
        return "as documented"
    doc = (sys.modules[cls.__module__].__doc__ or "") + (cls.__doc__ or "")
    cell = r"`{0,2}" + re.escape(field) + r"`{0,2}"
    row = re.search(r"^\s*\|\s*" + cell + r"\s*\|[^|]*\|([^|]*)\|", doc, re.M)
    if row is None:
        return "as documented"
    allowed = row.group(1)
    token = _UNIT_TOKEN.search(allowed)
    if token:
        unit = token.group(1)
        return {"metres": "m", "steps": "step", "hops": "hop"}.get(unit, unit)
    bounds = _RANGE.match(allowed)
    if bounds:
        try:
            low, high = float(bounds.group(1)), float(bounds.group(2))
        except ValueError:
            low, high = math.nan, math.nan
        if 0.0 <= low and high <= 1.0:
            return "-"
    if _INTEGERS.match(allowed):
        return "count"
    return "as documented"


def figure(metrics: dict):
    """Position error against the swept value (or per backend without a sweep): each backend's mean with its
    95 % interval as a dot with an error bar (dodged sideways so that backends with equal values stay
    apart), its RMSE (x) and the bound sqrt(pcrb_centralized) (dashed; one black line where it is the
    same for every backend); with two or more backends a second panel with the paired difference to the
    first backend (``paired``) and its 95 % interval. The legend sits right of the panels."""
    import matplotlib

    if not os.environ.get("MPLBACKEND"):
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from train.plotting import label, legend_outside

    backends = list(metrics["backends"])
    keys = list(metrics["backends"][backends[0]])
    sweep = metrics["config"]["sweep"]
    reference = metrics.get("reference", backends[0])
    paired = metrics.get("paired") or {}
    cells = metrics["backends"]

    def number(value):
        return math.nan if value is None or isinstance(value, str) else float(value)

    means = {b: np.array([number(cells[b][k]["position_error"]["mean"]) for k in keys]) for b in backends}
    halves = {b: np.array([number(cells[b][k]["position_error"]["ci95"]) for k in keys]) for b in backends}
    rmse = {b: np.array([number(cells[b][k].get("rmse")) for k in keys]) for b in backends}
    bound = {b: np.array([number(cells[b][k].get("pcrb_centralized")) for k in keys]) for b in backends}
    with_diff = len(backends) > 1 and bool(paired)
    fig, axes = plt.subplots(1, 2 if with_diff else 1, figsize=(10.5 if with_diff else 6.0, 3.9), squeeze=False)
    ax = axes[0, 0]
    if sweep is None:
        x = np.arange(len(backends), dtype=float)
        positions = {b: x[i:i + 1] for i, b in enumerate(backends)}
        dodge = {b: 0.0 for b in backends}
    else:
        values = sweep["values"]
        numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in values)
        x = np.array(values, dtype=float) if numeric else np.arange(len(keys), dtype=float)
        span = float(np.ptp(x)) if len(x) > 1 and np.ptp(x) > 0 else 1.0
        step = 0.04 * span if numeric else 0.12
        dodge = {b: (i - (len(backends) - 1) / 2) * step for i, b in enumerate(backends)}
        positions = {b: x + dodge[b] for b in backends}
    colours = {b: f"C{i}" for i, b in enumerate(backends)}
    handles = []
    cut = slice(None) if sweep is not None else slice(0, 1)  # without a sweep: the one "default" cell
    for b in backends:
        handles.append(ax.errorbar(positions[b], means[b][cut], yerr=halves[b][cut], fmt="o", ms=5, capsize=3,
                                   color=colours[b], label=b))
        ax.plot(positions[b], rmse[b][cut], "x", color=colours[b], ms=7)
    finite = [b for b in backends if np.isfinite(bound[b]).any()]
    same_bound = bool(finite) and len(finite) == len(backends) and all(
        np.allclose(bound[b], bound[finite[0]], rtol=1e-9, atol=0, equal_nan=True) for b in finite)
    if sweep is None:
        for b in finite:
            i = backends.index(b)
            ax.hlines(bound[b][0], i - 0.35, i + 0.35, colors="k" if same_bound else colours[b], linestyles="--")
    elif same_bound:
        ax.plot(x, bound[finite[0]], "k--", lw=1.2)
    else:
        for b in finite:
            ax.plot(x, bound[b], "--", color=colours[b], lw=1.2)
    handles.append(Line2D([], [], color="0.3", marker="x", ls="", ms=7, label="x: RMSE, colour of its backend"))
    if finite:
        text = ("bound sqrt(pcrb_centralized),\nthe same for every backend" if same_bound else
                "dashed: bound sqrt(pcrb_centralized),\ncolour of its backend")
        handles.append(Line2D([], [], color="k" if same_bound else "0.3", ls="--", label=text))
    handles.append(Line2D([], [], color="0.3", marker="o", ls="", label="dot: mean with its 95 % interval"))
    ax.set_ylabel(label("position error", "m"))
    ax.grid(alpha=0.3)
    if sweep is None:
        ax.set_xticks(x, backends, rotation=20)
        ax.set_xlabel("backend")
        ax.set_xlim(-0.6, len(backends) - 0.4)
    else:
        if not numeric:
            ax.set_xticks(x, keys)
        name = metrics["config"]["compositions"][backends[0]][keys[0]][sweep["part"]]["name"]
        xlabel = label(f"{sweep['part']}.{sweep['field']}", field_unit(sweep["part"], name, sweep["field"]))
        ax.set_xlabel(xlabel)
    config = metrics["config"]
    ax.set_title(f"{metrics['world']} / {metrics['network']}: {config['policy']}, {config['episodes']} episodes",
                 fontsize=10)
    target = ax
    if with_diff:
        dx = axes[0, 1]
        dx.axhline(0.0, color="k", lw=0.8)
        for b in backends[1:]:
            diff = np.array([number(paired[b][k]["mean"]) for k in keys])
            half = np.array([number(paired[b][k]["ci95"]) for k in keys])
            dx.errorbar(positions[b], diff[cut], yerr=half[cut], fmt="o", ms=5, capsize=3, color=colours[b])
        dx.set_ylabel(label(f"error - error of {reference}", "m"))
        dx.set_title(f"paired on the same episodes, against {reference}", fontsize=10)
        dx.grid(alpha=0.3)
        dx.set_xlim(ax.get_xlim())
        if sweep is None:
            dx.set_xticks(x, backends, rotation=20)
            dx.set_xlabel("backend")
        else:
            if not numeric:
                dx.set_xticks(x, keys)
            dx.set_xlabel(xlabel)
        target = dx
    legend_outside(target, handles=handles)
    fig.tight_layout()
    return fig


# --- the study ---------------------------------------------------------------------------------------------
def run_study(world: str, network: str, backends: str | Sequence[str], sweep: str | None = None,
              policy: str = "always", episodes: int = 30, seed: int = 0, horizon: int | None = None,
              batched: bool = False, executor: str = "local", address: str | None = None, out: str = "results",
              name: str | None = None, progress: Callable[[int, int], None] | None = None,
              mark: Callable[[str], AbstractContextManager] | None = None) -> tuple[dict, str]:
    """Run the study (see the module docstring) and write its three files; returns (metrics, folder).

    ``progress(done, total)`` is called as episodes finish (per cell with ``batched`` or Ray).
    After every check and before the first episode, the folder is marked: ``mark(folder)`` is entered
    around the computing and the writing, by default ``train.io.result_folder(folder, command line)``,
    whose ``INCOMPLETE`` file stays behind if the study is interrupted (Ctrl-C) or fails; the command
    line passes its own, which also remembers the folder to name it on Ctrl-C."""
    import agents
    import coloc_env

    # 1. every check, before anything is computed or written
    for label, value in (("world", world), ("network", network)):
        if not isinstance(value, str):
            raise BadInput(f"{label} must be a name, one of {list(getattr(coloc_env, label.upper() + 'S'))}, "
                           f"got {value!r}")
    backends = _backend_list(backends)
    parsed = parse_sweep(sweep)
    if not isinstance(policy, str) or policy not in POLICIES:
        raise BadInput(f"policy must be one of {list(POLICIES)}, got {policy!r}")
    if not isinstance(batched, (bool, np.bool_)):
        raise BadInput(f"batched must be True or False, got {batched!r}")
    if batched and policy not in BATCHABLE_POLICIES:
        raise BadInput(f"batched runs support the policies {list(BATCHABLE_POLICIES)} (their actions never read "
                       f"the env), got {policy!r}; run it without batched")
    episodes = _check_int("episodes", episodes, 2, MAX_EPISODES)
    seed = _check_int("seed", seed, 0, MAX_SEED)
    if executor not in ("local", "ray"):
        raise BadInput(f"executor must be 'local' or 'ray', got {executor!r}")
    if not isinstance(out, (str, os.PathLike)):
        raise BadInput(f"out must be a folder path, got {out!r}")
    name = _check_name(study_name(world, network, parsed) if name is None else name)
    cells = build_cells(world, network, backends, parsed, horizon)
    keys = ["default"] if parsed is None else parsed[2]
    for backend in backends:  # the policy exists for each backend's composition (paper: only where defined)
        view = coloc_env.parallel_env(cells[backend, keys[0]])
        agents.make_policy(policy, view, seed=seed)
        view.close()
    from train.io import check_output_folder, result_folder, save_figure, write_json, write_text

    folder = os.path.join(os.fspath(out), "study", name)
    try:
        check_output_folder(folder)  # creates nothing: refused input leaves OUT as it was
    except ValueError as exc:
        raise BadInput(f"study folder not writable: {exc}") from exc
    command = command_line(world, network, backends, sweep, policy, episodes, seed, horizon, batched, executor,
                           address, os.fspath(out), name)

    # from here to the last file the folder is marked INCOMPLETE; an interrupt or a failure leaves the mark
    with result_folder(folder, command) if mark is None else mark(folder):
        # 2. the cells: (backend, value) -> per-episode arrays, the same seeds everywhere
        order = [(b, k) for b in backends for k in keys]
        total = len(order) * (1 if batched else episodes)
        done = 0

        def tick():
            nonlocal done
            done += 1
            if progress:
                progress(done, total)

        if executor == "local":
            results = {cell: run_cell(cells[cell], policy, episodes, seed, batched, tick) for cell in order}
        else:
            from train.executor import map_tasks

            outputs = map_tasks(run_cell, [(cells[cell], policy, episodes, seed, batched) for cell in order], "ray",
                                address, progress=progress)
            results = dict(zip(order, outputs, strict=True))

        # 3. the bounds of each cell on its episodes (coloc_env.pcrb), then metrics, report, figure
        from coloc_env.bounds.models import has_bound_model

        bounds = {cell: cell_bounds(cells[cell], policy, episodes, seed) if has_bound_model(world) else None
                  for cell in order}
        spec0 = cells[order[0]]
        sweep_config = None if parsed is None else {"part": parsed[0], "field": parsed[1], "values": parsed[3],
                                                    "keys": parsed[2]}
        metrics = {
            "world": world,
            "network": network,
            "reference": backends[0],
            "backends": {b: {k: cell_metrics(results[b, k], bounds[b, k]) for k in keys} for b in backends},
            "paired": paired_metrics(results, backends, keys),
            "config": {"seed": seed, "episodes": episodes, "episode_seeds": f"{seed} + e, e = 0..{episodes - 1}",
                       "policy": policy, "sweep": sweep_config, "horizon": horizon,
                       "episode_steps": spec0.episode_steps, "batched": bool(batched),
                       "pcrb_model_based": None if bounds[order[0]] is None else bounds[order[0]]["model_based"],
                       "compositions": {b: {k: {part: getattr(cells[b, k], part).as_dict() for part in PARTS}
                                            for k in keys} for b in backends}},
        }
        metrics = _finite(metrics)
        write_json(os.path.join(folder, "metrics.json"), metrics)
        write_text(os.path.join(folder, "report.md"), report(metrics, command))
        save_figure(os.path.join(folder, FIGURE), figure(metrics))
    return metrics, folder


__all__ = ["FIGURE", "PARTS", "POLICIES", "build_cells", "cell_metrics", "mean_ci95", "parse_sweep", "parse_value",
           "run_cell", "run_study", "study_name", "verdict"]
