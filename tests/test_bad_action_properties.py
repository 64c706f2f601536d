"""Bad actions are a ValueError naming the agent, never a silent coercion; one rule for values everywhere.

The rule (:meth:`coloc_env.scenarios.base.Scenario.check_actions`), the same in every preset and composition,
in the parallel env and in the AEC view: entries of a continuous (``Box``) block are clipped to its bounds;
entries of a discrete block outside its choices (or non-integers in a ``MultiDiscrete``) and NaN / inf
anywhere are a ValueError naming the agent.

For every preset and one composition per registered part (the partners of
tests/test_bad_config_properties.py), hypothesis draws an agent and a bad action for its action space:
out of range (per space: MultiDiscrete ``nvec`` / -1 / a fraction, MultiBinary 2 / -1 / 0.3 / 1e300,
Box beyond its bounds), NaN and ±inf, wrong shapes (a scalar, an empty array, one entry too many, 2-d),
wrong types (strings incl. numerals, complex numbers, None, nested lists); and bad dicts (not a dict, an
unknown agent, a missing agent). ``vector_env`` with a wrong shape names the expected and the given shape.
``HYPOTHESIS_PROFILE=slow`` draws many more; ``python -m tests.test_bad_action_properties`` runs the fixed
lists exhaustively and prints the counts.
"""

from __future__ import annotations

import functools
import math
import re

import gymnasium
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import coloc_env
from tests.test_bad_config_properties import CHEAP_PART, CHEAP_PRESET, PROFILE, partners, parts, presets


def make(target):
    if target[0] == "preset":
        return coloc_env.parallel_env(target[1], **CHEAP_PRESET.get(target[1], {}))
    trio = partners(*target)
    return coloc_env.parallel_env(coloc_env.compose(**{k: {"name": trio[k], **CHEAP_PART.get(trio[k], {})}
                                                       for k in ("world", "network", "backend")}))


def _targets():
    seen, out = set(), []
    for t in [("preset", n) for n in presets()] + parts():
        key = tuple(sorted(partners(*t).items())) if t[0] != "preset" else t
        if key not in seen:
            seen.add(key)
            out.append(t)
    return out


TARGETS = _targets()


def valid_action(space):
    if isinstance(space, gymnasium.spaces.Box):
        return np.clip(np.zeros(space.shape), space.low, space.high)
    return np.zeros(space.shape, dtype=np.int64)


def out_of_range(space) -> list[np.ndarray]:
    """Actions of the right shape and type that the space does not contain (a Box preset documents that it
    clips a finite value beyond its bounds: there such a value is accepted, see :func:`classify`)."""
    base = valid_action(space).astype(float)
    out = []
    for i in range(min(base.size, 3)):
        if isinstance(space, gymnasium.spaces.MultiDiscrete):
            values = [float(np.asarray(space.nvec).reshape(-1)[i]), -1.0, 0.5, 1e300]
        elif isinstance(space, gymnasium.spaces.MultiBinary):
            values = [2.0, -1.0, 0.3, 1e300]
        else:
            high, low = np.asarray(space.high, float).reshape(-1)[i], np.asarray(space.low, float).reshape(-1)[i]
            values = [v for v in (high + 0.5, low - 0.5, 1e300, -1e300) if np.isfinite(v)]
        for v in values:
            a = base.copy().reshape(-1)
            a[i] = v
            out.append(a.reshape(base.shape))
    for v in (math.nan, math.inf, -math.inf):
        a = base.copy().reshape(-1)
        a[0] = v
        out.append(a.reshape(base.shape))
    return out


def malformed(space) -> list:
    """Actions of a wrong shape or type: a ValueError naming the agent."""
    base = valid_action(space)
    return [None, 0, 0.0, np.float64(0.0), np.array([]), np.append(base, 0), base[None], np.zeros(base.shape + (2,)),
            "0", "abc", b"0", base.astype(str), base.astype(complex), base + 1j, [None] * base.size,
            {"a": 0}, [[0]]]


def step_with(env, agent, action):
    actions = {a: valid_action(env.action_space(a)) for a in env.agents}
    actions[agent] = action
    env.step(actions)


