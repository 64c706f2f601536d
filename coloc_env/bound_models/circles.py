"""Bound model of the ``circles`` world (wang2019): positions driven by odometry, ranges and anchor fixes.

Estimation problem (the one the ``ukf_ccl`` / ``ukf_dcl`` / ``dead_reckoning`` filters face):

| item        | value                                                                                  |
|-------------|----------------------------------------------------------------------------------------|
| state       | every platform's position p_i (2 N); the bound is reported per platform                |
| prior       | J0 = P0^-1, P0 = initial_position_std^2 I: the filters start at the exact truth with   |
|             | that covariance, and so does the bound                                                 |
| motion      | p_i(k+1) = p_i(k) + dt V_m [cos phi_m, sin phi_m] + w, the measured speed and the      |
|             | heading integrated from the measured turn rate as inputs, w ~ N(0, Q_i(k)) the         |
|             | filters' :class:`estimators.models.OdometryDisplacement` noise (speed noise along the  |
|             | track, the heading variance k dt^2 sigma_omega^2 across it; none with              |
|             | ``heading_noise`` off: Q rank 1). F = I; Q_i(k) depends only on the inputs             |
| episodes    | one recursion per episode (covariance form, exact for the singular Q), then the mean   |
|             | of the episodes' bounds. What differs between the episodes is what the estimator      |
|             | observes (its odometry, which range was taken to whom); the truth (the circles) is the |
|             | same in every episode. So each episode's bound is the PCRB conditioned on observed      |
|             | quantities, a valid bound on that episode's conditional MSE, and their mean bounds the |
|             | MSE (tighter than averaging the D-terms first: 6.3 vs 5.4 m^2 for the local bound at k |
|             | = 199, 4 episodes; with ``heading_noise`` off the averaged rank-1 Q of headings that   |
|             | differ would leave almost no process noise, 0.05 m^2)                                  |
| readings    | the range each step's measuring platform took to the partner its sensing chose (as    |
|             | recorded: [[B, -B], [-B, B]], B = u u^T / range_noise_var at the true positions);      |
|             | the anchors' fixes, I / fix_noise_std^2, every step                                     |
| centralized | all of them                                                                            |
| local       | each platform's own odometry and (an anchor) its own fixes; a range to another        |
|             | platform carries no information on its own without that platform's position           |
| delivered   | ``dead_reckoning`` (sends nothing): = local; ``ukf_ccl``: the centre's (every          |
|             | odometry, the ranges and fixes whose message reached agent 0), every platform's; the  |
|             | other backends' messages carry estimates or relayed location information (left out,   |
|             | :mod:`coloc_env.bounds`)                                                               |

This is the filters' model, not the world's truth: the truth flies exact circles, and the heading
error the filters integrate is correlated over time, which the per-step Q does not represent.
"""

from __future__ import annotations

import numpy as np

from coloc_env.bound_models import centre_received, delivered_kind, estimates_reason
from coloc_env.bounds import BoundProblem, Recursion
from estimators.bounds import fix_information, pair_information, range_information


def problem(core, record) -> BoundProblem:
    world = core.world
    c = world.config
    K, N = record.steps, world.num_agents
    n = 2 * N
    P0 = c.initial_position_std**2 * np.eye(n)
    k = np.arange(K - 1)
    inputs = np.stack([world.measured_speed[0, :K - 1], world.measured_heading[0, :K - 1],
                       np.broadcast_to(world.heading_variance(k)[:, None], (K - 1, N))], axis=-1)  # (K-1, N, 3)
    q = world.motion_model.covar(np.zeros((K - 1, N, 2)), inputs)  # (K-1, N, 2, 2)
    Q = np.zeros((K - 1, n, n))
    for i in range(N):
        Q[:, 2 * i:2 * i + 2, 2 * i:2 * i + 2] = q[:, i]
    own = np.zeros((K, N, 2, 2))
    own[:, :c.num_anchors] = fix_information(c.fix_noise_std**2)
    info = np.zeros((K, n, n))
    for i in range(N):
        info[:, 2 * i:2 * i + 2, 2 * i:2 * i + 2] = own[:, i]
    central = core.composition.backend.name == "ukf_ccl"  # the centre's information, for its delivered bound
    centre = np.zeros((K, n, n)) if central else None
    for step in range(K):
        valid = record.readings[step].range_valid[0]
        pairs = list(zip(*np.nonzero(valid), strict=True))
        if central:
            fixes = np.flatnonzero(record.readings[step].fix_valid[0])
            got_range, got_fix = centre_received(record, step, pairs, fixes, N)
            for i, got in zip(fixes, got_fix, strict=True):
                if got:
                    centre[step, 2 * i:2 * i + 2, 2 * i:2 * i + 2] += own[step, i]
        for r, (m, j) in enumerate(pairs):
            block = range_information(world.truth[step, m], world.truth[step, j], c.range_noise_var)
            idx = np.r_[2 * m:2 * m + 2, 2 * j:2 * j + 2]
            info[step][np.ix_(idx, idx)] += pair_information(block)
            if central and got_range[r]:
                centre[step][np.ix_(idx, idx)] += pair_information(block)
    positions = np.arange(n).reshape(N, 2)
    centralized = Recursion(P0, info, None, Q, positions)
    local = [Recursion(P0[:2, :2], own[:, i], None, q[:, i], np.array([[0, 1]])) for i in range(N)]
    agents = [np.array([i]) for i in range(N)]
    result = BoundProblem(centralized, local, agents, per_episode=True)
    if delivered_kind(core.composition.backend.name) == "nothing":
        result.delivered, result.delivered_agents = local, agents
    elif central:  # every platform reads its estimate at the centre
        result.delivered, result.delivered_agents = [Recursion(P0, centre, None, Q, positions)], [np.arange(N)]
    else:
        result.delivered_reason = estimates_reason(core.composition.backend.name)
    return result
