"""Policies for ``lossy_fusion`` (fu2017).

* ``paper``: the paper's distributed algorithm (B): every follower transmits
  every slot, the leader compensates with the expectation weights (29) and
  fuses with the inverse-trace weights (30) (all weight tilts zero). Also ``always``.
* ``silent``: no follower ever transmits, the weights as in ``paper``. Not the
  leader-alone Kalman filter: the leader keeps fusing the prior packet it holds,
  so this is far worse; the leader-alone filter and the centralized filter (A),
  the baselines of this scenario, are estimators the env's actions cannot
  express and ``coloc evaluate`` runs them as reference filters on the same
  episodes (``train.evaluate.REFERENCE_FILTERS``).
"""

from __future__ import annotations

from agents.base import FixedActionPolicy
from coloc_env.config import BadInput


def _scenario(env):
    scenario = getattr(env, "scenario", None) or env.unwrapped.scenario
    if scenario.name != "lossy_fusion":
        raise BadInput(f"this policy is for lossy_fusion, not {scenario.name}")
    return scenario


class PaperPolicy(FixedActionPolicy):
    """Always transmit; weights (29)/(30)."""

    def __init__(self, env):
        super().__init__(env, _scenario(env).paper_actions())


class SilentPolicy(FixedActionPolicy):
    """No follower transmits; weights (29)/(30)."""

    def __init__(self, env):
        actions = _scenario(env).paper_actions()
        actions[:, 0] = -1.0
        super().__init__(env, actions)


POLICIES = {"paper": PaperPolicy, "always": PaperPolicy, "silent": SilentPolicy}
