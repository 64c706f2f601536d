"""The per-scenario PPO settings: ``train.hyperparams.ppo`` starts from stable-baselines3's own PPO defaults and
gives each module its own copy, so that changing one scenario's settings cannot change another's."""

from __future__ import annotations

import inspect

from stable_baselines3 import PPO

import train.hyperparams as hp


def test_the_shared_settings_are_sb3s_ppo_defaults():
    defaults = inspect.signature(PPO.__init__).parameters
    for name, value in hp.PPO_DEFAULTS.items():
        if name != "policy_kwargs":  # SB3's default network is (64, 64) for the actor and the critic alike
            assert defaults[name].default == value, name
    assert hp.ppo(n_steps=64, n_epochs=3)["n_epochs"] == 3


def test_modules_do_not_share_the_defaults_nested_values():
    relay = hp.module("relay_ukf").HYPERPARAMS
    mrclam = hp.module("mrclam_relay").HYPERPARAMS
    assert relay["policy_kwargs"] is not mrclam["policy_kwargs"]
    assert relay["policy_kwargs"] is not hp.PPO_DEFAULTS["policy_kwargs"]
    hp.ppo()["policy_kwargs"]["net_arch"].append(32)
    assert hp.PPO_DEFAULTS["policy_kwargs"] == {"net_arch": [64, 64]}
