"""Backend ``kalman``: fu2017's Kalman baselines at the leader, as one backend with a ``variant``.

Fu, Bi, Gao 2017 compare their estimators with Kalman filters run at the
leader (agent 0) on what it receives (``estimators.lossy_fusion``, the
reproduction's ``naive_kf``, ``leader_only_kf``, ``informed_kf``,
``ideal_kf``). The followers send their z_i(k) to the leader as packets; the
leader's buffer follows eq. (3) (fresh if on time, the previous slot's if it
arrives late, else what it held; ``coloc_env.backends.fusion.LeaderLinks``).

| variant       | what the leader's filter takes                                                  |
|---------------|---------------------------------------------------------------------------------|
| ``naive``     | every held y_i(k) as a fresh z_i(k) (the paper's "general Kalman filter")       |
| ``leader_only`` | its own z_0(k) only; the followers send nothing                               |
| ``informed``  | knows each packet's age: a Kalman filter on [x(k); x(k-1)] takes an on-time     |
|               | packet as a measurement of x(k), a late one of x(k-1), skips lost slots and     |
|               | duplicates (``estimators.lossy_fusion.informed_update``): the MMSE estimator |
|               | given y and the ages                                                            |
| ``ideal``     | an oracle: every z_i(k) as if the network were ideal (packets are sent and       |
|               | counted, their delivery ignored); the bound no real network reaches               |

With every link ideal, naive = informed = ideal. Over a lossy network, over
seeded Monte Carlo runs, ideal <= informed <= naive in squared error (the
informed filter is optimal for its information, which includes naive's;
fu2017's Sec. 4 and this package's tests). The time update is the world's
linear model (x -> A x, P -> A P A^T + Q, the known input b by the change of
variables of ``coloc_env.backends.fusion``); the measurement update is
``estimators.lossy_fusion.kalman_update`` (Joseph form).

The covariance of ``naive``, ``leader_only`` and ``ideal`` does not depend on the data (the same H
and R every slot, whatever arrived): it is the Riccati recursion from the prior, a function of k
alone. Those variants compute P(k|k-1), the gain and P(k|k) once per k and share them among the
copies at that k (the values per copy are those of the per-copy computation); ``informed``'s
covariance depends on which packets arrived and stays per copy.

| quantity        | value                                                                  |
|-----------------|------------------------------------------------------------------------|
| estimand        | target (the leader's estimate, reported by every agent: shared)        |
| motion kinds    | ``linear_gaussian``                                                    |
| needs           | ``linear_observation``                                                 |
| messages        | ``packets``: each follower's z_i(k) to agent 0 (p floats)              |
| payload         | p floats (3 in target_cv, m in drift)                                  |
| lost message    | naive: the held y_i used again as fresh; informed: skipped             |
| late message    | naive: used as fresh; informed: a measurement of x(k-1) (new ones only)|
|                 | delays of 2 or more are discarded                                      |
| under-determined| never: the leader's own z_0 every slot                                 |
| decisions       | none                                                                   |

Arguments (``coloc_env.backends.Kalman``)

| field    | default  | allowed                                             |
|----------|----------|-----------------------------------------------------|
| variant  | "naive"  | "naive", "leader_only", "informed", "ideal"        |
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

import estimators.lossy_fusion as lf
from coloc_env.backends.base import Backend
from coloc_env.backends.fusion import LINEAR, NEEDS_LINEAR, LeaderLinks, ShiftedInput, TargetBackend, lossy_model
from coloc_env.parts import BACKENDS, PartConfig, check_choice
from estimators.kalman import symmetrize

VARIANTS = ("naive", "leader_only", "informed", "ideal")


@BACKENDS.register
@dataclass(frozen=True)
class Kalman(PartConfig):
    name = "kalman"
    estimand = "target"
    motion_kinds = LINEAR
    requires = NEEDS_LINEAR
    message_kind = "packets"
    message_content = "readings"
    shared_estimate = True
    variant: str = "naive"

    def check(self, prefix: str) -> None:
        check_choice(f"{prefix}variant", self.variant, VARIANTS)

    def build(self, world, network, batch: int) -> Backend:
        return KalmanBackend(self, world, network, batch)


class KalmanBackend(TargetBackend):
    def __init__(self, config, world, network, batch):
        super().__init__(config, world, network, batch)
        self.variant = config.variant
        self.model = lossy_model(world, network) if self.variant == "informed" else None
        motion, sensor = world.motion_model, world.measurement_model
        self.A, self.Q = motion.transition, motion.process_noise
        self.C = sensor.matrix
        self.R = sensor.noise_of(self.num_agents)
        self.links = LeaderLinks(network, self.batch, self.num_agents)
        self.shift = ShiftedInput(world)
        self._x0, self._P0 = world.prior()
        B, N, n = self.batch, self.num_agents, self.n
        p = self.C.shape[0]
        self.buffer_init = self.C @ self._x0
        self.held = np.broadcast_to(self.buffer_init, (B, N, p)).copy()
        self.previous = self.held.copy()
        uavs = [0] if self.variant == "leader_only" else list(range(N))
        self.H_stack = np.vstack([self.C] * len(uavs))
        self.R_stack = scipy.linalg.block_diag(*self.R[uavs])
        if self.variant == "informed":
            self.mats = lf.informed_matrices(self.model)
            self.mean, self.full_cov, self.used_before = lf.informed_initial(self.model, self._x0, self._P0, (B,))
        else:
            self.mean = np.broadcast_to(self._x0, (B, n)).copy()
            self.full_cov = np.broadcast_to(self._P0, (B, n, n)).copy()
        self.estimate[:] = self._x0
        self.cov[:] = self._P0
        # data-independent variants: P(k|k-1) and P(k|k) per k (1, n, n), shared by the copies at k
        self._priors = [np.asarray(self._P0, float)[None]]
        self._posteriors: list = []

    def reset(self, rngs, idx) -> None:
        n = self.n
        if self.variant == "informed":
            mean, cov, used = lf.informed_initial(self.model, self._x0, self._P0, (len(idx),))
            self.mean[idx], self.full_cov[idx], self.used_before[idx] = mean, cov, used
        else:
            self.mean[idx] = self._x0
            self.full_cov[idx] = self._P0
        self.held[idx] = self.buffer_init
        self.previous[idx] = self.buffer_init
        self.links.reset(idx)
        self.estimate[idx] = self.mean[idx, None, :n]  # c(0) = 0: xt(0) = x(0); one estimate for every agent
        self.cov[idx] = self.full_cov[idx, None, :n, :n]
        self._record(idx)

    def update(self, readings, decisions) -> None:
        z = self.shift.measurements(readings.extra["linear"])
        B = self.batch
        n = self.n
        if self.variant == "leader_only":
            self.links.outcomes(0.0, transmit=False)
            self._shared_update(z[:, 0])
        elif self.variant == "ideal":
            self.links.outcomes(float(self.C.shape[0]))  # sent and counted; the oracle ignores the delivery
            self._shared_update(z.reshape(B, -1))
        else:
            outcome = self.links.outcomes(float(self.C.shape[0]))
            self.held = lf.deliver(z, self.previous, self.held, outcome)
            self.previous = z
            if self.variant == "naive":
                self._shared_update(self.held.reshape(B, -1))
            else:
                self.mean, self.full_cov, self.used_before = lf.informed_update(
                    self.model, self.mean, self.full_cov, self.used_before, self.held, outcome, self.mats)
        offset = self.shift.now()
        self.estimate[:] = (self.mean[:, :n] + offset)[:, None, :]
        self.cov[:] = self.full_cov[:, None, :n, :n]

    def step(self, readings, decisions) -> None:
        super().step(readings, decisions)  # update, record the posterior of k; then the time update to k + 1
        if self.variant == "informed":
            F, Qa = self.mats[0], self.mats[1]
            self.mean, self.full_cov = self.mean @ F.T, symmetrize(F @ self.full_cov @ F.T + Qa)
        else:
            self.mean = self.mean @ self.A.T
            for k, rows in self.copies_by_step():
                if len(self._priors) == k + 1:
                    self._priors.append(symmetrize(self.A @ self._posteriors[k] @ self.A.T + self.Q))
                self.full_cov[rows] = self._priors[k + 1]

    def _shared_update(self, z: np.ndarray) -> None:
        """``estimators.lossy_fusion.kalman_update`` of every copy with z (B, p), the covariance of the
        copies at the same k computed once (a (1, n, n) stack, the batched path's values per copy)."""
        for k, rows in self.copies_by_step():
            mean, post = lf.kalman_update(self.mean[rows], self._priors[k], z[rows], self.H_stack, self.R_stack)
            if len(self._posteriors) == k:
                self._posteriors.append(post)
            self.mean[rows] = mean
            self.full_cov[rows] = post


__all__ = ["Kalman", "VARIANTS"]
