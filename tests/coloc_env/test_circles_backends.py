"""dNBP and least squares on wang2019's circles: cross-combinations no paper ran.

Both run through the motion-model interface (particles propagated by the
model's function and one draw of its process noise; the KF by the EKF time
update), so they must beat dead reckoning on the same flights, and the
paper's own UKF-DCL, which fuses every range with the full cross-covariance,
must beat both.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

import coloc_env
from coloc_env.scenarios.composed import ComposedScenario

COPIES, STEPS, SEED = 6, 80, 300


def mean_errors(backend) -> np.ndarray:
    """Per-copy mean position error (m) over the steps and agents of the `always` policy."""
    spec = coloc_env.compose(world="circles", network="ideal", backend=backend, horizon=STEPS)
    core = ComposedScenario(spec, batch=COPIES)
    core.reset([np.random.default_rng(SEED + c) for c in range(COPIES)])
    one = core.action_vector("maximum")
    actions = np.broadcast_to(one, (COPIES, core.num_agents, one.size))
    total = np.zeros(COPIES)
    for _ in range(STEPS):
        core.step(actions)
        total += core.info()["position_error"].mean(axis=1)
    return total / STEPS


def paired_upper(a: np.ndarray, b: np.ndarray) -> float:
    """Upper end of the 95 % t-interval of mean(a - b) over paired copies."""
    diff = a - b
    return float(diff.mean() + stats.t.ppf(0.975, len(diff) - 1) * diff.std(ddof=1) / np.sqrt(len(diff)))


def test_particles_and_least_squares_beat_dead_reckoning_and_lose_to_ukf_dcl():
    errors = {b: mean_errors(b) for b in ("dead_reckoning", "range_ls", "dnbp", "ukf_dcl")}
    assert paired_upper(errors["dnbp"], errors["dead_reckoning"]) < 0
    assert paired_upper(errors["range_ls"], errors["dead_reckoning"]) < 0
    assert paired_upper(errors["ukf_dcl"], errors["dnbp"]) < 0
    assert paired_upper(errors["ukf_dcl"], errors["range_ls"]) < 0


def test_dnbp_reads_the_receivers_own_range():
    """circles measures one direction only ([m, n]: m ranged n); the message n -> m must carry that range.

    Regression: with the reading taken at [n, m] (0 there) the message put m on n's position and the
    estimate jumped tens of metres. Over ideal links the error stays at the metre level."""
    assert mean_errors("dnbp").max() < 3.0
