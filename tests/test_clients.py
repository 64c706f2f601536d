"""The MARL clients people use run on coloc: PettingZoo's module convention (``max_cycles``), TorchRL's
``PettingZooWrapper`` + ``check_env_specs`` on every preset and on compositions, and the client examples
under ``docs/clients`` (SB3 + SuperSuit, TorchRL; the RLlib one runs in its own venv, ``make rllib-example``).
TorchRL is in the ``test`` extra, so ``make test`` runs its checks; they skip only where it is not installed.
"""

from __future__ import annotations

import importlib
import os
import runpy
import warnings

import numpy as np
import pytest
from pettingzoo.test import max_cycles_test, parallel_api_test
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

import coloc_env
from coloc_env.env import episode_length_field
from coloc_env.envs import PRESET_MODULES
from tests.conftest import MRCLAM_DATASET6 as DATASET6
from tests.conftest import MRCLAM_SKIP_REASON as NO_MRCLAM

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CLIENTS = os.path.join(REPO, "docs", "clients")
HAVE_MRCLAM = os.path.isdir(DATASET6)
NO_TORCHRL = "torchrl is not installed (it is in the test extra: pip install -e '.[test]')"

# Small settings keeping each check under a second or two (episode length comes from max_cycles).
FAST = {"gps_denied_nbp": {"num_particles": 40}, "mrclam_relay": {"data": DATASET6}}


def _module(name: str):
    return importlib.import_module(f"coloc_env.envs.{name}")


def _presets_with_data():
    return [pytest.param(n, marks=pytest.mark.skipif(n == "mrclam_relay" and not HAVE_MRCLAM, reason=NO_MRCLAM))
            for n in PRESET_MODULES]


def test_every_preset_has_a_module():
    assert sorted(PRESET_MODULES) == sorted(coloc_env.SCENARIOS)
    for name in PRESET_MODULES:
        module = _module(name)
        assert {"parallel_env", "env", "raw_env"} <= set(dir(module))


@pytest.mark.parametrize("name", _presets_with_data())
def test_pettingzoo_max_cycles_test_passes(name, monkeypatch):
    if name == "mrclam_relay":
        monkeypatch.setenv("COLOC_MRCLAM_DATA", DATASET6)
    max_cycles_test(_module(name))


@pytest.mark.parametrize("name", _presets_with_data())
def test_max_cycles_is_the_scenarios_episode_length(name):
    module = _module(name)
    env = module.parallel_env(max_cycles=7, **FAST.get(name, {}))
    assert env.scenario.horizon == 7
    assert getattr(env.config, episode_length_field(env.scenario.__class__)) == 7
    env.reset(seed=0)
    steps = 0
    while env.agents:
        _, _, terminations, truncations, _ = env.step({a: env.action_space(a).sample() for a in env.agents})
        steps += 1
    assert steps == 7 and all(truncations.values()) and not any(terminations.values())
    assert isinstance(module.env(max_cycles=3, **FAST.get(name, {})), OrderEnforcingWrapper)
    assert not isinstance(module.raw_env(max_cycles=3, **FAST.get(name, {})), OrderEnforcingWrapper)


def test_module_env_is_the_same_env_as_coloc_env_parallel_env():
    from coloc_env.envs import relay_ukf

    a, b = relay_ukf.parallel_env(max_cycles=12), coloc_env.parallel_env("relay_ukf", horizon=12)
    obs_a, _ = a.reset(seed=4)
    obs_b, _ = b.reset(seed=4)
    for _ in range(12):
        actions = {agent: a.action_space(agent).sample() for agent in a.agents}
        obs_a, rew_a, *_ = a.step(actions)
        obs_b, rew_b, *_ = b.step(actions)
        for agent in a.possible_agents:
            np.testing.assert_allclose(obs_a[agent], obs_b[agent], rtol=0, atol=1e-9)
            assert abs(rew_a[agent] - rew_b[agent]) <= 1e-9


