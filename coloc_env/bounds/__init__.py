"""Posterior Cramér–Rao bounds of a composition over the seeded episodes an evaluation plays.

The package: ``record`` (the play and its record), ``models`` (one bound model per world model),
``problem`` (recursions, the bound problem, the delivered bound of reading messages),
``information_set`` (the delivered bound of estimate messages), ``compute`` (``pcrb``).

>>> import coloc_env
>>> bounds = coloc_env.pcrb("target_cv/bernoulli_delay/kalman", episodes=8, seed=0)
>>> bounds["centralized"].shape          # (K, N), m^2

``pcrb`` builds one copy of the composition's core per episode, resets episode e with
seed ``seed + e`` (the episode an evaluation's ``env.reset(seed=seed + e)`` plays; one copy
each, so any backend's batching is beside the point), steps it under the policy, and
records what the world read (the ranges taken, the fixes that existed) and what the
network delivered (each packet's delay, each broadcast, each relay chain) through the
hooks the core calls (``record``: ``ComposedScenario.observe``; the world's readings as
the core reads them, every ``Network`` delivery call as it returns). The world's bound model
(``coloc_env.bounds.models``, one module per world, each stating its estimation
problem) turns that record into the per-step Fisher information, transition Jacobians
and process noises; ``estimators.bounds.filtering_bound`` runs one recursion on the
D-terms averaged over the E episodes (Tichavský, Muravchik and
Nehorai 1998). Three bounds, each (K, N) in m^2 (agent n's trace of the bound's
position block at step k, after the readings of k; a shared target's bound for every
agent):

| key            | information                                                                 |
|----------------|-----------------------------------------------------------------------------|
| ``centralized``| every reading of every agent, fused centrally (unlimited communication)      |
| ``local``      | each agent with only its own readings: own motion inputs, own fixes, readings |
|                | of known anchors (no communication); a range to another agent is not its own  |
|                | information without that agent's position                                    |
| ``delivered``  | per receiver: its own readings plus every reading the messages that reached  |
|                | it carried, counted at the step it was *measured* from the step it arrives   |

What a message carries is the backend's declaration (``message_content``,
``coloc_env.backends.base``). Where a packet carries its sender's reading of the step it is
stamped with (``"readings"``: the ``kalman`` and ``centralized_lmmse`` backends' packets of
z_i(k), whose leader's bound is every agent's since every agent reports the leader's estimate;
the ``nlos_orbit`` neighbours' RSS/AOA packets to ``afge`` and ``dfir``; ``ukf_ccl``'s ranges and
fixes to its centre, agent 0, whose estimates every agent reads) the world's bound model gives
the lag-augmented recursion [x(k), ..., x(k - D)], D the network's longest delay
(``problem.delivered_recursion``); for backends that send nothing (``"nothing"``:
``dead_reckoning``) delivered = local; where a message carries an estimate (``"estimates"``:
``prediction_compensation``, ``bandwidth_fusion``, ``dnbp``'s beliefs, ``ukf_dcl``'s and
``ukf_se2``'s relayed location information, ``range_ls``) it is the information-set bound
(``information_set``): each message credited with every reading its sender held, the receiver's
bound given the union (``"delivered_capped"`` in the result: the share of those readings credited
earlier than they arrived, beyond the lag cap).
By construction local >= delivered >= centralized (each adds information to the one before),
for the receiver's own columns; where the delivered bound is a fusing agent's (a shared estimate), another
agent's local bound can be below it (its own fixes need not reach the centre).

Policies: ``"always"`` and ``"silent"`` play every transport decision at its maximum /
minimum with the default sensing and backend decisions
(``coloc_env.scenarios.composed.ComposedScenario.action_vector``, in the parts'
blocks, so a preset's own codec is bypassed: its world and seeds are the preset's);
``"random"`` draws every block uniformly from a generator seeded with ``seed``; a callable
``act(observations) -> actions`` (dicts over the agents, as the PettingZoo env passes
them) is stepped through the scenario's own codec, and a sequence of E callables plays one
per episode (``coloc evaluate`` replays the actions its rows played that way). Under a
policy that reads no observation (a name, or a callable with ``blind = True``) a backend
whose messages do not define the bound is not run (the world's readings never depend on
it), unless the preset's own step reads the backend's result (``gps_denied_nbp``); the
``nlos_orbit`` neighbours' packets are then asked of the network by the bound model's
stand-in (the same counter-based draws as the backend's call: a test holds them equal).

Where each episode is a problem of its own (``mrclam``: recorded windows, each conditioned on
its trajectory), the bound model asks for one recursion per episode and the mean of their
bounds (``BoundProblem.per_episode``). A mean of per-episode bounds is a bound on the averaged
MSE only where what differs between the episodes is known to the estimator *and* independent of
the noises it faces (then each is the bound conditioned on it, E[J(U)^-1] >= (E J(U))^-1); where
the Jacobians are evaluated at a truth that differs through noise the estimator does not observe,
or the readings taken depend on earlier readings (a policy that chooses from its estimates), it
is not, and the averaged D-terms are.

``mrclam`` (recorded data) has no generative model: its bound is model-based (the
world's calibrated noise model along each recorded window's Vicon trajectory, one recursion
per window, then their mean) and says so (``"model_based"``).
"""

from __future__ import annotations

from coloc_env.bounds.compute import pcrb
from coloc_env.bounds.problem import (
           BoundProblem,
           ReadingInformation,
           Recursion,
           delivered_recursion,
           lag_augmented,
           position_traces,
)
from coloc_env.bounds.record import POLICIES, Record, Recorder, record_play

__all__ = ["POLICIES", "BoundProblem", "ReadingInformation", "Record", "Recorder", "Recursion", "delivered_recursion",
           "lag_augmented", "pcrb", "position_traces", "record_play"]
