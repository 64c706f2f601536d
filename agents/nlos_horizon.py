"""Policies for ``nlos_horizon`` (gao2016).

* ``paper``: AHG (Algorithm 10, spec §7) with the config's defaults (N_min 4, N_max 30,
  dN 2, M 5, N_c(0) 12, ``likelihood`` from the config) and every neighbour kept (the
  ``n_strongest`` rule then selects the packets). With it the env *is* AFGE. It reads the
  costs J_N(k) of the agent's own DFIR stack from the scenario (information the agent has;
  the env's observation carries only a summary of it).
* ``oracle_constant``: the best constant horizon in hindsight. At the start of each episode
  it plays the whole episode on a copy of the world (privileged look-ahead) and keeps, per
  agent, the N in [N_min, N_max] with the lowest summed squared error; every neighbour kept.
* ``constant:N``: horizon N every step (default N_c(0) = 12), all kept.
"""

from __future__ import annotations

import numpy as np

import estimators.afge as af
from agents.base import Policy


def _scenario(env):
    scenario = getattr(env, "scenario", None) or env.unwrapped.scenario
    if scenario.name != "nlos_horizon":
        raise ValueError(f"this policy is for nlos_horizon, not {scenario.name}")
    return scenario


class _EpisodePolicy(Policy):
    """Restarts its own state when the scenario starts a new episode."""

    def __init__(self, env):
        super().__init__(env)
        self.scenario = _scenario(env)
        self._episode = None

    def _new_episode(self) -> bool:
        current = self.scenario.episode_id.copy()
        fresh = self._episode is None or not np.array_equal(current, self._episode)
        self._episode = current
        return fresh

    def _actions(self, window: np.ndarray, observations) -> dict:
        actions = self.scenario.encode_actions(window)[0]
        order = self.env.possible_agents
        return {a: actions[order.index(a)] for a in observations}


class PaperPolicy(_EpisodePolicy):
    """AHG: the horizon group around the centre N_c, the member with the lowest likelihood cost."""

    def __init__(self, env, likelihood: str | None = None, tables: str | None = None):
        super().__init__(env)
        self.params = self.scenario.ahg
        # ``paper:smoothed`` (make_policy's variant syntax) arrives as ``tables``
        self.likelihood = likelihood or tables or self.params.likelihood
        if self.likelihood not in af.LIKELIHOODS:
            raise ValueError(f"likelihood must be one of {af.LIKELIHOODS}, got {self.likelihood!r}")

    def act(self, observations):
        sc = self.scenario
        shape = (sc.batch, sc.num_agents)
        if self._new_episode():
            self.centre = np.full(shape, self.params.centre0)
            self.raw = np.zeros((*shape, sc.S))
            self.count = np.zeros((*shape, sc.S), np.int64)
        if self.likelihood == "paper":
            costs = sc.horizon_costs("paper")
        else:
            costs = sc.horizon_costs("predictive")
            if self.likelihood == "smoothed":
                self.raw, self.count, costs = af.smooth_costs(self.raw, self.count, costs, self.params.smoothing)
        chosen, self.centre = af.ahg_select(self.params, self.centre, costs, sc.horizon_valid, sc.fresh)
        # chosen = 0: no member has an estimate; the centre (also without one) makes the env predict
        return self._actions(np.where(chosen > 0, chosen, self.centre), observations)


class ConstantPolicy(_EpisodePolicy):
    """Horizon ``window`` every step (default: the AHG's N_c(0)), all neighbours kept."""

    def __init__(self, env, window: int | None = None, tables: str | None = None):
        super().__init__(env)
        c = self.scenario.config
        if window is None and tables is not None:  # ``constant:12``
            window = int(tables)
        self.window = c.window_centre if window is None else int(window)
        if not c.window_min <= self.window <= c.window_max:
            raise ValueError(f"window must be in [{c.window_min}, {c.window_max}], got {window}")

    def act(self, observations):
        sc = self.scenario
        return self._actions(np.full((sc.batch, sc.num_agents), self.window), observations)


class OracleConstantPolicy(_EpisodePolicy):
    """The constant horizon with the lowest summed squared error over the episode (privileged)."""

    def act(self, observations):
        sc = self.scenario
        if self._new_episode():
            c = sc.config
            errors = sc.constant_horizon_errors()[..., c.window_min - 1:c.window_max]
            self.window = c.window_min + np.argmin(errors, axis=-1)
        return self._actions(self.window, observations)


POLICIES = {"paper": PaperPolicy, "oracle_constant": OracleConstantPolicy, "constant": ConstantPolicy}
