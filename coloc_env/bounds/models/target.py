"""Bound model of the target worlds ``target_cv`` (fu2017) and ``drift`` (zhao2020): linear-Gaussian, so exact.

Estimation problem (every agent estimates one shared state x, n = 6 or the drift's n):

| item        | value                                                                                  |
|-------------|----------------------------------------------------------------------------------------|
| state       | x(k) (target_cv: [x, vx, y, vy, z, vz]; drift: the drift state)                        |
| prior       | J0 = P0^-1, P0 the world's ``initial_cov`` (every agent starts from it)                |
| motion      | x(k+1) = A x(k) + b + w, w ~ N(0, Q) (target_cv: Q = q G G^T, rank 3 of 6: the        |
|             | covariance form of ``estimators.bounds`` is exact for it); the known input b moves  |
|             | no information                                                                         |
| readings    | agent i's z_i(k) = C x(k) + v_i, v_i ~ N(0, R_i), at every step: C^T R_i^-1 C         |
| centralized | sum over the agents, every step                                                        |
| local       | agent i's own z_i only                                                                 |
| delivered   | (``kalman``, ``centralized_lmmse``: followers' packets of z_i(k) to the leader) the   |
|             | receiver's own z plus each packet's z_t(k) from the step it arrived, as a reading of   |
|             | x(k) (a lag-augmented state); every agent reports the leader's estimate, so the       |
|             | leader's delivered bound is every agent's; ``prediction_compensation`` (the leader's,  |
|             | shared) and ``bandwidth_fusion`` (each agent's) carry estimates: the information set   |
|             | (``coloc_env.bounds.information_set``)                                                 |
| position    | the world's ``position_index`` components (the ``position_error`` coordinates), the  |
|             | same bound for every agent                                                             |

The problem is linear and Gaussian, so the bound is the covariance of the Kalman filter that has
the same information (centralized: ``kalman`` variant ``ideal``; delivered at the leader over
``bernoulli_delay``: variant ``informed``), to rounding.
"""

from __future__ import annotations

import numpy as np

from coloc_env.bounds.problem import BoundProblem, ReadingInformation, Recursion, delivered_recursion, with_delivered
from estimators.bounds import linear_information

# the worlds this module is the bound model of (coloc_env.bounds.models reads it)
WORLDS = ("drift", "target_cv")


def problem(core, record) -> BoundProblem:
    world = core.world
    K, N = record.steps, world.num_agents
    _, P0 = world.prior()
    P0 = np.asarray(P0, float)
    n = P0.shape[0]
    motion = world.motion_model
    F = np.broadcast_to(np.asarray(motion.transition, float), (max(K - 1, 0), n, n))
    Q = np.broadcast_to(np.asarray(motion.process_noise, float), (max(K - 1, 0), n, n))
    C = np.asarray(world.measurement_model.matrix, float)
    R = np.asarray(world.measurement_model.noise_of(N), float)  # (N, m, m)
    own = linear_information(C, R)  # (N, n, n)
    positions = np.tile(np.asarray(world.position_index), (N, 1))
    one = positions[:1]
    centralized = Recursion(P0, np.broadcast_to(own.sum(axis=0), (K, n, n)), F, Q, positions)
    local = [Recursion(P0, np.broadcast_to(own[i], (K, n, n)), F, Q, one) for i in range(N)]
    agents = [np.array([i]) for i in range(N)]
    shared = core.composition.backend.shared_estimate  # every agent reports the leader's estimate
    sender_info = np.broadcast_to(own, (K, N, n, n))

    def readings_bound(arrival, lags):  # arrival (K, N, N) [t, s]: each receiver's own z at once, the packets' later
        delivered = []
        for s in range(1 if shared else N):
            at_s = arrival[..., s].copy()
            at_s[..., s] = 0
            delivered.append(delivered_recursion(P0, F, Q, sender_info, at_s, lags, one))
        return delivered, ([np.arange(N)] if shared else agents)

    readings = ReadingInformation(n)
    everything = np.arange(n)
    for k in range(K):
        for i in range(N):  # z_i(k), agent i's own
            readings.add(k, i, -1, everything, own[i])
    problem = BoundProblem(centralized, local, agents, readings=readings)
    return with_delivered(problem, core, record, "packets", (K, N, N), readings_bound)
