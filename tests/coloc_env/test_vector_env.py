"""The batched SB3 vector env is the parallel env, copy for copy, bit for bit."""

import dataclasses
import os
import warnings

import numpy as np
import pytest

import coloc_env
from tests.conftest import MRCLAM_DATASET6, MRCLAM_SKIP_REASON

NAME = "bandwidth_fusion"
HORIZON = 6  # short episodes so that two auto-resets happen quickly
# scenarios whose episode length is not ``horizon`` or that replay recorded data (skipped without it)
SHORT_CONFIGS = {"mrclam_relay": {"data": MRCLAM_DATASET6, "window_steps": HORIZON}}


def short_config(name: str) -> dict:
    """A short horizon where the scenario's config has one, so that auto-resets come quickly."""
    if name in SHORT_CONFIGS:
        config = dict(SHORT_CONFIGS[name])
        if "data" in config and not os.path.isdir(config["data"]):
            pytest.skip(MRCLAM_SKIP_REASON)
        return config
    fields = {f.name for f in dataclasses.fields(coloc_env.scenario_class(name).Config)}
    return {"horizon": HORIZON} if "horizon" in fields else {}


@pytest.mark.parametrize("name", [
    # Known defect, kept visible (strict): gps_denied_nbp's reported dNBP trace differs from the single env's in its
    # last bits (4e-15 relative) in a batch since the belief covariance gained its kernel term; everything else equal.
    pytest.param(n, marks=pytest.mark.xfail(strict=True, reason="dNBP trace rounds with the batch"))
    if n == "gps_denied_nbp" else n for n in coloc_env.SCENARIOS])
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
    returns = np.zeros(B * N, dtype=np.float32)  # what VecMonitor accumulates
    lengths = np.zeros(B * N, dtype=int)
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
                returns[sub] += np.float32(r[agent])
                lengths[sub] += 1
                if trunc[agent]:
                    np.testing.assert_array_equal(infos[sub]["terminal_observation"], o[agent])
                    assert infos[sub]["TimeLimit.truncated"] is True
                    assert infos[sub]["episode"]["r"] == float(returns[sub])
                    assert infos[sub]["episode"]["l"] == lengths[sub] == horizon
                    assert infos[sub]["episode"]["t"] >= 0
                    returns[sub] = lengths[sub] = 0
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
    np.testing.assert_array_equal(a.scenario.world.truth, b.scenario.world.truth)
    c = coloc_env.vector_env(NAME, num_envs=3)
    c.reset()
    assert not np.array_equal(a.scenario.world.truth, c.scenario.world.truth)


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


def test_episode_infos_are_vecmonitors():
    """The VecEnv's own ``episode`` infos are the ones SB3's VecMonitor computes from the same steps."""
    from stable_baselines3.common.vec_env import VecMonitor

    bare = coloc_env.vector_env(NAME, num_envs=2, seed=5, horizon=HORIZON)
    monitored = VecMonitor(coloc_env.vector_env(NAME, num_envs=2, seed=5, horizon=HORIZON))
    bare.reset()
    monitored.reset()
    rng = np.random.default_rng(2)
    seen = 0
    for _ in range(2 * HORIZON):
        actions = rng.uniform(-1, 1, size=(bare.num_envs, bare.action_space.shape[0]))
        _, _, dones, infos = bare.step(actions)
        _, _, _, monitor_infos = monitored.step(actions)
        for sub in np.flatnonzero(dones):
            assert infos[sub]["episode"]["r"] == monitor_infos[sub]["episode"]["r"]
            assert infos[sub]["episode"]["l"] == monitor_infos[sub]["episode"]["l"] == HORIZON
            seen += 1
        assert all("episode" not in infos[sub] for sub in np.flatnonzero(~dones))
    assert seen == 2 * bare.num_envs


def test_ppo_logs_the_episode_return_and_no_render_mode_warning(tmp_path):
    """A tiny PPO run on the bare VecEnv logs rollout/ep_rew_mean (the mean of the episodes' returns), and
    building SB3 VecEnvs over coloc (native, or SuperSuit through train.training) warns about no render_mode."""
    import csv

    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import configure

    from train.training import make_supersuit_vec_env

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        venv = coloc_env.vector_env(NAME, num_envs=1, seed=0, horizon=HORIZON)
        make_supersuit_vec_env(NAME, 2, {"horizon": HORIZON}).close()
        model = PPO("MlpPolicy", venv, n_steps=2 * HORIZON, batch_size=4 * HORIZON, n_epochs=1, seed=0,
                    device="cpu", verbose=0)
    assert not [str(w.message) for w in caught if "render_mode" in str(w.message)]
    model.set_logger(configure(str(tmp_path), ["csv"]))
    model.learn(total_timesteps=8 * HORIZON)
    with open(tmp_path / "progress.csv") as f:
        rows = list(csv.DictReader(f))
    assert rows and all(row["rollout/ep_rew_mean"] != "" for row in rows)
    returns = [info["r"] for info in model.ep_info_buffer]
    assert len(returns) == 2 * 4  # two rollouts of 2 episodes x 4 agents
    assert float(rows[-1]["rollout/ep_rew_mean"]) == pytest.approx(np.mean(returns), rel=1e-6)
    assert float(rows[-1]["rollout/ep_len_mean"]) == HORIZON
