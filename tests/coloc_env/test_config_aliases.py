"""Older names of a part's fields (its config's ``aliases``) are read as their current names wherever a part is
given as a dict, and giving both names is refused naming the two."""

from __future__ import annotations

import pytest

import coloc_env
from coloc_env.networks.relay import Relay
from coloc_env.parts import BACKENDS, NETWORKS, WORLDS, make_config

REGISTRIES = {"world": WORLDS, "network": NETWORKS, "backend": BACKENDS}


@pytest.fixture
def relay_alias(monkeypatch):
    monkeypatch.setattr(Relay, "aliases", {"loss0": "loss_at_zero"})


def test_a_part_alias_sets_the_current_field(relay_alias):
    assert make_config(Relay, {"loss0": 0.25}, "network") == Relay(loss_at_zero=0.25)
    spec = coloc_env.compose(world="circles", network={"name": "relay", "loss0": 0.25}, backend="ukf_ccl")
    assert spec.network == Relay(loss_at_zero=0.25)


def test_replace_takes_an_alias_for_the_field_it_changes():
    from coloc_env.worlds.circles import Circles

    assert Circles(num_anchors=1).replace(num_platforms=4) == Circles(num_agents=4, num_anchors=1)
    with pytest.raises(ValueError, match=r"^world\.num_platforms must be in \[2, 16\], got 1$"):
        Circles().replace(num_platforms=1)
    with pytest.raises(ValueError, match=r"^world\.num_platforms is another name of world\.num_agents; give only"):
        Circles().replace(num_platforms=4, num_agents=4)


def test_a_part_alias_and_its_current_name_together_are_refused(relay_alias):
    with pytest.raises(ValueError, match=r"^network\.loss0 is another name of network\.loss_at_zero; give only one"):
        make_config(Relay, {"loss0": 0.25, "loss_at_zero": 0.5}, "network")


def test_a_part_alias_is_checked_like_its_current_name_and_refused_as_written(relay_alias):
    with pytest.raises(ValueError, match=r"^network\.loss0 must be in \[0\.0, 1\.0\], got 1\.5$"):
        coloc_env.compose(world="circles", network={"name": "relay", "loss0": 1.5}, backend="ukf_ccl")
    with pytest.raises(ValueError, match=r"^network\.loss_at_zero must be in \[0\.0, 1\.0\], got 1\.5$"):
        coloc_env.compose(world="circles", network={"name": "relay", "loss_at_zero": 1.5}, backend="ukf_ccl")


@pytest.mark.parametrize(("part", "fields", "message"), [
    # circles reads wang2019's num_platforms as num_agents: the range, and a bound it sets, under that name
    ("world", {"name": "circles", "num_platforms": 1}, r"^world\.num_platforms must be in \[2, 16\], got 1$"),
    ("world", {"name": "circles", "num_platforms": 3, "num_anchors": 4},
     r"^world\.num_anchors must be in \[0, world\.num_platforms = 3\], got 4$"),
    ("world", {"name": "circles", "num_platforms": "4"},
     r"^world\.num_platforms must be an integer in \[2, 16\], got '4'$"),
    # dfir reads the FIR window's older name horizon as window
    ("backend", {"name": "dfir", "horizon": 1}, r"^backend\.horizon must be in \[2, 1000\], got 1$"),
])
def test_a_registered_part_alias_is_refused_under_the_name_written(part, fields, message):
    with pytest.raises(ValueError, match=message):
        make_config(REGISTRIES[part][fields["name"]], {k: v for k, v in fields.items() if k != "name"}, part)


def test_compose_and_a_sweep_refuse_a_part_alias_under_the_name_written():
    from train.study import build_cells, parse_sweep

    with pytest.raises(ValueError, match=r"^world\.num_platforms must be in \[2, 16\], got 17$"):
        coloc_env.compose(world={"name": "circles", "num_platforms": 17}, network="relay", backend="ukf_dcl")
    with pytest.raises(ValueError, match=r"^--sweep world\.num_platforms=1 with backend ukf_dcl: "
                                         r"world\.num_platforms must be in \[2, 16\], got 1$"):
        build_cells("circles", "relay", ["ukf_dcl"], parse_sweep("world.num_platforms=4,1"), None)


def test_without_the_alias_the_older_name_is_unknown():
    with pytest.raises(ValueError, match=r"unknown network field\(s\) \['loss0'\]"):
        make_config(Relay, {"loss0": 0.25}, "network")


# relay's hop_cost: the network's older name of a hop's flat price, which is the composition's communication_cost
RELAY = {"world": "circles", "backend": "ukf_dcl"}


def test_a_relay_hop_cost_is_the_compositions_communication_cost():
    spec = coloc_env.compose(**RELAY, network={"name": "relay", "hop_cost": 0.5, "max_hops": 2})
    assert spec == coloc_env.compose(**RELAY, network={"name": "relay", "max_hops": 2}, communication_cost=0.5)
    assert "hop_cost" not in spec.network.as_dict()


def test_a_relay_hop_cost_is_refused_as_written_and_not_beside_communication_cost():
    with pytest.raises(ValueError, match=r"^network\.hop_cost must be in \[0\.0, 1000000000000\.0\], got -1\.0$"):
        coloc_env.compose(**RELAY, network={"name": "relay", "hop_cost": -1.0})
    with pytest.raises(ValueError, match=r"^network\.hop_cost is another name of communication_cost; give only one"):
        coloc_env.compose(**RELAY, network={"name": "relay", "hop_cost": 0.5}, communication_cost=0.5)
    with pytest.raises(ValueError, match=r"unknown network field\(s\) \['hop_cost'\] for network 'relay'.*"
                                         r"\(network\.hop_cost is the composition's communication_cost: give it to"):
        Relay().replace(hop_cost=0.5)
    with pytest.raises(ValueError, match=r"unknown network field\(s\) \['hop_cost'\] for network 'broadcast'"):
        coloc_env.compose(**RELAY, network={"name": "broadcast", "hop_cost": 0.5})


def test_a_sweep_over_relay_hop_cost_sets_the_communication_cost():
    from train.study import build_cells, parse_sweep

    cells = build_cells("circles", "relay", ["ukf_dcl"], parse_sweep("network.hop_cost=0,0.25"), None)
    assert [cells["ukf_dcl", v].communication_cost for v in ("0", "0.25")] == [0, 0.25]
    with pytest.raises(ValueError, match=r"^--sweep network\.hop_cost=-1 with backend ukf_dcl: "
                                         r"network\.hop_cost must be in \[0\.0, "):
        build_cells("circles", "relay", ["ukf_dcl"], parse_sweep("network.hop_cost=-1"), None)
