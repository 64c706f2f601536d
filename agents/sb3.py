"""Trained stable-baselines3 models as policies.

A saved model ``model.zip`` has a sidecar ``model.json`` recording the
scenario and its config; loading it for another scenario, or for spaces that
differ from the ones it was trained on, is a ``ValueError``.
"""

from __future__ import annotations

import json
import os

import numpy as np

from agents.base import Policy


def metadata_path(model_path: str) -> str:
    return os.path.splitext(model_path)[0] + ".json"


class SB3Policy(Policy):
    """Deterministic actions of a trained SB3 model, shared by all agents (parameter sharing)."""

    def __init__(self, env, path: str, deterministic: bool = True):
        super().__init__(env)
        from stable_baselines3 import PPO

        if not os.path.isfile(path):
            raise ValueError(f"policy model {path!r} does not exist")
        meta_file = metadata_path(path)
        scenario_name = env.unwrapped.scenario.name
        if os.path.isfile(meta_file):
            with open(meta_file) as fh:
                meta = json.load(fh)
            if meta.get("scenario") != scenario_name:
                raise ValueError(f"model {path!r} was trained on {meta.get('scenario')!r}, not {scenario_name!r}")
        self.model = PPO.load(path, device="cpu")
        agent = env.possible_agents[0]
        for kind, ours, theirs in (("observation", env.observation_space(agent), self.model.observation_space),
                                   ("action", env.action_space(agent), self.model.action_space)):
            if ours.shape != theirs.shape or type(ours) is not type(theirs):
                raise ValueError(f"model {path!r} has {kind} space {theirs}, the env has {ours}")
        self.deterministic = deterministic

    def act(self, observations):
        agents = list(observations)
        batch = np.stack([observations[a] for a in agents])
        actions, _ = self.model.predict(batch, deterministic=self.deterministic)
        return {a: actions[i] for i, a in enumerate(agents)}
