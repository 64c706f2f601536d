"""The composed observation's own features (covariance_known, displacement, steps_since, message_value,
communication_cost) and the cost-conditioned episodes of ``cost_range``."""

import numpy as np
import pytest

import coloc_env
from coloc_env.backends.base import Backend
from coloc_env.scenarios.composed import DISTANCE_SCALE, OWN_FEATURES

ACKNOWLEDGED = "circles/gilbert_elliott/ukf_ccl"  # acknowledgements; central messages, lost in bursts
UNACKNOWLEDGED = "circles/broadcast/ukf_ccl"
SMALL = "drift/broadcast/kalman"  # 4 agents, one shared target


def core_of(name: str, batch: int = 1, **options):
    return coloc_env.make_core(coloc_env.composition_named(name, **options), batch=batch)


def own(core) -> dict:
    """{feature: (B, N)} of the current observation (displacement in m)."""
    obs = core.observation().astype(float)
    out = {name: obs[..., core.feature_index(name)] for name in OWN_FEATURES}
    out["displacement"] = out["displacement"] * DISTANCE_SCALE
    return out


def test_feature_indices_follow_the_step_fraction_in_the_documented_order():
    core = core_of(SMALL)
    N = core.num_agents
    assert [core.feature_index(name) for name in OWN_FEATURES] == list(range(3 * N + 2, 3 * N + 7))
    assert (core.feature_index("log_trace"), core.feature_index("step_fraction")) == (N, 3 * N + 1)
    with pytest.raises(ValueError, match="has no feature 'nonsense'"):
        core.feature_index("nonsense")
    preset = coloc_env.make_core("contention_localization")  # the composition's whole table
    composed = core_of("gps_denied/contention/ukf_ccl")
    assert preset.obs_dim == composed.obs_dim
    assert [preset.feature_index(n) for n in OWN_FEATURES] == [composed.feature_index(n) for n in OWN_FEATURES]
    with pytest.raises(ValueError, match="has no feature 'displacement'"):
        coloc_env.make_core("bandwidth_fusion").feature_index("displacement")


@pytest.mark.parametrize("name", [ACKNOWLEDGED, UNACKNOWLEDGED])
def test_the_reference_is_the_last_delivered_or_sent_transmission(name):
    """Played with every transmission on: an agent whose transmission of the step was acknowledged (over
    gilbert_elliott) or sent (over broadcast, no acknowledgements) observes displacement 0 and steps_since 0; any
    other agent's steps_since grows by 1 / horizon, and its displacement is the distance of its estimate from the
    estimate the infos reported at its reference step."""
    core = core_of(name, horizon=40)
    core.reset([np.random.default_rng(4)])
    action = np.tile(core.action_vector("maximum"), (1, core.num_agents, 1))
    reference = core.backend.posterior_position.copy()
    before = own(core)
    assert np.all(before["steps_since"] == 0) and np.all(before["displacement"] == 0)
    kept = lost = 0
    while not core.done().all():
        core.step(action)
        now = own(core)
        sent = core.network.transmissions > 0
        acknowledged = core.network.acknowledged()
        renewed = sent if acknowledged is None else sent & acknowledged
        estimate = core.info()["estimated_position"]
        reference = np.where(renewed[..., None], estimate, reference)
        np.testing.assert_array_equal(now["steps_since"][renewed], 0.0)
        np.testing.assert_allclose(now["steps_since"][~renewed], before["steps_since"][~renewed] + 1 / 40, rtol=1e-6)
        np.testing.assert_allclose(now["displacement"], np.linalg.norm(estimate - reference, axis=-1), rtol=1e-5,
                                   atol=1e-9)
        kept += int((~renewed).sum())
        lost += int((sent & ~renewed).sum())
        before = now
    assert kept > 0  # the centre never transmits (ukf_ccl)
    if acknowledged is not None:
        assert lost > 0  # a lost transmission kept its agent's reference: the case is exercised
    assert acknowledged is None if name == UNACKNOWLEDGED else acknowledged is not None


