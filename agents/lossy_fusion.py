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

import numpy as np

from agents import event_triggered
from agents.base import FixedActionPolicy
from coloc_env.config import BadInput


def _scenario(env):
    scenario = getattr(env, "scenario", None) or env.unwrapped.scenario
    if scenario.name != "lossy_fusion":
        raise BadInput(f"this policy is for lossy_fusion, not {scenario.name}")
    return scenario


def paper_actions(scenario) -> np.ndarray:
    """The action (N, A) of the paper's algorithm (B) on a ``lossy_fusion`` core: every follower transmits
    (entry 0 >= 0), every tilt 0, i.e. the compensation weights (29) and the fusion weights (30)."""
    actions = np.zeros((scenario.num_agents, scenario.action_dim))
    actions[:, 0] = 1.0
    return actions


class PaperPolicy(FixedActionPolicy):
    """Always transmit; weights (29)/(30)."""

    def __init__(self, env):
        super().__init__(env, paper_actions(_scenario(env)))


class SilentPolicy(FixedActionPolicy):
    """No follower transmits; weights (29)/(30)."""

    def __init__(self, env):
        actions = paper_actions(_scenario(env))
        actions[:, 0] = -1.0
        super().__init__(env, actions)


# the event-triggered families decide each follower's transmit entry (agents.event_triggered)
POLICIES = {"paper": PaperPolicy, "always": PaperPolicy, "silent": SilentPolicy, **event_triggered.POLICIES}
# The strongest baselines are the leader-alone Kalman filter and the centralized filter (A), estimators rather
# than env policies: ``train.evaluate.REFERENCE_FILTERS`` runs them on the same episodes (its informed filter is
# a bound).
STRONGEST_BASELINES = ()
