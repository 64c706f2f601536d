"""Action masks: invalid choices are masked, never punished or refused.

``Scenario.action_mask`` (B, N, sum(nvec)) bool, ``infos[agent]["action_mask"]`` (int8) and
``CoLocVecEnv.action_masks()`` (what sb3_contrib's MaskablePPO reads). The rules are the tables of
:mod:`coloc_env.scenarios.composed` and :mod:`coloc_env.scenarios.relay_ukf`: a masked choice does by
definition what the explicit stop / no-measurement choice does.
"""

import copy
import os

import gymnasium
import numpy as np
import pytest

import coloc_env
from coloc_env.data import mrclam
from tests.conftest import MRCLAM_DATASET6, MRCLAM_SKIP_REASON

# finite ranges that the circles' distances (11 to 156 m) cross both ways
RANGES = {"comm_range": 90.0, "sensing_range": 85.0}
COMPOSITIONS = [  # (world, network, backend): the relay's next hop, the circles' partner, blocks without rules
    ("circles", "relay", "ukf_dcl"), ("gps_denied", "relay", "ukf_dcl"), ("circles", "broadcast", "dnbp"),
    ("nlos_orbit", "relay", "afge"), ("drift", "bandwidth", "bandwidth_fusion"), ("drift", "ideal", "kalman"),
    ("drift", "relay", "prediction_compensation"),
]
OK = {(r["world"], r["network"], r["backend"]) for r in coloc_env.compatibility() if r["ok"]}


def _mask_size(space):
    if isinstance(space, gymnasium.spaces.Discrete):
        return int(space.n)
    if isinstance(space, gymnasium.spaces.MultiDiscrete):
        return int(np.sum(space.nvec))
    return None


def _check_infos(env, infos):
    agent = env.possible_agents[0]
    size = _mask_size(env.action_space(agent))
    scenario_mask = env.unwrapped.scenario.action_mask()
    if size is None:
        assert scenario_mask is None and all("action_mask" not in infos[a] for a in env.possible_agents)
        return
    assert scenario_mask.shape == (1, len(env.possible_agents), size) and scenario_mask.dtype == bool
    for i, a in enumerate(env.possible_agents):
        mask = infos[a]["action_mask"]
        nvec = np.atleast_1d(getattr(env.action_space(a), "nvec", size))
        # flat, or (k, n) for k equal sizes n (TorchRL's one-hot shape); flattened: sb3_contrib's layout
        shape = (len(nvec), int(nvec[0])) if hasattr(env.action_space(a), "nvec") and len(set(nvec)) == 1 else (size,)
        assert mask.shape == shape and mask.dtype == np.int8
        np.testing.assert_array_equal(mask.reshape(-1), scenario_mask[0, i])
        # every dimension keeps a valid choice
        assert all(part.any() for part in np.split(mask.reshape(-1), np.cumsum(nvec)[:-1]))
        # PettingZoo's idiom: the space samples a valid action from the infos' mask
        action = np.atleast_1d(env.action_space(a).sample(mask))
        assert env.action_space(a).contains(action.reshape(env.action_space(a).shape))
        assert all(mask.reshape(-1)[start + v] for start, v in zip(np.cumsum(nvec) - nvec, action, strict=True))


def _sample(space, mask, rng):
    """One action from the valid choices of ``mask`` (flat, sb3_contrib's layout)."""
    if isinstance(space, gymnasium.spaces.Discrete):
        return rng.choice(np.flatnonzero(mask))
    parts = np.split(np.asarray(mask, bool).reshape(-1), np.cumsum(space.nvec)[:-1])
    return np.array([rng.choice(np.flatnonzero(p)) for p in parts])


