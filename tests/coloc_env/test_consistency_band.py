"""Matched-model consistency: where the filter's model is the world's, its covariance states its error.

For each row, J = 40 checks: check j looks at one step k_j and one agent a_j (cycling through the agents) and
averages that agent's position NEES e^T P^-1 e (``train.study``'s, from the infos' ``estimated_position``,
``true_position`` and the backend's ``posterior_position_cov``) over its own E = 20 seeded episodes. A
consistent filter with Gaussian errors puts that mean in the chi2(2E)/E 95 % band with probability 0.95,
and since no two checks share an episode the number of checks outside is Binomial(J, 0.05): the test allows
its 99.9 % quantile (7 of 40). Checks on one set of episodes at consecutive steps would not be independent
(a dead-reckoning error is a random walk: one unlucky set of episodes stays out of the band for many steps).

The matched rows: fu2017's Kalman filters at the leader (``kalman`` ideal, leader_only, informed) and the
centralized LMMSE filter (A) on ``target_cv`` over Bernoulli on-time / late / lost links (the LMMSE's
covariance is the error's second moment over the link outcomes, so its NEES averages to 2 though its error is
a mixture of Gaussians); zhao2020's ``bandwidth_fusion`` on ``drift`` with its budgets (the exact covariance
(10) of the delivered selection); the UKFs and dead reckoning on ``circles`` with the turn-rate noise off
(the heading is then exact and the odometry displacement's noise is the speed's, along the track, as the
model says) and the smallest prior the world allows (the world starts each estimate at the true start
position, so the prior that matches it is a point mass).
"""

import numpy as np
import pytest
import scipy.stats

import agents
import coloc_env
from coloc_env.scenarios.composed import ComposedScenario
from train.study import _nees

E, J, SPACING, SEED = 20, 40, 3, 300
MATCHED_CIRCLES = {"name": "circles", "turn_rate_noise_std": 0.0, "initial_position_std": 1e-6}
ROWS = {
    "target_cv/kalman:ideal": dict(world="target_cv", network="bernoulli_delay",
                                   backend={"name": "kalman", "variant": "ideal"}),
    "target_cv/kalman:leader_only": dict(world="target_cv", network="bernoulli_delay",
                                         backend={"name": "kalman", "variant": "leader_only"}),
    "target_cv/kalman:informed": dict(world="target_cv", network="bernoulli_delay",
                                      backend={"name": "kalman", "variant": "informed"}),
    "target_cv/centralized_lmmse": dict(world="target_cv", network="bernoulli_delay", backend="centralized_lmmse"),
    "drift/bandwidth_fusion": dict(world="drift", network="bandwidth", backend="bandwidth_fusion"),
    "circles/ukf_ccl": dict(world=MATCHED_CIRCLES, network="ideal", backend="ukf_ccl"),
    "circles/ukf_dcl": dict(world=MATCHED_CIRCLES, network="ideal", backend="ukf_dcl"),
    "circles/dead_reckoning": dict(world=MATCHED_CIRCLES, network="ideal", backend="dead_reckoning"),
}


def band_checks(parts: dict, episodes: int = E, checks: int = J, spacing: int = SPACING, seed: int = SEED):
    """(J,) mean NEES of check j (step k_j = spacing (j + 1), agent j mod N, episodes seed + j E .. + E - 1)
    under the ``always`` policy, and the chi2(2E)/E 95 % band."""
    spec = coloc_env.compose(**parts, horizon=spacing * checks + 1)
    view = coloc_env.parallel_env(spec)
    order = view.possible_agents
    act = agents.make_policy("always", view, seed=seed).act(dict.fromkeys(order))  # the same every step
    actions = np.stack([np.asarray(act[a], float) for a in order])
    core = ComposedScenario(spec, batch=episodes * checks)
    core.reset([np.random.default_rng(seed + c) for c in range(episodes * checks)])
    steps = spacing * (np.arange(checks) + 1)
    agent = np.arange(checks) % len(order)
    means = np.zeros(checks)
    for k in range(steps[-1] + 1):
        core.step(np.broadcast_to(actions, (core.batch, *actions.shape)))
        for j in np.flatnonzero(steps == k):
            rows = slice(j * episodes, (j + 1) * episodes)
            info = core.info()
            error = info["estimated_position"][rows, agent[j]] - info["true_position"][rows, agent[j]]
            means[j] = _nees(error, core.backend.posterior_position_cov[rows, agent[j]]).mean()
    view.close()
    return means, scipy.stats.chi2.ppf([0.025, 0.975], 2 * episodes) / episodes


@pytest.mark.parametrize("name", list(ROWS))
def test_a_matched_filter_s_mean_nees_lies_in_the_chi2_band_at_most_checks(name):
    means, (low, high) = band_checks(ROWS[name])
    outside = int(((means < low) | (means > high)).sum())
    allowed = int(scipy.stats.binom.ppf(0.999, J, 0.05))
    assert allowed == 7
    assert outside <= allowed, (f"{name}: {outside} of {J} checks outside [{low:.2f}, {high:.2f}]; mean NEES "
                                f"{means.mean():.2f} (2 if consistent); per check {np.round(means, 2).tolist()}")


def test_the_band_check_rejects_an_overconfident_filter():
    """The same checks on the ``naive`` Kalman filter at the leader (held and late packets taken as fresh
    measurements, so its covariance counts information it does not have) fall outside at every check."""
    means, (low, high) = band_checks(dict(world="target_cv", network="bernoulli_delay", backend="kalman"), checks=10)
    assert (means > high).all()
