"""``coloc evaluate``: a policy's mean estimation error over seeded episodes, with a 95 % interval.

Seeds (documented once, used everywhere):

* training: seed S seeds the network and copy c of the training env with S + c
  (small integers);
* validation (learning curves during training, and every choice made before
  evaluation: the ``best_constant`` horizon, the ``threshold`` rule's spread):
  VALIDATION_SEED_BASE + e;
* ``coloc evaluate``: EVAL_SEED_BASE + e.

The three ranges are disjoint (each holds SEED_RANGE episodes), so no policy is
evaluated on a training seed and nothing is tuned on the evaluation seeds
(``check_not_evaluation_seeds`` refuses a tuning run that asks for them).
Every policy of a scenario plays the same episodes: episode e is
``env.reset(seed=seed_base + e)`` for every policy, so two rows of a
leaderboard pair episode by episode (``train.leaderboard.paired_difference``);
each result keeps its per-episode costs for that.

The metric is the scenario's own, ``Scenario.episode_error`` of every step's
``infos[agent][Scenario.metric_error_key]`` (``"error"`` except where the paper samples
its error elsewhere in the step: relay_ukf's ``"posterior_error"``; by default the sum
over steps and agents); communication is the per-step sum over agents of
``infos[agent]["communication"]`` (components, messages or hops, as the
scenario counts it). ``paper_cost`` adds ``Scenario.initial_cost()``, the
part of a paper's cost an episode does not contain (bandwidth_fusion's k = 0
term).

Reference filters (``REFERENCE_FILTERS``) are rows that are not policies of
the env: another estimator run on the very episodes the env draws for the same
seeds (lossy_fusion's leader-alone Kalman filter and the paper's centralized
filter (A), which the env's actions cannot express). A name starting with
``bound_`` uses what the agents cannot have and is shown apart as a bound.
"""

from __future__ import annotations

import math

import numpy as np

from coloc_env.config import BadInput, module_names

EVAL_SEED_BASE = 10**6
VALIDATION_SEED_BASE = 2 * 10**6
SEED_RANGE = 10**6  # episodes each seed range can hold before it would run into the next
BOUND_PREFIX = "bound_"

# lossy_fusion (fu2017): row name -> (the filter of estimators.lossy_fusion.FILTERS, packets each follower
# sends per slot, what it is). Every row runs on the episode env.reset(seed=seed_base + e) draws
# (train.reproduce.fu2017.filter_runs; a test checks that "distributed" equals the env's paper row).
REFERENCE_FILTERS = {
    "lossy_fusion": {
        "leader_only_kf": ("leader_only_kf", 0.0, "the leader's Kalman filter on its own measurements"),
        "centralized_A": ("centralized", 1.0, "the paper's centralized augmented-state filter (A), every "
                                              "follower sending its measurement each slot"),
        "bound_informed_kf": ("informed_kf", 1.0, "a Kalman filter told every packet's age (the agents have no "
                                                  "time stamps): a bound below (A)"),
    },
}


def is_bound(name: str) -> bool:
    """Bounds (``bound_*``) use hindsight, the truth or information the agents lack; never a baseline."""
    return name.startswith(BOUND_PREFIX)


def reference_rows(scenario: str) -> list[str]:
    """The reference filters ``coloc evaluate`` can add for ``scenario`` (bounds included)."""
    return list(REFERENCE_FILTERS.get(scenario, {}))


def baselines(scenario: str) -> tuple[str, ...]:
    """The strongest realizable baselines of ``scenario``: its policies (``agents.strongest_baselines``)
    and its realizable reference filters; a target is judged against the best of them on paired episodes."""
    import agents

    return (*agents.strongest_baselines(scenario), *(n for n in reference_rows(scenario) if not is_bound(n)))


def extra_rows(scenario: str) -> tuple[str, ...]:
    """Variants worth a row of their own under ``--policy all``: a preset's ``EVALUATE_EXTRA_ROWS`` in
    train/hyperparams/<preset>.py (none by default)."""
    from train import hyperparams

    return tuple(hyperparams.setting(scenario, "EVALUATE_EXTRA_ROWS", ()))


