"""The batched SB3 vector env is the parallel env, copy for copy, bit for bit."""

import dataclasses
import os

import numpy as np
import pytest

import coloc_env

NAME = "bandwidth_fusion"
HORIZON = 6  # short episodes so that two auto-resets happen quickly
MRCLAM_DATA = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                           "..", "shared", "data", "mrclam", "MRCLAM_Dataset6")
# scenarios whose episode length is not ``horizon`` or that replay recorded data (skipped without it)
SHORT_CONFIGS = {"mrclam_relay": {"data": MRCLAM_DATA, "window_steps": HORIZON}}


def short_config(name: str) -> dict:
    """A short horizon where the scenario's config has one, so that auto-resets come quickly."""
    if name in SHORT_CONFIGS:
        config = dict(SHORT_CONFIGS[name])
        if "data" in config and not os.path.isdir(config["data"]):
            pytest.skip(f"{name}: recorded data not found at {config['data']}")
        return config
    fields = {f.name for f in dataclasses.fields(coloc_env.scenario_class(name).Config)}
    return {"horizon": HORIZON} if "horizon" in fields else {}


@pytest.mark.parametrize("name", coloc_env.SCENARIOS)
def test_copy_b_equals_parallel_env_seeded_s_plus_b_across_auto_resets(name):
    B, seed = 3, 40
    config = short_config(name)
    venv = coloc_env.vector_env(name, num_envs=B, seed=seed, **config)
    singles = [coloc_env.parallel_env(name, **config) for _ in range(B)]
    N = venv.num_agents
    horizon = venv.scenario.horizon
    obs = venv.reset()
    single_obs = [env.reset(seed=seed + b)[0] for b, env in enumerate(singles)]
    space = venv.action_space
    space.seed(0)
    ended = 0
    for _step in range(2 * horizon + 3):
        actions = np.stack([space.sample() for _ in range(B * N)])
        for b, env in enumerate(singles):
            for i, agent in enumerate(env.possible_agents):
                np.testing.assert_array_equal(obs[b * N + i], single_obs[b][agent])
        obs, rewards, dones, infos = venv.step(actions)
        for b, env in enumerate(singles):
            o, r, term, trunc, info = env.step({a: actions[b * N + i] for i, a in enumerate(env.possible_agents)})
            for i, agent in enumerate(env.possible_agents):
                sub = b * N + i
                assert rewards[sub] == np.float32(r[agent])
                assert dones[sub] == trunc[agent]
                if trunc[agent]:
                    np.testing.assert_array_equal(infos[sub]["terminal_observation"], o[agent])
                    assert infos[sub]["TimeLimit.truncated"] is True
                    ended += 1
                else:
                    batched_info = venv.scenario.info()
                    for key, value in info[agent].items():
                        if key == "action_mask":  # the env view's, not the scenario's: the vector env's action_masks()
                            np.testing.assert_array_equal(venv.action_masks()[sub], value.reshape(-1) == 1, err_msg=key)
                            continue
                        np.testing.assert_array_equal(batched_info[key][b, i], value, err_msg=key)
                    assert infos[sub] == {}
            single_obs[b] = env.reset()[0] if not env.agents else o
    assert ended >= 2 * B * N


def test_seed_method_reseeds_copies_and_none_draws_fresh_entropy():
    a = coloc_env.vector_env(NAME, num_envs=3, seed=7)
    b = coloc_env.vector_env(NAME, num_envs=3)
    b.seed(7)
    np.testing.assert_array_equal(a.reset(), b.reset())
    np.testing.assert_array_equal(a.scenario.truth, b.scenario.truth)
    c = coloc_env.vector_env(NAME, num_envs=3)
    c.reset()
    assert not np.array_equal(a.scenario.truth, c.scenario.truth)


def test_vector_env_spaces_and_errors():
    venv = coloc_env.vector_env(NAME, num_envs=2, seed=0)
    assert venv.num_envs == 8
    assert venv.action_space == coloc_env.parallel_env(NAME).action_space("uav_0")
    venv.reset()
    bad = np.zeros((8, venv.action_space.shape[0]))
    bad[3, 0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        venv.step(bad)
    with pytest.raises(ValueError, match="num_envs"):
        coloc_env.vector_env(NAME, num_envs=0)
    with pytest.raises(ValueError, match="unknown config key"):
        coloc_env.vector_env(NAME, num_envs=1, horizn=3)
    assert venv.get_attr("num_agents") == [4] * 8
    assert venv.render("rgb_array").ndim == 3


def test_native_and_supersuit_give_identical_transitions():
    from train.training import make_supersuit_vec_env

    B, seed = 3, 11
    native = coloc_env.vector_env(NAME, num_envs=B, seed=seed, horizon=HORIZON)
    supersuit = make_supersuit_vec_env(NAME, B, {"horizon": HORIZON})
    obs_s, _ = supersuit.venv.venv.reset(seed=seed)  # SuperSuit's ConcatVecEnv resets copy c with seed + c
    np.testing.assert_array_equal(native.reset(), obs_s)
    rng = np.random.default_rng(1)
    ended = 0
    for _ in range(2 * HORIZON + 1):
        actions = rng.uniform(-1, 1, size=(B * 4, native.action_space.shape[0]))
        o1, r1, d1, i1 = native.step(actions)
        o2, r2, d2, i2 = supersuit.step(actions)
        np.testing.assert_array_equal(o1, o2)
        np.testing.assert_array_equal(r1, r2)
        np.testing.assert_array_equal(d1, d2)
        for a, b in zip(i1, i2, strict=True):
            if "terminal_observation" in a:
                np.testing.assert_array_equal(a["terminal_observation"], b["terminal_observation"])
                assert a["TimeLimit.truncated"] and b["TimeLimit.truncated"]
                ended += 1
    assert ended == 2 * B * 4
