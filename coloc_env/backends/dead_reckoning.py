"""Backend ``dead_reckoning``: each agent integrates its own motion inputs; no measurement, no message.

The reference every cooperative estimator must beat. Each agent keeps its
own Gaussian, predicted through the world's motion model
(``estimators.models.predict_joint``, one agent at a time): the mean is the
noiseless model, the covariance grows by the model's process noise.

| quantity     | value                                                 |
|--------------|-------------------------------------------------------|
| estimand     | self                                                  |
| motion kinds | any model with function / jacobian / covar           |
| needs        | nothing                                               |
| messages     | none                                                  |
| decisions    | none                                                  |

No fields.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.backends.base import Backend
from coloc_env.parts import BACKENDS, PartConfig
from estimators.models import predict_joint


@BACKENDS.register
@dataclass(frozen=True)
class DeadReckoning(PartConfig):
    name = "dead_reckoning"
    estimand = "self"
    motion_kinds = frozenset({"odometry_displacement", "cv_accel", "se2_odometry", "cv_white_accel"})
    requires = ()
    message_kind = "none"
    message_content = "nothing"
    shared_estimate = False

    def check(self, prefix: str) -> None:
        return None

    def build(self, world, network, batch: int) -> Backend:
        return DeadReckoningBackend(self, world, network, batch)


class DeadReckoningBackend(Backend):
    reads_fixes = False  # the inputs only
    def reset(self, rngs, idx) -> None:
        mean, cov = self.world.initial_belief()
        if not hasattr(self, "mean"):
            self.mean, self.cov = np.zeros_like(mean), np.zeros_like(cov)
        self.mean[idx], self.cov[idx] = mean[idx], cov[idx]
        self.posterior_position[idx] = mean[idx, :, :2]

    def update(self, readings, decisions) -> None:
        return None

    def predict(self, inputs) -> None:
        B, N, d = self.mean.shape
        mean, cov = predict_joint(self.world.motion_model, self.mean[:, :, None, :], self.cov, inputs[:, :, None, :])
        self.mean, self.cov = mean[:, :, 0, :], cov

    def position(self) -> np.ndarray:
        return self.mean[..., :2]

    def position_cov(self) -> np.ndarray:
        return self.cov[..., :2, :2]

