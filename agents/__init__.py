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

import importlib
import inspect
import os
from types import ModuleType

from agents import contention, event_triggered, generic
from agents.base import FixedActionPolicy, Policy, RandomPolicy
from coloc_env.config import BadInput, check_seed, module_names
from coloc_env.scenarios import REGISTRY

COMPOSITION_BASELINES = ("always", "silent")
# the policies a composition gets from its network: every composition over ``contention`` schedules its slots
NETWORK_POLICIES = {"contention": (contention.POLICIES, contention.BASELINES)}


def _name(scenario) -> str:
    """A scenario's name: a preset's, a composition name, or a ``Composition``'s."""
    return scenario.name if hasattr(scenario, "network") else scenario


def _network(scenario) -> str | None:
    """The network of a composition (a ``Composition``, or its name ``world/network/backend``); None for a preset."""
    network = getattr(scenario, "network", None)
    if network is not None:
        return network.name
    parts = scenario.split("/") if isinstance(scenario, str) else []
    return parts[1] if len(parts) == 3 else None


def policy_module(scenario: str) -> ModuleType | None:
    """The module of a preset's policies (its declared ``policy_module``); None for a composition's name.

    The module has ``POLICIES`` (name -> factory, the realizable policies), ``STRONGEST_BASELINES`` (the
    realizable policies a learned one with the same information must beat; empty where the baselines are reference
    filters rather than env policies: lossy_fusion's, run by ``train.evaluate.REFERENCE_FILTERS``), and
    optionally ``BOUNDS`` (the ``bound_*`` policies) and ``ALIASES`` (old name -> current name, accepted by
    ``make_policy`` only)."""
    scenario = _name(scenario)
    if scenario not in REGISTRY:
        return None
    return importlib.import_module(REGISTRY[scenario].policy_module)


def _policies(scenario) -> dict:
    """The realizable policies of a preset, or of a composition: the generic ones and its network's."""
    module = policy_module(scenario)
    if module is not None:
        return module.POLICIES
    return {**_composition_policies(_name(scenario)), **NETWORK_POLICIES.get(_network(scenario), ({}, ()))[0]}


def _composition_policies(scenario: str) -> dict:
    """A composition's policies by name: the generic ones, and the event-triggered families
    (``agents.event_triggered``) where its network has a transport decision."""
    import coloc_env

    if coloc_env.is_composition_name(scenario) and \
            event_triggered.has_transport_decision(coloc_env.composition_named(scenario)):
        return {**generic.POLICIES, **event_triggered.POLICIES}
    return generic.POLICIES


def _bounds(scenario) -> dict:
    return getattr(policy_module(scenario), "BOUNDS", {})


def available_policies(scenario) -> list[str]:
    """Realizable policy names for a preset, or for a composition (a ``Composition`` or its name
    ``world/network/backend``: ``always``, ``silent``, ``greedy`` and its network's, e.g. ``round_robin`` and
    ``aloha`` over ``contention``); ``random`` first, no bound."""
    return ["random", *_policies(scenario)]


def duplicates(scenario: str) -> dict[str, str]:
    """Names that build the same policy as an earlier name of ``available_policies`` (``always`` is
    ``paper`` where the paper already sends everything): name -> the earlier name. Evaluating them again
    would repeat the same episodes."""
    table = _policies(scenario)
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
    return list(_bounds(scenario))


def strongest_baselines(scenario: str) -> tuple[str, ...]:
    """The realizable policies a learned one must beat on ``scenario`` (a composition: ``always``, ``silent`` and
    its network's baselines)."""
    module = policy_module(scenario)
    if module is None:
        return COMPOSITION_BASELINES + NETWORK_POLICIES.get(_network(scenario), ({}, ()))[1]
    return tuple(module.STRONGEST_BASELINES)


def paper_entries(scenario: str, name: str | None):
    """The object that fills the action entries ``name`` a trained model leaves to ``scenario``'s paper rule (its
    policy module's ``PAPER_ENTRIES[name]()``, with ``entries(generators, observations, actions)`` and
    ``restrict(masks, num_agents)``); None for ``name`` None. An unknown name is a ``ValueError`` listing the
    scenario's."""
    if name is None:
        return None
    table = getattr(policy_module(scenario), "PAPER_ENTRIES", {}) if scenario in REGISTRY else {}
    if name not in table:
        raise BadInput(f"paper entries {name!r}: {scenario} has " + (f"{sorted(table)}" if table else "none"))
    return table[name]()


def make_policy(name: str, env, seed: int | None = None, **kwargs) -> Policy:
    """A policy for ``env`` by name: ``paper`` (``paper:T2P3`` for other tables where the
    scenario has them), ``random``, ``always``, ``silent``, ``greedy``, ``round_robin`` and ``aloha`` (``aloha:p``)
    over ``contention``, ``oracle_*``, a scenario's
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

        return SB3Policy(env, name, seed=seed, **kwargs)
    if name == "random":
        return RandomPolicy(env, seed=seed)
    base, colon, variant = name.partition(":")
    if colon and not variant.strip():
        raise BadInput(f"policy {name!r}: the variant after ':' is empty")
    base = getattr(policy_module(scenario), "ALIASES", {}).get(base, base)
    composition = getattr(env.unwrapped.scenario, "composition", None)
    which = composition if composition is not None and composition.preset is None else scenario
    table = {**_policies(which), **_bounds(scenario)}
    if base not in table:
        raise BadInput(f"unknown policy {name!r} for {scenario}; available: {available_policies(which)}, "
                       f"bounds: {bound_policies(scenario)} or a .zip")
    if variant:
        parameters = inspect.signature(table[base]).parameters
        if "variant" in parameters:  # the knob of a family (periodic:4)
            kwargs["variant"] = variant
        elif "tables" in parameters:
            kwargs["tables"] = variant
        else:
            raise BadInput(f"policy {base!r} of {scenario} takes no variant, got {name!r}")
    if "seed" in inspect.signature(table[base]).parameters:  # stochastic scenario policies take their own seed
        kwargs.setdefault("seed", seed)
    return table[base](env, **kwargs)


__all__ = ["FixedActionPolicy", "Policy", "RandomPolicy", "available_policies", "bound_policies", "duplicates",
           "make_policy", "paper_entries", "policy_module", "strongest_baselines"]


def _per_preset(read) -> dict:
    values = {scenario: read(policy_module(scenario)) for scenario in REGISTRY}
    return {scenario: value for scenario, value in values.items() if value is not None}


# the per-preset tables this module held before each preset's policy module declared them
_TABLES = {"SCENARIO_POLICIES": lambda m: m.POLICIES, "BOUND_POLICIES": lambda m: getattr(m, "BOUNDS", None),
           "ALIASES": lambda m: getattr(m, "ALIASES", None),
           "STRONGEST_BASELINES": lambda m: tuple(m.STRONGEST_BASELINES)}
__getattr__ = module_names(__name__, {name: (lambda read=read: _per_preset(read)) for name, read in _TABLES.items()},
                           deprecated=dict.fromkeys(_TABLES, "each preset's policy module declares it "
                                                             "(agents.policy_module)"))
