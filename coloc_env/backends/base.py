"""The backend of a composition: one adapter per estimator of ``estimators``.

A backend's config class declares what it needs, so that ``coloc_env.compatibility``
can say in words why a combination cannot run:

| attribute          | meaning                                                                   |
|--------------------|---------------------------------------------------------------------------|
| estimand           | ``"self"`` (each agent's own position) or ``"target"`` (a shared state)   |
| motion_kinds       | the ``estimators.models`` kinds it can run on                          |
| requires           | groups of measurement kinds; the world must offer one kind of each group  |
| message_kind       | what it sends over the network (``coloc_env.networks.base``)            |
| message_content    | what a message carries: ``"readings"`` (the sender's reading of the step it |
|                    | is stamped with), ``"estimates"`` (a summary of everything the sender held), |
|                    | ``"nothing"`` (it sends none); ``coloc_env.bounds`` reads it               |
| shared_estimate    | True where every agent reports the centre's (agent 0's) estimate          |

At each step the composition hands it the world's ``coloc_env.worlds.base.Readings``
of time k and the decoded backend decisions; the backend updates (asking the
network for every delivery), keeps the posterior of time k (what the infos
report), then predicts to k + 1 with the readings' inputs.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from coloc_env.parts import Block


class Backend:
    """Runtime of one backend for B copies; its config class carries the declarations above."""

    # Whether it reads ``Readings.fix`` / ``fix_valid`` (the world may skip computing fixes nobody reads).
    reads_fixes: ClassVar[bool] = True
    # Whether its decisions choose among what has arrived, so that the agents should see the readings of
    # time k (and their delivery) before they decide: the core then calls ``receive`` ahead of the step
    # where the composition allows it (``coloc_env.scenarios.composed``, "Receive, then decide").
    receives_before_deciding: ClassVar[bool] = False

    def __init__(self, config, world, network, batch: int):
        self.config = config
        self.world = world
        self.network = network
        self.batch = int(batch)
        self.num_agents = world.num_agents
        B, N = self.batch, self.num_agents
        self.posterior_position = np.zeros((B, N, 2))
        self.posterior_position_cov: np.ndarray | None = None
        # an SE(2) backend's whole pose [x, y, heading] and its covariance at the same time (``pose``)
        self.posterior_pose: np.ndarray | None = None
        self.posterior_pose_cov: np.ndarray | None = None

    def decision_blocks(self) -> list[Block]:
        return []

    def reset(self, rngs, idx: np.ndarray) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def start(self, idx: np.ndarray) -> None:
        """After ``reset`` of the copies ``idx``: their posterior (what the infos report before the first step)
        is the initial belief the backend now holds, its covariance included (``position_cov``)."""
        cov = self.position_cov()
        if cov is not None:
            if self.posterior_position_cov is None:
                self.posterior_position_cov = np.array(cov, dtype=float)
            else:
                self.posterior_position_cov[idx] = cov[idx]
        pose = self.pose()
        if pose is not None:
            if self.posterior_pose is None:
                self.posterior_pose, self.posterior_pose_cov = np.array(pose[0], float), np.array(pose[1], float)
            else:
                self.posterior_pose[idx], self.posterior_pose_cov[idx] = pose[0][idx], pose[1][idx]

    def step(self, readings, decisions: np.ndarray) -> None:
        self.update(readings, decisions)
        self.posterior_position = self.position().copy()
        cov = self.position_cov()
        self.posterior_position_cov = None if cov is None else cov.copy()
        pose = self.pose()
        if pose is not None:
            self.posterior_pose, self.posterior_pose_cov = pose[0].copy(), pose[1].copy()
        self.predict(readings.inputs)

    def update(self, readings, decisions: np.ndarray) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def receive(self, readings, idx: np.ndarray) -> None:  # pragma: no cover - interface
        """The readings of time k of the copies ``idx``, delivered through the network before the agents
        decide (only for a backend with ``receives_before_deciding``); ``update`` then uses them."""
        raise NotImplementedError

    def predict(self, inputs: np.ndarray) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def position(self) -> np.ndarray:  # pragma: no cover - interface
        """Current position estimates (B, N, 2)."""
        raise NotImplementedError

    def position_cov(self) -> np.ndarray | None:
        """Current per-agent position covariance (B, N, 2, 2); None where the backend has none."""
        return None

    def pose(self) -> tuple[np.ndarray, np.ndarray] | None:
        """An SE(2) backend's current pose estimates (B, N, 3) [x, y, heading] and their covariances (B, N, 3, 3);
        None where the backend estimates positions only."""
        return None

    def observation_features(self) -> np.ndarray:
        return np.zeros((self.batch, self.num_agents, 0))

    def feature_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(0), np.zeros(0)

    def particles(self, b: int) -> np.ndarray | None:
        return None


def position_blocks(cov: np.ndarray, num_agents: int, d: int) -> np.ndarray:
    """The (B, N, 2, 2) position blocks of a joint covariance (B, N d, N d) with positions first in each block."""
    B = cov.shape[0]
    blocks = cov.reshape(B, num_agents, d, num_agents, d)
    idx = np.arange(num_agents)
    return blocks[:, idx, :2, idx, :2].transpose(1, 0, 2, 3)


def measurement_list(valid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Valid (B, N, N) -> per copy the j-th valid (m, n) pair in row-major order: (count (B,), m (B, J), n (B, J))."""
    B, N = valid.shape[:2]
    flat = valid.reshape(B, N * N)
    count = flat.sum(axis=1)
    J = int(count.max()) if B else 0
    order = np.argsort(~flat, axis=1, kind="stable")[:, :J]
    return count, order // N, order % N
