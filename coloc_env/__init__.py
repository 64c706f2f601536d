"""coloc_env: PettingZoo environments for communication-aware cooperative localization.

>>> import coloc_env
>>> env = coloc_env.parallel_env("bandwidth_fusion")                 # a preset (a paper scenario)
>>> spec = coloc_env.compose(world="circles", network="relay", backend="ukf_dcl")
>>> env = coloc_env.parallel_env(spec)                                # any compatible composition
>>> observations, infos = env.reset(seed=0)

``WORLDS``, ``NETWORKS`` and ``BACKENDS`` name the composable parts;
``compatibility()`` says which combinations run and why the others do not;
``PRESETS[name]`` is the Composition each scenario name stands for.
Importing the package registers every preset with PettingZoo as
``coloc/<preset>-v<N>`` (`coloc_env.registry`).
"""

from __future__ import annotations

from pettingzoo.utils.conversions import parallel_to_aec

import coloc_env.backends as backends
import coloc_env.networks as networks
import coloc_env.worlds as worlds
from coloc_env.bounds import pcrb
from coloc_env.composition import Composition, compatibility, compose
from coloc_env.cores import _spec, composition_named, is_composition_name, make_core, scenario_class
from coloc_env.env import CoLocParallelEnv
from coloc_env.parts import BACKENDS as _BACKENDS
from coloc_env.parts import NETWORKS as _NETWORKS
from coloc_env.parts import WORLDS as _WORLDS
from coloc_env.presets import PRESETS
from coloc_env.registry import register_presets as _register_presets
from coloc_env.scenarios import REGISTRY

_register_presets()  # every preset as coloc/<preset>-v<N> in PettingZoo's registry (coloc_env.registry)

WORLDS: tuple[str, ...] = tuple(_WORLDS)
NETWORKS: tuple[str, ...] = tuple(_NETWORKS)
BACKENDS: tuple[str, ...] = tuple(_BACKENDS)


def parallel_env(name, render_mode: str | None = None, max_cycles: int | None = None, **config) -> CoLocParallelEnv:
    """The PettingZoo ``ParallelEnv`` of a preset name (``config`` = its dataclass fields), a composition's name
    ``WORLD/NETWORK/BACKEND`` (``config`` = the composition-level options) or a Composition.

    ``max_cycles`` is PettingZoo's name for the episode length: a preset's ``horizon`` (``window_steps`` for
    mrclam_relay), a composition's ``horizon``."""
    cls, spec, config = _spec(name, config)
    return CoLocParallelEnv(cls, render_mode=render_mode, composition=spec, max_cycles=max_cycles, **config)


def vector_env(name, num_envs: int = 1, seed: int | None = None, max_cycles: int | None = None, **config):
    """An SB3 ``VecEnv`` of ``num_envs`` copies x N agents in one batched core (see ``coloc_env.vector``)."""
    from coloc_env.vector import CoLocVecEnv

    cls, spec, config = _spec(name, config)
    return CoLocVecEnv(cls, num_envs=num_envs, seed=seed, composition=spec, max_cycles=max_cycles, **config)


def env(name, render_mode: str | None = None, max_cycles: int | None = None, **config):
    """The AEC view of ``parallel_env`` (``pettingzoo.utils.parallel_to_aec``)."""
    return parallel_to_aec(parallel_env(name, render_mode=render_mode, max_cycles=max_cycles, **config))


def __getattr__(name: str):
    if name == "SCENARIOS":  # the registered presets' names, in registry order (a preset registered later included)
        return tuple(REGISTRY)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["BACKENDS", "NETWORKS", "PRESETS", "SCENARIOS", "WORLDS", "CoLocParallelEnv", "Composition",
           "backends", "compatibility", "compose", "composition_named", "env", "is_composition_name", "make_core",
           "networks", "parallel_env", "pcrb", "scenario_class", "vector_env", "worlds"]