def classify(target, agent_index, action, must_name_agent=True) -> str:
    """"" where the rule holds: a ValueError naming the agent, or (a finite value in a ``Box``) a clip; a
    defect in words otherwise."""
    env = make(target)
    env.reset(seed=0)
    agent = env.possible_agents[agent_index % len(env.possible_agents)]
    try:
        step_with(env, agent, action)
    except ValueError as exc:
        if must_name_agent and not re.search(rf"\b{re.escape(agent)}\b", str(exc)):
            return f"ValueError without the agent: {exc}"
        return ""
    except Exception as exc:  # noqa: BLE001
        return f"{type(exc).__name__}: {exc}"
    raw = np.asarray(action)
    clipped = (isinstance(env.action_space(agent), gymnasium.spaces.Box)
               and raw.dtype.kind in "iuf" and bool(np.all(np.isfinite(raw))))
    return "" if clipped else "accepted"


@functools.cache
def space_of(target) -> gymnasium.Space:
    """The first agent's action space (built when a test first asks: a recorded world takes seconds to build,
    and collection would pay it in every worker)."""
    env = make(target)
    return env.action_space(env.possible_agents[0])


@pytest.mark.parametrize("target", TARGETS, ids="/".join)
def test_a_bad_action_is_a_value_error(target):
    space = space_of(target)
    bad = st.one_of(st.tuples(st.sampled_from(out_of_range(space)), st.just(True)),
                    st.tuples(st.sampled_from(malformed(space)), st.just(True)))
    if PROFILE == "slow":
        bad = bad | st.tuples(st.text(max_size=3) | st.complex_numbers() | st.booleans(), st.just(True))

    @settings(settings.get_profile(PROFILE))
    @given(st.integers(0, 63), bad)
    def check(agent_index, case):
        action, must_name = case
        defect = classify(target, agent_index, action, must_name)
        assert not defect, f"{'/'.join(target)}: action {action!r}: {defect}"

    check()


@pytest.mark.parametrize("target", TARGETS, ids="/".join)
def test_a_bad_action_dict_is_a_value_error(target):
    env = make(target)
    env.reset(seed=0)
    good = {a: valid_action(env.action_space(a)) for a in env.agents}
    for actions, match in ((None, "dict"), (list(good.values()), "dict"), ({**good, "intruder": "garbage"}, "intruder"),
                           ({a: v for a, v in good.items() if a != env.agents[-1]}, env.agents[-1])):
        with pytest.raises(ValueError, match=re.escape(match)):
            env.step(actions)
    env.step(good)  # the refusals changed nothing: the episode goes on


def test_gps_denied_binary_actions_are_zero_or_one():
    env = coloc_env.parallel_env("gps_denied_nbp", **CHEAP_PRESET["gps_denied_nbp"])
    env.reset(seed=0)
    n = env.action_space(env.agents[0]).shape
    for value in (2, -1, 0.3, 1e300):
        actions = {a: np.zeros(n) for a in env.agents}
        actions[env.agents[1]] = np.full(n, value)
        with pytest.raises(ValueError, match=rf"of {env.agents[1]} must be an integer in \[0, 1\], got"):
            env.step(actions)
    env.step({a: np.ones(n, dtype=np.int8) for a in env.agents})
    env.step({a: np.zeros(n, dtype=bool) for a in env.agents})


@pytest.mark.parametrize("name", ["relay_ukf", "bandwidth_fusion"])
def test_vector_env_wrong_shape_states_expected_and_got(name):
    venv = coloc_env.vector_env(name, num_envs=2, seed=0)
    venv.reset()
    shape = venv.action_space.shape
    with pytest.raises(ValueError, match=re.escape(f"must have shape {(venv.num_envs, *shape)}") + ".*got \\(3,"):
        venv.step(np.zeros((3, *shape)))


def count_all() -> tuple[int, list[str]]:
    tried, defects = 0, []
    for target in TARGETS:
        space = space_of(target)
        for must, actions in ((True, out_of_range(space)), (True, malformed(space))):
            for action in actions:
                for agent_index in (0, 1):
                    tried += 1
                    defect = classify(target, agent_index, action, must)
                    if defect:
                        line = f"{'/'.join(target)} agent {agent_index}: {action!r}: {defect}"
                        defects.append(" ".join(line.split())[:250])
    return tried, defects