def all_rows(scenario: str) -> list[str]:
    """What ``coloc evaluate S --policy all`` runs besides trained models: the realizable policies (and
    ``extra_rows``), the bounds and the reference filters. A name that builds the same policy as an
    earlier one (``agents.duplicates``: ``always`` = ``paper`` on relay_ukf) is left out; the leaderboard
    names it beside the row it equals."""
    import agents

    same = agents.duplicates(scenario)
    realizable = [n for n in agents.available_policies(scenario) if n not in same]
    return [*realizable, *extra_rows(scenario), *agents.bound_policies(scenario), *reference_rows(scenario)]


# --- bounds and consistency of a row -----------------------------------------------------------------------
NEES_DOF = 2  # the position block
POSE_NEES_DOF = 3  # an SE(2) backend's pose [x, y, heading]


def reported_covariances(scenario, copies=None) -> tuple:
    """What the NEES of a step read: the covariance (B, N, 2, 2) of the infos' estimated position (None without
    one) and, for an SE(2) backend, (estimate, truth, covariance) of the pose at the same time (None otherwise);
    the scenario's ``reported_position_cov`` / ``reported_pose`` (``coloc_env.scenarios.composed``). ``copies``
    keeps those copies of the batch."""
    cov = scenario.reported_position_cov() if hasattr(scenario, "reported_position_cov") \
        else scenario.backend.posterior_position_cov
    pose = scenario.reported_pose() if hasattr(scenario, "reported_pose") else None
    if copies is not None:
        cov = None if cov is None else cov[copies]
        pose = None if pose is None else tuple(a[copies] for a in pose)
    return cov, pose


def _nees(error: np.ndarray, cov) -> np.ndarray:
    solved = np.einsum("...ij,...j->...i", np.linalg.pinv(np.asarray(cov, float)), error)
    return np.einsum("...i,...i->...", error, solved)


def _trace_step(trace: dict, actions: np.ndarray, info: dict, cov, pose=None) -> None:
    """One step of every copy: actions (B, N, ...), squared errors (B, N) of the 2-D position, NEES (B, N) or None,
    and with ``pose`` = (estimate, truth, covariance) of an SE(2) backend the pose NEES (B, N) (heading error
    wrapped to (-pi, pi]); ``pose_nees`` is None when a step has none.

    The 2-D position: the first two components of estimated_position - true_position, the plane the bound's and
    the backends' position covariance describe (a preset reporting a 3-D target position, lossy_fusion and
    bandwidth_fusion, is reduced to its x, y)."""
    trace.setdefault("actions", []).append(np.array(actions, float))
    error = (np.asarray(info["estimated_position"], float) - np.asarray(info["true_position"], float))[..., :2]
    trace.setdefault("squared", []).append(np.sum(error**2, axis=-1))
    if cov is None:
        trace["nees"] = None
    elif trace.get("nees", []) is not None:
        trace.setdefault("nees", []).append(_nees(error, cov))
    if pose is None:
        trace["pose_nees"] = None
    elif trace.get("pose_nees", []) is not None:
        estimate, truth, pose_cov = (np.asarray(a, float) for a in pose)
        pose_error = estimate - truth
        pose_error[..., 2] = (pose_error[..., 2] + np.pi) % (2 * np.pi) - np.pi
        trace.setdefault("pose_nees", []).append(_nees(pose_error, pose_cov))


def _merge_trace(into: dict, part: dict) -> None:
    """Append a chunk's (or an episode's) trace along the episode axis (steps stacked first)."""
    stacked = {key: (None if value is None else np.stack(value, axis=1)) for key, value in part.items()}
    for key, value in stacked.items():
        if value is None or into.get(key, 0) is None:
            into[key] = None
        else:
            into.setdefault(key, []).append(value)


class _Replay:
    """Episode e's recorded actions, step after step, as a policy ``coloc_env.pcrb`` can play (it reads no
    observation: ``blind``)."""

    blind = True

    def __init__(self, names, steps: np.ndarray):
        self.names, self.steps, self.k = list(names), steps, 0

    def __call__(self, observations):
        actions = self.steps[self.k]
        self.k += 1
        return {name: actions[i] for i, name in enumerate(self.names)}


