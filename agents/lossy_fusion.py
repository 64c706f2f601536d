"""Policies for ``lossy_fusion`` (fu2017).

* ``paper``: the paper's distributed algorithm (B): every follower transmits
  every slot, the leader compensates with the expectation weights (29) and
  fuses with the inverse-trace weights (30) (all weight tilts zero).
"""

from __future__ import annotations

from agents.base import FixedActionPolicy


def _scenario(env):
    scenario = getattr(env, "scenario", None) or env.unwrapped.scenario
    if scenario.name != "lossy_fusion":
        raise ValueError(f"this policy is for lossy_fusion, not {scenario.name}")
    return scenario


class PaperPolicy(FixedActionPolicy):
    """Always transmit; weights (29)/(30)."""

    def __init__(self, env):
        super().__init__(env, _scenario(env).paper_actions())


POLICIES = {"paper": PaperPolicy}
