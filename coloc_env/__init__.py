"""coloc_env: PettingZoo environments for communication-aware cooperative localization.

>>> import coloc_env
>>> env = coloc_env.parallel_env("bandwidth_fusion")
>>> observations, infos = env.reset(seed=0)
"""

from __future__ import annotations

from pettingzoo.utils.conversions import parallel_to_aec

from coloc_env.env import CoLocParallelEnv
from coloc_env.scenarios import REGISTRY

SCENARIOS: tuple[str, ...] = tuple(REGISTRY)


def scenario_class(name: str):
    """The :class:`~coloc_env.scenarios.base.Scenario` subclass registered as ``name``."""
    if name not in REGISTRY:
        raise ValueError(f"unknown scenario {name!r}; available: {list(SCENARIOS)}")
    return REGISTRY[name]


def parallel_env(name: str, render_mode: str | None = None, **config) -> CoLocParallelEnv:
    """The PettingZoo ``ParallelEnv`` of scenario ``name``; ``config`` = the scenario's dataclass fields."""
    return CoLocParallelEnv(scenario_class(name), render_mode=render_mode, **config)


def vector_env(name: str, num_envs: int = 1, seed: int | None = None, **config):
    """An SB3 ``VecEnv`` of ``num_envs`` copies x N agents in one batched core (see :mod:`coloc_env.vector`)."""
    from coloc_env.vector import CoLocVecEnv

    return CoLocVecEnv(scenario_class(name), num_envs=num_envs, seed=seed, **config)


def env(name: str, render_mode: str | None = None, **config):
    """The AEC view of :func:`parallel_env` (``pettingzoo.utils.parallel_to_aec``)."""
    return parallel_to_aec(parallel_env(name, render_mode=render_mode, **config))


__all__ = ["SCENARIOS", "CoLocParallelEnv", "env", "parallel_env", "scenario_class", "vector_env"]