def attach_bounds(result: dict, scenario: str, seed_base: int, trace: dict, bounds: bool = True,
                  bound_episodes: int | None = None, **env_config) -> dict:
    """The row plus ``rmse`` (m, sqrt of the mean squared 2-D position error, ``_trace_step``), ``nees`` with
    ``nees_band`` (the chi^2(2E)/E 95 % band of a per-step NEES averaged over the E episodes) and ``nees_in_band``
    (the share of (step, agent) in it), for an SE(2) backend ``pose_nees``, ``pose_nees_band`` (chi^2(3E)/E) and
    ``pose_nees_in_band`` likewise, and, with ``bounds``, ``coloc_env.pcrb`` on the very episodes and actions
    played: ``pcrb_centralized``, ``pcrb_local``, ``pcrb_delivered`` (sqrt of the mean over steps and agents, m;
    None where not defined), ``efficiency`` = rmse / pcrb_centralized and ``pcrb_model_based``.

    ``bound_episodes`` K: the bounds on the first K of the E episodes only (``pcrb_episodes`` says how many). A
    bound replays its episodes one env at a time, which costs far more than the batched play; where a row is
    judged by its error over many episodes (``coloc frontier``), its bounds are reference marks from a few."""
    from scipy import stats

    import coloc_env
    from coloc_env.bounds.models import has_bound_model

    out = dict(result)
    chunks = trace.get("squared")
    if not chunks:
        return out
    squared = np.concatenate(chunks, axis=0)  # (E, K, N)
    rmse = float(np.sqrt(squared.mean()))
    out["rmse"] = rmse
    E = squared.shape[0]
    for key, dof in (("nees", NEES_DOF), ("pose_nees", POSE_NEES_DOF)):
        nees = trace.get(key)
        if nees is None:
            if key == "nees":  # the pose NEES columns only where a backend estimates poses
                out.update(nees=None, nees_band=None, nees_in_band=None)
            continue
        per_step = np.concatenate(nees, axis=0)  # (E, K, N)
        low, high = (float(stats.chi2.ppf(q, E * dof) / E) for q in (0.025, 0.975))
        mean_step = per_step.mean(axis=0)
        out.update({key: float(per_step.mean()), f"{key}_band": [low, high],
                    f"{key}_in_band": float(np.mean((mean_step >= low) & (mean_step <= high)))})
    out.update(pcrb_centralized=None, pcrb_local=None, pcrb_delivered=None, efficiency=None, pcrb_model_based=None,
               pcrb_episodes=None)
    spec = (coloc_env.composition_named(scenario) if coloc_env.is_composition_name(scenario)
            else coloc_env.PRESETS.get(scenario))
    if not bounds or spec is None or not has_bound_model(spec.world.name):
        return out
    actions = np.concatenate(trace["actions"], axis=0)  # (E, K, N, ...)
    names = coloc_env.make_core(scenario, batch=1, **env_config).agent_names
    played = E if bound_episodes is None else min(E, bound_episodes)
    replays = [_Replay(names, actions[e]) for e in range(played)]
    bound = coloc_env.pcrb(spec, episodes=played, seed=seed_base, policy=replays, **env_config)
    out["pcrb_episodes"] = played
    for key in ("centralized", "local", "delivered"):
        out[f"pcrb_{key}"] = float(np.sqrt(np.mean(bound[key]))) if key in bound else None
    out["efficiency"] = rmse / out["pcrb_centralized"] if out["pcrb_centralized"] else None
    out["pcrb_model_based"] = bool(bound["model_based"])
    return out


def check_not_evaluation_seeds(seed_base: int, episodes: int, what: str) -> None:
    """Refuse a tuning run whose seeds seed_base .. seed_base + episodes - 1 meet the evaluation seeds."""
    if seed_base < EVAL_SEED_BASE + SEED_RANGE and seed_base + episodes > EVAL_SEED_BASE:
        raise BadInput(f"{what}: seed_base {seed_base} with {episodes} episodes overlaps the evaluation seeds "
                       f"[{EVAL_SEED_BASE}, {EVAL_SEED_BASE + SEED_RANGE}); choose on validation seeds "
                         f"(seed_base >= {VALIDATION_SEED_BASE})")


def mean_ci95(values) -> tuple[float, float]:
    """Mean and the half-width of its 95 % Student-t interval (t_{0.975, n-1} s / sqrt(n)); nan for n < 2."""
    from scipy import stats

    values = np.asarray(values, float)
    if len(values) < 2:
        return float(values.mean()) if len(values) else float("nan"), float("nan")
    half = stats.t.ppf(0.975, len(values) - 1) * values.std(ddof=1) / math.sqrt(len(values))
    return float(values.mean()), float(half)


