"""Helpers shared by the scenario tests."""


def play(env, policy, seed):
    """One episode of ``policy`` from ``reset(seed=seed)``: [(obs, infos), (obs, rewards, infos), ...]."""
    observations, infos = env.reset(seed=seed)
    history = [(observations, infos)]
    while env.agents:
        observations, rewards, terms, truncs, infos = env.step(policy.act(observations))
        history.append((observations, rewards, infos))
    return history


def decode_tables(scenario, actions):
    """Actions (B, N, A) of the ``bandwidth_fusion`` core -> the receiver-relative selections (B, N, N-1, n) and
    absolute weights (B, N, N) it decodes them to (the network's selection, the backend's fusion weights)."""
    blocks = scenario.decode_actions(actions)
    selection = scenario.links.selection_at(blocks[..., 0].astype("int64"))
    return selection, scenario.backend.decode_weights(blocks[..., 1:])


def settings_module(scenario: str, **settings):
    """A stand-in for ``train/hyperparams/<scenario>.py`` holding ``settings``, tiny PPO rollouts
    (``HYPERPARAMS``) unless given; install it with ``monkeypatch.setitem(sys.modules, module.__name__, module)``."""
    import types

    from train.hyperparams import module_name, ppo

    module = types.ModuleType(f"train.hyperparams.{module_name(scenario)}")
    module.HYPERPARAMS = ppo(n_steps=8, batch_size=32, n_epochs=1)
    for field, value in settings.items():
        setattr(module, field, value)
    return module


def leaderboard_row(policy, costs, comm=1.0, scenario="relay_ukf"):
    """A hand-made leaderboard row of ``policy`` with per-episode ``costs`` on the evaluation seeds."""
    import numpy as np

    from train.evaluate import EVAL_SEED_BASE

    costs = np.asarray(costs, float)
    return {"scenario": scenario, "policy": policy, "mean_cost": float(costs.mean()), "ci95": 0.1,
            "paper_cost": float(costs.mean()), "initial_cost": 0.0, "communication_per_step": comm,
            "episodes": len(costs), "seed_base": EVAL_SEED_BASE, "per_episode_cost": list(costs)}
