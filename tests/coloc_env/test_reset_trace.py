"""``infos[agent]["trace"]`` right after ``reset``: the trace of the initial belief's position covariance in
every compatible composition whose backend keeps a covariance, NaN only where the backend has none."""

import os

import numpy as np
import pytest

import coloc_env
from coloc_env.data import mrclam
from tests.conftest import MRCLAM_DATASET6, MRCLAM_SKIP_REASON, RECORDED_WORLDS

OK_ROWS = [r for r in coloc_env.compatibility() if r["ok"]]


@pytest.mark.parametrize("row", OK_ROWS, ids=lambda r: f"{r['world']}/{r['network']}/{r['backend']}")
def test_the_trace_at_reset_is_the_initial_covariance_s(row, monkeypatch):
    if row["world"] in RECORDED_WORLDS:
        if not os.path.isdir(MRCLAM_DATASET6):
            pytest.skip(MRCLAM_SKIP_REASON)
        monkeypatch.setenv(mrclam.ENV_VAR, MRCLAM_DATASET6)
    env = coloc_env.parallel_env(coloc_env.compose(world=row["world"], network=row["network"],
                                                   backend=row["backend"]))
    _, infos = env.reset(seed=0)
    trace = np.array([infos[a]["trace"] for a in env.possible_agents])
    cov = env.unwrapped.scenario.backend.position_cov()  # what the backend holds at k = 0: its initial belief
    if cov is None:
        assert np.isnan(trace).all()
        return
    assert np.isfinite(trace).all() and (trace > 0).all()
    np.testing.assert_allclose(trace, np.trace(cov[0], axis1=-2, axis2=-1), rtol=1e-12)
    # the first step's infos carry the same key with the posterior's trace: finite too
    _, _, _, _, infos = env.step({a: env.action_space(a).sample() * 0 for a in env.agents})
    assert np.isfinite([infos[a]["trace"] for a in env.possible_agents]).all()
