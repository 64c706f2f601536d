"""``scenario.true_position()`` is every agent's ``infos[agent]["true_position"]`` at once, (B, N, d), for every
preset and composition: the same shape and values at reset and after each step, the truth at the time of the
estimate the infos report (``position_error`` is the distance between the two), and a new array each call."""

import numpy as np
import pytest

import coloc_env
from coloc_env.data import mrclam
from tests.conftest import RECORDED_WORLDS

COMPOSITIONS = ("drift/bandwidth/bandwidth_fusion", "target_cv/bernoulli_delay/kalman", "circles/relay/ukf_dcl",
                "gps_denied/broadcast/range_ls", "nlos_orbit/random_delay/afge", "mrclam/relay/ukf_se2",
                "mrclam_slices/ideal/dead_reckoning")
STEPS = 3


def _check(scenario, infos, agents):
    truth = scenario.true_position()
    assert truth.shape[:2] == (1, len(agents))
    for i, agent in enumerate(agents):
        info = infos[agent]
        assert truth[0, i].shape == np.shape(info["true_position"]), agent
        np.testing.assert_array_equal(truth[0, i], info["true_position"], err_msg=agent)
        distance = np.linalg.norm(np.asarray(info["estimated_position"]) - truth[0, i])
        np.testing.assert_allclose(distance, info["position_error"], rtol=1e-12, atol=1e-12, err_msg=agent)
    truth[...] = np.nan  # the caller's array: the scenario's truth does not change with it
    assert np.isfinite(scenario.true_position()).all()


@pytest.mark.parametrize("name", [*coloc_env.SCENARIOS, *COMPOSITIONS])
def test_true_position_is_the_infos_true_position_of_every_agent(name, request, monkeypatch):
    if name == "mrclam_relay" or name.split("/")[0] in RECORDED_WORLDS:
        monkeypatch.setenv(mrclam.ENV_VAR, request.getfixturevalue("mrclam_dataset6"))
    env = coloc_env.parallel_env(name)
    _, infos = env.reset(seed=3)
    scenario = env.unwrapped.scenario
    _check(scenario, infos, env.possible_agents)
    space = env.action_space(env.possible_agents[0])
    space.seed(4)
    for _ in range(STEPS):
        _, _, _, _, infos = env.step({agent: space.sample() for agent in env.possible_agents})
        _check(scenario, infos, env.possible_agents)
