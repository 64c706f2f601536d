"""Bound model of the ``circles`` world (wang2019): unicycles on known-start circles, odometry, ranges, fixes.

The world's generative model (``coloc_env.worlds.circles``): the truth is deterministic, the same
in every episode: each platform flies its circle, p(k+1) = p(k) + dt V t(phi(k)), phi(k+1) =
phi(k) + dt omega (t(a) = [cos a; sin a]), from a start pose the estimators are given exactly
(``initial_belief``'s mean is the true position; the integrated heading starts at the true phi(0)).
What is random: the odometry noises (V_m(k) = V + n_v(k), omega_m(k) = omega + n_omega(k), white), the
range noise, the fix noise, and which platform ranges at which step (the schedule; whom it ranges with
is its sensing action). The estimators do not know that the tracks are circles: they take the odometry
as the motion's inputs. The estimation problem is therefore the one whose unknowns are the start pose
and the per-step speeds V(k) and turn rates omega(k), each known only through its reading
(information 1 / sigma_v^2, 1 / sigma_omega^2; no other prior), and whose positions p(k) follow from
them. Linearized at the world's truth (the only trajectory the world flies) this is the linear-Gaussian
state-space model, per platform, of the state s = (x, y, phi):

    s(k+1) = s(k) + [dt V t(phi(k)); dt omega] + w(k),     F_k = [[I_2, dt V n(phi(k))], [0, 1]],
    Q_k = blockdiag(dt^2 sigma_v^2 t t^T, dt^2 sigma_omega^2)   (t = t(phi(k)), n = [-sin phi; cos phi]),

(dp(k+1)/dV(k) = dt t, dp(k+1)/dphi(k) = dt V n), the heading's error a random walk shared by every
later displacement: the time correlation that a per-step position noise cannot carry. F, Q and the
readings' Jacobians (u u^T at the true positions) are the truth's, identical in every episode; the
covariance-form recursion is then the Cramér–Rao bound of the start pose and the inputs (TMN's
recursion with F and Q fixed, exact for the singular Q and prior here), evaluated at the truth. It is
the model ``estimators.heading_models.OdometryHeadingError`` filters (the heading error e =
phi_m - phi is -dphi), without that filter's departures (its prior variance of e, its Jacobians at
the estimate).

| item        | value                                                                                  |
|-------------|----------------------------------------------------------------------------------------|
| state       | every platform's (x, y, phi) (3 N); with ``turn_rate_noise_std`` = 0 the heading is    |
|             | exact and the state is the positions (2 N): the same bound (a test holds them equal)  |
| prior       | P0 = 0: the start pose is given exactly (the filters' ``initial_position_std`` is     |
|             | their stated uncertainty, not the error of their start; a bound from it would credit  |
|             | the estimator with less than it has)                                                   |
| motion      | F_k, Q_k above at the true headings and speed; the world's turn-rate noise whatever   |
|             | ``heading_noise`` (which changes only the model the backends assume) says             |
| readings    | the range each step's measuring platform took to the partner its sensing chose (as    |
|             | recorded: [[B, -B], [-B, B]], B = u u^T / range_noise_var at the true positions);      |
|             | the anchors' fixes, I / fix_noise_std^2, every step                                     |
| episodes    | the D-terms averaged over the episodes, one recursion (``coloc_env.bounds``): F and |
|             | Q are common, so that is the reading information averaged per step. A mean of per-     |
|             | episode bounds would be a valid, tighter bound only while what differs between        |
|             | episodes (the schedule, the partners, the deliveries) is independent of the noises;   |
|             | a policy that chooses its partners from its estimates (``coloc evaluate`` replays      |
|             | such actions) breaks that, the averaged information does not need it                   |
| centralized | all of them                                                                            |
| local       | each platform's own odometry and (an anchor) its own fixes; a range to another        |
|             | platform carries no information on its own without that platform's position           |
| delivered   | ``dead_reckoning`` (sends nothing): = local; ``ukf_ccl``: the centre's (every          |
|             | odometry, the ranges and fixes whose message reached agent 0), every platform's; the  |
|             | other backends' messages carry estimates or relayed location information: each       |
|             | platform's information set (``coloc_env.bounds.information_set``)                   |

It bounds estimators that use the odometry as inputs and do not know the circles (one that
knew the tracks would need no readings at all); it is a Cramér–Rao bound at the truth, so it holds for
estimators unbiased to first order, which the filters here are (their errors are metres on tracks of
tens of metres).
"""

from __future__ import annotations

import numpy as np

from coloc_env.bounds.problem import BoundProblem, ReadingInformation, Recursion, centre_received, with_delivered
from estimators.bounds import fix_information, pair_information, range_information