def summarize(scenario, policy_name: str, costs, comms, seed_base: int, initial_cost: float) -> dict:
    """One leaderboard row; ``per_episode_cost`` / ``per_episode_communication`` (episode e: seed seed_base + e)
    are what the paired comparisons use."""
    costs = np.asarray(costs, float)
    comms = np.broadcast_to(np.asarray(comms, float), costs.shape)
    mean, half = mean_ci95(costs)
    return {
        "scenario": scenario,
        "policy": policy_name,
        "episodes": len(costs),
        "seed_base": seed_base,
        "mean_cost": mean,
        "ci95": half,
        "paper_cost": float(mean + initial_cost),
        "initial_cost": float(initial_cost),
        "communication_per_step": float(np.mean(comms)),
        "per_episode_cost": [float(c) for c in costs],
        "per_episode_communication": [float(c) for c in comms],
    }


# --- a trained model's communication cost --------------------------------------------------------------
COST_TAG = " @ cost="  # a model's row at one communication cost: ``PATH.zip @ cost=c``


def trained_costs(path: str) -> tuple[tuple[float, float] | None, float | None]:
    """(``cost_range``, fixed ``communication_cost``) a model was trained with, read from its run's ``model.json``
    (``agents.sb3.model_metadata``); (None, None) where there is none or it records neither."""
    from agents.sb3 import model_metadata

    meta = model_metadata(path)
    if meta is None:
        return None, None
    env_config = meta.get("env_config") if isinstance(meta.get("env_config"), dict) else {}
    cost_range = meta.get("cost_range", env_config.get("cost_range"))
    fixed = env_config.get("communication_cost")
    return (None if cost_range is None else (float(cost_range[0]), float(cost_range[1])),
            None if fixed is None else float(fixed))


def model_actions(path: str) -> str:
    """How the model ``path`` acts, as its run's ``model.json`` records it (``train.hyperparams.ACTIONS``):
    ``"sampled"`` or ``"deterministic"`` (also where it records none)."""
    from agents.sb3 import model_metadata, samples_actions

    return "sampled" if samples_actions(model_metadata(path)) else "deterministic"


def median_cost(cost_range: tuple[float, float]) -> float:
    """The median of ``cost_range``'s law (``coloc_env.composition``): sqrt(lo hi) for the log-uniform law (lo > 0),
    hi / 2 for the uniform one (lo = 0)."""
    lo, hi = cost_range
    return math.sqrt(lo * hi) if lo > 0 else hi / 2


def model_row(path: str, cost: float | None = None) -> tuple[str, float | None]:
    """(row name, the ``communication_cost`` of the env it plays in; None: the scenario's default) of the model
    ``path`` evaluated at ``cost``. The observation carries the episode's cost, so a model plays at cost c in an
    env built with ``communication_cost=c``.

    | ``cost`` | model trained over ``cost_range``            | model trained at a fixed cost x                |
    |----------|----------------------------------------------|------------------------------------------------|
    | c        | ``PATH.zip @ cost=c``                        | ``PATH.zip @ cost=c (trained at fixed cost x)`` |
    |          |                                              | (``(no training cost recorded)`` without x)    |
    | None     | ``PATH.zip`` at m, the median of its range   | ``PATH.zip`` at x, the cost it observed in     |
    |          | (``median_cost``)                            | training (the scenario's default where         |
    |          |                                              | model.json records none)                       |

    A row records the cost it was played at (``communication_cost``).
    """
    cost_range, fixed = trained_costs(path)
    if cost is None:
        return path, (fixed if cost_range is None else median_cost(cost_range))
    name = f"{path}{COST_TAG}{cost:g}"
    if cost_range is None:
        name += " (no training cost recorded)" if fixed is None else f" (trained at fixed cost {fixed:g})"
    return name, float(cost)


