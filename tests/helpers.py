"""Helpers shared by the scenario tests."""


def play(env, policy, seed):
    """One episode of ``policy`` from ``reset(seed=seed)``: [(obs, infos), (obs, rewards, infos), ...]."""
    observations, infos = env.reset(seed=seed)
    history = [(observations, infos)]
    while env.agents:
        observations, rewards, terms, truncs, infos = env.step(policy.act(observations))
        history.append((observations, rewards, infos))
    return history
