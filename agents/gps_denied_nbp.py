"""Policies for ``gps_denied_nbp`` (wan2014).

* ``paper``: the paper's modified schedule (Sec. 3.4, spec §5): every UAV
  broadcasts whenever the schedule allows it (all action bits set).
* ``silent``: nobody ever broadcasts; every fault UAV is reduced to dead
  reckoning on its own prior (the "never send" reference of spec §9).
"""

from __future__ import annotations

import numpy as np

from agents.base import FixedActionPolicy


def _scenario(env):
    scenario = getattr(env, "scenario", None) or env.unwrapped.scenario
    if scenario.name != "gps_denied_nbp":
        raise ValueError(f"this policy is for gps_denied_nbp, not {scenario.name}")
    return scenario


class PaperPolicy(FixedActionPolicy):
    """Broadcast whenever the schedule allows (the paper's fixed schedule)."""

    def __init__(self, env):
        scenario = _scenario(env)
        super().__init__(env, np.ones((scenario.num_agents, scenario.config.num_iterations), dtype=np.int8))


class SilentPolicy(FixedActionPolicy):
    """Never broadcast: dead reckoning for every fault UAV."""

    def __init__(self, env):
        scenario = _scenario(env)
        super().__init__(env, np.zeros((scenario.num_agents, scenario.config.num_iterations), dtype=np.int8))


POLICIES = {"paper": PaperPolicy, "silent": SilentPolicy}