def check_costs(costs) -> list[float]:
    """``costs`` (``--costs``): one or more distinct numbers in [0, ``COST_LIMIT``], else a ``BadInput`` naming
    ``--costs`` and the range."""
    from coloc_env.composition import COST_LIMIT
    from coloc_env.config import check_range

    costs = list(costs)
    if not costs:
        raise BadInput(f"--costs must name at least one cost in [0, {COST_LIMIT:g}]")
    for c in costs:
        check_range("--costs", c, 0.0, COST_LIMIT)
    if len(set(map(float, costs))) != len(costs):
        raise BadInput(f"--costs must not repeat a cost, got {costs}")
    return [float(c) for c in costs]


def evaluate_policy(scenario: str, policy_name: str, episodes: int, seed_base: int = EVAL_SEED_BASE,
                    progress=None, stochastic: bool | None = None, bounds: bool = True, cost: float | None = None,
                    bound_episodes: int | None = None) -> dict:
    """A trained model (``.zip``) on the batched core, a reference filter on the same episodes, any other
    policy through the PettingZoo env.

    The two env paths give the same episodes (``vector_env`` equals ``parallel_env``
    copy for copy; a test checks the costs agree); the batched one runs every
    episode in one call per step. ``stochastic``: True, a model samples its actions
    (torch seeded with ``seed_base``) and is recorded as ``PATH.zip (stochastic)``; False, it takes its most
    likely ones; None, as its ``model.json`` records (``model_actions``: a model trained with sampled actions
    samples).
    A model plays in an env built with the ``communication_cost`` of ``model_row(policy_name, cost)`` and its
    row takes that name (``cost`` applies to models only: the fixed policies never read the cost).
    Every policy row gets the columns of ``attach_bounds`` (``bounds=False``: RMSE and NEES only; ``bound_episodes``:
    the bounds on the first that many episodes).
    """
    if cost is not None and not policy_name.endswith(".zip"):
        raise BadInput(f"a communication cost applies to trained models (PATH.zip), not to {policy_name!r}, "
                       "which does not read it")
    if policy_name in REFERENCE_FILTERS.get(scenario, {}):
        result = run_reference_filter(scenario, policy_name, episodes, seed_base)
        if progress:
            for _ in range(episodes):
                progress()
        return result
    trace: dict = {}
    if not policy_name.endswith(".zip"):
        result = run_policy_batched(scenario, policy_name, episodes, seed_base, trace=trace)
        if result is None:
            trace = {}
            result = run_episodes(scenario, policy_name, episodes, seed_base, progress, trace=trace)
        elif progress:
            for _ in range(episodes):
                progress()
        return attach_bounds(result, scenario, seed_base, trace, bounds, bound_episodes)
    import agents
    import coloc_env

    if episodes < 2:
        raise BadInput(f"episodes must be >= 2 for a confidence interval, got {episodes}")
    name, communication_cost = model_row(policy_name, cost)
    env_config = {} if communication_cost is None else {"communication_cost": communication_cost}
    try:
        env = coloc_env.parallel_env(scenario, **env_config)
    except ValueError as exc:
        raise BadInput(f"{scenario} cannot be evaluated at communication cost {communication_cost:g}: {exc}") from exc
    policy = agents.make_policy(policy_name, env)  # checks scenario and spaces
    if stochastic is None:
        stochastic = model_actions(policy_name) == "sampled"
    result = run_model_batched(policy.model, scenario, episodes, seed_base, deterministic=not stochastic, trace=trace,
                               paper_entries=policy.paper_entries, **env_config)
    if progress:
        for _ in range(episodes):
            progress()
    result = attach_bounds(result, scenario, seed_base, trace, bounds, bound_episodes)
    return dict(result, policy=name + (" (stochastic)" if stochastic else ""), communication_cost=communication_cost)


def run_reference_filter(scenario: str, name: str, episodes: int, seed_base: int = EVAL_SEED_BASE,
                         **env_config) -> dict:
    """A reference filter of ``REFERENCE_FILTERS`` on the episodes the env draws for seeds seed_base + e.

    lossy_fusion's metric is the fused position MSE averaged over the slots (its ``episode_error``);
    communication is the packets the followers send per slot as the env counts them.
    """
    filters = REFERENCE_FILTERS.get(scenario, {})
    if name not in filters:
        raise BadInput(f"unknown reference filter {name!r} for {scenario}; available: {list(filters)}")
    if episodes < 2:
        raise BadInput(f"episodes must be >= 2 for a confidence interval, got {episodes}")
    costs, comms = reference_filter_costs(scenario, filters[name][0], episodes, seed_base, **env_config)
    return summarize(scenario, name, costs, comms * filters[name][1], seed_base, 0.0)


