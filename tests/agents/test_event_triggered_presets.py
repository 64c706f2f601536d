"""The event-triggered families on the presets whose transmit or relay decision maps
(``PresetScenario.transport_entries``): their extremes are the preset's ``always`` and ``silent`` exactly, their
knobs order what they send, and they read the features by name from the preset's observation."""

import numpy as np
import pytest

import agents
import coloc_env
from agents.event_triggered import EXTREMES, POLICIES
from tests.test_bad_config_properties import HAVE_MRCLAM, MRCLAM_DATA

PRESETS = {
    "gps_denied_nbp": {"num_particles": 30, "num_iterations": 2, "horizon": 8},
    "lossy_fusion": {"horizon": 20},
    "relay_ukf": {"horizon": 20},
    "mrclam_relay": {"data": MRCLAM_DATA, "window_steps": 10, "noise_model": "calibrated"},
    "contention_localization": {"horizon": 12, "slots": 2},
}
MAPPED = [pytest.param(name, marks=pytest.mark.skipif(not HAVE_MRCLAM, reason="MRCLAM dataset 6 absent"))
          if name == "mrclam_relay" else name for name in PRESETS]


def play(name: str, policy_name: str, seed: int):
    """(actions (K, N, A), summed position error, summed rewards, messages) of one seeded episode."""
    env = coloc_env.parallel_env(name, **PRESETS[name])
    policy = agents.make_policy(policy_name, env, seed=7)
    policy.start_episode(seed)
    observations, _ = env.reset(seed=seed)
    actions, error, reward, messages = [], 0.0, 0.0, 0.0
    while env.agents:
        chosen = policy.act(observations)
        actions.append(np.stack([np.asarray(chosen[a], float) for a in env.possible_agents]))
        observations, rewards, _, _, infos = env.step(chosen)
        error += sum(i["position_error"] for i in infos.values())
        reward += sum(rewards.values())
        messages += sum(i["transmissions"] for i in infos.values())
    return np.array(actions), error, reward, messages


@pytest.mark.parametrize("name", MAPPED)
def test_the_families_are_named_for_the_presets_whose_decision_maps(name):
    assert set(POLICIES) <= set(agents.available_policies(name))
    assert coloc_env.make_core(name, **PRESETS[name]).transport_entries() is not None


@pytest.mark.parametrize("name", ["bandwidth_fusion", "nlos_horizon"])
def test_a_preset_without_a_mapped_decision_refuses_the_families(name):
    assert "periodic" not in agents.available_policies(name)
    env = coloc_env.parallel_env(name)
    with pytest.raises(ValueError, match=f"unknown policy 'periodic:2' for {name}"):
        agents.make_policy("periodic:2", env)


@pytest.mark.parametrize("name", MAPPED)
@pytest.mark.parametrize("family", sorted(EXTREMES))
def test_a_family_at_its_extreme_knobs_is_the_presets_always_and_silent(name, family):
    loud, quiet = EXTREMES[family]
    for knob, reference in ((loud, "always"), (quiet, "silent")):
        got = play(name, f"{family}:{knob}", seed=3)
        expected = play(name, reference, seed=3)
        np.testing.assert_array_equal(got[0], expected[0], err_msg=f"{family}:{knob}")
        assert got[1:] == expected[1:]
    assert play(name, "silent", seed=3)[3] < play(name, "always", seed=3)[3]  # the decision carries messages


@pytest.mark.parametrize("name", MAPPED)
def test_periodic_sends_fewer_messages_as_its_period_grows(name):
    """Per seeded episode, what periodic:P sends never grows with P (a quiet agent never sends more), from always
    (P = 1) down to silent (inf), and some period lies strictly between them."""
    sent = [play(name, f"periodic:{p}", seed=3)[3] for p in ("1", "2", "4", "inf")]
    assert all(a >= b for a, b in zip(sent[:-1], sent[1:], strict=True)), sent
    assert sent[0] > sent[2] > sent[-1] or sent[0] > sent[1] > sent[-1], sent


@pytest.mark.parametrize(("name", "family", "knobs"), [
    ("gps_denied_nbp", "uncertainty", ("0", "30", "100", "inf")),
    ("lossy_fusion", "send_on_delta", ("0", "1", "5", "inf")),
    ("lossy_fusion", "value", ("0", "50", "500", "inf")),
    ("relay_ukf", "uncertainty", ("0", "0.05", "0.2", "inf")),
])
def test_a_familys_messages_fall_as_its_knob_grows(name, family, knobs):
    """The mean messages over three seeded episodes never grow with the knob (a grid where what was sent feeds back
    on the features without crossing the means), from always down to none."""
    sent = [np.mean([play(name, f"{family}:{knob}", seed=s)[3] for s in range(3)]) for knob in knobs]
    assert all(a >= b for a, b in zip(sent[:-1], sent[1:], strict=True)), sent
    assert sent[0] > sent[-1] and len(set(sent)) > 2, sent
