"""Policies for ``relay_ukf`` (wang2019).

* ``paper``: the paper's choices (Sec. 4). The measuring platform ranges with a
  partner drawn uniformly among the others (from the policy's own generator,
  ``seed``, which an evaluation restarts for each episode from the episode's seed:
  ``agents.base.SeededPolicy``); the location information then goes to the nearest platform not yet
  reached, until every platform is reached (the paper's "closest neighbour"
  topology). One relay choice per agent is enough: a chain is a path, so each
  platform has at most one successor; the last one stops.
* ``no_relay``: the same random partner, but the chain stops at the measured
  platform: only m and n update (with the consistent cross-covariance update).

* ``nearest_local``: a rule that needs only the agent's OWN observation (what a
  shared decentralized policy sees): the measuring platform ranges with its
  nearest platform, and every holder relays to its own nearest platform (the
  chain stops where that one was already reached). It shows what the
  observation allows without knowing who measured and who was reached.

``paper`` and ``no_relay`` read every agent's observation (the measuring flag
and the distances), so they know m and can compute the whole chain.

A trained model may leave the partner to the paper (``PAPER_ENTRIES["partner"]``, the settings module's
``PAPER_ENTRIES = "partner"``): the model decides every relay entry, and the measuring platform ranges with the
partner ``paper`` would draw, from the same per-episode generator, so a model and the fixed schedules play the
same partners on the same evaluation episode.
"""

from __future__ import annotations

import numpy as np

from agents import event_triggered
from agents.base import Policy, SeededPolicy, own_choice_only
from coloc_env.scenarios.relay_ukf import DISTANCE_SCALE


def random_partners(rng: np.random.Generator, measuring: np.ndarray, num_platforms: int) -> np.ndarray:
    """A partner != m drawn uniformly for every copy (B,); one draw per copy, with or without a measurement."""
    offset = rng.integers(1, num_platforms, size=np.shape(measuring))
    return (np.maximum(measuring, 0) + offset) % num_platforms


def nearest_chain_choices(distances: np.ndarray, measuring: np.ndarray, partner: np.ndarray) -> np.ndarray:
    """Relay choices (B, N) of the chain m -> n -> nearest not yet reached -> ... (N = stop).

    ``distances`` (B, N, N); ``measuring`` (B,) (-1: no measurement, every
    platform stops); ``partner`` (B,). Ties go to the lower index.
    """
    distances = np.asarray(distances, float)
    B, N = distances.shape[:2]
    rows = np.arange(B)
    choice = np.full((B, N), N)
    has = measuring >= 0
    source = np.maximum(measuring, 0)
    reached = np.zeros((B, N), dtype=bool)
    reached[rows, source] = True
    reached[rows, partner] = True
    choice[rows[has], source[has]] = partner[has]
    holder = partner.copy()
    for _ in range(N - 2):
        candidate = np.where(reached, np.inf, distances[rows, holder])
        nearest = np.argmin(candidate, axis=-1)
        more = has & ~reached.all(axis=-1)
        choice[rows[more], holder[more]] = nearest[more]
        reached[rows[more], nearest[more]] = True
        holder = np.where(more, nearest, holder)
    return choice


def measuring_platforms(observations: np.ndarray) -> np.ndarray:
    """The measuring platform m of each copy (B,), -1 where none measures, from every agent's observation
    (B, N, obs_dim): entry N is 1 for m."""
    N = np.shape(observations)[1]
    flags = np.asarray(observations)[:, :, N]
    return np.where(flags.max(axis=1) > 0.5, np.argmax(flags, axis=1), -1)


def ranging_entries(measuring: np.ndarray, partner: np.ndarray, num_platforms: int) -> np.ndarray:
    """Index 0 of every platform's action (B, N): m ranges with ``partner``, every other platform names itself
    (no measurement)."""
    entries = np.tile(np.arange(num_platforms), (len(measuring), 1))
    rows = np.flatnonzero(measuring >= 0)
    entries[rows, measuring[rows]] = partner[rows]
    return entries


