"""Policies with one interface, ``act(observations) -> actions``, for the env and for scripts.

>>> import agents, coloc_env
>>> env = coloc_env.parallel_env("bandwidth_fusion")
>>> policy = agents.make_policy("paper", env)

Three lists per scenario:

* ``available_policies``: the realizable policies, those that use only what the agents
  can have (``random``, ``always`` and ``silent`` included);
* ``bound_policies``: the ``bound_*`` policies, which use what the agents cannot have
  (hindsight on the episode, the truth, packet ages without time stamps); leaderboards show
  them apart, as bounds, and never judge a target against them;
* ``strongest_baselines``: the realizable policies a learned policy with the same
  information must beat (a leaderboard picks the best of them on the paired episodes;
  ``train.evaluate.baselines`` adds the reference filters that are not env policies).
"""

from __future__ import annotations

import inspect
import os

from agents import bandwidth_fusion, generic, gps_denied_nbp, lossy_fusion, mrclam_relay, nlos_horizon, relay_ukf
from agents.base import FixedActionPolicy, Policy, RandomPolicy
from coloc_env.config import BadInput, check_seed

SCENARIO_POLICIES = {"bandwidth_fusion": {**bandwidth_fusion.POLICIES, **generic.PRESET_FIXED["bandwidth_fusion"]},
                     "lossy_fusion": lossy_fusion.POLICIES, "relay_ukf": relay_ukf.POLICIES,
                     "nlos_horizon": nlos_horizon.POLICIES, "gps_denied_nbp": gps_denied_nbp.POLICIES,
                     "mrclam_relay": mrclam_relay.POLICIES}
BOUND_POLICIES = {"nlos_horizon": nlos_horizon.BOUNDS}
ALIASES = {"nlos_horizon": nlos_horizon.ALIASES}  # old name -> current name, accepted by make_policy only

# The strongest realizable baselines with the agents' information. lossy_fusion's are the
# leader-alone Kalman filter and the centralized filter (A), estimators rather than env policies:
# ``train.evaluate.REFERENCE_FILTERS`` runs them on the same episodes; its informed filter is a bound.
STRONGEST_BASELINES = {
    "bandwidth_fusion": ("oracle_static",),
    "lossy_fusion": (),
    "relay_ukf": ("paper", "no_relay"),
    "nlos_horizon": ("best_constant",),
    "gps_denied_nbp": ("paper", "threshold"),
    "mrclam_relay": ("paper",),
}
COMPOSITION_BASELINES = ("always", "silent")


def available_policies(scenario: str) -> list[str]:
    """Realizable policy names for a preset, or for a composition's name ``world/network/backend``
    (``random`` first; ``always`` and ``silent`` included; no bound)."""
    if scenario in SCENARIO_POLICIES:
        return ["random", *SCENARIO_POLICIES[scenario]]
    return ["random", *generic.POLICIES]


def duplicates(scenario: str) -> dict[str, str]:
    """Names that build the same policy as an earlier name of ``available_policies`` (``always`` is
    ``paper`` where the paper already sends everything): name -> the earlier name. Evaluating them again
    would repeat the same episodes."""
    table = SCENARIO_POLICIES.get(scenario, generic.POLICIES)
    baselines = strongest_baselines(scenario)
    names = sorted(available_policies(scenario)[1:], key=lambda n: n not in baselines)  # a baseline keeps its name
    first, same = {}, {}
    for name in names:
        factory = table[name]
        if factory in first:
            same[name] = first[factory]
        else:
            first[factory] = name
    return same


def bound_policies(scenario: str) -> list[str]:
    """The ``bound_*`` policies of ``scenario`` (what the agents cannot have); empty where it has none."""
    return list(BOUND_POLICIES.get(scenario, {}))


def strongest_baselines(scenario: str) -> tuple[str, ...]:
    """The realizable policies a learned one must beat on ``scenario`` (a composition: ``always``, ``silent``)."""
    if scenario in SCENARIO_POLICIES:
        return STRONGEST_BASELINES[scenario]
    return COMPOSITION_BASELINES


def make_policy(name: str, env, seed: int | None = None, **kwargs) -> Policy:
    """A policy for ``env`` by name: ``paper`` (``paper:T2P3`` for other tables where the
    scenario has them), ``random``, ``always``, ``silent``, ``greedy``, ``oracle_*``, a scenario's
    ``bound_*``, or a path to a trained ``.zip``. A name that is not a string, a variant (``:X``) the policy
    does not take or cannot read, a seed that is not None or an integer in [0, 2**63 - 1], or an ``env``
    that is not a coloc env is a ``ValueError`` saying which."""
    if not isinstance(name, (str, os.PathLike)):
        raise BadInput(f"policy name must be a string (a policy's name or a path to a .zip), got {name!r}")
    name = os.fspath(name)
    check_seed("seed", seed)
    scenario = getattr(getattr(getattr(env, "unwrapped", None), "scenario", None), "name", None)
    if not isinstance(scenario, str):
        raise BadInput(f"env must be a coloc env (coloc_env.parallel_env(...) or env(...)), got {env!r}")
    if name.endswith(".zip"):
        from agents.sb3 import SB3Policy

        return SB3Policy(env, name, **kwargs)
    if name == "random":
        return RandomPolicy(env, seed=seed)
    base, colon, variant = name.partition(":")
    if colon and not variant.strip():
        raise BadInput(f"policy {name!r}: the variant after ':' is empty")
    base = ALIASES.get(scenario, {}).get(base, base)
    table = {**SCENARIO_POLICIES.get(scenario, generic.POLICIES), **BOUND_POLICIES.get(scenario, {})}
    if base not in table:
        raise BadInput(f"unknown policy {name!r} for {scenario}; available: {available_policies(scenario)}, "
                       f"bounds: {bound_policies(scenario)} or a .zip")
    if variant:
        if "tables" not in inspect.signature(table[base]).parameters:
            raise BadInput(f"policy {base!r} of {scenario} takes no variant, got {name!r}")
        kwargs["tables"] = variant
    if "seed" in inspect.signature(table[base]).parameters:  # stochastic scenario policies take their own seed
        kwargs.setdefault("seed", seed)
    return table[base](env, **kwargs)


__all__ = ["FixedActionPolicy", "Policy", "RandomPolicy", "available_policies", "bound_policies", "duplicates",
           "make_policy", "strongest_baselines"]
