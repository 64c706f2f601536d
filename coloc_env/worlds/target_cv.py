"""World ``target_cv`` (fu2017): a constant-velocity target in 3-D, its position measured by every agent.

Fu, Bi, Gao 2017 (seed ``000_de65bd0f0f4a0cb7.txt``), Sec. 4: the target
state is x = [x, vx, y, vy, z, vz] with x(k+1) = Phi x(k) + Gamma w(k),
Phi = blockdiag([[1, T], [0, 1]] x 3), w ~ N(0, q I_3) (eq. 1;
``coloc_env.worlds.blocks.target.ConstantVelocityTarget``), and every UAV i
measures z_i(k) = H x(k) + v_i(k), H the position rows, v_i ~ N(0, r I_3)
(eq. 2). Every agent estimates the target (estimand ``target``).

The episode is drawn at reset from each copy's generator, in this order:
x(0) ~ N(X0, P0), the accelerations w(0..K-2), the K x L measurement noises
v_i(0..K-1), then w(K-1), so that x(K), the state after the last step (which
the last observation and the renderer read), exists. The link outcomes are
the network's, drawn from a generator of its own.

The paper does not place the UAVs; they hold a fixed ring of radius
``formation_radius`` (the link state of distance-dependent networks reads it).

| quantity          | value                                                                            |
|-------------------|----------------------------------------------------------------------------------|
| estimand          | ``target``: the target state x (6)                                               |
| motion model      | ``estimators.linear_models.LinearGaussian`` (Phi, 0, q G G^T), ``linear_gaussian`` |
| measurements      | ``linear_observation``: z_i = H x + v_i at every step, every agent               |
| anchors           | none: every agent measures the target's absolute position                         |
| sensing action    | none                                                                             |
| observation       | none                                                                             |
| "position"        | the target's horizontal position (x, y) = state components 0 and 2, metres       |
| ``error``         | ||H (xhat - x)||^2, the squared 3-D position error (m^2): fu2017's MSE (Figs. 2-5) |
| prior             | every agent starts from X0 with covariance P0                                    |

Arguments (``coloc_env.worlds.TargetCv``; defaults = the paper's Sec. 4)

| field              | default                          | allowed                                  |
|--------------------|----------------------------------|------------------------------------------|
| num_agents         | 2                                | 2..16 (L; agent 0 is the leader)         |
| period             | 1.0                              | (0, 1e4] s (T); with accel_noise, the    |
|                    |                                  | singular Q = q G G^T must pass the       |
|                    |                                  | model's PSD check (a large q T^4 fails)  |
| accel_noise        | 5.0                              | [0, 1e12] m^2/s^4 per axis (q)           |
| measurement_noise  | 10.0                             | [1e-6, 1e12] m^2 per axis (r)            |
| initial_state      | (100, 10, 100, 10, 100, 0)       | (6,) in [-1e6, 1e6]: X0; x(0) ~ N(X0, P0)|
| initial_cov        | diag(100, 5, 100, 5, 100, 5)     | (6, 6) positive definite, entries        |
|                    |                                  | <= 1e12: P0 (the fusion weights divide   |
|                    |                                  | by covariance traces)                    |
| horizon            | 100                              | 1..100000 steps (the composition's default) |
| formation_radius   | 10.0                             | [0, 1e6] m: the agents' fixed ring       |

Estimation problem (what ``coloc_env.pcrb`` bounds; details in ``coloc_env.bounds.models.target``): the
state is the target's [x, vx, y, vy, z, vz]; the prior is the world's initial covariance; the motion is
constant velocity with white acceleration (a rank-3 process noise); every agent reads the target's
position with Gaussian noise at every step. Linear and Gaussian, so the bound is the covariance of the
Kalman filter with the same information (the ``kalman`` backend's ``ideal`` and ``informed`` variants).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import as_array, check_psd, check_range
from coloc_env.parts import WORLDS, PartConfig
from coloc_env.worlds.blocks.sensors import LinearSensor
from coloc_env.worlds.blocks.target import ConstantVelocityTarget
from coloc_env.worlds.drift import TargetWorld
from estimators.linear_models import LinearGaussian, LinearObservation


def _diag(*values):
    return tuple(tuple(v if i == j else 0.0 for j in range(len(values))) for i, v in enumerate(values))


@WORLDS.register
@dataclass(frozen=True)
class TargetCv(PartConfig):
    """Config of the ``target_cv`` world (see the module table)."""

    name = "target_cv"
    bound_model = "target"  # coloc_env.bounds.models.target
    estimand = "target"
    motion_kind = LinearGaussian.kind
    measurements = frozenset({"linear_observation"})
    anchors = "none: every agent measures the target's absolute position"
    num_agents: int = 2
    period: float = 1.0
    accel_noise: float = 5.0
    measurement_noise: float = 10.0
    initial_state: tuple = (100.0, 10.0, 100.0, 10.0, 100.0, 0.0)
    initial_cov: tuple = _diag(100.0, 5.0, 100.0, 5.0, 100.0, 5.0)
    horizon: int = 100
    formation_radius: float = 10.0

    def check(self, prefix: str) -> None:
        check_range(f"{prefix}num_agents", self.num_agents, 2, 16, integer=True)
        self.target.validate(prefix)
        target = self.target
        try:  # the model the world builds: its covariance check is absolute, so a large q T^4 fails it
            LinearGaussian(target.transition, np.zeros(6), target.process_noise)
        except ValueError as exc:
            raise ValueError(f"{prefix}period={self.period!r} with {prefix}accel_noise={self.accel_noise!r} gives a "
                             f"process noise q G G^T (rank 3) that rounding makes indefinite ({exc}); choose a smaller "
                             f"period or accel_noise") from exc
        check_range(f"{prefix}measurement_noise", self.measurement_noise, 1e-6, 1e12)
        as_array(f"{prefix}initial_state", self.initial_state, shape=(6,), bound=1e6)
        check_psd(f"{prefix}initial_cov", self.initial_cov, 6, strict=True, bound=1e12)
        check_range(f"{prefix}horizon", self.horizon, 1, 100_000, integer=True)
        check_range(f"{prefix}formation_radius", self.formation_radius, 0.0, 1e6)

    @property
    def target(self) -> ConstantVelocityTarget:
        return ConstantVelocityTarget(3, self.period, self.accel_noise)

    @property
    def sensor(self) -> LinearSensor:
        return LinearSensor(self.target.position_matrix, float(self.measurement_noise) * np.eye(3))

    def build(self, batch: int, horizon: int) -> TargetCvWorld:
        return TargetCvWorld(self, batch, horizon)


class TargetCvWorld(TargetWorld):
    position_index = (0, 2)

    def __init__(self, config: TargetCv, batch: int, horizon: int):
        target = config.target
        super().__init__(config, batch, horizon, 6, 3, target.position_matrix)
        self.target = target
        self.sensor = config.sensor
        self.motion_model = LinearGaussian(target.transition, np.zeros(6), target.process_noise)
        self.measurement_model = LinearObservation(target.position_matrix, self.sensor.noise)

    def prior(self):
        return np.asarray(self.config.initial_state, float), np.asarray(self.config.initial_cov, float)

    def draw_episode(self, rngs, idx) -> None:
        K, L = self.horizon, self.num_agents
        x0_mean, P0 = self.prior()
        C = len(rngs)
        x0, accelerations, noise = np.empty((C, 6)), np.empty((C, K, 3)), np.empty((C, K, L, 3))
        for c, rng in enumerate(rngs):
            # the module's order: x(0), w(0..K-2), the measurement noise, then w(K-1) (for x(K) only)
            x0[c] = rng.multivariate_normal(x0_mean, P0)
            accelerations[c, :K - 1] = self.target.sample_noise(rng, (K - 1,))
            noise[c] = self.sensor.sample_noise(rng, (K, L))
            accelerations[c, K - 1:] = self.target.sample_noise(rng, (1,))
        # every copy's trajectory and measurements at once, not a loop over the horizon per copy: the same
        # numbers, the motion being written per axis (ConstantVelocityTarget.step)
        truth = self.target.trajectory(x0, accelerations)
        idx = np.asarray(idx)
        self.truth[idx] = truth
        self.observations[idx] = self.sensor.measure(truth[:, :K, None, :], noise)


__all__ = ["TargetCv", "TargetCvWorld"]