@pytest.mark.parametrize("name", coloc_env.SCENARIOS)
def test_every_preset_reports_masks_of_its_space(name, monkeypatch):
    config = {}
    if name == "mrclam_relay":
        if not os.path.isdir(MRCLAM_DATASET6):
            pytest.skip(MRCLAM_SKIP_REASON)
        config = {"data": MRCLAM_DATASET6, "window_steps": 5}
    env = coloc_env.parallel_env(name, **config)
    _, infos = env.reset(seed=0)
    _check_infos(env, infos)
    rng = np.random.default_rng(0)
    for _ in range(2):
        actions = {}
        for a in env.agents:
            space = env.action_space(a)
            actions[a] = space.sample() if "action_mask" not in infos[a] else _sample(space, infos[a]["action_mask"],
                                                                                    rng)
        _, _, _, _, infos = env.step(actions)
        _check_infos(env, infos)


@pytest.mark.parametrize("parts", COMPOSITIONS, ids="/".join)
def test_compositions_report_masks_and_masked_sampling_is_never_refused(parts):
    assert parts in OK
    world, network, backend = parts
    if network == "relay":
        network = {"name": "relay", "comm_range": 60.0}
    spec = coloc_env.compose(world=world, network=network, backend=backend, horizon=12)
    env = coloc_env.parallel_env(spec)
    _, infos = env.reset(seed=1)
    rng = np.random.default_rng(1)
    _check_infos(env, infos)
    for _ in range(12):
        actions = {a: (env.action_space(a).sample() if "action_mask" not in infos[a]
                       else _sample(env.action_space(a), infos[a]["action_mask"], rng)) for a in env.agents}
        _, _, _, _, infos = env.step(actions)
        _check_infos(env, infos)


def _expected_relay_ukf(scenario):
    """relay_ukf's table, computed here from the positions: index 0 (N), then index 1 (N + 1)."""
    N = scenario.num_agents
    p = scenario.world.positions()[0]
    d = np.linalg.norm(p[:, None] - p[None], axis=-1)
    eye = np.eye(N, dtype=bool)
    partner = eye | (d <= scenario.config.sensing_range)
    relay = ~eye & (d <= scenario.config.comm_range)
    return np.concatenate([partner, relay, np.ones((N, 1), bool)], axis=-1)


def test_relay_ukf_masks_exactly_its_rules_and_masked_choices_are_aliases():
    env = coloc_env.parallel_env("relay_ukf", measurement_probability=1.0, horizon=110, **RANGES)
    _, infos = env.reset(seed=3)
    scenario = env.unwrapped.scenario
    N = scenario.num_agents
    rng = np.random.default_rng(3)
    masked_seen = {0: 0, 1: 0}
    extended = 0
    for step in range(110):
        mask = scenario.action_mask()[0]
        np.testing.assert_array_equal(mask, _expected_relay_ukf(scenario))
        np.testing.assert_array_equal(np.stack([infos[a]["action_mask"] for a in env.possible_agents]), mask)
        assert isinstance(env.action_space("platform_0"), gymnasium.spaces.MultiDiscrete)
        if step % 22 == 0:  # branch the state: every masked choice does what the explicit one does
            m = int(scenario.world.measuring()[0])
            base = np.stack([np.arange(N), np.full(N, N)], axis=-1)  # itself (no measurement), stop

            def branch(actions):
                c = copy.deepcopy(scenario)
                c.step(actions[None])
                return c

            ref = branch(base)
            for j in range(N):
                a = base.copy()
                a[m, 0] = j
                c = branch(a)
                if not mask[m, j]:
                    masked_seen[0] += 1
                    np.testing.assert_array_equal(c.backend.cov, ref.backend.cov)
                    assert not c.readings.range_valid.any()
                elif j != m:  # a valid partner measures
                    assert c.readings.range_valid[0, m, j]
            # a partner the chain reaches (within both ranges of m): its next hop decides the chain
            near = [n for n in range(N) if n != m and mask[m, n] and mask[m, N + n]]
            for n in near:
                a = base.copy()
                a[m, 0] = n
                ref = branch(a)
                assert ref.chain.length[0] == 2
                for j in range(N + 1):
                    a[n, 1] = j
                    c = branch(a)
                    if not mask[n, N + j]:
                        masked_seen[1] += 1
                        np.testing.assert_array_equal(c.chain.chain, ref.chain.chain)
                        np.testing.assert_array_equal(c.backend.cov, ref.backend.cov)
                    elif j not in (m, N):  # a valid next hop not yet reached extends the chain
                        assert c.chain.length[0] == 3
                        extended += 1
        actions = {a: _sample(env.action_space(a), infos[a]["action_mask"], rng) for a in env.possible_agents}
        _, _, _, _, infos = env.step(actions)
    assert masked_seen[0] > 0 and masked_seen[1] > 0 and extended > 0


