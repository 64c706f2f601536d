"""Backends ``ukf_ccl`` and ``ukf_dcl`` (wang2019): the joint UKF, centralized or over relay chains.

Both keep the joint Gaussian of every agent's state (``estimators.ukf_relay``;
the joint covariance array stands for the platforms' rows in the distributed
filter). Time update: ``estimators.models.predict_joint`` on the backend's
motion model (``coloc_env.backends.heading``: on an odometry world with
turn-rate noise, ``motion="heading"`` adds each platform's heading error to its
block, (x, y, e); ``motion="displacement"`` is wang2019's position-only model).
Measurement updates, in a fixed order (ranges in row-major order of (measuring,
measured), then position fixes by agent):

* a range m -> n: **ukf_ccl** sends it from m to the fusion centre (agent 0,
  message kind ``central``); if it arrives, the centre applies the UKF-CCL
  update (eqs. 5-12, 17). **ukf_dcl** starts a relay chain m -> n -> ... on
  the network (kind ``chain``); if n is reached, the UKF-DCL update runs
  along the chain (Algorithms 1-2) and the platforms not reached keep their
  estimates (``truncation``: the consistent cross-covariance rule by default,
  the paper's rule on request).
* a position fix of agent i (an anchor, a normal GPS): a linear update of the
  joint state (``estimators.kalman.joseph_update``). ukf_ccl sends it to
  the centre; ukf_dcl relays its location information from i like a range's,
  and only the reached platforms update (the gain of the others is zero, the
  Joseph form keeps P the true covariance).

Over ``ideal`` every chain reaches everyone and every message the centre, so
ukf_dcl equals ukf_ccl (to rounding; the tests check 1e-9).

Cost per step with N agents of state dimension d (L = d N) and J range
readings: the network resolves every chain or centre message of the step in
one call (O(J N) array work, no per-reading Python call), then each reading
costs a 2d x 2d Cholesky and O(L d) work plus its share of a rank-2 update of
P folded every 16 readings (O(L^2)), each fix O(L^2): O(J L^2 + N L^2)
(``estimators.ukf_relay.range_updates``), never an L x L Cholesky per
reading. ukf_dcl computes the chain's numbers in the same closed form, so over
``ideal`` it costs what ukf_ccl does; with ``truncation="paper"`` it runs each
chain hop by hop (O(N) Schur complements per reading), which catches the loss
of positive definiteness that rule causes.

A lost or late update is skipped (nothing is buffered). ``ukf_ccl``'s agents
read their estimates at the centre (the return path is not charged).

| quantity      | value                                                                  |
|---------------|------------------------------------------------------------------------|
| estimand      | self                                                                   |
| motion kinds  | ``odometry_displacement`` (wang2019's position-only state), ``cv_accel`` |
|               | (wan2014's [p, v] blocks: the range's sigma points span every block)   |
| needs         | ``range``                                                              |
| messages      | ukf_ccl: ``central`` (a range 1 float, a fix 2); ukf_dcl: ``chain`` (below)          |

A ukf_dcl hop h carries S_m (10 floats) and the A_i row blocks and Pxz^i of
the r = h + 1 platforms reached so far: 10 + 5 r + 2 r (r - 1) floats for
position-only blocks (``dcl_floats`` for d-dimensional ones). In a world
whose range readings are symmetric (``gps_denied``: one measurement per edge,
known to both ends) each pair is fused once, m < n.
| decisions     | none                                                                   |

Arguments (``coloc_env.backends.UkfCcl`` / ``UkfDcl``)

| field       | default      | allowed                                           |
|-------------|--------------|---------------------------------------------------|
| ukf_lambda  | 0.0          | (-2N, 1e6], N the agents, checked at build (0 = filterpy's) |
| truncation  | "consistent" | ukf_dcl only: "consistent", "paper"               |
| motion      | "heading"    | "heading", "displacement": on odometry, the heading error in the state or not |
|             |              | (``coloc_env.backends.heading``)               |
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

import estimators.ukf_relay as ukf
from coloc_env.backends.base import Backend, measurement_list, position_blocks
from coloc_env.backends.heading import MOTIONS, ukf_motion_model
from coloc_env.networks.base import CENTRE
from coloc_env.parts import BACKENDS, PartConfig, check_choice, check_range
from estimators.models import predict_joint


def dcl_floats(hop: int, d: int = 2) -> float:
    """Payload of ukf_dcl hop ``hop`` (0-based) with d-dimensional platform blocks: S_m (2 + 4 d floats),
    then for the r = hop + 1 platforms reached so far their row blocks A_i of the lower block-triangular
    factor (r d (d + 1) / 2 + d^2 r (r - 1) / 2) and their update weights Pxz^i (r d); 10 + 5 r + 2 r (r - 1)
    for wang2019's d = 2."""
    r = hop + 1
    return 2 + 4 * d + r * d * (d + 1) / 2 + d * d * r * (r - 1) / 2 + r * d


