"""The presets' registered ids (`coloc/<preset>-v<N>`): made through PettingZoo's registry, and pinned to
their versions so that a change of a preset's spaces or dynamics without a version bump fails here."""

import numpy as np
import pettingzoo
import pytest
from pettingzoo.utils.env import AECEnv

import coloc_env
from coloc_env.env import CoLocParallelEnv
from coloc_env.registry import VERSIONS, env_id, env_ids, fingerprint, spaces_text
from tests.conftest import MRCLAM_DATASET6, needs_mrclam

# id -> (spaces, fingerprint of a 5-step rollout with seed 0: sums of observations, rewards, position errors).
# A bump adds a line for the new id (the failing test prints it) and keeps the old ones.
PINS = {
    "coloc/bandwidth_fusion-v1": (
        "4 agents; observation Box(shape=(13,), dtype=float32, low=[-inf, 0.0], high=[1.0, inf]); "
        "action Box(shape=(13,), dtype=float64, low=[-1.0], high=[1.0])",
        [-154.78892884775996, -2.6887372904466122, 6.571709008894274]),
    "coloc/lossy_fusion-v1": (
        "2 agents; observation Box(shape=(7,), dtype=float32, low=[-inf, 0.0], high=[1.0, inf]); "
        "action Box(shape=(6,), dtype=float64, low=[-1.0], high=[1.0])",
        [151.86613804847002, -3786.2784401252143, 176.2358645357422]),
    "coloc/relay_ukf-v1": (
        "4 agents; observation Box(shape=(11,), dtype=float32, low=[-inf, 0.0], high=[1.0, inf]); "
        "action MultiDiscrete([4, 5])",
        [46.11253483220935, -5.3820248116133795, 5.3820248116133795]),
    "coloc/gps_denied_nbp-v1": (
        "10 agents; observation Box(shape=(8,), dtype=float32, low=[0.0], high=[1.0, inf]); "
        "action MultiDiscrete([2, 2, 2, 2, 2])",
        [239.23559740185738, -217.28506213996212, 199.7501488348018]),
    # v2: a GPS-faulty UAV's messages tempered (fault_message_power 0.5), the covariance of a prior-only belief
    # with its KDE kernel; the observation gains the UAV's index, log tr of its belief's covariance, displacement,
    # steps_since and message_value since its last broadcast, and the episode's communication cost
    "coloc/gps_denied_nbp-v2": (
        "10 agents; observation Box(shape=(23,), dtype=float32, low=[-50.0, 0.0], high=[1.0, 50.0, inf]); "
        "action MultiDiscrete([2, 2, 2, 2, 2])",
        [543.6626199446619, -228.83581136378413, 205.52552344671284]),
    "coloc/nlos_horizon-v1": (
        "4 agents; observation Box(shape=(41,), dtype=float32, low=[-50.0, -20.0, -1.0, 0.0], high=[1.0, 20.0, 50.0]); "
        "action MultiDiscrete([27, 2, 2, 2, 2, 2, 2, 2, 2])",
        [3373.7995815912436, -16802.978441201354, 282.1756351899859]),
    "coloc/mrclam_relay-v1": (
        "5 agents; observation Box(shape=(18,), dtype=float32, low=[-inf, 0.0], high=[1.0, inf]); "
        "action MultiDiscrete([5, 6, 6, 6, 6, 6])",
        [-165.5488801568281, -0.07537058304313216, 0.07537058304313216]),
    "coloc/contention_localization-v1": (
        "10 agents; observation Box(shape=(34,), dtype=float32, low=[-50.0, 0.0], high=[1.0, 50.0, inf]); "
        "action MultiDiscrete([2])",
        [1893.805515833199, -271.27224529005156, 271.27224529005156]),
    # v2: noise_model="likelihood" by default (v1: "calibrated"), the filter's covariance in the observation moved;
    # the observation gains displacement, steps_since and message_value since the robot's last relayed hop and the
    # episode's communication cost
    "coloc/mrclam_relay-v2": (
        "5 agents; observation Box(shape=(22,), dtype=float32, low=[-inf, 0.0], high=[1.0, inf]); "
        "action MultiDiscrete([5, 6, 6, 6, 6, 6])",
        [-157.1258293110306, -0.07803140656694496, 0.07803140656694496]),
    # v2 of the others: the observation gains the episode's communication cost (cost_range's draw where given) and,
    # where it lacked it, the agent's index; lossy_fusion and relay_ukf also the features since the last
    # transmission (lossy_fusion log tr P too); contention_localization observes the composition's whole table
    "coloc/bandwidth_fusion-v2": (
        "4 agents; observation Box(shape=(18,), dtype=float32, low=[-inf, 0.0], high=[1.0, inf]); "
        "action Box(shape=(13,), dtype=float64, low=[-1.0], high=[1.0])",
        [-130.78892884775996, -2.6887372904466122, 6.571709008894274]),
    "coloc/lossy_fusion-v2": (
        "2 agents; observation Box(shape=(14,), dtype=float32, low=[-inf, -50.0, 0.0], high=[1.0, 50.0, inf]); "
        "action Box(shape=(6,), dtype=float64, low=[-1.0], high=[1.0])",
        [1001.633779456839, -3786.2784401252143, 176.2358645357422]),
    "coloc/relay_ukf-v2": (
        "4 agents; observation Box(shape=(15,), dtype=float32, low=[-inf, 0.0], high=[1.0, inf]); "
        "action MultiDiscrete([4, 5])",
        [46.363162901665795, -5.382024811613382, 5.382024811613382]),
    "coloc/nlos_horizon-v2": (
        "4 agents; observation Box(shape=(46,), dtype=float32, low=[-50.0, -20.0, -1.0, 0.0], "
        "high=[1.0, 20.0, 50.0, inf]); action MultiDiscrete([27, 2, 2, 2, 2, 2, 2, 2, 2])",
        [3397.7995815912436, -16802.978441352876, 282.17563519136115]),
    "coloc/contention_localization-v2": (
        "10 agents; observation Box(shape=(39,), dtype=float32, low=[-50.0, 0.0], high=[1.0, 50.0, inf]); "
        "action MultiDiscrete([2])",
        [1982.0459504066966, -271.27224529005156, 271.27224529005156]),
}

