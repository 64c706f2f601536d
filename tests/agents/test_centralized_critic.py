"""The centralized-critic recipe: the critic reads ``[own observation | state()]``, the actor only
its own observation, in training and at evaluation (:mod:`agents.centralized_critic`)."""

import os

import numpy as np
import pytest

import coloc_env
from agents.centralized_critic import (
    CentralizedCriticPolicy,
    CriticStateObservation,
    critic_observation_space,
    extend_observation,
    is_centralized,
)
from train.io import read_json

torch = pytest.importorskip("torch")


def test_extend_observation_puts_each_copys_state_after_each_agents_observation():
    observation = np.arange(2 * 3 * 4, dtype=float).reshape(2, 3, 4)
    state = np.array([[100.0, 101.0], [200.0, 201.0]])
    out = extend_observation(observation, state)
    assert out.shape == (2, 3, 6) and out.dtype == np.float32
    np.testing.assert_array_equal(out[..., :4], observation)
    np.testing.assert_array_equal(out[1, 2, 4:], [200.0, 201.0])
    np.testing.assert_array_equal(out[0, 1, 4:], [100.0, 101.0])


def test_the_actor_ignores_the_state_part_and_the_critic_reads_it():
    torch.set_num_threads(1)
    from stable_baselines3 import PPO

    venv = CriticStateObservation(coloc_env.vector_env("lossy_fusion", num_envs=2, seed=0))
    model = PPO(CentralizedCriticPolicy, venv, n_steps=8, batch_size=16, seed=0, device="cpu",
                policy_kwargs={"local_dim": venv.local_dim})
    assert is_centralized(model)
    obs = venv.reset()
    assert obs.shape == (venv.num_envs, venv.local_dim + venv.scenario.state_space().shape[0])
    other = obs.copy()
    other[:, venv.local_dim:] = np.random.default_rng(1).normal(size=other[:, venv.local_dim:].shape) * 10
    policy = model.policy
    with torch.no_grad():
        a, b = (policy.get_distribution(policy.obs_to_tensor(o)[0]).distribution for o in (obs, other))
        assert torch.equal(a.mean, b.mean) and torch.equal(a.stddev, b.stddev)
        values = [policy.predict_values(policy.obs_to_tensor(o)[0]) for o in (obs, other)]
    assert not torch.allclose(*values)  # the critic does read the state


def test_terminal_observations_carry_the_state_before_the_auto_reset():
    """An ended episode's terminal observation ends with the state its copy had at the last step: the state
    ``parallel_env`` seeded the same shows after the same actions."""
    horizon, seed = 3, 7
    venv = CriticStateObservation(coloc_env.vector_env("relay_ukf", num_envs=2, seed=seed, horizon=horizon))
    venv.reset()
    actions = np.zeros((venv.num_envs, *venv.action_space.shape), dtype=np.int64)
    for _ in range(horizon):
        _, _, dones, infos = venv.step(actions)
    assert dones.all()
    for b in range(2):
        env = coloc_env.parallel_env("relay_ukf", horizon=horizon)
        env.reset(seed=seed + b)
        for _ in range(horizon):
            env.step({a: actions[0] for a in env.agents})
        for i in range(venv.num_agents):
            terminal = infos[b * venv.num_agents + i]["terminal_observation"]
            np.testing.assert_allclose(terminal[venv.local_dim:], env.state().astype(np.float32), rtol=0, atol=0)


def test_a_centralized_critic_model_trains_loads_and_evaluates_alike_batched_and_looped(tmp_path, monkeypatch):
    """CRITIC = "centralized" trains the split policy (with MaskablePPO here), model.json names it, make_policy
    loads it and checks its [observation | state] space, and the batched evaluation equals the env loop."""
    import agents
    import train.hyperparams.relay_ukf as settings
    from train.evaluate import run_episodes, run_model_batched
    from train.training import train

    monkeypatch.setattr(settings, "CRITIC", "centralized", raising=False)
    path = train("relay_ukf", timesteps=256, seed=2, out=str(tmp_path), progress_bar=False, curve_points=0)
    meta = read_json(os.path.join(os.path.dirname(path), "model.json"))
    assert meta["critic"] == "centralized" and meta["algorithm"] == "maskable_ppo"
    env = coloc_env.parallel_env("relay_ukf", horizon=40)
    policy = agents.make_policy(path, env)
    assert is_centralized(policy.model)
    agent = env.possible_agents[0]
    assert policy.model.observation_space == critic_observation_space(env.observation_space(agent), env.state_space)
    batched = run_model_batched(policy.model, "relay_ukf", 3, seed_base=91, horizon=40,
                               paper_entries=policy.paper_entries)
    looped = run_episodes("relay_ukf", path, 3, seed_base=91, horizon=40)
    assert batched["per_episode_cost"] == pytest.approx(looped["per_episode_cost"], rel=1e-9)
    monkeypatch.setattr(settings, "CRITIC", "global")
    with pytest.raises(ValueError, match=r"CRITIC of train/hyperparams/relay_ukf.py must be one of"):
        train("relay_ukf", timesteps=1, seed=0, out=str(tmp_path), progress_bar=False, curve_points=0)


def test_a_model_for_another_state_is_refused(tmp_path, monkeypatch):
    """The space check compares the model's input with [observation | state] of the env it is loaded for."""
    import agents
    import train.hyperparams.lossy_fusion as settings
    from train.training import train

    monkeypatch.setattr(settings, "CRITIC", "centralized", raising=False)
    path = train("lossy_fusion", timesteps=64, seed=0, out=str(tmp_path), progress_bar=False, curve_points=0)
    agents.make_policy(path, coloc_env.parallel_env("lossy_fusion"))
    with pytest.raises(ValueError, match=r"(?s)has observation space .*\(45,\), float32\), the env has .*\(82,\)"):
        agents.make_policy(path, coloc_env.parallel_env("lossy_fusion", num_agents=3))
    with pytest.raises(ValueError, match=r"centralized critic, which reads the native vector env's state"):
        train("lossy_fusion", timesteps=1, seed=0, out=str(tmp_path), vec="supersuit", progress_bar=False,
              curve_points=0)


def test_a_vec_env_without_a_core_is_refused():
    with pytest.raises(ValueError, match=r"centralized critic needs coloc_env.vector_env"):
        CriticStateObservation(object())