def test_per_source_next_hop_masks_itself_and_the_source():
    spec = coloc_env.compose(world="circles", network={"name": "relay", "routing": "per_source", "comm_range": 60.0},
                             backend="ukf_dcl", horizon=5)
    env = coloc_env.parallel_env(spec)
    env.reset(seed=0)
    scenario = env.unwrapped.scenario
    N = scenario.num_agents
    p = scenario.world.positions()[0]
    reach = (np.linalg.norm(p[:, None] - p[None], axis=-1) <= 60.0) & ~np.eye(N, dtype=bool)
    mask = scenario.action_mask()[0]
    table = mask[:, N + 1:].reshape(N, N, N + 2)  # after the partner block: [holder, source m, choice]
    for i in range(N):
        for m in range(N):
            allowed = reach[i] & (np.arange(N) != m)
            np.testing.assert_array_equal(table[i, m, :N], allowed)
            assert table[i, m, N] and table[i, m, N + 1] == allowed.any()


def test_vector_action_masks_follow_the_copies_across_auto_resets():
    B, horizon, seed = 3, 5, 10
    world = coloc_env.parallel_env("relay_ukf").unwrapped.scenario.world
    d0, dK = world.distance_table[0], world.distance_table[horizon]
    i, j = np.unravel_index(np.argmax(np.abs(d0 - dK)), d0.shape)
    config = {"comm_range": float(d0[i, j] + dK[i, j]) / 2, "horizon": horizon}  # the pair crosses it
    venv = coloc_env.vector_env("relay_ukf", num_envs=B, seed=seed, **config)
    singles = [coloc_env.parallel_env("relay_ukf", **config) for _ in range(B)]
    venv.reset()
    infos = [env.reset(seed=seed + b)[1] for b, env in enumerate(singles)]
    N, rng, resets = venv.num_agents, np.random.default_rng(0), 0

    def per_copy():
        return np.concatenate([[info[a]["action_mask"] for a in env.possible_agents]
                               for env, info in zip(singles, infos, strict=True)]).astype(bool)

    from sb3_contrib.common.maskable.utils import get_action_masks, is_masking_supported
    assert is_masking_supported(venv)
    for _ in range(2 * horizon + 2):
        masks = venv.action_masks()
        assert masks.shape == (B * N, 2 * N + 1) and masks.dtype == bool
        np.testing.assert_array_equal(masks, per_copy())
        np.testing.assert_array_equal(get_action_masks(venv), masks)
        actions = np.stack([_sample(singles[0].action_space("platform_0"), m, rng) for m in masks])
        _, _, dones, _ = venv.step(actions)
        for b, env in enumerate(singles):
            _, _, _, trunc, infos[b] = env.step({a: actions[b * N + k] for k, a in enumerate(env.possible_agents)})
            if not env.agents:
                terminal = np.stack([infos[b][a]["action_mask"] for a in env.possible_agents]).astype(bool)
                infos[b] = env.reset()[1]
                fresh = np.stack([infos[b][a]["action_mask"] for a in env.possible_agents]).astype(bool)
                assert not np.array_equal(terminal, fresh)  # the test can tell the two apart
                resets += 1
    assert resets == 2 * B


