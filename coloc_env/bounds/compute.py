"""``pcrb``: the bounds of a composition over seeded episodes (the package docstring, ``coloc_env.bounds``)."""

from __future__ import annotations

import numpy as np

from coloc_env.bounds.information_set import SetRecursion, held, receiver_entries
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
    observation (a name, or a callable marked ``blind``) a backend that sends nothing need not run, nor one whose
    packets the world's own nodes send (the bound model's stand-in asks the network), unless the scenario's own
    step reads the backend's result; one whose messages define the bound (readings or estimates) runs."""
    blind = not callable(policy) or bool(getattr(policy, "blind", False))
    content = core.composition.backend.message_content
    substitute = stand_in(core) if content == "readings" else None
    if not blind or reads_backend(core) or content == "estimates" or (content == "readings" and substitute is None):
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


LAG_CAP = 40  # the information-set bound's default lag cap L (coloc_env.bounds.information_set)


def pcrb(spec_or_name, episodes: int = 16, seed: int = 0, policy="always",
         regularization: float = DEFAULT_REGULARIZATION, lag_cap: int = LAG_CAP, **config) -> dict:
    """The posterior Cramér–Rao bounds of a composition (module docstring): a dict with ``"centralized"``,
    ``"local"`` and, where defined, ``"delivered"``, each (K, N) in m^2, plus ``"model_based"`` (bool), where
    ``delivered`` is left out, ``"delivered_reason"``, and where it is the information-set bound (a backend whose
    messages carry estimates), ``"delivered_capped"``: the share of the delivered readings that arrived later
    than ``lag_cap`` steps after they were taken (credited at that lag: 0 means the bound is exact for its sets).

    | argument        | allowed                                                                    |
    |-----------------|----------------------------------------------------------------------------|
    | spec_or_name    | a Composition, a preset name or ``WORLD/NETWORK/BACKEND``                    |
    | episodes        | 1..100000 (E; episode e is reset with seed ``seed + e``)                    |
    | seed            | an integer >= 0                                                            |
    | policy          | ``"always"``, ``"silent"``, ``"random"``, a callable act(observations), or a  |
    |                 | sequence of E callables (episode e plays the e-th: seeded per-episode policies) |
    | regularization  | [0, 1e-3]: relative ridge on a per-episode singular Q (estimators.bounds)   |
    | lag_cap         | 0..50: the information-set bound's lag cap L (steps)                        |
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
    if isinstance(lag_cap, bool) or not isinstance(lag_cap, (int, np.integer)) or not 0 <= lag_cap <= 50:
        raise ValueError(f"lag_cap must be an integer in [0, 50], got {lag_cap!r}")
    spec = _resolve(spec_or_name)
    rng = np.random.default_rng(int(seed)) if policy == "random" else None
    problems, outs = [], []
    sets = None
    for e in range(int(episodes)):
        # one copy per episode: the episode env.reset(seed=seed + e) plays, whatever a backend's batching
        core = make_core(spec, batch=1, **config)
        played = policy[e] if isinstance(policy, (list, tuple)) else policy
        record = record_play(core, np.random.default_rng(int(seed) + e), played, rng, _stand_in(core, played))
        steps = record.steps
        problem = bound_problem(core, record)
        if core.composition.backend.message_content == "estimates":
            sets = sets or _InformationSetBound(core, int(lag_cap))
            sets.add(problem, record)
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
        merged = _merge(problems)
        if sets is not None:
            sets.set_merged(merged, len(problems))
        out = _bounds(merged, K, N, regularization)
    if sets is not None:
        out["delivered_capped"] = sets.capped / max(sets.credited, 1)
    return out


class _InformationSetBound:
    """The information-set delivered bound (``coloc_env.bounds.information_set``) over the episodes: per receiver
    (the centre alone where every agent reports its estimate) the information of its set on the lag-augmented
    state, set on each per-episode problem, or summed for one recursion on the episodes' mean."""

    def __init__(self, core, lag_cap: int):
        self.N = core.num_agents
        self.lag_cap = lag_cap
        self.receivers = [0] if core.composition.backend.shared_estimate else list(range(self.N))
        self.sums: list[np.ndarray] | None = None
        self.capped = self.credited = 0

    def _agents(self):
        return [np.arange(self.N)] if len(self.receivers) == 1 and self.N > 1 else [np.array([r])
                                                                                   for r in self.receivers]

    def _positions(self, centralized: Recursion, r: int) -> np.ndarray:
        return centralized.positions if len(self.receivers) == 1 and self.N > 1 else centralized.positions[[r]]

    def add(self, problem: BoundProblem, record) -> None:
        K = self.steps = record.steps
        arrival = held(problem.readings, record, self.N, "estimates")
        sets = []
        for r in self.receivers:
            entries, capped = receiver_entries(problem.readings, arrival[r], K, self.lag_cap)
            sets.append(entries)
            self.capped += capped
            self.credited += int(np.sum(arrival[r] < K))
        problem.delivered_reason = ""
        if problem.per_episode:
            self._set(problem, sets)
        elif self.sums is None:
            self.sums = sets
        else:
            for total, entries in zip(self.sums, sets, strict=True):
                for key, block in entries.items():
                    total[key] = total[key] + block if key in total else block

    def _set(self, problem: BoundProblem, sets: list[dict]) -> None:
        c = problem.centralized
        problem.delivered = [SetRecursion(c.P0, c.F, c.Q, entries, self.steps, self._positions(c, r))
                             for r, entries in zip(self.receivers, sets, strict=True)]
        problem.delivered_agents = self._agents()

    def set_merged(self, merged: BoundProblem, episodes: int) -> None:
        self._set(merged, [{key: block / episodes for key, block in total.items()} for total in self.sums])


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
