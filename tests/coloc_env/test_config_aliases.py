"""Older names of a part's fields (its config's ``aliases``) are read as their current names wherever a part is
given as a dict, and giving both names is refused naming the two."""

from __future__ import annotations

import pytest

import coloc_env
from coloc_env.networks.relay import Relay
from coloc_env.parts import make_config


@pytest.fixture
def relay_alias(monkeypatch):
    monkeypatch.setattr(Relay, "aliases", {"loss0": "loss_at_zero"})


def test_a_part_alias_sets_the_current_field(relay_alias):
    assert make_config(Relay, {"loss0": 0.25}, "network") == Relay(loss_at_zero=0.25)
    spec = coloc_env.compose(world="circles", network={"name": "relay", "loss0": 0.25}, backend="ukf_ccl")
    assert spec.network == Relay(loss_at_zero=0.25)


def test_a_part_alias_and_its_current_name_together_are_refused(relay_alias):
    with pytest.raises(ValueError, match=r"^network\.loss0 is another name of network\.loss_at_zero; give only one"):
        make_config(Relay, {"loss0": 0.25, "loss_at_zero": 0.5}, "network")


def test_a_part_alias_is_checked_like_its_current_name(relay_alias):
    with pytest.raises(ValueError, match=r"network\.loss_at_zero must be in \[0"):
        coloc_env.compose(world="circles", network={"name": "relay", "loss0": 1.5}, backend="ukf_ccl")


def test_without_the_alias_the_older_name_is_unknown():
    with pytest.raises(ValueError, match=r"unknown network field\(s\) \['loss0'\]"):
        make_config(Relay, {"loss0": 0.25}, "network")