def reference_filter_costs(scenario: str, filter_name: str, episodes: int, seed_base: int,
                           **env_config) -> tuple[np.ndarray, float]:
    """Per-episode costs (episodes,) of one of fu2017's filters and the followers' count L - 1."""
    from coloc_env.config import build_config
    from coloc_env.scenarios.lossy_fusion import LossyFusionConfig
    from train.reproduce.fu2017 import filter_runs

    if scenario != "lossy_fusion":
        raise BadInput(f"reference filters exist for {list(REFERENCE_FILTERS)}, not {scenario!r}")
    config = build_config(LossyFusionConfig, env_config)
    seeds = [seed_base + e for e in range(episodes)]
    errors = filter_runs(config, seeds, (filter_name,))["errors"][filter_name]  # (episodes, K) squared errors
    return errors.mean(axis=1), float(config.num_agents - 1)


def run_episodes(scenario: str, policy_name: str, episodes: int, seed_base: int = EVAL_SEED_BASE,
                 progress=None, trace: dict | None = None, **env_config) -> dict:
    """Any policy by name through the PettingZoo env, one episode per seed ``seed_base + e``."""
    import agents
    import coloc_env

    if episodes < 2:
        raise BadInput(f"episodes must be >= 2 for a confidence interval, got {episodes}")
    env = coloc_env.parallel_env(scenario, **env_config)
    policy = agents.make_policy(policy_name, env, seed=seed_base)
    error_key, weight_key = env.scenario.metric_error_key, env.scenario.metric_weight_key
    costs, comms = [], []
    for e in range(episodes):
        observations, _ = env.reset(seed=seed_base + e)
        policy.start_episode(seed_base + e)
        errors, weights, comm = [], [], 0.0
        episode_trace = {} if trace is not None else None
        while env.agents:
            chosen = policy.act(observations)
            observations, _, _, _, infos = env.step(chosen)
            if episode_trace is not None:
                order = env.possible_agents
                info = {key: np.array([[infos[a][key] for a in order]], float)
                        for key in ("position_error", "estimated_position", "true_position")}
                _trace_step(episode_trace, np.array([[np.asarray(chosen[a], float) for a in order]]), info,
                            *reported_covariances(env.scenario))
            errors.append([float(infos[a][error_key]) for a in env.possible_agents])
            if weight_key:
                weights.append([float(infos[a][weight_key]) for a in env.possible_agents])
            comm += sum(float(info.get("communication", 0.0)) for info in infos.values())
        costs.append(float(env.scenario.episode_error(np.array(errors), np.array(weights) if weight_key else None)))
        comms.append(comm / len(errors))
        if episode_trace is not None:
            _merge_trace(trace, episode_trace)
        if progress:
            progress()
    return summarize(scenario, policy_name, costs, comms, seed_base, env.scenario.initial_cost())


def _run_core(scenario: str, episodes: int, seed_base: int, choose, env_config: dict,
              trace: dict | None = None) -> tuple:
    """Steps ``episodes`` copies of the batched core (copy e seeded ``seed_base + e``) with
    ``choose(core) -> actions (episodes, N, *action_shape)``; returns (costs, comms per step, initial cost).
    ``trace`` (a dict) receives what ``attach_bounds`` needs, per step (lists of (B, ...) arrays: callers
    ``_merge_trace`` them into episode-first arrays): the actions, squared position errors and NEES."""
    import coloc_env

    core = coloc_env.make_core(scenario, batch=episodes, **env_config)
    core.reset([np.random.default_rng(seed_base + e) for e in range(episodes)])
    errors, weights, comm = [], [], np.zeros(episodes)
    while not core.done().all():
        actions = choose(core)
        core.step(actions)
        info = core.info()
        if trace is not None:
            _trace_step(trace, np.asarray(actions, float), info, *reported_covariances(core))
        errors.append(info[core.metric_error_key])
        if core.metric_weight_key:
            weights.append(info[core.metric_weight_key])
        comm += info["communication"].sum(axis=-1) if "communication" in info else 0.0
    # (episodes, T, N) -> (episodes,)
    cost = core.episode_error(np.stack(errors, axis=1), np.stack(weights, axis=1) if weights else None)
    return cost, comm / len(errors), core.initial_cost()


