"""Policies for ``gps_denied_nbp`` (wan2014).

* ``paper`` (also ``always``): the paper's modified schedule (Sec. 3.4; docs/wan2014.md, section 5): every UAV
  broadcasts whenever the schedule allows it (all action bits set).
* ``silent``: nobody ever broadcasts; every fault UAV is reduced to dead
  reckoning on its own prior (the "never send" reference of docs/wan2014.md, section 9).
* ``threshold:S`` (``threshold`` = ``THRESHOLD_SPREAD`` metres): a GPS-normal UAV broadcasts
  whenever the schedule allows (its fix is what the fault UAVs localize against); a fault UAV
  broadcasts only while the spread of its own prior, sqrt(tr Cov) of its particle positions
  (observation entry 4 = log(1 + spread)), is at most S metres. Why this direction: a broadcast
  helps the receivers, not the sender, and a diffuse belief carries little information to them
  (its message is nearly flat), so the rule saves the broadcasts that would help least. It reads
  only the UAV's own observation, what the paper's agents have.
"""

from __future__ import annotations

import math

import numpy as np

from agents import event_triggered
from agents.base import FixedActionPolicy, Policy
from coloc_env.config import BadInput

SPREAD_ENTRY = 4  # observation index of log(1 + spread of the own prior), metres
GPS_ENTRY = 0  # observation index of the own GPS status (1 normal, 0 fault)
# The threshold's default, chosen on validation seeds 2 * 10^6 + e (never the evaluation seeds) by
#   .venv/bin/python -c "from train.evaluate import threshold_sweep as s; \
#     r = s((5, 10, 20, 40), episodes=12); print({k: (round(v['mean_cost'], 3), \
#     round(v['communication_per_step'], 2)) for k, v in r.items()})"
# which printed (mean error m, broadcasts / step): 5: (8.09, 10.65), 10: (8.258, 16.69), 20: (7.731, 17.71),
# 40: (7.948, 17.77), inf (= paper): (8.879, 17.84). The rule: the lowest validation mean error, 20 m. On
# these 12 heavy-tailed episodes no threshold is distinguishable from the paper's schedule (paired
# differences: 20 m -1.149 [-2.752, +0.455] m; 5 m -0.789 [-5.079, +3.502] m with 40 % fewer broadcasts),
# so ``threshold:5`` is worth a row whenever a policy claims the paper's error with fewer broadcasts.
THRESHOLD_VALIDATION = {"seed_base": 2 * 10**6, "episodes": 12, "spreads": (5.0, 10.0, 20.0, 40.0)}
THRESHOLD_SPREAD = 20.0


def _scenario(env):
    scenario = getattr(env, "scenario", None) or env.unwrapped.scenario
    if scenario.name != "gps_denied_nbp":
        raise BadInput(f"this policy is for gps_denied_nbp, not {scenario.name}")
    return scenario


def threshold_actions(observations: np.ndarray, spread: float, num_iterations: int) -> np.ndarray:
    """Actions (..., N, num_iterations) int8 of ``threshold:spread`` from observations (..., N, 8).

    Broadcast bit n = 1 for every iteration when GPS is normal or log(1 + spread of the prior) <=
    log(1 + ``spread``); ``spread = inf`` is the paper's schedule.
    """
    observations = np.asarray(observations, float)
    limit = math.log1p(spread) if math.isfinite(spread) else math.inf
    send = (observations[..., GPS_ENTRY] > 0.5) | (observations[..., SPREAD_ENTRY] <= limit)
    return np.broadcast_to(send[..., None], (*send.shape, num_iterations)).astype(np.int8)


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


class ThresholdPolicy(Policy):
    """Fault UAVs broadcast only while their own prior's spread is at most ``spread`` metres."""

    batching = "per_copy"

    def __init__(self, env, spread: float | None = None, tables: str | None = None):
        super().__init__(env)
        self.iterations = _scenario(env).config.num_iterations
        if spread is None and tables is not None:  # ``threshold:15``
            try:
                spread = float(tables)
            except ValueError:
                raise BadInput(f"threshold spread must be a number of metres > 0, got {tables!r}") from None
        spread = THRESHOLD_SPREAD if spread is None else spread
        if isinstance(spread, bool) or not isinstance(spread, (int, float)) or not spread > 0:
            raise BadInput(f"threshold spread must be a number of metres > 0, got {spread!r}")
        self.spread = float(spread)

    def act(self, observations):
        names = list(observations)
        stacked = np.stack([np.asarray(observations[a], float) for a in names])
        actions = threshold_actions(stacked, self.spread, self.iterations)
        return {a: actions[i] for i, a in enumerate(names)}


# the event-triggered families decide every broadcast bit of a step at once (agents.event_triggered)
POLICIES = {"paper": PaperPolicy, "always": PaperPolicy, "silent": SilentPolicy, "threshold": ThresholdPolicy,
            **event_triggered.POLICIES}
STRONGEST_BASELINES = ("paper", "threshold")
