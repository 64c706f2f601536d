"""Each preset as a module, the way PettingZoo ships its own environments.

>>> from coloc_env.envs import relay_ukf
>>> env = relay_ukf.parallel_env(max_cycles=100, speed_noise_std=0.02)

Every module ``coloc_env.envs.<preset>`` has

* ``parallel_env(max_cycles=None, render_mode=None, **config)``: the
  ``coloc_env.env.CoLocParallelEnv`` (``config`` = the preset's flat
  dataclass fields, as ``coloc_env.parallel_env(name, **config)``);
* ``raw_env(...)``: its AEC view without wrappers;
* ``env(...)``: the AEC view wrapped in PettingZoo's ``OrderEnforcingWrapper``;

``max_cycles`` is the episode length (PettingZoo's keyword, checked by
``pettingzoo.test.max_cycles_test``): the preset's ``episode_length_field``
(``horizon``, or ``window_steps`` for ``mrclam_relay``; ``coloc_env.env.with_max_cycles``).

The modules are made here, one per registered preset (``coloc_env.scenarios.REGISTRY``), when this package
is imported or a preset registers later; a preset needs no file in this package.
"""

from __future__ import annotations

import sys
import types
from collections.abc import Callable

from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from coloc_env.config import module_names
from coloc_env.env import CoLocParallelEnv
from coloc_env.scenarios import REGISTRY


def constructors(name: str) -> tuple[Callable[..., CoLocParallelEnv], Callable, Callable]:
    """``(parallel_env, raw_env, env)`` of the preset ``name`` (one module per preset calls this)."""
    if name not in REGISTRY:
        raise ValueError(f"unknown preset {name!r}; available: {sorted(REGISTRY)}")
    scenario_cls = REGISTRY[name]

    def parallel_env(max_cycles: int | None = None, render_mode: str | None = None, **config) -> CoLocParallelEnv:
        return CoLocParallelEnv(scenario_cls, render_mode=render_mode, max_cycles=max_cycles, **config)

    def raw_env(max_cycles: int | None = None, render_mode: str | None = None, **config):
        return parallel_to_aec_wrapper(parallel_env(max_cycles=max_cycles, render_mode=render_mode, **config))

    def env(max_cycles: int | None = None, render_mode: str | None = None, **config):
        return OrderEnforcingWrapper(raw_env(max_cycles=max_cycles, render_mode=render_mode, **config))

    for function, what in ((parallel_env, "the PettingZoo ParallelEnv"), (raw_env, "the unwrapped AEC env"),
                           (env, "the AEC env with PettingZoo's OrderEnforcingWrapper")):
        function.__doc__ = (f"{what} of ``{name}``; ``max_cycles`` = episode length, ``config`` = "
                            f"{scenario_cls.Config.__name__} fields.")
        function.__qualname__ = function.__name__
        function.__module__ = f"coloc_env.envs.{name}"
    return parallel_env, raw_env, env


def _add_module(scenario_cls) -> None:
    """The module ``coloc_env.envs.<name>`` of a registered preset, importable and an attribute of this package."""
    name = scenario_cls.name
    module = types.ModuleType(f"{__name__}.{name}", f"``{name}`` as a PettingZoo environment module: "
                              f"``parallel_env``, ``raw_env`` and ``env``.\n\n``max_cycles`` sets "
                              f"``{scenario_cls.episode_length_field}``. See ``coloc_env.envs``.\n")
    module.parallel_env, module.raw_env, module.env = constructors(name)
    module.__all__ = ["env", "parallel_env", "raw_env"]
    sys.modules[module.__name__] = module
    setattr(sys.modules[__name__], name, module)


def _remove_module(scenario_cls) -> None:
    sys.modules.pop(f"{__name__}.{scenario_cls.name}", None)
    if scenario_cls.name in globals():
        del globals()[scenario_cls.name]


REGISTRY.subscribe(_add_module, _remove_module)


# the presets that have a module here: every registered one
__getattr__ = module_names(__name__, {"PRESET_MODULES": lambda: tuple(REGISTRY)})
__all__ = ["PRESET_MODULES", "constructors"]