def test_max_cycles_errors_name_the_keyword():
    from coloc_env.envs import gps_denied_nbp, relay_ukf

    with pytest.raises(ValueError, match=r"max_cycles must be an integer in \[1, 1000000000\], got 0.5"):
        relay_ukf.parallel_env(max_cycles=0.5)
    with pytest.raises(ValueError, match=r"max_cycles must be in \[1, 1000000000\], got 0"):
        relay_ukf.parallel_env(max_cycles=0)
    with pytest.raises(ValueError, match=r"max_cycles sets horizon of gps_denied_nbp: horizon must be in \[1, 10000\]"):
        gps_denied_nbp.parallel_env(max_cycles=20_000)
    with pytest.raises(ValueError, match="max_cycles=5 and horizon=6 both set the episode length of relay_ukf"):
        relay_ukf.parallel_env(max_cycles=5, horizon=6)
    assert relay_ukf.parallel_env(max_cycles=5, horizon=5).scenario.horizon == 5


def test_max_cycles_sets_a_compositions_horizon():
    from coloc_env.env import CoLocParallelEnv
    from coloc_env.scenarios.composed import ComposedScenario

    spec = coloc_env.compose(world="circles", network="relay", backend="ukf_dcl")
    env = CoLocParallelEnv(ComposedScenario, composition=spec, max_cycles=4)
    env.reset(seed=0)
    steps = 0
    while env.agents:
        env.step({a: env.action_space(a).sample() for a in env.agents})
        steps += 1
    assert steps == 4 == env.scenario.horizon
    assert coloc_env.parallel_env(coloc_env.PRESETS["relay_ukf"], max_cycles=6).scenario.horizon == 6


def test_vector_env_takes_max_cycles():
    from coloc_env.scenarios import REGISTRY
    from coloc_env.vector import CoLocVecEnv

    vec = CoLocVecEnv(REGISTRY["relay_ukf"], num_envs=2, seed=0, max_cycles=3)
    vec.reset()
    actions = np.zeros((vec.num_envs, *vec.action_space.shape))
    dones = [vec.step(actions)[2] for _ in range(3)]
    assert not dones[0].any() and not dones[1].any() and dones[2].all()


def test_render_mode_argument_keeps_the_pettingzoo_api():
    env = coloc_env.parallel_env("relay_ukf", render_mode="rgb_array", horizon=6)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        parallel_api_test(env, num_cycles=6)
    env.reset(seed=0)
    assert env.render("rgb_array").shape == env.render().shape
    with pytest.raises(ValueError, match="render mode 'human' differs"):
        env.render("human")


# --- TorchRL ---------------------------------------------------------------------------------------------
COMPOSITIONS = [
    {"world": "circles", "network": "relay", "backend": "ukf_dcl"},
    {"world": "circles", "network": "broadcast", "backend": {"name": "dnbp", "num_particles": 40}},
    {"world": "gps_denied", "network": "ideal", "backend": "range_ls"},
    {"world": "target_cv", "network": "bernoulli_delay", "backend": "kalman"},
    {"world": "drift", "network": "bandwidth", "backend": "bandwidth_fusion"},
]


def _torchrl_check(env, steps: int) -> None:
    """``check_env_specs`` and a rollout whose rewards are those the coloc env gives for the same actions."""
    torchrl_pettingzoo = pytest.importorskip("torchrl.envs.libs.pettingzoo", reason=NO_TORCHRL)
    from torchrl.envs.utils import check_env_specs

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "PettingZoo in TorchRL is tested using version == 1.24.3"
        wrapped = torchrl_pettingzoo.PettingZooWrapper(env, use_mask=False, categorical_actions=False, seed=0)
        check_env_specs(wrapped, seed=0)
        rollout = wrapped.rollout(steps)
    groups = list(wrapped.group_map)
    assert rollout.batch_size[0] == steps
    for group in groups:
        agents = wrapped.group_map[group]
        assert rollout[group, "observation"].shape[:2] == (steps, len(agents))
        assert np.isfinite(rollout["next", group, "reward"].numpy()).all()


