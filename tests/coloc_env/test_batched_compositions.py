"""Every compatible composition runs batched: copy b of ``vector_env(spec, num_envs=3, seed=s)`` is the
parallel env reset with seed s + b, step for step (the seeding rule of the design, for compositions as
``test_vector_env`` checks it for the presets), and a copy reset alone mid-run starts over as a fresh env."""

import numpy as np
import pytest

import coloc_env
from coloc_env.backends.kalman import VARIANTS
from coloc_env.data import mrclam
from tests.conftest import RECORDED_WORLDS

OK_ROWS = [r for r in coloc_env.compatibility() if r["ok"]]
B, SEED, STEPS = 3, 20, 4
SPECS = {f"{r['world']}/{r['network']}/{r['backend']}": dict(world=r["world"], network=r["network"],
                                                             backend=r["backend"]) for r in OK_ROWS}
# the backend options the compatibility rows (defaults only) do not reach, on a lossy network
SPECS.update({f"target_cv/bernoulli_delay/kalman:{v}": dict(world="target_cv", network="bernoulli_delay",
                                                            backend={"name": "kalman", "variant": v})
              for v in VARIANTS if v != "naive"})
SPECS["drift/bernoulli_delay/centralized_lmmse:paper"] = dict(
    world="drift", network="bernoulli_delay", backend={"name": "centralized_lmmse", "gain": "paper"})
SPECS.update({f"drift/bernoulli_delay/prediction_compensation:{r}": dict(
    world="drift", network="bernoulli_delay", backend={"name": "prediction_compensation", "reading": r})
    for r in ("forward", "age_aware")})


def _assert_copies_equal_singles(venv, singles, single_obs, actions_of):
    """Step the vector env and the single envs together; every observation, reward and info the same."""
    N = venv.num_agents
    obs = venv.scenario.observation().reshape(B * N, -1)
    for step in range(STEPS):
        for b, env in enumerate(singles):
            for i, agent in enumerate(env.possible_agents):
                np.testing.assert_allclose(obs[b * N + i], single_obs[b][agent], rtol=0, atol=1e-9)
        actions = actions_of(step)
        obs, rewards, _, _ = venv.step(actions)
        batched_info = venv.scenario.info()
        for b, env in enumerate(singles):
            single_obs[b], r, _, _, info = env.step({a: actions[b * N + i] for i, a in enumerate(env.possible_agents)})
            for i, agent in enumerate(env.possible_agents):
                np.testing.assert_allclose(rewards[b * N + i], np.float32(r[agent]), rtol=0, atol=1e-9)
                for key, value in info[agent].items():
                    if key == "action_mask":  # the env view's; the batched core's is venv.action_masks()
                        np.testing.assert_array_equal(venv.action_masks()[b * N + i], value.reshape(-1) == 1)
                        continue
                    np.testing.assert_allclose(batched_info[key][b, i], value, rtol=0, atol=1e-9, err_msg=key)


def _sampler(venv):
    space = venv.action_space
    space.seed(0)
    return lambda step: np.stack([space.sample() for _ in range(venv.num_envs)])


@pytest.mark.parametrize("name", list(SPECS))
def test_copy_b_of_a_batched_composition_equals_the_single_env_seeded_s_plus_b(name, request, monkeypatch):
    """Copy b equals the single env reset with seed SEED + b for STEPS steps; then copy 1 alone restarts with
    its own generator (a reset of a subset of copies) while copies 0 and 2 go on, and each copy still equals
    its single env."""
    if name.split("/")[0] in RECORDED_WORLDS:  # recorded data: data=None reads $COLOC_MRCLAM_DATA at build time
        monkeypatch.setenv(mrclam.ENV_VAR, request.getfixturevalue("mrclam_dataset6"))
    spec = coloc_env.compose(**SPECS[name])
    venv = coloc_env.vector_env(spec, num_envs=B, seed=SEED)
    singles = [coloc_env.parallel_env(spec) for _ in range(B)]
    venv.reset()
    single_obs = [env.reset(seed=SEED + b)[0] for b, env in enumerate(singles)]
    sample = _sampler(venv)
    _assert_copies_equal_singles(venv, singles, single_obs, sample)
    venv.scenario.reset([np.random.default_rng(SEED + 10)], env_index=np.array([1]))
    single_obs[1] = singles[1].reset(seed=SEED + 10)[0]
    _assert_copies_equal_singles(venv, singles, single_obs, sample)
