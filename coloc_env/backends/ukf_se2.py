"""Backend ``ukf_se2``: UKF-DCL of wang2019 on planar robots with heading, range and bearing, and landmarks.

Adapter over ``estimators.ukf_relay_se2`` (its docstring has the
equations: the SE(2) unicycle time update, the 2-vector range+bearing
observation through the UT on the joint state L = 3N, the Roumeliotis-Bekey
factored cross-covariances P_ij = Phi_i sigma_ij Phi_j^T, the look-up
Cholesky along the relay chain, the exact update of robots a truncated chain
does not reach, the chi-square outlier gate). Each copy keeps its robots'
estimates (B, N, 3) and the factors P_ii, Phi_i, sigma_ij (B, ...). The updates are stacked over the
copies: per observation slot, the copies whose observation of that slot is of one kind (landmark or robot)
and whose delivered chain has one length are updated together
(``estimators.ukf_relay_se2.dcl_update_rows``), and every copy predicts at once
(``estimators.ukf_relay_se2.time_update_batch``); copy b equals the same copy run alone.

Step k, in the world's file order (``Readings.extra["obs_*"]``, see
``coloc_env.worlds.mrclam``):

* a landmark sighting by robot m: with ``landmark_updates="local"``, ``dcl_update`` on
  the chain [m] alone (the exact truncated-chain update: m and, through the cross
  terms, everyone's sigma rows change; no communication); with ``"relay"``, on the
  chain m -> ... the network delivers (``coloc_env.networks.base.Network.relay``
  with no measured robot, one slot per observation), so a chain that reaches everyone
  gives exactly UKF-CCL's update: its unscented transform runs on the whole joint
  state (L = 3N), where [m] alone runs it on m's three components (lambda = 0 spreads
  the sigma points by sqrt(L)): for the nonlinear range+bearing a different update once
  the robots' estimates are correlated (0.04 m apart within the first 60 s of dataset 6);
* a robot m's range+bearing of robot n: a relay chain m -> n -> ... on the
  network (message kind ``chain``, ``coloc_env.networks.base.Network.relay``,
  one slot per observation); if n is reached, ``dcl_update`` along the chain
  actually delivered (a chain that reaches everyone gives exactly UKF-CCL);
  a chain that does not reach n applies nothing;
* (the world's ``position_fix`` pseudo-fixes are not used: they are made from the
  same landmark sightings, and using both would count them twice);
* then every robot predicts with its odometry input (``time_update_factored``,
  Q = G diag(var_v, var_omega) G^T per robot and step: the world's input).

The preset ``mrclam_relay`` is this backend on the ``mrclam`` world over a relay
network with ``routing="per_source"`` (a routing table per source robot). Over an ideal
network, or a loss-free relay whose chains are complete, every update is UKF-CCL's;
the preset and the plain composition give the same estimates to 1e-9 under any
routing, hop budget, range limit and loss when handed the same network key
(tests/coloc_env/test_mrclam_composition.py, tests/coloc_env/test_mrclam_preset_parts.py).

| quantity         | value                                                                                |
|------------------|--------------------------------------------------------------------------------------|
| estimand         | self (x, y and heading of each robot; the position is reported)                      |
| motion kinds     | ``se2_odometry``                                                                     |
| needs            | ``landmark_range_bearing`` (robot-robot range+bearing are used where the world has them) |
| messages         | ``chain``; hop h (r = h + 1 robots reached) carries nu and Pz (2 + 3), the 3q x 2    |
|                  | update weights g (q = 2 robots observed, q = 1 for a relayed landmark sighting),     |
|                  | the reached robots' rows of A (3r(3r + 1)/2), their Pxz and Phi (6 + 9 each) and     |
|                  | the unreached robots' r_U (6 each): 5 + 6q + 3r(3r + 1)/2 + 15 r + 6 (N - r) floats  |
| lost message     | the chain stops there; the reached robots update with the exact truncated-chain     |
|                  | rule (the unreached keep their estimates); a chain that misses n applies nothing     |
| under-determined | nothing to solve: a step without observations is a time update only                 |
| outliers         | normalized innovation nu^T Pz^-1 nu > ``gate``: the observation is not applied       |
| decisions        | none (the relay next hop is the network's)                                           |
| records          | per observer m of the last step: ``partner`` (the robot its robot observation        |
|                  | measured, -1), ``used`` (that observation reached it and passed the gate),           |
|                  | ``landmarks_applied``, ``applied``, ``rejected``, and ``chains`` (rows b N + m: its   |
|                  | robot observation's chain; relayed landmark chains are not recorded); with several   |
|                  | robot observations per observer (sensing "every robot"), the last one's              |

Arguments (``coloc_env.backends.UkfSe2``)

| field            | default  | allowed                                                                  |
|------------------|----------|--------------------------------------------------------------------------|
| ukf_lambda       | 0.0      | (-15, 1e6] and > -3N at build (the UT's lambda; 0 = filterpy's)          |
| gate             | 13.8155  | (0, 1e12] (chi-square(2) 99.9 %, ``coloc reproduce mrclam``); None = apply all |
| landmark_updates | "local"  | "local": a landmark sighting updates on [m] alone (the ``mrclam_relay``  |
|                  |          | scenario's rule, no messages); "relay": along the network's chain from m |
|                  |          | (``coloc reproduce mrclam``'s DCL; a complete chain is UKF-CCL)          |
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import estimators.ukf_relay_se2 as se2
from coloc_env.backends.base import Backend
from coloc_env.data.mrclam_noise import GATE_999
from coloc_env.networks.blocks.relay_chain import RelayChain
from coloc_env.parts import BACKENDS, PartConfig, check_choice, check_range


def hop_floats(hop: int, num_agents: int, observed: int = 2) -> float:
    """Floats of relay hop ``hop`` (0-based) of an SE(2) DCL chain over ``num_agents`` robots (module table);
    ``observed`` q: 2 for a robot-robot observation, 1 for a landmark sighting."""
    r = hop + 1
    return 5 + 6 * observed + 3 * r * (3 * r + 1) / 2 + 15 * r + 6 * (num_agents - r)


@BACKENDS.register
@dataclass(frozen=True)
class UkfSe2(PartConfig):
    """Config of the ``ukf_se2`` backend (see the module tables)."""

    name = "ukf_se2"
    estimand = "self"
    motion_kinds = frozenset({"se2_odometry"})
    requires = (frozenset({"landmark_range_bearing"}),)
    message_kind = "chain"
    message_content = "estimates"
    shared_estimate = False
    ukf_lambda: float = 0.0
    gate: float | None = GATE_999
    landmark_updates: str = "local"

    def check(self, prefix: str) -> None:
        check_range(f"{prefix}ukf_lambda", self.ukf_lambda, -15.0, 1e6, low_open=True)
        if self.gate is not None:
            check_range(f"{prefix}gate", self.gate, 0.0, 1e12, low_open=True)
        check_choice(f"{prefix}landmark_updates", self.landmark_updates, ("local", "relay"))

    def check_spread(self, num_agents: int, prefix: str, agents: str) -> None:
        """The UT's lambda against the team: > -3N (N the robots, named ``agents`` in the message)."""
        check_range(f"{prefix}ukf_lambda", self.ukf_lambda, -3.0 * num_agents, 1e6, low_open=True,
                    low_label=f"-3 {agents}")

    def build(self, world, network, batch: int) -> Backend:
        return UkfSe2Backend(self, world, network, batch)


