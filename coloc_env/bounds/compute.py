"""``pcrb``: the bounds of a composition over seeded episodes (the package docstring, ``coloc_env.bounds``)."""

from __future__ import annotations

import numpy as np

from coloc_env.bounds.models import bound_problem, stand_in
from coloc_env.bounds.problem import BoundProblem, Recursion
from coloc_env.bounds.record import POLICIES, reads_backend, record_play
from coloc_env.composition import Composition
from coloc_env.cores import composition_named, is_composition_name, make_core
from coloc_env.presets import PRESETS
from estimators.bounds import DEFAULT_REGULARIZATION


def _stand_in(core, policy):
    """What runs in the backend's place during the play (``record_play``), or None where the backend must run.

    What the world reads depends on the actions only, never on the backend's state: under a policy that reads no
    observation (a name, or a callable marked ``blind``) a backend whose messages do not define the bound need
    not run, nor one whose packets the world's own nodes send (the bound model's stand-in asks the network), unless
    the scenario's own step reads the backend's result."""
    blind = not callable(policy) or bool(getattr(policy, "blind", False))
    content = core.composition.backend.message_content
    substitute = stand_in(core) if content == "readings" else None
    if not blind or reads_backend(core) or (content == "readings" and substitute is None):
        return None
    return substitute if substitute is not None else True


def _resolve(spec_or_name):
    if isinstance(spec_or_name, Composition):
        return spec_or_name
    if is_composition_name(spec_or_name):
        return composition_named(spec_or_name)
    if isinstance(spec_or_name, str) and spec_or_name in PRESETS:
        return PRESETS[spec_or_name]
    raise ValueError(f"pcrb: spec must be a Composition, a preset name {list(PRESETS)} or "
                     f"WORLD/NETWORK/BACKEND, got {spec_or_name!r}")


def pcrb(spec_or_name, episodes: int = 16, seed: int = 0, policy="always",
         regularization: float = DEFAULT_REGULARIZATION, **config) -> dict:
    """The posterior Cramér–Rao bounds of a composition (module docstring): a dict with ``"centralized"``,
    ``"local"`` and, where defined, ``"delivered"``, each (K, N) in m^2, plus ``"model_based"`` (bool) and, where
    ``delivered`` is left out, ``"delivered_reason"``.

    | argument        | allowed                                                                    |
    |-----------------|----------------------------------------------------------------------------|
    | spec_or_name    | a Composition, a preset name or ``WORLD/NETWORK/BACKEND``                    |
    | episodes        | 1..100000 (E; episode e is reset with seed ``seed + e``)                    |
    | seed            | an integer >= 0                                                            |
    | policy          | ``"always"``, ``"silent"``, ``"random"``, a callable act(observations), or a  |
    |                 | sequence of E callables (episode e plays the e-th: seeded per-episode policies) |
    | regularization  | [0, 1e-3]: relative ridge on a per-episode singular Q (estimators.bounds)   |
    | config          | a preset's flat config keywords (``data=`` for mrclam_relay)                |
    """
    if isinstance(episodes, bool) or not isinstance(episodes, (int, np.integer)) or not 1 <= episodes <= 100_000:
        raise ValueError(f"episodes must be an integer in [1, 100000], got {episodes!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    if isinstance(policy, (list, tuple)):
        if len(policy) != episodes or not all(callable(p) for p in policy):
            raise ValueError(f"policy as a sequence must hold one callable per episode ({episodes}), got {policy!r}")
    elif not callable(policy) and policy not in POLICIES:
        raise ValueError(f"policy must be one of {list(POLICIES)} or a callable act(observations) -> actions, "
                         f"got {policy!r}")
    if not 0.0 <= float(regularization) <= 1e-3:
        raise ValueError(f"regularization must be in [0, 1e-3], got {regularization!r}")
    spec = _resolve(spec_or_name)
    rng = np.random.default_rng(int(seed)) if policy == "random" else None
    problems, outs = [], []
    for e in range(int(episodes)):
        # one copy per episode: the episode env.reset(seed=seed + e) plays, whatever a backend's batching
        core = make_core(spec, batch=1, **config)
        played = policy[e] if isinstance(policy, (list, tuple)) else policy
        record = record_play(core, np.random.default_rng(int(seed) + e), played, rng, _stand_in(core, played))
        steps = record.steps
        problem = bound_problem(core, record)
        if problem.per_episode:  # each episode its own bound: computed now, its arrays dropped
            outs.append(_bounds(problem, steps, core.num_agents, regularization))
        else:
            problem.readings = None
            problems.append(problem)
    K, N = steps, core.num_agents
    if outs:
        out = dict(outs[0])
        for key in ("centralized", "local", "delivered"):
            if key in out:
                out[key] = np.mean([o[key] for o in outs], axis=0)
    else:
        out = _bounds(_merge(problems), K, N, regularization)
    return out


def _bounds(problem: BoundProblem, K: int, N: int, regularization: float) -> dict:
    out = {"centralized": problem.centralized.run(regularization), "model_based": bool(problem.model_based)}
    out["local"] = _assemble(problem.local, problem.local_agents, K, N, regularization)
    if problem.delivered is not None:
        out["delivered"] = _assemble(problem.delivered, problem.delivered_agents, K, N, regularization)
    else:
        out["delivered_reason"] = problem.delivered_reason
    return out


def _collapse(arrays):
    """Per-episode F or Q (K-1, n, n) -> (K-1, n, n) where every episode has the same, else (K-1, E, n, n)."""
    if arrays[0] is None:
        return None
    first = np.asarray(arrays[0])
    if all(np.array_equal(first, a) for a in arrays[1:]):
        return first
    return np.stack([np.asarray(a) for a in arrays], axis=1)


def _merge_recursions(recursions: list[Recursion]) -> Recursion:
    first = recursions[0]
    return Recursion(first.P0, np.mean([r.info for r in recursions], axis=0), _collapse([r.F for r in recursions]),
                     _collapse([r.Q for r in recursions]), first.positions)


def _merge(problems: list[BoundProblem]) -> BoundProblem:
    """The D-terms of every episode averaged: the reading information's mean per step; F and Q kept per episode
    where they differ (estimators.bounds takes the expectations over them)."""
    first = problems[0]
    merged = BoundProblem(_merge_recursions([p.centralized for p in problems]),
                          [_merge_recursions([p.local[i] for p in problems]) for i in range(len(first.local))],
                          first.local_agents, model_based=first.model_based, delivered_reason=first.delivered_reason)
    if first.delivered is not None:
        merged.delivered = [_merge_recursions([p.delivered[i] for p in problems]) for i in range(len(first.delivered))]
        merged.delivered_agents = first.delivered_agents
    return merged


def _assemble(recursions, agents, K: int, N: int, regularization: float) -> np.ndarray:
    out = np.full((K, N), np.nan)
    for recursion, columns in zip(recursions, agents, strict=True):
        out[:, np.asarray(columns)] = recursion.run(regularization)
    return out
