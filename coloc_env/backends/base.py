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

Its runtime (``Backend``) may override what the composed observation reads of it: ``position_cov``
(the agent's own position covariance; None: it keeps none), ``position_process_noise`` and
``message_value`` (the value of transmitting now, the ``value:tau`` policies' feature; the method's
docstring gives the equation and its approximation).

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

    def local_covariance(self) -> np.ndarray | None:
        """The position covariance (B, N, 2, 2) each agent holds itself: ``local_position_cov`` where the backend
        has one (its exact covariance is not local: bandwidth_fusion's bound M_i), else ``position_cov``; None
        where it keeps none. What the composed observation's log tr P and ``message_value`` read."""
        local = getattr(self, "local_position_cov", None)
        return local() if local is not None else self.position_cov()

    def position_process_noise(self, inputs: np.ndarray | None = None) -> np.ndarray | None:
        """Q_pos, the per-step process noise of the estimated position (m^2): (B, N, 2, 2), or (2, 2) for every
        agent; None where the backend declares no value of a message (then ``message_value`` is None).

        By default the position block of the world's motion model's noise covariance (``covar``, the model the
        backend runs on through the model interface): for a ``target`` estimand the two components
        ``world.position_index`` names; for ``self`` each agent's at its current estimate (the position, and the
        heading of an SE(2) backend's pose) under ``inputs`` (B, N, u), the readings' motion inputs of the step
        just done (None: zero inputs). None where the world has no motion model. A backend that runs on another
        model than the world's overrides it."""
        model = getattr(self.world, "motion_model", None)
        if model is None or not hasattr(model, "covar"):
            return None
        index = getattr(self.world, "position_index", None)
        if getattr(self.config, "estimand", "self") == "target" and index is not None:
            # the target's noise does not depend on the state: gathered once per model (read every step)
            cached = getattr(self, "_target_position_noise", None)
            if cached is None or cached[0] is not model:
                index = list(index)
                noise = np.asarray(model.covar(), float)[index][:, index]
                noise.flags.writeable = False
                cached = (model, noise)
                self._target_position_noise = cached
            return cached[1]
        B, N = self.batch, self.num_agents
        state = np.zeros((B, N, int(model.state_dim)))
        state[..., :2] = self.posterior_position
        if self.posterior_pose is not None and state.shape[-1] == 3:
            state = np.array(self.posterior_pose, float)
        u = np.zeros((B, N, int(getattr(model, "input_dim", 0)))) if inputs is None else np.asarray(inputs, float)
        return np.asarray(model.covar(state, u), float)[..., :2, :2]

    def message_value(self, reference_cov: np.ndarray, steps: np.ndarray, inputs: np.ndarray | None = None,
                      cov: np.ndarray | None = None) -> np.ndarray | None:
        """The value (m^2) of each agent transmitting now (B, N), from what the agent holds itself; None where the
        backend declares none (it keeps no covariance, or ``position_process_noise`` is None).

        The approximation: the receivers' knowledge of the sender's position is the sender's covariance at its
        reference transmission (its last one delivered, or its last one sent where the network gives no
        acknowledgements; the episode's start before any), ``reference_cov`` P_ref (B, N, 2, 2), propagated open
        loop by the per-step position process noise Q_pos (``position_process_noise``) over the ``steps`` (B, N)
        since then; transmitting now would bring it to the sender's own P_i,k. The value is the expected
        reduction of its trace:

            v_i,k = max(0, tr(P_ref + (k - k_ref) Q_pos) - tr(P_i,k)).

        It ignores what the receivers learned otherwise (their own readings of the sender, other senders) and, for
        a model with a velocity, the growth of the position uncertainty through the velocity's (so it is a lower
        estimate there). ``inputs``: as ``position_process_noise`` reads them; ``cov``: P_i,k where the caller holds
        it (``local_covariance``). A backend with a better model of its receivers overrides this method."""
        cov = self.local_covariance() if cov is None else cov
        Q = self.position_process_noise(inputs)
        if cov is None or Q is None:
            return None
        # the ndarray.trace method: np.trace's dispatch costs more than the trace at these sizes
        grown = (np.asarray(reference_cov).trace(axis1=-2, axis2=-1)
                 + np.asarray(steps, float) * Q.trace(axis1=-2, axis2=-1))
        return np.maximum(grown - np.asarray(cov).trace(axis1=-2, axis2=-1), 0.0)

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
