"""Bound model of the ``gps_denied`` world (wan2014): constant-velocity UAVs, accelerometer inputs, GPS and ranges.

Estimation problem (the one the ``ukf_ccl`` / ``dnbp`` / ``range_ls`` / ``dead_reckoning`` backends face):

| item        | value                                                                                  |
|-------------|----------------------------------------------------------------------------------------|
| state       | every UAV's [p; v] (4 N); the bound is reported on each p                              |
| prior       | J0 = P0^-1, P0 = diag(gps_std^2 I2, velocity_spread^2 I2) per UAV (the world's initial |
|             | belief)                                                                                |
| motion      | x(k+1) = F x + G a_hat + w with the accelerometer reading a_hat as input, w ~ N(0, Q), |
|             | Q = accel_noise_std^2 G G^T (rank 2 of 4: the covariance form, exact): exact for this  |
|             | generator, the true acceleration entering truth and reading alike                       |
| readings    | a GPS fix (I / gps_std^2) for each UAV whose receiver is normal at k; one range per    |
|             | unordered pair within ``comm_range`` ([[B, -B], [-B, B]], B = u u^T / range_std^2 at   |
|             | the true positions)                                                                    |
| centralized | all of them                                                                            |
| local       | each UAV's own accelerometer and own fixes                                             |
| delivered   | ``dead_reckoning``: = local; ``ukf_ccl``: the centre's (every accelerometer, the      |
|             | ranges and fixes whose message reached agent 0), every UAV's; the other backends'      |
|             | messages carry beliefs or estimates: each UAV's information set                        |
|             | (``coloc_env.bounds.information_set``)                                                 |
"""

from __future__ import annotations

import numpy as np

from coloc_env.bounds.problem import BoundProblem, ReadingInformation, Recursion, centre_received, with_delivered
from estimators.bounds import fix_information, pair_information, range_information

# the worlds this module is the bound model of (coloc_env.bounds.models reads it)
WORLDS = ("gps_denied",)


def problem(core, record) -> BoundProblem:
    world = core.world
    c = world.config
    K, N = record.steps, world.num_agents
    n = 4 * N
    p0 = np.diag([c.gps_std**2] * 2 + [c.velocity_spread**2] * 2)
    model = world.motion_model
    f, q = np.asarray(model.transition, float), np.asarray(model.process_noise, float)
    eye = np.eye(N)
    P0, F, Q = np.kron(eye, p0), np.kron(eye, f), np.kron(eye, q)
    normal = world.gps_normal[0, :K]  # (K, N)
    own = np.zeros((K, N, 4, 4))
    own[:, :, :2, :2] = normal[..., None, None] * fix_information(c.gps_std**2)
    info = np.zeros((K, n, n))
    for i in range(N):
        info[:, 4 * i:4 * i + 4, 4 * i:4 * i + 4] = own[:, i]
    readings = ReadingInformation(n)
    # the centre's information, for the delivered bound of a backend that sends its readings there (ukf_ccl)
    central = core.composition.backend.message_kind == "central"
    centre = np.zeros((K, n, n)) if central else None
    for step in range(K):
        pairs = list(zip(*np.nonzero(np.triu(world.adjacency[0, step], 1)), strict=True))  # one per unordered pair
        p = world.truth[0, step, :, :2]
        for i in np.flatnonzero(normal[step]):  # the GPS fixes
            readings.add(step, i, -1, np.arange(4 * i, 4 * i + 4), own[step, i])
        if central:
            fixes = np.flatnonzero(normal[step])
            got_range, got_fix = centre_received(record, step, pairs, fixes, N)
            for i, got in zip(fixes, got_fix, strict=True):
                if got:
                    centre[step, 4 * i:4 * i + 4, 4 * i:4 * i + 4] += own[step, i]
        for r, (a, b) in enumerate(pairs):
            idx = np.r_[4 * a:4 * a + 2, 4 * b:4 * b + 2]
            block = pair_information(range_information(p[a], p[b], c.range_std**2))
            info[step][np.ix_(idx, idx)] += block
            readings.add(step, a, b, idx, block)
            if central and got_range[r]:
                centre[step][np.ix_(idx, idx)] += block
    steps = max(K - 1, 0)
    positions = np.array([[4 * i, 4 * i + 1] for i in range(N)])
    centralized = Recursion(P0, info, np.broadcast_to(F, (steps, n, n)), np.broadcast_to(Q, (steps, n, n)), positions)
    local = [Recursion(p0, own[:, i], np.broadcast_to(f, (steps, 4, 4)), np.broadcast_to(q, (steps, 4, 4)),
                       np.array([[0, 1]])) for i in range(N)]
    agents = [np.array([i]) for i in range(N)]

    def centre_bound():  # every UAV reads its estimate at the centre
        return [Recursion(P0, centre, centralized.F, centralized.Q, positions)], [np.arange(N)]

    return with_delivered(BoundProblem(centralized, local, agents, readings=readings), core, record,
                          readings_bound=centre_bound if central else None)
