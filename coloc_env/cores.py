"""Naming and building a composition's batched core: a preset name, a composition's name ``WORLD/NETWORK/BACKEND``
or a Composition, as ``coloc_env.parallel_env``, ``coloc_env.vector_env`` and ``coloc_env.pcrb`` take them
(re-exported by ``coloc_env``)."""

from __future__ import annotations

from coloc_env.composition import Composition, compose
from coloc_env.env import build_scenario
from coloc_env.scenarios import REGISTRY
from coloc_env.scenarios.composed import ComposedScenario


def is_composition_name(name) -> bool:
    """True for a composition's name ``WORLD/NETWORK/BACKEND`` (``Composition.name``, as ``coloc list`` prints it)."""
    return isinstance(name, str) and "/" in name


def composition_named(name: str, **options) -> Composition:
    """The composition of the parts ``WORLD/NETWORK/BACKEND`` names, each at its defaults, with composition-level
    ``options`` (``reward``, ``communication_cost``, ``cost_range``, ``horizon``); a ValueError says which name or
    option is wrong."""
    parts = name.split("/")
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"a composition name is WORLD/NETWORK/BACKEND (e.g. circles/broadcast/ukf_ccl), got {name!r}")
    return compose(*parts, **options)


def scenario_class(name: str):
    """The ``coloc_env.scenarios.base.Scenario`` subclass registered as ``name``; for a composition's name
    ``WORLD/NETWORK/BACKEND`` the composed core's class, once the parts are known to compose."""
    if is_composition_name(name):
        composition_named(name)
        return ComposedScenario
    if not isinstance(name, str) or name not in REGISTRY:
        raise ValueError(f"unknown scenario {name!r}; available: {list(REGISTRY)}, a composition's name "
                         "WORLD/NETWORK/BACKEND (coloc list) or a coloc_env.compose(...)")
    return REGISTRY[name]


def make_core(name, batch: int = 1, **config):
    """The batched core (``coloc_env.scenarios.base.Scenario``) of ``batch`` copies of a preset name, a
    composition's name or a Composition, as ``parallel_env`` and ``vector_env`` build it."""
    cls, spec, config = _spec(name, config)
    return build_scenario(cls, batch, spec, **config)


def _spec(name_or_spec, config: dict):
    """(scenario class, composition or None, config) for a preset name, a composition's name or a Composition
    (a composition's name takes the composition-level options as its config)."""
    if is_composition_name(name_or_spec):
        return ComposedScenario, composition_named(name_or_spec, **config), {}
    if isinstance(name_or_spec, Composition):
        if name_or_spec.preset is not None:
            return scenario_class(name_or_spec.preset), None, {**dict(name_or_spec.preset_config), **config}
        if config:
            raise ValueError(f"a Composition takes no keywords here, got {sorted(config)}; set a part's field in "
                             "compose(world={'name': ..., field: value}, ...)")
        return ComposedScenario, name_or_spec, {}
    return scenario_class(name_or_spec), None, config