DATA_PRESETS = {"mrclam_relay"}  # presets that replay recorded data: built with data=MRCLAM_DATASET6


def _kwargs(name):
    return {"data": MRCLAM_DATASET6} if name in DATA_PRESETS else {}


def _marks(name):
    return [needs_mrclam] if name in DATA_PRESETS else []


PRESET_PARAMS = [pytest.param(name, marks=_marks(name)) for name in coloc_env.SCENARIOS]


def test_every_preset_is_registered_for_both_apis_at_its_version():
    assert set(VERSIONS) == set(coloc_env.SCENARIOS)
    assert env_ids() == tuple(f"coloc/{name}-v{VERSIONS[name]}" for name in coloc_env.SCENARIOS)
    for id_ in env_ids():
        assert pettingzoo.spec("parallel", id_).id == id_
        assert pettingzoo.spec("aec", id_).id == id_


@pytest.mark.parametrize("name", PRESET_PARAMS)
def test_pinned_spaces_and_rollout_match_the_registered_version(name):
    id_ = env_id(name)
    env = pettingzoo.make("parallel", id_, **_kwargs(name))
    spaces, digest = spaces_text(env), fingerprint(env)
    line = f'"{id_}": ({spaces!r},\n    {digest!r}),'
    assert id_ in PINS, f"{id_} has no pin; add to PINS:\n{line}"
    pinned_spaces, pinned_digest = PINS[id_]
    hint = (f"{name}'s spaces or dynamics changed: add 1 to the version of {name!r}'s scenario class and "
            f"add the new id's pin to PINS (keep the old ones):\n{line}")
    assert spaces == pinned_spaces, hint
    np.testing.assert_allclose(digest, pinned_digest, rtol=1e-7, atol=1e-9, err_msg=hint)


@pytest.mark.parametrize("name", PRESET_PARAMS)
def test_made_env_is_the_presets_env(name):
    """pettingzoo.make builds the same env as coloc_env.parallel_env (bit-identical rollouts), and the
    AEC id gives the AEC view."""
    made = pettingzoo.make("parallel", env_id(name), **_kwargs(name))
    assert isinstance(made, CoLocParallelEnv)
    assert fingerprint(made, seed=3) == fingerprint(coloc_env.parallel_env(name, **_kwargs(name)), seed=3)
    aec = pettingzoo.make("aec", env_id(name), **_kwargs(name))
    assert isinstance(aec, AECEnv)
    aec.reset(seed=0)
    assert aec.agents == made.possible_agents


def test_keywords_reach_the_presets_config():
    env = pettingzoo.make("parallel", "coloc/relay_ukf-v2", num_platforms=6, max_cycles=3)
    assert len(env.possible_agents) == 6
    env.reset(seed=0)
    steps = 0
    while env.agents:
        env.step({a: env.action_space(a).sample() for a in env.agents})
        steps += 1
    assert steps == 3
    with pytest.raises(ValueError, match="measurement_probability"):
        pettingzoo.make("parallel", "coloc/relay_ukf-v2", measurement_probability=1.5)
    with pytest.raises(ValueError, match="no_such_field"):
        pettingzoo.make("parallel", "coloc/relay_ukf-v2", no_such_field=1)


def test_unversioned_id_resolves_to_the_latest_and_a_wrong_version_is_refused():
    assert pettingzoo.spec("parallel", "coloc/relay_ukf").id == env_id("relay_ukf")
    with pytest.raises(pettingzoo.env_registry.exceptions.VersionNotFound, match="relay_ukf"):
        pettingzoo.make("parallel", f"coloc/relay_ukf-v{VERSIONS['relay_ukf'] + 1}")
    with pytest.raises(ValueError, match="unknown preset 'nope'"):
        env_id("nope")


def test_registration_is_idempotent(recwarn):
    """Registering again (as a reload of coloc_env would) overrides nothing and warns about nothing."""
    from coloc_env.registry import register_presets

    before = {id_: pettingzoo.spec("parallel", id_) for id_ in env_ids()}
    register_presets()
    assert {id_: pettingzoo.spec("parallel", id_) for id_ in env_ids()} == before
    assert not [w for w in recwarn if "Overriding" in str(w.message)]
