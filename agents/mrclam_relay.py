"""Policies for ``mrclam_relay`` (UTIAS MRCLAM replay).

* ``paper``: every robot that recorded other robots this step uses one of those
  measurements, the lowest-index robot it recorded (the observation lists whom
  it recorded, not in which order); each chain is the complete one of
  ``coloc reproduce mrclam`` and of ``relay_ukf``'s paper setting: m -> n ->
  the other robots in ascending order, so every robot is reached and (without
  losses or a hop budget) UKF-DCL equals UKF-CCL.
* ``no_relay``: the same measurement choice; every chain stops at the measured
  robot (only m and n update, with the consistent cross-covariance update).

Both are deterministic and read only the observations (the "recorded" flags).

A trained model may leave the measurement to the paper (``PAPER_ENTRIES["measurement"]``, the settings module's
``PAPER_ENTRIES = "measurement"``): the model decides every relay entry, and each robot uses the measurement
``paper`` uses, so a model and the fixed schedules (which all choose so) apply the same measurements and differ only
in how far each travels.
"""

from __future__ import annotations

import numpy as np

from agents import event_triggered
from agents.base import Policy, own_choice_only


def recorded_flags(observations: np.ndarray) -> np.ndarray:
    """(..., N, N) bool: whom each robot recorded at this step, from its observation's entries [N, 2N)
    (``observations`` (..., N, obs_dim), one row per robot)."""
    observations = np.asarray(observations, float)
    N = observations.shape[-2]
    return observations[..., N:2 * N] > 0.5


def paper_partners(recorded: np.ndarray) -> np.ndarray:
    """(B, N) the lowest-index robot each robot recorded, itself where none. ``recorded`` (B, N, N) bool."""
    recorded = np.asarray(recorded, bool)
    B, N = recorded.shape[:2]
    own = np.broadcast_to(np.arange(N), (B, N))
    return np.where(recorded.any(axis=-1), np.argmax(recorded, axis=-1), own)


def complete_chain_routing(partner: np.ndarray) -> np.ndarray:
    """Routing tables (B, N holders, N sources) of the chains m -> partner[m] -> others ascending (N = stop).

    Sources without a partner (partner[m] == m) and the last robot of each chain stop.
    """
    partner = np.asarray(partner, int)
    B, N = partner.shape
    routing = np.full((B, N, N), N)
    for b in range(B):
        for m in range(N):
            n = int(partner[b, m])
            if n == m:
                continue
            order = [n] + [i for i in range(N) if i not in (m, n)]
            for holder, target in zip(order[:-1], order[1:], strict=True):
                routing[b, holder, m] = target
    return routing


def paper_actions(recorded: np.ndarray, relay: bool = True) -> np.ndarray:
    """Actions (B, N, 1 + N) int64 of ``paper`` (``relay=False``: ``no_relay``) from the recorded flags."""
    recorded = np.asarray(recorded, bool)
    B, N = recorded.shape[:2]
    partner = paper_partners(recorded)
    actions = np.empty((B, N, 1 + N), dtype=np.int64)
    actions[..., 0] = partner
    actions[..., 1:] = complete_chain_routing(partner) if relay else N
    return actions


class PaperPolicy(Policy):
    """The lowest-index recorded robot; complete chains m -> n -> the others ascending."""

    relay = True
    batching = "per_copy"

    def act(self, observations):
        order = list(self.env.possible_agents)
        size = self.env.observation_space(order[0]).shape[0]
        obs = np.stack([np.asarray(observations[a], float) if a in observations else np.zeros(size) for a in order])
        actions = paper_actions(recorded_flags(obs)[None], relay=self.relay)[0]
        return {a: actions[order.index(a)] for a in observations}


class NoRelayPolicy(PaperPolicy):
    """The same measurements; every chain stops at the measured robot."""

    relay = False


class PaperMeasurement:
    """The measurement entry (index 0) of a learned policy left to ``paper``'s rule: the lowest-index robot each
    robot recorded at this step (``paper_partners`` of its observation's recorded flags, entries [N, 2N)), itself
    where it recorded nobody. The rule draws nothing, so ``generators`` are not used (``agents.paper_entries``'
    interface). ``restrict`` leaves index 0 one choice in a batch of action masks (the agent itself), so that a
    masked training spends no entropy and no gradient on an entry the env never receives from the model."""

    def entries(self, generators, observations: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """``actions`` (B, N, 1 + N) with index 0 replaced; ``observations`` (B, N, obs_dim)."""
        out = np.array(actions, dtype=np.int64, copy=True)
        out[..., 0] = paper_partners(recorded_flags(observations))
        return out

    def restrict(self, masks: np.ndarray, num_agents: int) -> np.ndarray:
        """Masks (rows, N + N (N + 1)) of sub-envs ordered copy by copy, agent by agent: index 0's block keeps only
        the agent's own index (``agents.base.own_choice_only``)."""
        return own_choice_only(masks, num_agents)


# The action entries a trained model may leave to the paper's rule (``coloc train --paper-entries``).
PAPER_ENTRIES = {"measurement": PaperMeasurement}

# ``always`` (every transport decision at its maximum: the complete chain) is ``paper``; ``silent``
# (nothing relayed: the measurement still updates m and n) is ``no_relay``.
# the event-triggered families decide each robot's relay entries (agents.event_triggered)
POLICIES = {"paper": PaperPolicy, "always": PaperPolicy, "silent": NoRelayPolicy, "no_relay": NoRelayPolicy,
            **event_triggered.POLICIES}
STRONGEST_BASELINES = ("paper",)