# Copies of the batched core one call of run_policy_batched steps at once: enough to amortize the step's
# per-call cost, few enough that a particle backend's arrays stay small.
EVALUATION_BATCH = 128


class _CoreView:
    """What a policy of ``batching = "core"`` reads of its env, with the batched core as the scenario:
    ``scenario`` and ``unwrapped.scenario`` are the core; agents and spaces are the single env's."""

    def __init__(self, core, env):
        self.scenario = core
        self.unwrapped = self
        self.possible_agents = env.possible_agents
        self.agents = list(env.possible_agents)
        self.action_space = env.action_space
        self.observation_space = env.observation_space


def run_policy_batched(scenario: str, policy_name: str, episodes: int, seed_base: int = EVAL_SEED_BASE,
                       trace: dict | None = None, **env_config) -> dict | None:
    """A named policy on copies of the batched core, every episode of a chunk in one call per step; None
    where the policy does not batch (``Policy.batching`` is None: ``run_episodes`` plays it).

    Episode e is the copy seeded ``seed_base + e`` and plays what ``run_episodes`` plays for it:
    a ``per_copy`` policy acts on copy e's observations alone (a shallow copy of the policy per episode,
    its generator restarted by ``start_episode(seed_base + e)``); a ``core`` policy is built on the
    batched core (``_CoreView``) and computes every copy at once. Tests hold the two paths equal.
    """
    import copy

    import agents
    import coloc_env

    if episodes < 2:
        raise BadInput(f"episodes must be >= 2 for a confidence interval, got {episodes}")
    env = coloc_env.parallel_env(scenario, **env_config)
    probe = agents.make_policy(policy_name, env, seed=seed_base)
    if probe.batching not in ("per_copy", "core"):
        return None
    order = list(env.possible_agents)
    costs, comms, initial = [], [], 0.0
    for start in range(0, episodes, EVALUATION_BATCH):
        count = min(EVALUATION_BATCH, episodes - start)
        if probe.batching == "core":
            built = {}

            def choose(core, built=built):
                if "policy" not in built:  # built on the reset core, so that it reads this batch
                    built["policy"] = agents.make_policy(policy_name, _CoreView(core, env), seed=seed_base)
                return np.asarray(built["policy"].batch_actions(), float)
        else:
            policies = [copy.copy(probe) for _ in range(count)]
            for e, policy in enumerate(policies):
                policy.start_episode(seed_base + start + e)

            def choose(core, policies=policies):
                observations = core.observation()
                actions = []
                for e, policy in enumerate(policies):
                    chosen = policy.act({a: observations[e, i] for i, a in enumerate(order)})
                    actions.append(np.stack([np.asarray(chosen[a]).astype(float) for a in order]))
                return np.stack(actions)

        chunk = {} if trace is not None else None
        cost, comm, initial = _run_core(scenario, count, seed_base + start, choose, env_config, chunk)
        if chunk is not None:
            _merge_trace(trace, chunk)
        costs.append(cost)
        comms.append(comm)
    return summarize(scenario, policy_name, np.concatenate(costs), np.concatenate(comms), seed_base, initial)