def check_spread(ukf_lambda, num_agents: int | None, prefix: str, agents: str) -> None:
    """The joint UKF's lambda against the team: (-2N, 1e6] (N the agents, named ``agents`` in the message).
    With ``num_agents`` None (a part's own check, before the team is known) the same message, without N's
    value: NaN, a non-number and the high bound are refused there, the low bound at build."""
    low = None if num_agents is None else -2.0 * num_agents
    check_range(f"{prefix}ukf_lambda", ukf_lambda, low, 1e6, low_open=True, low_label=f"-2 {agents}")


def team_label(prefix: str) -> str:
    """What names the team's size N in a part's message: a composition's backend (``prefix`` "backend.") reads it
    from ``world.num_agents``; a preset's keyword is ``num_agents``."""
    return "world.num_agents" if prefix == "backend." else "num_agents"


@BACKENDS.register
@dataclass(frozen=True)
class UkfCcl(PartConfig):
    name = "ukf_ccl"
    estimand = "self"
    motion_kinds = frozenset({"odometry_displacement", "cv_accel"})
    requires = (frozenset({"range"}),)
    message_kind = "central"
    message_content = "readings"
    shared_estimate = True
    ukf_lambda: float = 0.0
    motion: str = "heading"

    def check(self, prefix: str) -> None:
        check_spread(self.ukf_lambda, None, prefix, team_label(prefix))  # > -2N: at build
        check_choice(f"{prefix}motion", self.motion, MOTIONS)

    def check_spread(self, num_agents: int, prefix: str, agents: str) -> None:
        check_spread(self.ukf_lambda, num_agents, prefix, agents)

    def build(self, world, network, batch: int) -> Backend:
        return JointUkfBackend(self, world, network, batch, distributed=False)


@BACKENDS.register
@dataclass(frozen=True)
class UkfDcl(PartConfig):
    name = "ukf_dcl"
    estimand = "self"
    motion_kinds = frozenset({"odometry_displacement", "cv_accel"})
    requires = (frozenset({"range"}),)
    message_kind = "chain"
    message_content = "estimates"
    shared_estimate = False
    ukf_lambda: float = 0.0
    truncation: str = "consistent"
    motion: str = "heading"

    def check(self, prefix: str) -> None:
        check_spread(self.ukf_lambda, None, prefix, team_label(prefix))  # > -2N: at build
        check_choice(f"{prefix}truncation", self.truncation, ("consistent", "paper"))
        check_choice(f"{prefix}motion", self.motion, MOTIONS)

    def check_spread(self, num_agents: int, prefix: str, agents: str) -> None:
        check_spread(self.ukf_lambda, num_agents, prefix, agents)

    def build(self, world, network, batch: int) -> Backend:
        return JointUkfBackend(self, world, network, batch, distributed=True)