def test_a_copy_reset_alone_resets_only_its_own_references():
    core = core_of(SMALL, batch=2)
    twin = core_of(SMALL, batch=2)
    for c in (core, twin):
        c.reset([np.random.default_rng(1), np.random.default_rng(2)])
    quiet = np.tile(core.action_vector("minimum"), (2, core.num_agents, 1))
    for _ in range(5):
        core.step(quiet)
        twin.step(quiet)
    before = core.observation()
    assert np.all(own(core)["steps_since"] > 0)
    core.reset([np.random.default_rng(9)], env_index=[1])
    after = own(core)
    np.testing.assert_array_equal(core.observation()[0], before[0])
    assert np.all(after["steps_since"][1] == 0) and np.all(after["displacement"][1] == 0)
    core.step(quiet)
    twin.step(quiet)
    np.testing.assert_array_equal(core.observation()[0], twin.observation()[0])


def test_message_value_is_the_open_loop_trace_growth_less_the_own_trace():
    core = core_of(SMALL)
    core.reset([np.random.default_rng(0)])
    B, N = core.batch, core.num_agents
    backend = core.backend
    P = np.broadcast_to(2.0 * np.eye(2), (B, N, 2, 2))
    Q = np.asarray(backend.position_process_noise(), float)
    reference = np.broadcast_to(np.eye(2), (B, N, 2, 2))
    steps = np.full((B, N), 3)
    value = backend.message_value(reference, steps, cov=P)
    np.testing.assert_allclose(value, max(2.0 + 3 * np.trace(Q) - 4.0, 0.0), rtol=1e-12)
    assert np.all(backend.message_value(reference, np.zeros((B, N)), cov=P) == 0.0)  # clipped at 0
    assert np.all(own(core)["message_value"] == 0.0)  # at reset: the reference is the agent's own covariance


def test_a_target_backend_reads_the_position_block_of_the_targets_noise_once_and_read_only():
    core = core_of("target_cv/ideal/kalman")
    core.reset([np.random.default_rng(0)])
    backend, world = core.backend, core.world
    Q = backend.position_process_noise()
    index = list(world.position_index)
    np.testing.assert_array_equal(Q, np.asarray(world.motion_model.covar())[np.ix_(index, index)])
    assert backend.position_process_noise() is Q  # gathered once
    with pytest.raises(ValueError, match="read-only"):
        Q[0, 0] = 1.0


def test_without_a_covariance_the_flag_says_so_and_the_features_are_zero(monkeypatch):
    core = core_of(SMALL)
    core.reset([np.random.default_rng(0)])
    assert np.all(own(core)["covariance_known"] == 1.0)
    monkeypatch.setattr(core.backend, "local_covariance", lambda: None)
    core.step(np.tile(core.action_vector("minimum"), (1, core.num_agents, 1)))
    features = own(core)
    assert np.all(features["covariance_known"] == 0.0) and np.all(features["message_value"] == 0.0)
    assert np.all(core.observation()[..., core.feature_index("log_trace")] == 0.0)
    assert Backend.position_cov(core.backend) is None  # the base declares none


# --- cost_range --------------------------------------------------------------------------------------------------
def rollout(name: str, seed: int, which: str = "maximum", **options):
    """(observations, rewards, infos' communication_cost, position errors) of one seeded episode."""
    core = core_of(name, **options)
    core.reset([np.random.default_rng(seed)])
    action = np.tile(core.action_vector(which), (1, core.num_agents, 1))
    obs, rewards, costs, errors = [core.observation()], [], [], []
    while not core.done().all():
        core.step(action)
        obs.append(core.observation())
        rewards.append(core.reward())
        info = core.info()
        costs.append(info["communication_cost"])
        errors.append(info["position_error"])
    return np.array(obs), np.array(rewards), np.array(costs), np.array(errors)


