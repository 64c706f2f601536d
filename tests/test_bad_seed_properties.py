"""Seeds and counts are checked where they enter: ``reset(seed=)``, ``seed_generator``, ``vector_env(seed=,
num_envs=)`` and its ``seed()``, ``agents.make_policy(seed=)``.

A seed is None or an integer in [0, 2**63 - 1] (``vector_env``: so that ``seed + b`` of every copy is one);
anything else (a string, even "0"; a float, even 1.0; a boolean; NaN; a negative integer) is a ValueError
naming ``seed``, never coerced. Hypothesis draws the values (derandomized: the same examples every run).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import agents
import coloc_env
from coloc_env.config import MAX_NUM_ENVS, SEED_MAX

settings.register_profile("seeds", max_examples=40, deadline=None, derandomize=True,
                          suppress_health_check=list(HealthCheck))
SEEDS = settings.get_profile("seeds")

BAD_SEEDS = st.one_of(
    st.text(max_size=3), st.sampled_from(["0", "1", b"0"]),
    st.floats(allow_nan=True), st.sampled_from([1.0, 0.0, math.nan, np.float64(2.0)]),
    st.booleans(), st.sampled_from([np.bool_(True)]),
    st.integers(max_value=-1), st.integers(min_value=SEED_MAX + 1),
    st.just([1]), st.just(1 + 0j),
)
GOOD_SEEDS = st.one_of(st.integers(0, SEED_MAX), st.sampled_from([np.int64(3), np.uint32(7), np.int8(0)]))


@pytest.fixture(scope="module")
def env():
    return coloc_env.parallel_env("lossy_fusion", horizon=3)


@settings(SEEDS)
@given(seed=BAD_SEEDS)
def test_reset_refuses_a_seed_that_is_not_a_non_negative_integer(env, seed):
    with pytest.raises(ValueError, match=r"^seed must be None or an integer in \[0, 9223372036854775807\], got"):
        env.reset(seed=seed)
    with pytest.raises(ValueError, match=r"^seed must be None or an integer"):
        env.seed_generator(seed)


@settings(SEEDS)
@given(seed=GOOD_SEEDS)
def test_reset_takes_every_integer_seed_and_reproduces_it(env, seed):
    first, _ = env.reset(seed=seed)
    again, _ = env.reset(seed=int(seed))
    for agent in first:
        np.testing.assert_array_equal(first[agent], again[agent])


@pytest.fixture(scope="module")
def venv():
    return coloc_env.vector_env("lossy_fusion", num_envs=2, seed=0, horizon=3)


@settings(SEEDS)
@given(seed=BAD_SEEDS)
def test_vector_env_refuses_a_bad_seed_when_made_and_when_reseeded(venv, seed):
    with pytest.raises(ValueError, match=r"^seed must be None or an integer in \[0, 9223372036854775806\], got"):
        venv.seed(seed)
    with pytest.raises(ValueError, match=r"^seed must be None or an integer"):
        coloc_env.vector_env("lossy_fusion", num_envs=2, seed=seed, horizon=3)


def test_vector_env_refuses_a_seed_whose_last_copy_would_overflow():
    coloc_env.vector_env("lossy_fusion", num_envs=2, seed=SEED_MAX - 1, horizon=3).reset()
    with pytest.raises(ValueError, match=r"seed must be None or an integer in \[0, 9223372036854775806\]"):
        coloc_env.vector_env("lossy_fusion", num_envs=2, seed=SEED_MAX, horizon=3)


@pytest.mark.parametrize("num_envs", [0, -1, MAX_NUM_ENVS + 1, 10**12, 1.0, "2", True, None])
def test_vector_env_refuses_a_number_of_copies_outside_its_range(num_envs):
    with pytest.raises(ValueError, match=rf"^num_envs must be (an integer )?in \[1, {MAX_NUM_ENVS}\]"):
        coloc_env.vector_env("lossy_fusion", num_envs=num_envs, seed=0)


@pytest.mark.parametrize("seed", ["0", 1.5, math.nan, True, -1])
def test_a_policy_refuses_a_bad_seed(env, seed):
    with pytest.raises(ValueError, match=r"^seed must be None or an integer"):
        agents.make_policy("random", env, seed=seed)