if __name__ == "__main__":
    n, found = count_all()
    print("\n".join(found))
    print(f"action cases tried: {n}, defects: {len(found)}")


def _discrete_presets() -> list[str]:
    out = []
    for name in presets():
        env = make(("preset", name))
        if isinstance(env.action_space(env.possible_agents[0]), gymnasium.spaces.MultiDiscrete):
            out.append(name)
    return out


@pytest.mark.parametrize("name", _discrete_presets())
def test_integer_actions_take_the_discrete_checks_shortcut_only_when_in_range(name):
    """check_discrete_actions returns in-range integer arrays as they are (int64), the values its full checks give
    the same actions as floats; an integer at nvec or -1 still gets the full checks' error."""
    scenario = coloc_env.vector_env(name, num_envs=2, **CHEAP_PRESET.get(name, {})).scenario
    nvec = np.asarray(scenario.action_space().nvec)
    shape = (2, scenario.num_agents, *nvec.shape)
    actions = np.random.default_rng(0).integers(0, np.broadcast_to(nvec, shape))
    for dtype in (np.int64, np.int16, np.uint8):
        got = scenario.check_discrete_actions(actions.astype(dtype))
        assert got.dtype == np.int64
        np.testing.assert_array_equal(got, scenario.check_discrete_actions(actions.astype(float)))
    for value in (-1, int(nvec.reshape(-1)[0])):
        bad = actions.copy()
        bad[1, 0].reshape(-1)[0] = value  # a view: the first entry of copy 1, agent 0
        with pytest.raises(ValueError) as as_int:
            scenario.check_discrete_actions(bad)
        with pytest.raises(ValueError) as as_float:
            scenario.check_discrete_actions(bad.astype(float))
        assert str(as_int.value) == str(as_float.value)
        assert re.search(rf"of {scenario.agent_names[0]}, copy 1 must be an integer in \[0, ", str(as_int.value))


@pytest.mark.parametrize("target", TARGETS, ids="/".join)
def test_a_box_action_beyond_its_bounds_plays_as_the_bound(target):
    """The clip rule: an episode played with actions scaled far beyond the bounds is the episode played with
    those actions clipped, bit for bit, in every Box scenario (presets and compositions alike)."""
    space = space_of(target)
    if not isinstance(space, gymnasium.spaces.Box):
        pytest.skip("the clip rule is for Box action spaces")
    rng = np.random.default_rng(1)
    runs = []
    for clip in (False, True):
        env = make(target)
        env.reset(seed=3)
        rewards = []
        for _ in range(3):
            raw = {a: space.sample() * 0 + rng.uniform(-5, 5, space.shape) for a in env.agents}
            # the discrete entries of a composition's Box keep in-range integers (they are refused, not clipped)
            if target[0] != "preset":
                scenario = env.unwrapped.scenario
                for a in raw:
                    flat = raw[a].reshape(-1)
                    start = 0
                    for blk in scenario.blocks:
                        if blk.discrete:
                            flat[start:start + blk.size] = 0
                        start += blk.size
            actions = {a: np.clip(v, space.low, space.high) if clip else v for a, v in raw.items()}
            _, r, *_ = env.step(actions)
            rewards.append([r[a] for a in env.possible_agents])
        runs.append(np.array(rewards))
        rng = np.random.default_rng(1)
    np.testing.assert_array_equal(runs[0], runs[1])


@pytest.mark.parametrize("target", [t for t in TARGETS if t[0] == "preset"], ids="/".join)
@pytest.mark.parametrize("value", [math.nan, math.inf])
def test_the_aec_view_names_the_agent_of_a_non_finite_action(target, value):
    name = target[1]
    aec = coloc_env.env(name, **CHEAP_PRESET.get(name, {}))
    aec.reset(seed=0)
    space = aec.action_space(aec.possible_agents[0])
    bad_agent = aec.possible_agents[1]
    with pytest.raises(ValueError, match=rf"of {bad_agent} must be finite, got (nan|inf)"):
        for agent in aec.agent_iter():
            action = valid_action(space).astype(float)
            if agent == bad_agent:
                action.reshape(-1)[0] = value
            aec.step(action)
