"""A preset's flat config is a declared map onto its parts: every keyword reaches the part field it names,
and a refused value is reported under the keyword the user wrote."""

import dataclasses

import pytest

import coloc_env
from coloc_env.composition import Composition
from coloc_env.config import build_config
from coloc_env.scenarios import REGISTRY
from coloc_env.scenarios.binding import PresetConfig

DECLARED = [name for name, cls in REGISTRY.items() if issubclass(cls.Config, PresetConfig)]
ALIASES = [(preset, alias, name) for preset in DECLARED for alias, name in REGISTRY[preset].Config.aliases.items()]


@pytest.mark.parametrize("preset", DECLARED)
def test_every_keyword_reaches_its_target(preset):
    config_cls = REGISTRY[preset].Config
    config = config_cls()
    world, network, backend = config.parts()
    parts = {"world": world, "network": network, "backend": backend,
             "composition": Composition(world, network, backend, **config.composition_options())}
    for name, targets in config_cls.bindings().items():
        assert targets, f"{preset}.{name} declares no target"
        for target in targets:
            if target != "preset":
                kind, field = target.split(".", 1)
                assert getattr(parts[kind], field) == getattr(config, name), (preset, name, target)


def test_refused_value_names_the_keyword():
    from coloc_env.scenarios.lossy_fusion import LossyFusionConfig

    with pytest.raises(ValueError, match=r"^lossy_fusion: communication_cost must be in \[0.0, "):
        LossyFusionConfig(communication_cost=-1.0).validate()
    with pytest.raises(ValueError, match=r"^lossy_fusion: on_time_probability \+ late_probability must be in"):
        coloc_env.parallel_env("lossy_fusion", on_time_probability=0.8)


@pytest.mark.parametrize(("preset", "alias", "name"), ALIASES)
def test_alias_is_read_as_its_keyword_and_not_both(preset, alias, name):
    cls = REGISTRY[preset].Config
    default = next(f for f in dataclasses.fields(cls) if f.name == name).default
    assert getattr(build_config(cls, {alias: default}), name) == default
    with pytest.raises(ValueError, match=f"{alias} is another name of {name}; give only one"):
        build_config(cls, {alias: default, name: default})


@pytest.mark.parametrize(("preset", "alias", "name"), ALIASES)
def test_refused_value_under_an_older_name_is_named_as_written(preset, alias, name):
    cls = REGISTRY[preset].Config
    bad = 0 if name == "num_agents" else -1.0  # below every count's and every cost's range
    if name != "num_agents" and not name.endswith("cost"):
        pytest.skip(f"{name}: no value known to be out of range for every preset")
    with pytest.raises(ValueError, match=rf"^{preset}: {alias} must be") as refused:
        build_config(cls, {alias: bad})
    assert f" {name} " not in str(refused.value)
