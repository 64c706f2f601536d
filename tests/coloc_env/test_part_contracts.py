"""Parts declare themselves: each kind's contract (``coloc_env.parts.CONTRACTS``) is checked when a part registers,
and a part added from a test module alone composes, runs, gets a bound and appears in the docs page."""

from dataclasses import dataclass

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

import coloc_env
import mkdocs_hooks
from coloc_env.backends.particles import RangeLs
from coloc_env.bounds.models import MODELS
from coloc_env.networks.base import Network
from coloc_env.parts import BACKENDS, CONTRACTS, MESSAGE_KINDS, NETWORKS, WORLDS, NoBound, PartConfig


@dataclass(frozen=True)
class ToyLossless(PartConfig):
    """A network with the base class's rules: every link usable, nothing lost, nothing late."""

    name = "toy_lossless"
    carries = frozenset({"broadcast", "central", "packets"})

    def check(self, prefix: str) -> None:
        return None

    def build(self, num_agents: int, batch: int, message_kind: str, rounds: int = 1) -> Network:
        return Network(self, num_agents, batch, message_kind, rounds)


@dataclass(frozen=True)
class ToyRangeLs(RangeLs):
    """range_ls under another name: a backend whose declarations and fields come from its parent."""

    name = "toy_range_ls"


@pytest.fixture
def toys():
    """The two toy parts registered for one test, then removed, so the registries are as before."""
    NETWORKS.register(ToyLossless)
    BACKENDS.register(ToyRangeLs)
    try:
        yield
    finally:
        NETWORKS.unregister("toy_lossless")
        BACKENDS.unregister("toy_range_ls")


def test_toy_parts_compose_run_and_get_a_bound(toys):
    rows = {(r["world"], r["network"], r["backend"]): r for r in coloc_env.compatibility()}
    assert rows["gps_denied", "toy_lossless", "toy_range_ls"]["ok"]
    assert not rows["gps_denied", "toy_lossless", "ukf_dcl"]["ok"]  # chains: not carried
    assert "cannot carry" in rows["gps_denied", "toy_lossless", "ukf_dcl"]["reason"]
    spec = coloc_env.compose(world="gps_denied", network="toy_lossless", backend="toy_range_ls", horizon=6)
    parallel_api_test(coloc_env.parallel_env(spec), num_cycles=6)
    # a lossless network with the base rules is the ideal network: the same episode to the last bit
    ideal = coloc_env.compose(world="gps_denied", network="ideal", backend="range_ls", horizon=6)
    infos = []
    for composition in (spec, ideal):
        env = coloc_env.parallel_env(composition)
        env.reset(seed=4)
        while env.agents:
            *_, info = env.step({a: np.zeros(env.action_space(a).shape, int) for a in env.agents})  # no decisions
        infos.append(np.array([info[a]["estimated_position"] for a in env.possible_agents]))
    assert np.array_equal(infos[0], infos[1])
    bound = coloc_env.pcrb(spec, episodes=2, seed=0)
    assert bound["centralized"].shape == (6, 10)
    assert np.all(bound["local"] >= bound["centralized"] - 1e-9)


def test_a_toy_part_appears_in_the_generated_docs_page(toys):
    page = mkdocs_hooks.parts_reference()
    worlds, rest = page.split("## Networks")
    networks, backends = rest.split("## Backends")
    assert f"::: {__name__}" not in worlds
    assert networks.count(f"::: {__name__}") == 1 and backends.count(f"::: {__name__}") == 1
    assert "::: coloc_env.worlds.mrclam_slices" in worlds


def test_unregistering_restores_the_registry(toys):
    before = set(NETWORKS)
    NETWORKS.unregister("toy_lossless")
    assert set(NETWORKS) == before - {"toy_lossless"}
    NETWORKS.register(ToyLossless)
    with pytest.raises(ValueError, match="network 'toy_lossless' registered twice"):
        NETWORKS.register(ToyLossless)
    with pytest.raises(ValueError, match="no network 'nope' registered"):
        NETWORKS.unregister("nope")


def declared(kind: str, **changes) -> type:
    """A part class of ``kind`` making every declaration of a registered one, with ``changes``."""
    template = {"world": WORLDS["circles"], "network": NETWORKS["broadcast"], "backend": BACKENDS["ukf_ccl"]}[kind]
    values = {d.name: getattr(template, d.name) for d in CONTRACTS[kind]}
    values.update(changes)
    values = {k: v for k, v in values.items() if v is not _DROP}
    return type(f"Toy{kind.title()}", (PartConfig,), {"name": f"toy_{kind}", **values})


_DROP = object()


@pytest.mark.parametrize(("kind", "changes", "message"), [
    ("world", {"estimand": "both"}, "world 'toy_world': estimand must be one of \\['self', 'target'\\]"),
    ("world", {"bound_model": _DROP}, "world 'toy_world' must declare bound_model"),
    ("world", {"bound_model": NoBound("")}, "world 'toy_world': bound_model must be a module name or NoBound"),
    ("world", {"measurements": {"range"}}, "world 'toy_world': measurements must be a frozenset"),
    ("network", {"carries": frozenset({"pigeons"})}, "network 'toy_network': carries must be a non-empty frozenset"),
    ("network", {"carries": _DROP}, "network 'toy_network' must declare carries"),
    ("backend", {"message_kind": "components "}, "backend 'toy_backend': message_kind must be one of"),
    ("backend", {"message_content": _DROP}, "backend 'toy_backend' must declare message_content"),
    ("backend", {"shared_estimate": 1}, "backend 'toy_backend': shared_estimate must be True or False"),
    ("backend", {"requires": [frozenset({"range"})]}, "backend 'toy_backend': requires must be a tuple"),
])
def test_a_missing_or_unknown_declaration_is_refused_at_registration(kind, changes, message):
    registry = {"world": WORLDS, "network": NETWORKS, "backend": BACKENDS}[kind]
    with pytest.raises(ValueError, match=message):
        registry.register(declared(kind, **changes))
    assert f"toy_{kind}" not in registry


def test_a_world_without_a_bound_model_says_why():
    cls = declared("world", bound_model=NoBound("a toy: nothing models its readings"))
    WORLDS.register(cls)
    WORLDS.unregister("toy_world")


def test_every_registered_part_is_consistent_with_the_others():
    """Every message kind a backend sends is carried by some network and declared in MESSAGE_KINDS; every world
    names a bound model that models it (or says why it has none)."""
    carried = set().union(*(cls.carries for cls in NETWORKS.values()))
    for name, cls in BACKENDS.items():
        assert cls.message_kind in MESSAGE_KINDS, name
        assert cls.message_kind == "none" or cls.message_kind in carried, name
    for name, cls in WORLDS.items():
        if isinstance(cls.bound_model, NoBound):
            continue
        assert MODELS[name].__name__ == f"coloc_env.bounds.models.{cls.bound_model}", name