def test_box_actions_have_no_masks():
    env = coloc_env.parallel_env("lossy_fusion")
    _, infos = env.reset(seed=0)
    assert all("action_mask" not in info for info in infos.values())
    with pytest.raises(ValueError, match="no action masks"):
        coloc_env.vector_env("lossy_fusion", num_envs=2, seed=0).action_masks()


def test_maskable_ppo_learns_and_never_predicts_a_masked_action():
    torch = pytest.importorskip("torch")
    sb3_contrib = pytest.importorskip("sb3_contrib")
    from sb3_contrib.common.maskable.utils import get_action_masks

    torch.set_num_threads(1)
    venv = coloc_env.vector_env("relay_ukf", num_envs=4, seed=0)
    model = sb3_contrib.MaskablePPO("MlpPolicy", venv, n_steps=32, batch_size=64, seed=0, device="cpu")
    model.learn(256)
    obs = venv.reset()
    N = venv.num_agents
    masked = 0
    for _ in range(50):
        masks = get_action_masks(venv)
        masked += int((~masks).sum())
        actions, _ = model.predict(obs, action_masks=masks, deterministic=False)
        chosen = np.stack([masks[np.arange(len(masks)), actions[:, 0]],
                           masks[np.arange(len(masks)), N + actions[:, 1]]], axis=-1)
        assert chosen.all()
        obs, _, _, _ = venv.step(actions)
    assert masked > 0  # relaying to itself is masked: the check has something to catch


def test_mrclam_world_partner_masks_nothing(monkeypatch):
    if not os.path.isdir(MRCLAM_DATASET6):
        pytest.skip(MRCLAM_SKIP_REASON)
    monkeypatch.setenv(mrclam.ENV_VAR, MRCLAM_DATASET6)
    spec = coloc_env.compose(world="mrclam", network="ideal", backend="ukf_se2", horizon=5)
    env = coloc_env.parallel_env(spec)
    _, infos = env.reset(seed=0)
    assert all(info["action_mask"].all() for info in infos.values())


@pytest.mark.skipif(not os.path.isdir(MRCLAM_DATASET6), reason=MRCLAM_SKIP_REASON)
def test_mrclam_relay_masks_unrecorded_partners_and_they_are_aliases_of_none():
    """mrclam_relay's index 0 allows exactly the robots it recorded (its observation shows them) and itself;
    a masked partner gives the estimates that choosing itself ("none") gives."""
    env = coloc_env.parallel_env("mrclam_relay", data=MRCLAM_DATASET6, window_steps=40)
    _, infos = env.reset(seed=1)
    scenario = env.unwrapped.scenario
    N = scenario.num_agents
    rng = np.random.default_rng(1)
    aliases = 0
    for _ in range(40):
        observations = scenario.observation()[0]
        mask = scenario.action_mask()[0]
        recorded = observations[:, N:2 * N] > 0.5
        np.testing.assert_array_equal(mask[:, :N], recorded | np.eye(N, dtype=bool))
        for i in range(N):  # entry 1 + m of robot i: itself and the source m masked, stop kept
            table = mask[i, N:].reshape(N, N + 1)
            assert table[:, N].all() and not table[:, i].any() and not table[np.arange(N), np.arange(N)].any()
        actions = np.stack([_sample(env.action_space(a), infos[a]["action_mask"], rng) for a in env.possible_agents])
        unrecorded = [(i, j) for i in range(N) for j in range(N) if not mask[i, j]]
        if unrecorded:
            i, j = unrecorded[0]
            none, masked = actions.copy(), actions.copy()
            none[i, 0], masked[i, 0] = i, j
            a, b = copy.deepcopy(scenario), copy.deepcopy(scenario)
            a.step(none[None])
            b.step(masked[None])
            np.testing.assert_array_equal(a.backend.estimate, b.backend.estimate)
            aliases += 1
        _, _, _, _, infos = env.step({agent: actions[k] for k, agent in enumerate(env.possible_agents)})
    assert aliases > 10