# the worlds this module is the bound model of (coloc_env.bounds.models reads it)
WORLDS = ("circles",)


def motion(world, steps: int, heading_state: bool) -> tuple[np.ndarray, np.ndarray]:
    """Per-platform F and Q (steps - 1, N, d, d) of the transitions k -> k + 1 at the truth (module docstring);
    d = 3 with the heading in the state, 2 without (then the heading must be exact: no turn-rate noise)."""
    c = world.config
    N, dt = world.num_agents, c.dt
    phi = np.asarray(world.true_heading[:steps - 1], float)  # (K-1, N): the heading each step moves along
    speed = np.asarray(world._speed, float)[None, :]
    along = np.stack([np.cos(phi), np.sin(phi)], axis=-1)
    normal = np.stack([-np.sin(phi), np.cos(phi)], axis=-1)
    d = 3 if heading_state else 2
    F = np.broadcast_to(np.eye(d), (steps - 1, N, d, d)).copy()
    Q = np.zeros((steps - 1, N, d, d))
    Q[..., :2, :2] = dt**2 * c.speed_noise_std**2 * along[..., :, None] * along[..., None, :]
    if heading_state:
        F[..., :2, 2] = dt * speed[..., None] * normal
        Q[..., 2, 2] = dt**2 * c.turn_rate_noise_std**2
    return F, Q


def _block_diagonal(blocks: np.ndarray) -> np.ndarray:
    """(..., N, d, d) -> (..., N d, N d)."""
    *lead, N, d, _ = blocks.shape
    out = np.zeros((*lead, N * d, N * d))
    for i in range(N):
        out[..., d * i:d * i + d, d * i:d * i + d] = blocks[..., i, :, :]
    return out


def problem(core, record, heading_state: bool | None = None) -> BoundProblem:
    """The bound problem of one recorded episode; ``heading_state`` None: the heading in the state where the
    world's turn-rate noise is not zero (False with noise is refused: the bound would miss the heading's error)."""
    world = core.world
    c = world.config
    K, N = record.steps, world.num_agents
    noisy = c.turn_rate_noise_std > 0
    if heading_state is None:
        heading_state = noisy
    if noisy and not heading_state:
        raise ValueError("heading_state=False needs turn_rate_noise_std = 0 (the heading is then exact)")
    d = 3 if heading_state else 2
    n = d * N
    f, q = motion(world, K, heading_state)
    F, Q = _block_diagonal(f), _block_diagonal(q)
    P0 = np.zeros((n, n))
    own = np.zeros((K, N, d, d))
    own[:, :c.num_anchors, :2, :2] = fix_information(c.fix_noise_std**2)
    info = _block_diagonal(own)
    readings = ReadingInformation(n)
    # the centre's information, for the delivered bound of a backend that sends its readings there (ukf_ccl)
    central = core.composition.backend.message_kind == "central"
    centre = np.zeros((K, n, n)) if central else None
    for step in range(K):
        for i in range(c.num_anchors):  # the anchors' fixes
            readings.add(step, i, -1, np.arange(d * i, d * i + d), own[step, i])
        valid = record.readings[step].range_valid[0]
        pairs = list(zip(*np.nonzero(valid), strict=True))
        if central:
            fixes = np.flatnonzero(record.readings[step].fix_valid[0])
            got_range, got_fix = centre_received(record, step, pairs, fixes, N)
            for i, got in zip(fixes, got_fix, strict=True):
                if got:
                    centre[step, d * i:d * i + d, d * i:d * i + d] += own[step, i]
        for r, (m, j) in enumerate(pairs):
            block = pair_information(range_information(world.truth[step, m], world.truth[step, j],
                                                       c.range_noise_var))
            idx = np.r_[d * m:d * m + 2, d * j:d * j + 2]
            info[step][np.ix_(idx, idx)] += block
            readings.add(step, m, j, idx, block)
            if central and got_range[r]:
                centre[step][np.ix_(idx, idx)] += block
    positions = d * np.arange(N)[:, None] + np.arange(2)[None, :]
    centralized = Recursion(P0, info, F, Q, positions)
    local = [Recursion(np.zeros((d, d)), own[:, i], f[:, i], q[:, i], np.array([[0, 1]])) for i in range(N)]
    agents = [np.array([i]) for i in range(N)]

    def centre_bound():  # every platform reads its estimate at the centre
        return [Recursion(P0, centre, F, Q, positions)], [np.arange(N)]

    return with_delivered(BoundProblem(centralized, local, agents, readings=readings), core, record,
                          readings_bound=centre_bound if central else None)
