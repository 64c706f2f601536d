"""A policy name, variant or seed that cannot be used is a one-line ValueError saying which (never a TypeError,
an AttributeError or int()'s message)."""

from __future__ import annotations

import os

import pytest

import agents
import coloc_env
from tests.conftest import MRCLAM_DATASET6, MRCLAM_SKIP_REASON


@pytest.mark.parametrize("scenario", ["relay_ukf", "gps_denied_nbp", "lossy_fusion", "mrclam_relay"])
def test_a_variant_of_a_policy_that_takes_none_is_refused(scenario):
    if scenario == "mrclam_relay":
        if not os.path.isdir(MRCLAM_DATASET6):
            pytest.skip(MRCLAM_SKIP_REASON)
        env = coloc_env.parallel_env(scenario, data=MRCLAM_DATASET6)
    else:
        env = coloc_env.parallel_env(scenario)
    with pytest.raises(ValueError, match=rf"^policy 'paper' of {scenario} takes no variant, got 'paper:NOPE'$"):
        agents.make_policy("paper:NOPE", env)


@pytest.mark.parametrize("variant", ["abc", "1.5", "-3", "1e1"])
def test_a_constant_window_that_is_not_an_integer_is_refused_with_its_range(variant):
    env = coloc_env.parallel_env("nlos_horizon")
    with pytest.raises(ValueError, match=r"constant's window \(constant:N\) must be an integer in \[4, 30\], got"):
        agents.make_policy(f"constant:{variant}", env)


def test_an_empty_variant_is_refused():
    env = coloc_env.parallel_env("nlos_horizon")
    with pytest.raises(ValueError, match=r"^policy 'constant:': the variant after ':' is empty$"):
        agents.make_policy("constant:", env)


@pytest.mark.parametrize("name", [5, None, 1.5, ["paper"], b"paper"])
def test_a_policy_name_that_is_not_a_string_is_refused(name):
    env = coloc_env.parallel_env("lossy_fusion")
    with pytest.raises(ValueError, match=r"^policy name must be a string"):
        agents.make_policy(name, env)


@pytest.mark.parametrize("env", [None, "lossy_fusion", 3])
def test_a_policy_needs_a_coloc_env(env):
    with pytest.raises(ValueError, match=r"^env must be a coloc env"):
        agents.make_policy("paper", env)
