"""Bound model of the ``nlos_orbit`` world (gao2016): target UAVs localized by orbiting neighbours' RSS/AOA packets.

Estimation problem (the one ``afge`` / ``dfir`` / ``dead_reckoning`` face; each target alone):

| item        | value                                                                                  |
|-------------|----------------------------------------------------------------------------------------|
| state       | every target's [p; v] (4 N), the targets independent of one another                    |
| prior       | J0 = P0^-1, P0 = diag(prior_std^2) (the world's prior; its mean is drawn around truth)  |
| motion      | the filters' ``estimators.nlos_models.ConstantVelocityWhiteAccel``: x(k+1) = F x + |
|             | w, w ~ N(0, Q), Q the white-acceleration noise of ``accel_sigma`` (no input)            |
| readings    | each neighbour j inside target i's receive-search area at k: RSS (dBm) and AOA (rad)   |
|             | (as ``sensors`` selects) of the target's true position seen from the neighbour's true  |
|             | position, with the LOS/NLOS mode of that link *known* (its bias removed, its variance  |
|             | used: a genie bound; an estimator that must infer the mode can only do worse); the    |
|             | neighbour's position known to sigma_nav per axis through its navigation estimate,      |
|             | eliminated as a Gaussian nuisance (``estimators.bounds.rss_aoa_information``)      |
| centralized | every reading measured, whether or not the network delivers it                         |
| local       | none: a target has no sensor of its own (prior and motion only)                        |
| delivered   | (``afge``, ``dfir``) the readings whose packet reached the target, each counted at the |
|             | step it was measured from the step it arrived (lag-augmented over the network's        |
|             | longest delay); ``dead_reckoning`` receives nothing (= local)                          |

This is the filters' model: the truth flies a deterministic turn schedule, not the white-acceleration
model the bound (and the filters) assume, so the bound describes the model, and an estimator can fall
below it where the truth is smoother than the model says (straight legs).
"""

from __future__ import annotations

import numpy as np

from coloc_env.bounds.problem import BoundProblem, ReadingInformation, Recursion, delivered_recursion, with_delivered
from coloc_env.worlds.blocks.flight import OrbitParameters
from coloc_env.worlds.nlos_orbit import ORBIT_FIELDS
from estimators.bounds import rss_aoa_information

# the worlds this module is the bound model of (coloc_env.bounds.models reads it)
WORLDS = ("nlos_orbit",)


def reading_information(world, K: int) -> np.ndarray:
    """(K, N, J, 4, 4): the information of neighbour j's reading of target i at k on i's [p; v] (0 outside the RSA)."""
    c = world.config
    orbits = OrbitParameters(*(getattr(world.orbits, f)[0] for f in ORBIT_FIELDS))
    truth = world.truth[0, :K]  # (K, N, 4)
    senders = truth[:, :, None, :2] + world.neighbours.offsets(orbits, world.horizon + 1)[:K]  # (K, N, J, 2)
    modes = world.modes[0, :K]
    variances = np.diagonal(world.measurement_model.covar(modes), axis1=-2, axis2=-1)  # (K, N, J, 2)
    use = ("rss" in c.sensors, "aoa" in c.sensors)
    block = rss_aoa_information(truth[:, :, None, :2], senders, float(world.signal.exponent), variances,
                                float(c.sigma_nav) ** 2, use)
    info = np.zeros((*block.shape[:3], 4, 4))
    info[..., :2, :2] = block * world.in_rsa[0, :K][..., None, None]
    return info


def stand_in(core):
    """The neighbours' packets of k to their target, asked of the network as ``afge`` / ``dfir`` ask it (every
    neighbour inside the RSA sends; ``coloc_env.networks.base.Network.node_packets``, slot 0: counter-based
    draws, so the same delays whoever asks)."""
    world, network = core.world, core.network

    def deliver(readings):
        network.node_packets(np.asarray(readings.extra["measured"], bool), world.neighbour_distances(), 0.0, slot=0)

    return deliver


def problem(core, record) -> BoundProblem:
    world = core.world
    K, N = record.steps, world.num_agents
    J = world.num_neighbours
    p0 = np.asarray(world.prior_cov, float)
    f = np.asarray(world.motion_model.transition, float)
    q = np.asarray(world.motion_model.process_noise, float)
    steps = max(K - 1, 0)
    eye = np.eye(N)
    per_reading = reading_information(world, K)  # (K, N, J, 4, 4)
    info = np.zeros((K, 4 * N, 4 * N))
    for i in range(N):
        info[:, 4 * i:4 * i + 4, 4 * i:4 * i + 4] = per_reading[:, i].sum(axis=1)
    positions = np.array([[4 * i, 4 * i + 1] for i in range(N)])
    centralized = Recursion(np.kron(eye, p0), info, np.broadcast_to(np.kron(eye, f), (steps, 4 * N, 4 * N)),
                            np.broadcast_to(np.kron(eye, q), (steps, 4 * N, 4 * N)), positions)
    F, Q = np.broadcast_to(f, (steps, 4, 4)), np.broadcast_to(q, (steps, 4, 4))
    local = [Recursion(p0, np.zeros((K, 4, 4)), F, Q, np.array([[0, 1]])) for _ in range(N)]
    agents = [np.array([i]) for i in range(N)]

    def readings_bound(arrival, lags):  # arrival (K, N, J)
        return [delivered_recursion(p0, F, Q, per_reading[:, i], arrival[:, i], lags, np.array([[0, 1]]))
                for i in range(N)], agents

    readings = ReadingInformation(4 * N)
    for k in range(K):
        for i in range(N):
            for j in range(J):  # neighbour j's reading of target i (a world node's: tagged with the target)
                readings.add(k, i, -1, np.arange(4 * i, 4 * i + 4), per_reading[k, i, j])
    return with_delivered(BoundProblem(centralized, local, agents, readings=readings), core, record, "node_packets",
                          (K, N, J), readings_bound)
