"""A preset is added from its own module alone: its class declares what the rest of coloc reads (id version, metric
and unit, communication, episode-length field, policy module), and ``register_preset`` makes it appear in
``coloc_env.SCENARIOS``, the PettingZoo ids, ``coloc_env.envs``, ``agents`` and the CLI's lists.

The toy preset here is ``lossy_fusion``'s binding under another name and version, with its policies in this module;
``unregister_preset`` removes it again, so the other tests see the six presets."""

import importlib
import re
import sys

import numpy as np
import pettingzoo
import pytest

import agents
import coloc_env
from agents.base import FixedActionPolicy
from coloc_env.registry import env_id, env_ids, fingerprint
from coloc_env.scenarios.binding import PresetScenario, register_preset, unregister_preset
from coloc_env.scenarios.lossy_fusion import LossyFusionScenario
from train import cli, leaderboard

TOY = "toy_lossy"


def _silent(env) -> FixedActionPolicy:
    """No follower transmits (entry 0 < 0), every weight tilt 0."""
    scenario = env.unwrapped.scenario
    actions = np.zeros((scenario.num_agents, scenario.action_dim))
    actions[:, 0] = -1.0
    return FixedActionPolicy(env, actions)


POLICIES = {"quiet": _silent}
STRONGEST_BASELINES = ("quiet",)


class ToyScenario(LossyFusionScenario):
    name = TOY
    paper = "toy2026"
    version = 3
    metric = "fused position MSE of the toy"
    metric_unit = "m^2"
    communication = "toy messages"
    policy_module = __name__


@pytest.fixture
def toy():
    register_preset(ToyScenario)
    try:
        yield ToyScenario
    finally:
        unregister_preset(TOY)


def test_a_preset_registered_from_a_test_module_appears_everywhere(toy):
    assert coloc_env.SCENARIOS[-1] == TOY and TOY in coloc_env.PRESETS
    assert env_id(TOY) == "coloc/toy_lossy-v3" and env_ids()[-1] == "coloc/toy_lossy-v3"
    assert "coloc/toy_lossy-v3" in pettingzoo.parallel_registry and "coloc/toy_lossy-v3" in pettingzoo.aec_registry
    assert importlib.import_module(f"coloc_env.envs.{TOY}").parallel_env is coloc_env.envs.toy_lossy.parallel_env
    assert agents.available_policies(TOY) == ["random", "quiet"] and agents.strongest_baselines(TOY) == ("quiet",)
    assert leaderboard.metric(TOY) == ("fused position MSE of the toy", "m^2")
    assert leaderboard.communication(TOY) == "toy messages"
    assert TOY in cli._scenarios_help()
    assert re.search(rf"^  {TOY} +random, quiet$", cli._policies_epilog(), re.M)


def test_the_toy_preset_runs_as_the_binding_it_reuses(toy):
    """Registered under its id, the toy plays lossy_fusion's dynamics: the same seeded fingerprint."""
    toy_env = pettingzoo.make("parallel", env_id(TOY), max_cycles=4)
    assert toy_env.scenario.horizon == 4
    assert fingerprint(toy_env) == fingerprint(coloc_env.parallel_env("lossy_fusion", max_cycles=4))
    env = coloc_env.parallel_env(TOY)
    policy = agents.make_policy("quiet", env)
    observations, _ = env.reset(seed=0)
    actions = policy.act(observations)
    assert all(actions[a][0] == -1.0 for a in env.agents)


def test_list_prints_the_registered_preset(toy, capsys):
    assert cli.main(["list", "--ok", "--world", "target_cv"]) == 0
    line = next(line for line in capsys.readouterr().out.splitlines() if line.strip().startswith(TOY))
    assert "(coloc/toy_lossy-v3)" in line and "target_cv / bernoulli_delay / prediction_compensation" in line


def test_unregister_removes_the_preset_and_its_views():
    register_preset(ToyScenario)
    unregister_preset(TOY)
    assert TOY not in coloc_env.SCENARIOS and TOY not in coloc_env.PRESETS
    assert not any(TOY in ident for ident in env_ids())
    assert "coloc/toy_lossy-v3" not in pettingzoo.parallel_registry
    assert f"coloc_env.envs.{TOY}" not in sys.modules and not hasattr(coloc_env.envs, TOY)
    with pytest.raises(ValueError, match="unknown preset 'toy_lossy'"):
        env_id(TOY)
    with pytest.raises(ValueError, match="unknown preset 'toy_lossy'"):
        unregister_preset(TOY)


def test_a_preset_registered_twice_is_refused(toy):
    with pytest.raises(ValueError, match="preset 'toy_lossy' registered twice"):
        register_preset(ToyScenario)


DECLARED = ("paper", "Config", "version", "metric", "metric_unit", "communication", "policy_module")


@pytest.mark.parametrize("field", DECLARED)
def test_a_missing_or_mistyped_declaration_names_the_preset_and_the_field(field):
    declared = {k: getattr(ToyScenario, k) for k in DECLARED if k != field}
    missing = type("Missing", (PresetScenario,), {"name": "missing", **declared})
    with pytest.raises(TypeError, match=f"preset 'missing' declares no {field} "):
        register_preset(missing)
    mistyped = type("Mistyped", (ToyScenario,), {"name": "mistyped", field: None})
    with pytest.raises(TypeError, match=f"preset 'mistyped': {field} must be "):
        register_preset(mistyped)
    assert "missing" not in coloc_env.SCENARIOS and "mistyped" not in coloc_env.SCENARIOS


def test_bad_declarations_are_refused_with_their_field():
    with pytest.raises(TypeError, match="preset 'bad': version must be an integer >= 1, got 0"):
        register_preset(type("Bad", (ToyScenario,), {"name": "bad", "version": 0}))
    with pytest.raises(TypeError, match="episode_length_field 'steps' is not a field of LossyFusionConfig"):
        register_preset(type("Bad", (ToyScenario,), {"name": "bad", "episode_length_field": "steps"}))
    with pytest.raises(TypeError, match="a preset is a PresetScenario subclass"):
        register_preset(type("Bad", (), {"name": "bad"}))


@pytest.mark.parametrize("module,name,expected", [
    ("train.cli", "METRIC_UNITS", {"bandwidth_fusion": "m^2", "lossy_fusion": "m^2", "relay_ukf": "m",
                                   "gps_denied_nbp": "m", "nlos_horizon": "m^2", "mrclam_relay": "m"}),
    ("coloc_env.env", "EPISODE_LENGTH_FIELDS", {"mrclam_relay": "window_steps"}),
    ("agents", "STRONGEST_BASELINES", {"bandwidth_fusion": ("oracle_static",), "lossy_fusion": (),
                                       "relay_ukf": ("paper", "no_relay"), "gps_denied_nbp": ("paper", "threshold"),
                                       "nlos_horizon": ("best_constant",), "mrclam_relay": ("paper",)}),
    ("train.demo", "DEMO_RUNS", {"bandwidth_fusion": (20_000, 100), "lossy_fusion": (40_000, 100),
                                 "relay_ukf": (20_000, 20), "gps_denied_nbp": (4_800, 6), "nlos_horizon": (20_000, 6)}),
    ("train.evaluate", "EXTRA_ROWS", {"gps_denied_nbp": ("threshold:5",)}),
])
def test_the_tables_the_declarations_replaced_still_read_with_a_deprecation_warning(module, name, expected):
    with pytest.warns(DeprecationWarning, match=name):
        table = getattr(importlib.import_module(module), name)
    assert {key: value for key, value in table.items() if key in expected} == expected  # presets added since: theirs