def _torchrl_matches_coloc(make_env, steps: int) -> None:
    """Replaying a TorchRL rollout's actions in a fresh coloc env with the same seed gives its rewards."""
    torchrl_pettingzoo = pytest.importorskip("torchrl.envs.libs.pettingzoo", reason=NO_TORCHRL)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        wrapped = torchrl_pettingzoo.PettingZooWrapper(make_env(), use_mask=False, categorical_actions=False)
        first = wrapped.reset(seed=11)  # TorchRL passes reset's seed on to the PettingZoo env
        rollout = wrapped.rollout(steps, auto_reset=False, tensordict=first)
    direct = make_env()
    direct.reset(seed=11)
    for k in range(steps):
        actions, expected = {}, {}
        for group, agents in wrapped.group_map.items():
            for i, agent in enumerate(agents):
                actions[agent] = rollout[group, "action"][k, i].numpy()
                expected[agent] = float(rollout["next", group, "reward"][k, i, 0])
        _, rewards, *_ = direct.step(actions)
        for agent, value in expected.items():
            assert rewards[agent] == pytest.approx(value, rel=1e-5, abs=1e-5)


@pytest.mark.parametrize("name", _presets_with_data())
def test_torchrl_check_env_specs_on_every_preset(name):
    _torchrl_check(_module(name).parallel_env(max_cycles=4, **FAST.get(name, {})), steps=4)


@pytest.mark.parametrize("parts", COMPOSITIONS, ids=lambda p: "-".join(
    v if isinstance(v, str) else v["name"] for v in p.values()))
def test_torchrl_check_env_specs_on_compositions(parts):
    _torchrl_check(coloc_env.parallel_env(coloc_env.compose(**parts, horizon=4)), steps=4)


def test_torchrl_rollout_replays_in_coloc():
    _torchrl_matches_coloc(lambda: coloc_env.parallel_env("lossy_fusion", horizon=6), steps=6)


# --- the examples in docs/clients ----------------------------------------------------------------------
def _example(filename: str) -> dict:
    return runpy.run_path(os.path.join(CLIENTS, filename), run_name="example")


def test_sb3_supersuit_example_trains_the_transitions_it_says():
    example = _example("sb3_ppo.py")
    model = example["main"](total_timesteps=256, copies=2, seed=0)
    # one PPO update is n_steps x (copies x agents) transitions, as the example's docstring says
    assert model.n_envs == 2 * 4 and model.n_steps == 32
    assert model.num_timesteps == 256
    again = example["main"](total_timesteps=256, copies=2, seed=0)
    for p, q in zip(model.policy.parameters(), again.policy.parameters(), strict=True):
        np.testing.assert_allclose(p.detach().numpy(), q.detach().numpy(), rtol=0, atol=1e-9)


def test_sb3_supersuit_example_records_its_episodes():
    """The example's VecMonitor gives SB3 the episodes' returns and lengths (rollout/ep_rew_mean)."""
    model = _example("sb3_ppo.py")["main"](total_timesteps=512, copies=1, seed=0)
    assert len(model.ep_info_buffer) == 2 * 4  # 128 steps of 4 agent-envs: two episodes of max_cycles = 64 each
    assert all(episode["l"] == 64 for episode in model.ep_info_buffer)


def test_torchrl_example_rolls_out_every_platform():
    pytest.importorskip("torchrl", reason="torchrl is not installed (pip install -e '.[test]')")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rollout = _example("torchrl_rollout.py")["main"](steps=5, seed=0)
    assert rollout["platform", "observation"].shape[:2] == (5, 4)
    assert rollout["next", "platform", "reward"].shape == (5, 4, 1)


def test_rllib_example_is_importable_python():
    source = open(os.path.join(CLIENTS, "rllib_ppo.py")).read()
    compile(source, "rllib_ppo.py", "exec")  # RLlib itself runs in its own venv (make rllib-example)
    assert "ParallelPettingZooEnv" in source and "max_cycles" in source