def test_a_cost_range_episode_is_reproduced_by_its_seed_and_moves_no_other_draw():
    first = rollout(SMALL, 5, cost_range=(0.1, 10.0))
    again = rollout(SMALL, 5, cost_range=(0.1, 10.0))
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a, b)
    fixed = rollout(SMALL, 5, communication_cost=0.0)
    np.testing.assert_array_equal(first[3], fixed[3])  # the same truth, readings and deliveries
    cost = first[2][0, 0, 0]
    assert 0.1 <= cost <= 10.0 and np.all(first[2] == cost)  # one cost for the whole episode
    index = core_of(SMALL).feature_index("communication_cost")
    np.testing.assert_array_equal(first[0][..., index], np.float32(cost))
    assert rollout(SMALL, 6, cost_range=(0.1, 10.0))[2][0, 0, 0] != cost


@pytest.mark.parametrize(("lo", "hi"), [(0.01, 100.0), (0.0, 3.0)])
def test_the_drawn_costs_lie_in_the_range_with_the_documented_law(lo, hi):
    """200 copies: every cost in [lo, hi]; log-uniform for lo > 0 (the mean of log c within 4 standard errors of
    the midpoint of [log lo, log hi]), uniform for lo = 0 (the mean within 4 standard errors of hi / 2)."""
    B = 200
    core = core_of(SMALL, batch=B, cost_range=(lo, hi))
    core.reset([np.random.default_rng(s) for s in range(B)])
    costs = core.costs.copy()
    assert np.all((lo <= costs) & (costs <= hi)) and len(np.unique(costs)) == B
    x, a, b = (np.log(costs), np.log(lo), np.log(hi)) if lo > 0 else (costs, lo, hi)
    assert abs(x.mean() - (a + b) / 2) < 4 * (b - a) / np.sqrt(12 * B)
    single = core_of(SMALL, cost_range=(lo, hi))
    single.reset([np.random.default_rng(7)])
    assert single.costs[0] == costs[7]  # copy b of a batch draws what the copy run alone draws


def test_a_degenerate_range_is_the_fixed_cost():
    ranged = rollout(SMALL, 2, cost_range=(0.3, 0.3))
    fixed = rollout(SMALL, 2, communication_cost=0.3)
    np.testing.assert_allclose(ranged[1], fixed[1], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(ranged[0], fixed[0])
    assert np.all(fixed[2] == 0.3) and fixed[1].sum() < rollout(SMALL, 2)[1].sum()  # the cost is charged
    index = core_of(SMALL).feature_index("communication_cost")
    np.testing.assert_array_equal(fixed[0][..., index], np.float32(0.3))  # the fixed cost is observed too


def test_the_range_ends_are_accepted():
    for value in ((0.0, 0.0), (0.0, 1e12), (1e12, 1e12), [0.5, 2.0]):
        spec = coloc_env.compose("drift", "broadcast", "kalman", cost_range=value)
        assert spec.cost_range == tuple(value)


@pytest.mark.parametrize(("value", "match"), [
    ((2.0, 1.0), r"cost_range must be None or a pair \(lo, hi\) with 0 <= lo <= hi <= 1e\+12, got lo = 2.0 > hi"),
    ((-1.0, 1.0), r"cost_range\[0\] \(lo\) must be in \[0.0, 1000000000000.0\], got -1.0"),
    ((0.0, 2e12), r"cost_range\[1\] \(hi\) must be in \[0.0, 1000000000000.0\], got 2000000000000.0"),
    ((1.0,), r"cost_range must be None or a pair"),
    ("cheap", r"cost_range must be None or a pair"),
    ((0.0, float("nan")), r"cost_range\[1\] \(hi\) must be in \[0.0, 1000000000000.0\], got nan"),
])
def test_a_bad_cost_range_is_refused_naming_the_field(value, match):
    with pytest.raises(ValueError, match=match):
        coloc_env.compose("drift", "broadcast", "kalman", cost_range=value)
