"""Policies that work on any composition: ``always`` and ``silent`` (``random`` is :class:`agents.base.RandomPolicy`).

``always`` plays every transport decision at its maximum (the full relay chain
nearest first, a broadcast at every opportunity, every packet transmitted);
``silent`` sends nothing; both keep the world's and the backend's default
decisions (the paper's weights, horizon, the nearest ranging partner). They
read only the composition's action blocks (:meth:`ComposedScenario.action_vector`).
"""

from __future__ import annotations

import numpy as np

from agents.base import FixedActionPolicy


def _fixed(env, which: str) -> FixedActionPolicy:
    scenario = env.unwrapped.scenario
    if not hasattr(scenario, "action_vector"):
        raise ValueError(f"policy {'always' if which == 'maximum' else 'silent'!r} needs a composition "
                         f"(coloc_env.compose); {scenario.name} is a preset with its own policies")
    vector = scenario.action_vector(which)
    return FixedActionPolicy(env, np.tile(vector, (scenario.num_agents, 1)))


def always(env) -> FixedActionPolicy:
    """Every transport decision at its maximum, the default sensing and backend decisions."""
    return _fixed(env, "maximum")


def silent(env) -> FixedActionPolicy:
    """Nothing sent (every transport decision at its minimum), the default sensing and backend decisions."""
    return _fixed(env, "minimum")


POLICIES = {"always": always, "silent": silent}