class UkfSe2Backend(Backend):
    reads_fixes = False  # the landmark sightings themselves, not the world's pseudo-fixes made from them

    def __init__(self, config: UkfSe2, world, network, batch: int):
        super().__init__(config, world, network, batch)
        B, N = self.batch, self.num_agents
        config.check_spread(N, "backend.", "world.num_agents")
        self.estimate = np.zeros((B, N, 3))
        self.P_ii = np.zeros((B, N, 3, 3))
        self.phi = np.zeros((B, N, 3, 3))
        self.sigma = np.zeros((B, N, N, 3, 3))
        self.applied = np.zeros((B, N))  # observations applied to each observer at the last step
        self.rejected = np.zeros((B, N))  # refused by the gate
        self.landmarks_applied = np.zeros((B, N))  # the landmark sightings among them
        self.partner = np.full((B, N), -1)  # the robot each observer's (last) robot observation measured, -1 none
        self.used = np.zeros((B, N), dtype=bool)  # that observation reached the measured robot and passed the gate
        self.chains = self._no_chains()  # rows b * N + m: the chain of observer m's (last) robot observation

    def reset(self, rngs, idx) -> None:
        mean, cov = self.world.initial_belief()
        N = self.num_agents
        for b in idx:
            joint = np.zeros((3 * N, 3 * N))
            for i in range(N):
                joint[3 * i:3 * i + 3, 3 * i:3 * i + 3] = cov[b, i]
            f = se2.factor(joint)
            self.estimate[b], self.P_ii[b], self.phi[b], self.sigma[b] = mean[b], f.P_ii, f.phi, f.sigma
        self.posterior_position[idx] = mean[idx, :, :2]
        self._clear_records(idx)

    def _no_chains(self) -> RelayChain:
        B, N = self.batch, self.num_agents
        return RelayChain(chain=np.full((B * N, N), -1), length=np.zeros(B * N, dtype=int),
                          hop_distance=np.full((B * N, max(N - 1, 1)), np.nan), stop=np.full(B * N, -1))

    def _clear_records(self, idx) -> None:
        N = self.num_agents
        self.applied[idx] = 0.0
        self.rejected[idx] = 0.0
        self.landmarks_applied[idx] = 0.0
        self.partner[idx] = -1
        self.used[idx] = False
        rows = (np.asarray(idx)[:, None] * N + np.arange(N)).ravel()
        self.chains.chain[rows] = -1
        self.chains.length[rows] = 0
        self.chains.hop_distance[rows] = np.nan
        self.chains.stop[rows] = -1

    def _factors(self, b: int) -> se2.FactoredCov:
        return se2.FactoredCov(self.P_ii[b], self.phi[b], self.sigma[b])

    def update(self, readings, decisions) -> None:
        N = self.num_agents
        extra = readings.extra
        observer, subject = extra["obs_observer"], extra["obs_subject"]
        self._clear_records(np.arange(self.batch))
        floats = lambda hop: hop_floats(hop, N)  # noqa: E731
        landmark_floats = lambda hop: hop_floats(hop, N, observed=1)  # noqa: E731
        relay_landmarks = self.config.landmark_updates == "relay"
        for j in range(observer.shape[1]):
            robot = (observer[:, j] >= 0) & (subject[:, j] >= 0)
            chain = landmark_chain = None
            if relay_landmarks and (sighting := (observer[:, j] >= 0) & ~robot).any():
                landmark_chain = self.network.relay(np.where(sighting, observer[:, j], -1), -1, landmark_floats,
                                                    slot=j)
            if robot.any():
                chain = self.network.relay(np.where(robot, observer[:, j], -1), np.where(robot, subject[:, j], -1),
                                           floats, slot=j)
                copies = np.flatnonzero(robot)
                rows = copies * N + observer[copies, j]
                for name in ("chain", "length", "hop_distance", "stop"):
                    getattr(self.chains, name)[rows] = getattr(chain, name)[copies]
                self.partner[copies, observer[copies, j]] = subject[copies, j]
            sighting = np.flatnonzero((observer[:, j] >= 0) & ~robot)
            if len(sighting):
                if landmark_chain is None:
                    paths, lengths = observer[sighting, j][:, None], np.ones(len(sighting), dtype=int)
                else:
                    paths, lengths = landmark_chain.chain[sighting], landmark_chain.length[sighting]
                ok = self._dcl(sighting, j, paths, lengths, extra, landmark=True)
                self.landmarks_applied[sighting, observer[sighting, j]] += ok
                self._count(sighting, observer[sighting, j], ok)
            if robot.any():
                copies = np.flatnonzero(robot & (chain.length >= 2))  # a chain that misses n applies nothing
                ok = self._dcl(copies, j, chain.chain[copies], chain.length[copies], extra, landmark=False)
                self.used[copies, observer[copies, j]] = ok
                self._count(copies, observer[copies, j], ok)

    def _dcl(self, copies, j, paths, lengths, extra, landmark: bool) -> np.ndarray:
        """UKF-DCL of observation slot j in the given copies, along their chains ``paths`` (n, N) of ``lengths``
        (n,): one stacked update per chain length (``estimators.ukf_relay_se2.dcl_update_rows``).
        Returns applied (n,) bool."""
        ok = np.zeros(len(copies), dtype=bool)
        if not len(copies):
            return ok
        shortest, longest = int(lengths.min()), int(lengths.max())
        for k in range(shortest, longest + 1):
            sel = np.flatnonzero(lengths == k) if shortest < longest else slice(None)
            b = copies[sel]
            if not len(b):
                continue
            ok[sel] = se2.dcl_update_rows(
                self.estimate, self.P_ii, self.phi, self.sigma, b, paths[sel, :k], extra["obs_z"][b, j],
                extra["obs_cov"][b, j], measured_in_chain=not landmark,
                landmark=extra["obs_target"][b, j] if landmark else None, lam=self.config.ukf_lambda,
                gate=self.config.gate)
        return ok

    def _count(self, copies, observers, ok) -> None:
        self.applied[copies, observers] += ok
        self.rejected[copies, observers] += ~ok

    def predict(self, inputs) -> None:
        self.estimate[:], self.P_ii[:], self.phi[:] = se2.time_update_batch(
            self.estimate, self.P_ii, self.phi, inputs[..., :2], self.world.motion_model.dt, inputs[..., 2:4])

    def position(self) -> np.ndarray:
        return self.estimate[..., :2]

    def position_cov(self) -> np.ndarray:
        return self.P_ii[..., :2, :2]

    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        return self.estimate, self.P_ii

    def joint_cov(self, b: int) -> np.ndarray:
        """The joint covariance (3N, 3N) of copy b that the factors stand for."""
        return self._factors(b).joint()