class JointUkfBackend(Backend):
    def __init__(self, config, world, network, batch, distributed: bool):
        super().__init__(config, world, network, batch)
        self.distributed = distributed
        N = self.num_agents
        self.motion_model = ukf_motion_model(config.motion, world)
        d = self.d = self.motion_model.state_dim
        config.check_spread(N, "backend.", "world.num_agents")
        self.mean = np.zeros((self.batch, N, d))
        self.cov = np.zeros((self.batch, d * N, d * N))
        if distributed and config.truncation == "paper":
            warnings.warn(ukf.PAPER_RULE_WARNING, UserWarning, stacklevel=2)
        # a world whose reading [m, n] is also [n, m] (one measurement known to both) is fused once per pair
        self.one_per_pair = bool(getattr(world, "symmetric_ranges", False))

    def reset(self, rngs, idx) -> None:
        mean, cov = self.world.initial_belief()
        if self.motion_model is not self.world.motion_model:  # the heading error joins each block
            mean, cov = self.motion_model.augment(mean, cov)
        N, d = self.num_agents, self.d
        self.mean[idx] = mean[idx]
        joint = np.zeros((len(idx), d * N, d * N))
        for i in range(N):
            joint[:, d * i:d * i + d, d * i:d * i + d] = cov[idx, i]
        self.cov[idx] = joint
        self.posterior_position[idx] = mean[idx, :, :2]

    def update(self, readings, decisions) -> None:
        """This step's readings in the fixed order: ranges (row-major (m, n)), then fixes by agent.

        Every message of the step goes to the network in one call per kind (the chains and deliveries of
        one step do not depend on each other: ``Network.relay_each`` / ``Network.messages_to`` with
        one slot per reading), then the updates run in order: J sequential range updates
        (``estimators.ukf_relay.range_updates``, O(L^2) each) and one linear update per fixed agent
        (``estimators.ukf_relay.fix_updates``, O(L^2) each). With ``truncation="paper"`` each range
        runs the chain hop by hop (``estimators.ukf_relay.dcl_update`` with ``method="chain"``), which
        detects the loss of positive definiteness that rule causes.
        """
        B, N, d = self.batch, self.num_agents, self.d
        rows = np.arange(B)
        lam = self.config.ukf_lambda
        valid = np.asarray(readings.range_valid, bool)
        if self.one_per_pair:
            valid = valid & np.triu(np.ones((N, N), dtype=bool), 1)
        count, m, n = measurement_list(valid)
        J = m.shape[1]
        has = np.arange(J) < count[:, None]
        z = readings.range[rows[:, None], m, n]
        R_range = self.world.range_noise_var()
        if J:
            if self.distributed:
                chains = self.network.relay_each(np.where(has, m, -1), np.where(has, n, -1),
                                                 lambda h: dcl_floats(h, d), np.arange(J))
                used = has & (chains.length >= 2)
                if self.config.truncation == "paper":
                    self._chain_updates(chains, used, z, R_range, lam)
                elif np.all(chains.length[used] == N):  # every chain reached everyone: UKF-CCL's update
                    ukf.range_updates(self.mean, self.cov, m, n, z, used, R_range, lam)
                else:
                    reached = np.zeros((B, J, N), dtype=bool)
                    b, j, p = np.nonzero(chains.chain >= 0)
                    reached[b, j, chains.chain[b, j, p]] = True
                    ukf.range_updates(self.mean, self.cov, m, n, z, used, R_range, lam, reached)
            else:
                used = self._to_centre(np.where(has, m, -1), 1.0, np.arange(J))
                ukf.range_updates(self.mean, self.cov, m, n, z, used, R_range, lam)
        fix_valid = np.asarray(readings.fix_valid, bool)
        if fix_valid.any():
            agents = np.flatnonzero(fix_valid.any(axis=0))  # the agents with a fix in some copy, in order
            sources = np.where(fix_valid[:, agents], agents, -1)
            active = np.zeros((B, N), dtype=bool)
            if self.distributed:
                chains = self.network.relay_each(sources, np.full_like(sources, -1), lambda h: dcl_floats(h, d),
                                                 N * N + agents)
                reached = np.zeros((B, N, N), dtype=bool)  # [b, i]: the platforms fix i's update reaches
                b, j, p = np.nonzero(chains.chain >= 0)
                reached[b, agents[j], chains.chain[b, j, p]] = True
                active[:, agents] = fix_valid[:, agents]
            else:
                reached = None
                active[:, agents] = self._to_centre(sources, 2.0, N * N + agents)
            ukf.fix_updates(self.mean, self.cov, readings.fix, active, self.world.fix_noise_var() * np.eye(2),
                            reached)

    def _to_centre(self, senders: np.ndarray, floats: float, slots: np.ndarray) -> np.ndarray:
        """(B, J) bool: message j of ``senders`` (B, J) reached the centre (the centre's own is local)."""
        delivered = self.network.messages_to(senders, CENTRE, floats, slots)
        return (senders >= 0) & ((senders == CENTRE) | delivered)

    def _chain_updates(self, chains, used, z, range_var, lam) -> None:
        """The paper's truncation rule: each range's chain hop by hop (it raises when P lost definiteness)."""
        for j in range(used.shape[1]):
            idx = np.flatnonzero(used[:, j])
            if not len(idx):
                continue
            try:
                self.mean[idx], self.cov[idx] = ukf.dcl_update(
                    self.mean[idx], self.cov[idx], chains.chain[idx, j], chains.length[idx, j], z[idx, j],
                    range_var, lam, "paper")
            except np.linalg.LinAlgError as exc:
                raise ukf.paper_rule_failure(exc, int(self.world.k.max())) from exc

    def predict(self, inputs) -> None:
        # into the same arrays: the updates work on them in place (and a recorded replay carries them)
        self.mean[...], self.cov[...] = predict_joint(self.motion_model, self.mean, self.cov, inputs)

    def position(self) -> np.ndarray:
        return self.mean[..., :2]

    def position_cov(self) -> np.ndarray:
        return position_blocks(self.cov, self.num_agents, self.d)