def run_model_batched(model, scenario: str, episodes: int, seed_base: int, deterministic: bool = True,
                      trace: dict | None = None, paper_entries=None, **env_config) -> dict:
    """An SB3 model on ``episodes`` copies of the batched core at once (copy e seeded ``seed_base + e``).

    Steps the scenario core directly rather than the VecEnv, whose auto-reset
    would discard the last step's infos. A MaskablePPO model gets the core's action
    masks, as in training, a centralized-critic model the core's ``state()``, and a RecurrentPPO model its
    LSTM memory from the step before (fresh at each episode's first step).
    Deterministic actions by default; sampled ones (``deterministic=False``) draw from torch's
    generator, seeded here with ``seed_base`` so that the run repeats. ``paper_entries``
    (``agents.paper_entries``) fills the entries the model leaves to the paper's rule, copy e drawing from
    ``episode_generator(seed_base + e)`` as the paper's policy does in that episode.
    """
    if not deterministic:
        import torch

        torch.manual_seed(seed_base)

    from agents.centralized_critic import extend_observation, is_centralized
    from agents.sb3 import is_maskable, is_recurrent

    masked = is_maskable(model)
    centralized = is_centralized(model)
    memory = {"lstm": None} if is_recurrent(model) else None  # every agent's LSTM memory, carried step to step
    if paper_entries is not None:
        from agents.base import episode_generator

        generators = [episode_generator(seed_base + e) for e in range(episodes)]

    def choose(core):
        observation = own = core.observation()
        if centralized:  # the model's input; its actor reads only the own observation
            observation = extend_observation(observation, core.state())
        rows = episodes * core.num_agents
        extra = {"action_masks": np.asarray(core.action_mask(), bool).reshape(rows, -1)} if masked else {}
        if memory is not None:
            extra = {"state": memory["lstm"], "episode_start": np.full(rows, memory["lstm"] is None)}
        actions, carried = model.predict(observation.reshape(rows, *observation.shape[2:]),
                                         deterministic=deterministic, **extra)
        if memory is not None:
            memory["lstm"] = carried
        actions = np.asarray(actions).reshape(episodes, core.num_agents, *core.action_space().shape)
        if paper_entries is not None:
            actions = paper_entries.entries(generators, own, actions)
        return np.asarray(actions, dtype=float)

    chunk = {} if trace is not None else None
    cost, comm, initial = _run_core(scenario, episodes, seed_base, choose, env_config, chunk)
    if chunk is not None:
        _merge_trace(trace, chunk)
    return summarize(scenario, "model", cost, comm, seed_base, initial)


def run_rule_batched(scenario: str, name: str, rule, episodes: int, seed_base: int, **env_config) -> dict:
    """A policy given as a batched rule ``rule(core) -> actions (B, N, *shape)`` on the batched core.

    For the validation sweeps: the rules of ``agents`` that read only the observation
    (``ConstantPolicy``, ``ThresholdPolicy``) have a batched form, so a sweep runs every
    episode of a candidate in one call per step (a test checks it equals the env loop).
    """
    cost, comm, initial = _run_core(scenario, episodes, seed_base, rule, env_config)
    return summarize(scenario, name, cost, comm, seed_base, initial)


def constant_horizon_sweep(windows, episodes: int, seed_base: int = VALIDATION_SEED_BASE, **env_config) -> dict:
    """nlos_horizon: each constant horizon N of ``windows`` (all packets kept) on the same validation
    episodes; returns N -> its result row. ``agents.nlos_horizon.BEST_CONSTANT_WINDOW`` is the argmin
    of the mean cost over N of such a sweep (never on evaluation seeds)."""
    check_not_evaluation_seeds(seed_base, episodes, "constant_horizon_sweep")
    out = {}
    for window in windows:
        def rule(core, window=int(window)):
            return core.encode_actions(np.full((core.batch, core.num_agents), window))

        out[int(window)] = run_rule_batched("nlos_horizon", f"constant:{int(window)}", rule, episodes, seed_base,
                                            **env_config)
    return out


def threshold_sweep(spreads, episodes: int, seed_base: int = VALIDATION_SEED_BASE, **env_config) -> dict:
    """gps_denied_nbp: the ``threshold:S`` rule (``agents.gps_denied_nbp.threshold_actions``) for each spread S
    in metres, and the paper's schedule (key ``inf``), on the same validation episodes."""
    from agents.gps_denied_nbp import threshold_actions

    check_not_evaluation_seeds(seed_base, episodes, "threshold_sweep")
    out = {}
    for spread in [*spreads, math.inf]:
        def rule(core, spread=float(spread)):
            return threshold_actions(core.observation(), spread, core.config.num_iterations)

        name = "paper" if math.isinf(spread) else f"threshold:{spread:g}"
        out[float(spread)] = run_rule_batched("gps_denied_nbp", name, rule, episodes, seed_base, **env_config)
    return out


def _extra_rows() -> dict:
    from train import hyperparams

    return hyperparams.presets_declaring("EVALUATE_EXTRA_ROWS")


# the table of extra rows this module held before each preset's hyperparameters declared them
__getattr__ = module_names(__name__, {"EXTRA_ROWS": _extra_rows},
                           deprecated={"EXTRA_ROWS": "EVALUATE_EXTRA_ROWS in train/hyperparams/<preset>.py"})
