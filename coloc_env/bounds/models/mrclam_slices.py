"""Bound model of the ``mrclam_slices`` world (UTIAS MRCLAM in slices): **model-based**.

As for ``mrclam``, recorded data have no generative model: the bound is the PCRB of the model the slices
state (each slice's velocity reading, sigma_acc, sigma_gps and sigma_d, the numbers of the readings'
``extra``), along the recorded Vicon positions with the pseudo-fixes and ranges of the episode's slices. It
says what an estimator matched to that model could reach, not what any estimator must exceed on the data.

| item        | value                                                                                  |
|-------------|----------------------------------------------------------------------------------------|
| state       | every robot's position (2 N): the velocity reading is taken as exact (the readings'   |
|             | ``velocity``), so the velocity carries no uncertainty of its own                       |
| prior       | J0 = P0^-1, P0 = initial_std^2 I2 per robot (the initial belief's position block)      |
| motion      | p(k+1) = p(k) + Delta t v_k + w, w ~ N(0, (sigma_acc,k Delta t^2 / 2)^2 I2): the known |
|             | displacement adds no information; sigma_acc,k the slice's ``accel_std``                |
| episodes    | each episode (a stretch of the run) its own problem: one recursion per episode, then   |
|             | the mean of the episodes' bounds                                                       |
| readings    | a pseudo-fix (I / sigma_gps,k^2, the slice's ``gps_std``) of each normal robot; one    |
|             | range per edge ([[B, -B], [-B, B]], B = u u^T / sigma_d,k^2 at the Vicon positions)    |
| centralized | all of them                                                                            |
| local       | each robot's own motion and pseudo-fixes                                               |
| delivered   | ``dead_reckoning``: = local; ``ukf_ccl``: the centre's (the pseudo-fixes and ranges    |
|             | whose message reached agent 0), every robot's; the other backends' messages carry      |
|             | beliefs or estimates: each robot's information set (``coloc_env.bounds.information_set``) |
"""

from __future__ import annotations

import numpy as np

from coloc_env.bounds.problem import BoundProblem, ReadingInformation, Recursion, centre_received, with_delivered
from estimators.bounds import fix_information, pair_information, range_information

# the worlds this module is the bound model of (coloc_env.bounds.models reads it)
MODEL_BASED = True  # recorded data: the bound of the model, not of the data (docstring)
WORLDS = ("mrclam_slices",)


def problem(core, record) -> BoundProblem:
    world = core.world
    K, N = record.steps, world.num_agents
    n = 2 * N
    truth = world.slices.truth[int(world.start[0]) + np.minimum(np.arange(K), world.horizon - 1), :N]  # (K, N, 2)
    p0 = world.config.initial_std**2 * np.eye(2)
    info = np.zeros((K, n, n))
    own = np.zeros((K, N, 2, 2))
    readings = ReadingInformation(n)
    central = core.composition.backend.message_kind == "central"  # the centre's information, for ukf_ccl
    centre = np.zeros((K, n, n)) if central else None
    q = np.zeros((max(K - 1, 0), 2, 2))
    for k in range(K):
        r = record.readings[k]
        if k < K - 1:
            q[k] = (float(r.extra["accel_std"][0]) * world.dt**2 / 2.0) ** 2 * np.eye(2)
        own[k] = r.fix_valid[0][:, None, None] * fix_information(float(r.extra["gps_std"][0]) ** 2)
        for i in range(N):
            info[k, 2 * i:2 * i + 2, 2 * i:2 * i + 2] = own[k, i]
            if r.fix_valid[0][i]:
                readings.add(k, i, -1, np.arange(2 * i, 2 * i + 2), own[k, i])
        variance = float(r.extra["range_std"][0]) ** 2
        pairs = list(zip(*np.nonzero(np.triu(r.range_valid[0], 1)), strict=True))  # in the backend's order
        if central:
            fixes = np.flatnonzero(r.fix_valid[0])
            got_range, got_fix = centre_received(record, k, pairs, fixes, N)
            for i, got in zip(fixes, got_fix, strict=True):
                if got:
                    centre[k, 2 * i:2 * i + 2, 2 * i:2 * i + 2] += own[k, i]
        for j, (a, b) in enumerate(pairs):
            idx = np.r_[2 * a:2 * a + 2, 2 * b:2 * b + 2]
            block = pair_information(range_information(truth[k, a], truth[k, b], variance))
            info[k][np.ix_(idx, idx)] += block
            readings.add(k, a, b, idx, block)
            if central and got_range[j]:
                centre[k][np.ix_(idx, idx)] += block
    steps = max(K - 1, 0)
    Q = np.stack([np.kron(np.eye(N), q[k]) for k in range(steps)]) if steps else np.zeros((0, n, n))
    positions = np.array([[2 * i, 2 * i + 1] for i in range(N)])
    centralized = Recursion(np.kron(np.eye(N), p0), info, None, Q, positions)
    local = [Recursion(p0, own[:, i], None, q, np.array([[0, 1]])) for i in range(N)]
    agents = [np.array([i]) for i in range(N)]

    def centre_bound():  # every robot reads its estimate at the centre (ukf_ccl)
        return [Recursion(centralized.P0, centre, None, Q, positions)], [np.arange(N)]

    return with_delivered(BoundProblem(centralized, local, agents, model_based=True, per_episode=True,
                                       readings=readings), core, record,
                          readings_bound=centre_bound if central else None)