def paper_actions(distances: np.ndarray, measuring: np.ndarray, rng: np.random.Generator,
                  relay: bool = True) -> np.ndarray:
    """Actions (B, N, 2) int64 of the ``paper`` policy (``relay=False``: ``no_relay``) for a batch."""
    B, N = np.shape(distances)[:2]
    partner = random_partners(rng, measuring, N)
    actions = np.empty((B, N, 2), dtype=np.int64)
    actions[..., 0] = ranging_entries(measuring, partner, N)
    if relay:
        actions[..., 1] = nearest_chain_choices(distances, measuring, partner)
    else:
        actions[..., 1] = N
    return actions


class PaperPolicy(SeededPolicy):
    """Random partner, nearest-not-yet-reached relay until everyone is reached (Sec. 4)."""

    relay = True
    batching = "per_copy"

    def act(self, observations):
        order, obs = self.observation_rows(observations)
        N = len(order)
        measuring = measuring_platforms(obs[None])
        distances = (obs[:, N + 1:2 * N + 1] * DISTANCE_SCALE)[None]
        actions = paper_actions(distances, measuring, self.rng, relay=self.relay)[0]
        return {a: actions[order.index(a)] for a in observations}


class NoRelayPolicy(PaperPolicy):
    """Random partner; the chain stops at the measured platform."""

    relay = False


class NearestLocalPolicy(Policy):
    """Each agent from its own observation: range with the nearest, relay to the nearest."""

    batching = "per_copy"

    def act(self, observations):
        N = len(self.env.possible_agents)
        actions = {}
        for agent, obs in observations.items():
            obs = np.asarray(obs, float)
            own = int(np.argmax(obs[:N]))
            distances = obs[N + 1:2 * N + 1].copy()
            distances[own] = np.inf
            nearest = int(np.argmin(distances))
            actions[agent] = np.array([nearest if obs[N] > 0.5 else own, nearest], dtype=np.int64)
        return actions


class PaperPartner:
    """The partner entry (index 0) of a learned policy left to ``paper``'s draw.

    ``entries`` overwrites index 0 of a batch of actions with ``paper``'s: the measuring platform (observation
    entry N, read from every agent's observation as ``paper`` does) ranges with ``random_partners``' draw, every
    other platform names itself. With one generator per copy, each drawing once per step whether or not a platform
    measures, copy e plays the partners ``paper`` plays in the episode its generator belongs to.
    ``restrict`` leaves index 0 one choice in a batch of action masks (the agent itself), so that a masked
    training spends no entropy and no gradient on an entry the env never receives from the model.
    """

    def entries(self, generators, observations: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """``actions`` (B, N, 2) with index 0 replaced; ``observations`` (B, N, obs_dim); ``generators``: B
        generators (one per copy) or one generator drawing for the whole batch (training)."""
        N = np.shape(observations)[1]
        measuring = measuring_platforms(observations)
        if isinstance(generators, np.random.Generator):
            partner = random_partners(generators, measuring, N)
        else:  # copy by copy, with the shapes ``paper`` draws with: the same numbers from the same generator
            partner = np.array([random_partners(rng, measuring[b:b + 1], N)[0] for b, rng in enumerate(generators)])
        out = np.array(actions, dtype=np.int64, copy=True)
        out[..., 0] = ranging_entries(measuring, partner, N)
        return out

    def restrict(self, masks: np.ndarray, num_agents: int) -> np.ndarray:
        """Masks (rows, 2N + 1) of sub-envs ordered copy by copy, agent by agent: index 0's block keeps only the
        agent's own index (``agents.base.own_choice_only``)."""
        return own_choice_only(masks, num_agents)


# The action entries a trained model may leave to the paper's rule (``coloc train --paper-entries``).
PAPER_ENTRIES = {"partner": PaperPartner}

# ``always`` (every transport decision at its maximum: the complete chain) is ``paper``; ``silent``
# (nothing relayed: the measurement still updates m and n) is ``no_relay``.
POLICIES = {"paper": PaperPolicy, "always": PaperPolicy, "silent": NoRelayPolicy, "no_relay": NoRelayPolicy,
            "nearest_local": NearestLocalPolicy, **event_triggered.POLICIES}  # families: the relay entry
STRONGEST_BASELINES = ("paper", "no_relay")
