"""Policies with one interface, ``act(observations) -> actions``, for the env and for scripts.

>>> import agents, coloc_env
>>> env = coloc_env.parallel_env("bandwidth_fusion")
>>> policy = agents.make_policy("paper", env)
"""

from __future__ import annotations

import inspect

from agents import bandwidth_fusion, generic, gps_denied_nbp, lossy_fusion, mrclam_relay, nlos_horizon, relay_ukf
from agents.base import FixedActionPolicy, Policy, RandomPolicy

SCENARIO_POLICIES = {"bandwidth_fusion": bandwidth_fusion.POLICIES, "lossy_fusion": lossy_fusion.POLICIES,
                     "relay_ukf": relay_ukf.POLICIES, "nlos_horizon": nlos_horizon.POLICIES,
                     "gps_denied_nbp": gps_denied_nbp.POLICIES, "mrclam_relay": mrclam_relay.POLICIES}


def available_policies(scenario: str) -> list[str]:
    """Policy names for a preset, or for a composition's name ``world/network/backend``."""
    if scenario in SCENARIO_POLICIES:
        return ["random", *SCENARIO_POLICIES[scenario]]
    return ["random", *generic.POLICIES]


def make_policy(name: str, env, seed: int | None = None, **kwargs) -> Policy:
    """A policy for ``env`` by name: ``paper`` (``paper:T2P3`` for other tables where the
    scenario has them), ``random``, ``greedy``, ``oracle_*``, or a path to a trained ``.zip``."""
    scenario = env.unwrapped.scenario.name
    if name.endswith(".zip"):
        from agents.sb3 import SB3Policy

        return SB3Policy(env, name, **kwargs)
    if name == "random":
        return RandomPolicy(env, seed=seed)
    base, _, variant = name.partition(":")
    table = SCENARIO_POLICIES.get(scenario, generic.POLICIES)
    if base not in table:
        raise ValueError(f"unknown policy {name!r} for {scenario}; available: {available_policies(scenario)} or a .zip")
    if variant:
        kwargs["tables"] = variant
    if "seed" in inspect.signature(table[base]).parameters:  # stochastic scenario policies take their own seed
        kwargs.setdefault("seed", seed)
    return table[base](env, **kwargs)


__all__ = ["FixedActionPolicy", "Policy", "RandomPolicy", "available_policies", "make_policy"]
