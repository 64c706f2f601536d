"""Bound model of the ``mrclam`` world (recorded UTIAS MRCLAM data): **model-based**.

Recorded data have no generative model, so there is no expectation over trajectories to take: the
bound here is the PCRB of the *model* the filters assume (the world's noise model, whichever its
``noise_model`` selects: the odometry variances and R are read from the readings' ``inputs`` and
``obs_cov``, the very numbers the backends read), evaluated along the recorded Vicon trajectory with the
readings the robots actually took. It says what an
estimator matched to that model could reach on these steps, not what any estimator must exceed on the
data (the data's errors need not follow the model), so it is labelled ``model_based`` and left out of
the "MSE >= bound" check.

| item        | value                                                                                  |
|-------------|----------------------------------------------------------------------------------------|
| state       | every robot's pose (x, y, theta) (3 N); the bound is reported on (x, y)                 |
| prior       | J0 = P0^-1, P0 = diag(initial_position_std^2 (x2), initial_heading_std^2) per robot: the |
|             | filters start at the Vicon pose with that covariance, and so does the bound            |
| motion      | ``estimators.se2_models.SE2Odometry`` on the world's corrected odometry inputs,    |
|             | F and Q = G diag(var_v, var_omega) G^T at the Vicon pose (Q has rank 2 of 3: the       |
|             | covariance form, exact)                                                                |
| episodes    | each window of the recording is its own problem, conditioned on its trajectory: one    |
|             | recursion per episode, then the mean of the episodes' bounds (averaging the D-terms of |
|             | windows whose rank-2 Q point different ways would leave no process noise at all: a      |
|             | valid but empty bound)                                                                 |
| readings    | each selected camera sighting of step k (``obs_*`` of the readings): range and bearing |
|             | from the observer's pose to a surveyed landmark (only the observer's block) or to      |
|             | another robot's position (both blocks), R the noise model's (``obs_cov``)              |
| centralized | all of them                                                                            |
| local       | each robot's own odometry and its own landmark sightings (the landmark pseudo-fixes    |
|             | are these sightings again and are not counted twice)                                   |
| delivered   | ``dead_reckoning``: = local; ``ukf_se2``'s relay chains, dNBP's and least squares'     |
|             | broadcasts carry estimates: each robot's information set                               |
|             | (``coloc_env.bounds.information_set``), per episode                                    |
"""

from __future__ import annotations

import numpy as np

from coloc_env.bounds.problem import BoundProblem, ReadingInformation, Recursion, with_delivered
from estimators.bounds import range_bearing_information

# the worlds this module is the bound model of (coloc_env.bounds.models reads it)
MODEL_BASED = True  # recorded data: the bound of the model, not of the data (docstring)
WORLDS = ("mrclam",)


def problem(core, record) -> BoundProblem:
    world = core.world
    K, N = record.steps, world.num_agents
    n = 3 * N
    start = int(world.start[0])
    poses = world.data.groundtruth[start:start + K, :N]  # (K, N, 3) Vicon
    _, cov = world.initial_belief()
    p0 = np.asarray(cov[0, 0], float)
    model = world.motion_model
    F = np.zeros((max(K - 1, 0), n, n))
    Q = np.zeros((max(K - 1, 0), n, n))
    f = np.zeros((max(K - 1, 0), N, 3, 3))
    q = np.zeros((max(K - 1, 0), N, 3, 3))
    for k in range(K - 1):
        inputs = np.asarray(record.readings[k].inputs[0], float)  # (N, 4)
        f[k] = model.jacobian(poses[k], inputs)
        q[k] = model.covar(poses[k], inputs)
        for i in range(N):
            F[k, 3 * i:3 * i + 3, 3 * i:3 * i + 3] = f[k, i]
            Q[k, 3 * i:3 * i + 3, 3 * i:3 * i + 3] = q[k, i]
    info = np.zeros((K, n, n))
    own = np.zeros((K, N, 3, 3))
    readings = ReadingInformation(n)
    for k in range(K):
        extra = record.readings[k].extra
        observer, subject = extra["obs_observer"][0], extra["obs_subject"][0]
        target, R = extra["obs_target"][0], extra["obs_cov"][0]
        for j in np.flatnonzero(observer >= 0):
            m = int(observer[j])
            if subject[j] < 0:  # a surveyed landmark: known, only the observer's pose
                block = range_bearing_information(poses[k, m], target[j], R[j])[:3, :3]
                own[k, m] += block
                info[k, 3 * m:3 * m + 3, 3 * m:3 * m + 3] += block
                readings.add(k, m, -1, np.arange(3 * m, 3 * m + 3), block)
            else:
                s = int(subject[j])
                block = range_bearing_information(poses[k, m], poses[k, s, :2], R[j])
                idx = np.r_[3 * m:3 * m + 3, 3 * s:3 * s + 2]
                info[k][np.ix_(idx, idx)] += block
                readings.add(k, m, s, idx, block)
    positions = np.array([[3 * i, 3 * i + 1] for i in range(N)])
    centralized = Recursion(np.kron(np.eye(N), p0), info, F, Q, positions)
    local = [Recursion(p0, own[:, i], f[:, i], q[:, i], np.array([[0, 1]])) for i in range(N)]
    agents = [np.array([i]) for i in range(N)]
    return with_delivered(BoundProblem(centralized, local, agents, model_based=True, per_episode=True,
                                       readings=readings), core, record)
