"""Event-triggered transmission: the one-knob schedulers of the event-based estimation literature.

Each family decides, per agent and step, one thing: send or not. *Send* plays the composition's
``always`` action (every transport entry at its maximum); *not send* sets the transport entries to
their minimum (``silent``'s) and keeps every other entry (sensing, fusion weights, windows) at
``always``'s. So a family's extreme knobs reproduce ``always`` and ``silent`` exactly, and any knob in
between changes only what is sent.

=======================  =================  ==========================================  ===========  ============
family                   knob               agent i sends at step k when                always       silent
=======================  =================  ==========================================  ===========  ============
``periodic:P``           P in {1, 2, ...}   (k - i) mod P = 0 (staggered by index:      P = 1        P = inf
                         or ``inf``         round robin when P = N)
``uncertainty:tau``      tau in [0, inf]    tr P_i >= tau, tr P_i its own position      tau = 0      tau = inf
                         (m^2)              covariance trace (observation entry N:
                                            log tr P_i, clipped to [-50, 50])
=======================  =================  ==========================================  ===========  ============

The rules read only the agent's own observation (its index one-hot, ``[0, N)``; log tr P_i, ``[N]``; the
step fraction k / horizon, ``[3N + 1]``; the composed observation table of
``coloc_env.scenarios.composed``) and the composition's static description (which action entries are
transport, the horizon): never ``info`` nor the env's state. They are the baselines a learned
communication policy must beat at its own message rate (``train.frontier``): Trimpe and D'Andrea (2014)
trigger on the estimator's variance (``uncertainty``); periodic transmission is the time-triggered
reference every event-triggered scheme is compared with.

Applies to plain compositions whose network has a transport decision (a block whose maximum and minimum
differ: ``transmit``, a relay's ``next_hop``, a bandwidth ``selection``); ``uncertainty`` also needs a
backend with a covariance. Elsewhere the factories raise ``ValueError`` saying why.
"""

from __future__ import annotations

import math

import numpy as np

from agents.base import Policy
from coloc_env.config import BadInput

INFINITY_WORDS = ("inf", "infinity", "never")


def _parse_knob(family: str, variant: str | None, default: float, low: float, integer: bool) -> float:
    """The knob after the colon (``periodic:4``, ``uncertainty:inf``): a number >= ``low`` (an integer for
    ``integer``), or ``inf``; ``default`` without a variant."""
    if variant is None:
        return default
    text = str(variant).strip().lower()
    kind = "an integer" if integer else "a number"
    if text in INFINITY_WORDS:
        return math.inf
    try:
        value = float(text)
    except ValueError:
        raise BadInput(f"{family}'s knob ({family}:x) must be {kind} >= {low:g} or inf, got {variant!r}") from None
    if not (value >= low) or (integer and value != math.inf and value != int(value)):
        raise BadInput(f"{family}'s knob ({family}:x) must be {kind} >= {low:g} or inf, got {variant!r}")
    return value


class TransmitRule(Policy):
    """Base of the families: ``sends(observation) -> bool`` per agent; the action follows from it."""

    batching = "per_copy"
    family = "rule"

    def __init__(self, env, knob: float):
        super().__init__(env)
        scenario = env.unwrapped.scenario
        from agents.generic import _is_composition

        if not _is_composition(scenario):
            raise BadInput(f"policy {self.family!r} needs a composition (coloc_env.compose); {scenario.name} is a "
                           f"preset with its own policies")
        send = np.asarray(scenario.action_vector("maximum"))
        quiet = np.asarray(scenario.action_vector("minimum"))
        if np.array_equal(send, quiet):
            raise BadInput(f"policy {self.family!r} needs a transport decision; network "
                           f"{scenario.composition.network.name} has none for backend "
                           f"{scenario.composition.backend.name}")
        self.knob = float(knob)
        self.num_agents = scenario.num_agents
        self.horizon = int(scenario.horizon)
        self.actions = {True: send, False: quiet}
        self.order = list(env.possible_agents)

    def agent_index(self, observation: np.ndarray) -> int:
        return int(np.argmax(observation[: self.num_agents]))

    def step_index(self, observation: np.ndarray) -> int:
        """k from the observed step fraction k / horizon."""
        return int(round(float(observation[3 * self.num_agents + 1]) * self.horizon))

    def sends(self, observation: np.ndarray) -> bool:  # pragma: no cover - interface
        raise NotImplementedError

    def act(self, observations: dict) -> dict:
        dtype = self.env.action_space(self.order[0]).dtype
        return {agent: self.actions[bool(self.sends(np.asarray(obs, float)))].astype(dtype)
                for agent, obs in observations.items()}


class Periodic(TransmitRule):
    """``periodic:P``: agent i sends at the steps k with (k - i) mod P = 0 (the module table)."""

    family = "periodic"

    def sends(self, observation):
        if math.isinf(self.knob):
            return False
        period = int(self.knob)
        return (self.step_index(observation) - self.agent_index(observation)) % period == 0


class Uncertainty(TransmitRule):
    """``uncertainty:tau``: an agent sends while its own position covariance trace is at least tau (m^2)."""

    family = "uncertainty"

    def __init__(self, env, knob: float):
        super().__init__(env, knob)
        from coloc_env.backends.base import Backend

        backend = env.unwrapped.scenario.backend
        if type(backend).position_cov is Backend.position_cov:
            raise BadInput(f"policy 'uncertainty' reads the agent's own covariance; backend "
                           f"{env.unwrapped.scenario.composition.backend.name} keeps none")
        self.log_threshold = math.log(self.knob) if self.knob > 0 else -math.inf

    def sends(self, observation):
        return float(observation[self.num_agents]) >= self.log_threshold


def has_transport_decision(spec) -> bool:
    """Whether a composition's network gives its agents a transport decision (a block whose maximum and
    minimum differ) for the backend's message kind: the compositions the families apply to."""
    network = spec.network.build(spec.world.num_agents, 1, spec.backend.message_kind,
                                 getattr(spec.backend, "rounds", 1))
    return any(block.maximum is not None and block.maximum != block.minimum for block in network.transport_blocks())


def periodic(env, variant: str | None = None) -> Periodic:
    """``periodic:P`` (default P = N, round robin)."""
    n = env.unwrapped.scenario.num_agents
    return Periodic(env, _parse_knob("periodic", variant, float(n), 1.0, integer=True))


def uncertainty(env, variant: str | None = None) -> Uncertainty:
    """``uncertainty:tau`` (tau in m^2, default 1)."""
    return Uncertainty(env, _parse_knob("uncertainty", variant, 1.0, 0.0, integer=False))


POLICIES = {"periodic": periodic, "uncertainty": uncertainty}
# each family's knob at its two ends: (the one that plays ``always``, the one that plays ``silent``)
EXTREMES = {"periodic": ("1", "inf"), "uncertainty": ("0", "inf")}

__all__ = ["EXTREMES", "POLICIES", "Periodic", "TransmitRule", "Uncertainty", "has_transport_decision", "periodic",
           "uncertainty"]
