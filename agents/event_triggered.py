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
                         (m^2)              covariance trace (feature ``log_trace``:
                                            log tr P_i, clipped to [-50, 50])
``send_on_delta:delta``  delta in [0, inf]  ||xhat_i,k - xhat_i,ref|| >= delta, the     delta = 0    delta = inf
                         (m)                displacement of its own estimate since its
                                            reference transmission (feature
                                            ``displacement``, in units of 100 m)
``value:tau``            tau in [0, inf]    v_i,k >= tau, v_i,k the expected trace      tau = 0      tau = inf
                         (m^2)              reduction its message would bring (feature
                                            ``message_value``, ``Backend.message_value``)
=======================  =================  ==========================================  ===========  ============

The reference transmission of ``send_on_delta`` and ``value`` is the agent's last transmission that was
delivered (acknowledged to it, where the network gives acknowledgements) or, without acknowledgements, its
last transmission; before any, the start of the episode (the composed observation's table). At knob 0 a
rule sends at every step and at inf never, whatever it observes, so the ends are ``always`` and
``silent`` exactly.

The rules read only the agent's own observation, by the feature names of the composed observation
(``ComposedScenario.feature_index``: its index one-hot ``index``, ``log_trace``, ``step_fraction`` k /
horizon, ``displacement``, ``message_value``; the table of ``coloc_env.scenarios.composed``) and the
composition's static description (which action entries are transport, the horizon): never ``info`` nor
the env's state. They are the baselines a learned communication policy must beat at its own message rate
(``train.frontier``): Trimpe and D'Andrea (2014) trigger on the estimator's variance (``uncertainty``);
send-on-delta (Miskowicz 2006) on the change of what was last sent; value-of-information scheduling (Wu et
al. 2013) on what the message would tell the receivers; periodic transmission is the time-triggered
reference every event-triggered scheme is compared with.

Applies to plain compositions whose network has a transport decision (a block whose maximum and minimum
differ: ``transmit``, a relay's ``next_hop``, a bandwidth ``selection``), and to the presets whose decision maps
(``PresetScenario.transport_entries``: ``gps_denied_nbp``'s broadcast bits, ``lossy_fusion``'s transmit entry,
``relay_ukf``'s and ``mrclam_relay``'s relay entries, ``contention_localization``'s slots). On a preset, *send*
plays the action of the policy its ``family_send`` names (built with the family's seed, restarted with it by
``start_episode``): ``paper``, which is ``always``'s on the first four, and ``always`` on
``contention_localization``, whose ``paper`` is round robin. *Not send* sets the declared entries to their
quiet values (``silent``'s), every other entry staying the send policy's: the extremes are the preset's
``always`` and ``silent`` exactly. The presets observe the features by the same names
(their module tables). ``uncertainty`` and ``value`` also need a backend with a covariance. Elsewhere the
factories raise ``ValueError`` saying why.
"""

from __future__ import annotations

import copy
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

    def __init__(self, env, knob: float, seed: int | None = None):
        super().__init__(env)
        scenario = env.unwrapped.scenario
        from agents.generic import _is_composition

        self.send_policy = None  # a preset's policy whose action a send keeps (its family_send)
        if _is_composition(scenario):
            send = np.asarray(scenario.action_vector("maximum"))
            quiet = np.asarray(scenario.action_vector("minimum"))
            if np.array_equal(send, quiet):
                raise BadInput(f"policy {self.family!r} needs a transport decision; network "
                               f"{scenario.composition.network.name} has none for backend "
                               f"{scenario.composition.backend.name}")
        else:
            declared = scenario.transport_entries()
            if declared is None:
                raise BadInput(f"policy {self.family!r} needs a transmit or relay decision; preset {scenario.name} "
                               f"declares none (PresetScenario.transport_entries)")
            from agents import make_policy

            self.entries, self.quiet = (np.asarray(a) for a in declared)
            self.send_policy = make_policy(scenario.family_send, env, seed=seed)
            send = quiet = None
        self.knob = float(knob)
        self.num_agents = scenario.num_agents
        self.horizon = int(scenario.horizon)
        self.actions = {True: send, False: quiet}
        self.order = list(env.possible_agents)
        self.index = {name: scenario.feature_index(name) for name in ("index", "log_trace", "step_fraction")}

    def agent_index(self, observation: np.ndarray) -> int:
        start = self.index["index"]
        return int(np.argmax(observation[start:start + self.num_agents]))

    def step_index(self, observation: np.ndarray) -> int:
        """k from the observed step fraction k / horizon."""
        return int(round(float(observation[self.index["step_fraction"]]) * self.horizon))

    def sends(self, observation: np.ndarray) -> bool:  # pragma: no cover - interface
        raise NotImplementedError

    def start_episode(self, seed: int) -> None:
        """Restart a preset's send policy for the episode (a copy of it: a shallow copy of this policy, as a
        batched evaluation makes one per episode, must not share its generator)."""
        if self.send_policy is not None:
            self.send_policy = copy.copy(self.send_policy)
            self.send_policy.start_episode(seed)

    def act(self, observations: dict) -> dict:
        dtype = self.env.action_space(self.order[0]).dtype
        if self.send_policy is None:
            return {agent: self.actions[bool(self.sends(np.asarray(obs, float)))].astype(dtype)
                    for agent, obs in observations.items()}
        actions = self.send_policy.act(observations)  # every agent's: a stochastic one draws as it would alone
        out = {}
        for agent, obs in observations.items():
            action = np.array(actions[agent], dtype=dtype)
            if not self.sends(np.asarray(obs, float)):
                flat = action.reshape(-1)
                flat[self.entries] = self.quiet[self.entries].astype(dtype)
            out[agent] = action
        return out


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

    def __init__(self, env, knob: float, seed: int | None = None):
        super().__init__(env, knob, seed)
        _needs_covariance(env, "uncertainty")
        self.log_threshold = math.log(self.knob) if self.knob > 0 else -math.inf

    def sends(self, observation):
        return float(observation[self.index["log_trace"]]) >= self.log_threshold


def _needs_covariance(env, family: str) -> None:
    """A ``BadInput`` where the composition's backend keeps no position covariance (what ``family`` reads)."""
    from coloc_env.backends.base import Backend

    backend = env.unwrapped.scenario.backend
    if type(backend).position_cov is Backend.position_cov and not hasattr(backend, "local_position_cov"):
        raise BadInput(f"policy {family!r} reads the agent's own covariance; backend "
                       f"{env.unwrapped.scenario.composition.backend.name} keeps none")


class SendOnDelta(TransmitRule):
    """``send_on_delta:delta``: an agent sends when its own estimate has moved by at least delta (m) since its
    reference transmission (the module table); delta = 0 sends always, delta = inf never."""

    family = "send_on_delta"

    def __init__(self, env, knob: float, seed: int | None = None):
        super().__init__(env, knob, seed)
        from coloc_env.scenarios.composed import DISTANCE_SCALE

        self.index["displacement"] = env.unwrapped.scenario.feature_index("displacement")
        self.threshold = self.knob / DISTANCE_SCALE  # the feature is in units of DISTANCE_SCALE metres

    def sends(self, observation):
        if self.knob == 0.0 or math.isinf(self.knob):
            return self.knob == 0.0
        return float(observation[self.index["displacement"]]) >= self.threshold


class Value(TransmitRule):
    """``value:tau``: an agent sends when the value of its message (the expected reduction of its receivers'
    position covariance trace, m^2: ``Backend.message_value``) is at least tau; tau = 0 sends always, inf never."""

    family = "value"

    def __init__(self, env, knob: float, seed: int | None = None):
        super().__init__(env, knob, seed)
        _needs_covariance(env, "value")
        scenario = env.unwrapped.scenario
        if scenario.backend.position_process_noise() is None:
            raise BadInput(f"policy 'value' reads the message value the backend declares; backend "
                           f"{scenario.composition.backend.name} on world {scenario.composition.world.name} "
                           f"declares none (no position process noise: Backend.position_process_noise)")
        self.index["message_value"] = env.unwrapped.scenario.feature_index("message_value")

    def sends(self, observation):
        if self.knob == 0.0 or math.isinf(self.knob):
            return self.knob == 0.0
        return float(observation[self.index["message_value"]]) >= self.knob


def has_transport_decision(spec) -> bool:
    """Whether a composition's network gives its agents a transport decision (a block whose maximum and
    minimum differ) for the backend's message kind: the compositions the families apply to."""
    network = spec.network.build(spec.world.num_agents, 1, spec.backend.message_kind,
                                 getattr(spec.backend, "rounds", 1))
    return any(block.maximum is not None and block.maximum != block.minimum for block in network.transport_blocks())


def periodic(env, variant: str | None = None, seed: int | None = None) -> Periodic:
    """``periodic:P`` (default P = N, round robin); ``seed``: a preset's send policy's."""
    n = env.unwrapped.scenario.num_agents
    return Periodic(env, _parse_knob("periodic", variant, float(n), 1.0, integer=True), seed)


def uncertainty(env, variant: str | None = None, seed: int | None = None) -> Uncertainty:
    """``uncertainty:tau`` (tau in m^2, default 1)."""
    return Uncertainty(env, _parse_knob("uncertainty", variant, 1.0, 0.0, integer=False), seed)


def send_on_delta(env, variant: str | None = None, seed: int | None = None) -> SendOnDelta:
    """``send_on_delta:delta`` (delta in m, default 1)."""
    return SendOnDelta(env, _parse_knob("send_on_delta", variant, 1.0, 0.0, integer=False), seed)


def value(env, variant: str | None = None, seed: int | None = None) -> Value:
    """``value:tau`` (tau in m^2, default 1)."""
    return Value(env, _parse_knob("value", variant, 1.0, 0.0, integer=False), seed)


POLICIES = {"periodic": periodic, "uncertainty": uncertainty, "send_on_delta": send_on_delta, "value": value}
# each family's knob at its two ends: (the one that plays ``always``, the one that plays ``silent``)
EXTREMES = {"periodic": ("1", "inf"), "uncertainty": ("0", "inf"), "send_on_delta": ("0", "inf"),
            "value": ("0", "inf")}

__all__ = ["EXTREMES", "POLICIES", "Periodic", "SendOnDelta", "TransmitRule", "Uncertainty", "Value",
           "has_transport_decision", "periodic", "send_on_delta", "uncertainty", "value"]
