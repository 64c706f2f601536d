"""Backends ``bandwidth_fusion`` (zhao2020), ``centralized_lmmse`` and ``prediction_compensation`` (fu2017 A, B).

Target backends: every agent holds an estimate of the world's shared state x
(estimand ``target``), on a linear-Gaussian world (``drift``, ``target_cv``)
whose agents each read z_j = C x + v_j. The math is the validated code of
``estimators.bandwidth_fusion`` and ``estimators.lossy_fusion``; these
adapters only ask the network what arrived and translate it.

**bandwidth_fusion** (zhao2020, eqs. 4-7, 18-19; ``estimators.bandwidth_fusion.step``).
Each agent forms its intermediate estimate lambda_j(k) (eq. 4) and sends
each receiver i the components T_ji the network lets i take (``bandwidth``:
the receivers' selections within their budgets; a network without
selections: every component); a component that does not arrive on time is
filled with the receiver's own prediction (eq. 6), i.e. the estimator runs
with the delivered selection T_ji & arrived_ji, for which the bound (19) and
the exact covariance stay exact. Receiver i fuses with its own weights p_i.
(the agents' decision, as in the scenario: p_i = softmax(``weight_logit_scale``
a) over [self, neighbour 0, ..., neighbour N-2], neighbour k = agent (i+1+k)
mod N; a = 0 gives the paper's uniform P1). The estimator is a one-step
predictor: xhat_i(k) uses y(0..k-1). At step k the backend reports xhat_i(k),
the estimate of x(k) (the pairing of the paper's cost J_K, eq. 12, and the
time every other backend reports), then updates to xhat_i(k+1) with y(k) and
this step's decisions: a step's selection and weights show in the next
step's estimate and reward (the ``bandwidth_fusion`` scenario instead
reports xhat(k+1) after step k; the estimates are the same sequence). Its
covariance is the exact Sigma_i of the stacked errors (the paper's (10),
``estimators.bandwidth_fusion.exact_covariance_step``: the infos' ``trace``
and ``reward="trace"``); the observation reads the bound M_i of eq. (19), which
node i computes itself (the scenario's observation does the same).

**centralized_lmmse** (fu2017 (A), Sec. 3.1; ``estimators.lossy_fusion.centralized_step``).
Agent 0 is the leader and fusion centre; each follower sends its z_i(k) as a
packet to the leader every slot (if its transmit decision says so); the
leader's buffer y_i(k) follows eq. (3): the fresh packet if it arrived on
time, the previous slot's if that arrives now (late), else what it held. The
filter assumes the links' per-slot statistics (alpha1, alpha2), which it
reads from the network at build (``bernoulli_delay``: its probabilities; a
network with no delay: alpha1 = P(delivered), alpha2 = 0). Every agent
reports the leader's xhat(k|k) and P(k|k) (the estimate is shared: the team's).

**prediction_compensation** (fu2017 (B), Sec. 3.2, eqs. 27-31;
``estimators.lossy_fusion.distributed_step``). Each follower runs its own
Kalman filter and sends the leader the packet [x(k|k), x(k|k-1), x(k|k-2)]
with covariances; the leader holds the last packet delivered (on time, late,
or the one it held), compensates it with the weights (29), fuses by
inverse-trace weights (30) and feeds back (31). ``reading`` says what the
weights (29) act on (``estimators.lossy_fusion.READINGS``, derived in that
module's docstring):

| reading       | the three compensated estimates of a held packet              | the leader needs      |
|---------------|----------------------------------------------------------------|-----------------------|
| ``current``   | its entries x(k'|k'), x(k'|k'-1), x(k'|k'-2) as if k' = k     | nothing more (paper)  |
|               | (the algorithm as printed; a stale packet lags the target)     |                       |
| ``forward``   | its filtered x(k'|k') predicted forward by 0, 1 and 2 slots    | nothing more          |
|               | (the possible ages, (22)); covariance with the spread of the   | (realizable)          |
|               | three predictions                                              |                       |
| ``age_aware`` | its entries predicted forward by the packet's true age         | time stamps, which    |
|               |                                                                | the paper's agents    |
|               |                                                                | do not have           |

Decisions (the leader's action, agent 0; the others' entries are ignored):
the fusion tilt t_i (a_i proportional to exp(scale t_i) / tr P_i) and the
compensation tilt per follower and compensated estimate (weights
proportional to c_j exp(scale t_fj), c = eq. 29); 0 = the paper, exactly as
in the ``lossy_fusion`` scenario.

A packet later than one slot (a network with delays of 2 or more) is
discarded by both fu2017 backends: their model (eq. 3) has one-slot lateness
only. A known input b (``drift``'s B) enters the fu2017 filters, written for
b = 0, by the exact change of variables x = xt + c(k), c(k+1) = A c(k) + b
(``estimators.linear_models.LinearGaussian.known_input``): they filter xt
from z - C c(k).

**bandwidth_fusion**

| quantity         | value                                                                           |
|------------------|---------------------------------------------------------------------------------|
| estimand         | target (each agent its own estimate)                                            |
| motion kinds     | ``linear_gaussian``                                                             |
| needs            | ``linear_observation``                                                          |
| messages         | ``components``: every agent to every other, the receiver's selection            |
| payload          | t_ji floats per (sender, receiver) link, one message each                        |
| lost message     | the receiver's own prediction fills the components (eq. 6)                      |
| late message     | discarded: compensated as a lost one (eq. 6)                                    |
| under-determined | never: every agent has its own measurement every step                           |
| decisions        | ``fusion_weights`` Box[-1, 1]^N                                                 |
| reported at k    | xhat_i(k), Sigma_i(k) (before this step's update; see above)                     |

**centralized_lmmse**

| quantity         | value                                                                           |
|------------------|---------------------------------------------------------------------------------|
| estimand         | target (the leader's xhat(k|k), reported by every agent: shared)                |
| motion kinds     | ``linear_gaussian``                                                             |
| needs            | ``linear_observation``                                                          |
| messages         | ``packets``: each follower's z_i(k) to agent 0                                  |
| payload          | p floats (z_i)                                                                  |
| lost message     | y_i(k) = y_i(k-1) (eq. 3), the filter's statistics account for it               |
| late message     | y_i(k) = z_i(k-1) (eq. 3); delays of 2 or more are discarded                    |
| under-determined | never: the leader's own z_0 every slot                                          |
| decisions        | none                                                                            |
| reported at k    | xhat(k|k), P(k|k)                                                               |

**prediction_compensation**

| quantity         | value                                                                           |
|------------------|---------------------------------------------------------------------------------|
| estimand         | target (the leader's fused x0(k), reported by every agent: shared)              |
| motion kinds     | ``linear_gaussian``                                                             |
| needs            | ``linear_observation``                                                          |
| messages         | ``packets``: each follower's packet to agent 0                                  |
| payload          | 3 n + 3 n (n + 1) / 2 floats (three estimates, three symmetric covariances)     |
| lost message     | the held packet is used again, compensated by (29) (``reading``: as if current, |
|                  | or predicted forward by each possible age)                                      |
| late message     | the previous slot's packet is held (eq. 3); delays of 2 or more are discarded   |
| under-determined | never: the leader's own z_0 every slot                                          |
| decisions        | ``fusion_tilt`` Box[-1, 1]^N, ``compensation_tilt`` Box[-1, 1]^(3(N-1))         |
| reported at k    | x0(k), P0(k) (eq. 30)                                                           |

Arguments

| backend                  | field               | default    | allowed                  |
|--------------------------|---------------------|------------|--------------------------|
| bandwidth_fusion         | weight_logit_scale  | 4.0        | (0, 1000]                |
| centralized_lmmse        | gain                | "optimal"  | "optimal", "paper" (eq. 21) |
| centralized_lmmse        | moments             | "derived"  | "derived", "printed"     |
| prediction_compensation  | weight_logit_scale  | 3.0        | (0, 50]                  |
| prediction_compensation  | reading             | "current"  | "current", "forward", "age_aware" (time stamps) |
| prediction_compensation  | forward_spread      | True       | True, False              |

``moments``: the second moments of the link terms in (A)'s recursion, as derived (the true MSE) or as
the paper prints them (eqs. 12-14, 20; ``estimators.lossy_fusion.centralized_step``), to measure
what the printed ones cost; the filter's covariance is then no longer its MSE. ``forward_spread``
(``reading="forward"`` only): the compensated covariance includes the spread of the three predictions
(True, the derived one) or is (26)'s printed sum_a w_a P_a (False;
``estimators.lossy_fusion.distributed_step``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import estimators.bandwidth_fusion as bf
import estimators.lossy_fusion as lf
from coloc_env.backends.base import Backend
from coloc_env.parts import BACKENDS, Block, PartConfig, check_choice, check_flag, check_range

LEADER = 0
LINEAR = frozenset({"linear_gaussian"})
NEEDS_LINEAR = (frozenset({"linear_observation"}),)


# --- shared pieces of the target backends --------------------------------------------------------------

def link_distances(world) -> np.ndarray:
    """(N, N) distances between the agents of copy 0 (the target worlds' formation is fixed)."""
    p = world.positions()[0]
    return np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)


def slot_probabilities(network, distance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(alpha1, alpha2) per link, the per-slot statistics fu2017's filters assume.

    A network that knows them says so (``slot_probabilities``, e.g. ``bernoulli_delay``); for one
    without delays they are (P(delivered), 0); otherwise the per-packet delay law is read off
    ``packet_delays`` on a grid of 4096 uniforms (exact to 1/4096 for threshold rules) and a packet one
    step late counts as a late slot when the fresh one is missing.
    """
    if hasattr(network, "slot_probabilities"):
        a1, a2 = network.slot_probabilities(distance)
        return np.asarray(a1, float), np.asarray(a2, float)
    usable = np.asarray(network.usable(distance), bool)
    if network.max_delay() == 0:
        return usable * (1.0 - np.asarray(network.loss_probability(distance), float)), np.zeros(np.shape(distance))
    u = (np.arange(4096) + 0.5) / 4096
    delays = np.asarray(network.packet_delays(np.asarray(distance)[..., None], np.broadcast_to(u, (*np.shape(distance),
                                                                                                  4096))))
    a1 = usable * (delays == 0).mean(axis=-1)
    return a1, usable * (delays == 1).mean(axis=-1) * (1.0 - a1)


class TargetBackend(Backend):
    """Runtime of a target backend: estimates of the world's state x for every agent.

    Subclasses keep ``self.estimate`` (B, N, n) and ``self.cov`` (B, N, n, n) (or None) current; the
    composition reads ``posterior_state`` / ``posterior_state_cov`` after each step: the estimate of x(k).
    """

    def __init__(self, config, world, network, batch):
        super().__init__(config, world, network, batch)
        self.n = world.state_dim
        self.pos = list(world.position_index)
        # the same components as a slice where they are evenly spaced ((0, 1), (0, 2)): _record copies blocks
        # through views instead of gathering them twice every step
        gaps = np.diff(self.pos)
        even = len(gaps) > 0 and gaps[0] > 0 and bool((gaps == gaps[0]).all())
        self._pos_key = slice(self.pos[0], self.pos[-1] + 1, int(gaps[0])) if even else self.pos
        B, N, n = self.batch, self.num_agents, self.n
        self.estimate = np.zeros((B, N, n))
        self.cov: np.ndarray | None = np.zeros((B, N, n, n))
        self.posterior_state = np.zeros((B, N, n))
        self.posterior_state_cov: np.ndarray | None = None

    def step(self, readings, decisions) -> None:
        self.update(readings, decisions)
        self._record()

    def _record(self, idx=None) -> None:
        idx = slice(None) if idx is None else idx
        pos = self._pos_key
        self.posterior_state[idx] = self.estimate[idx]
        self.posterior_position[idx] = self.estimate[idx][..., pos]
        if self.cov is None:
            self.posterior_state_cov = None
            self.posterior_position_cov = None
            return
        if self.posterior_state_cov is None:
            self.posterior_state_cov = self.cov.copy()
            self.posterior_position_cov = self.position_cov().copy()
        self.posterior_state_cov[idx] = self.cov[idx]
        self.posterior_position_cov[idx] = self.cov[idx][..., pos, :][..., :, pos]

    def predict(self, inputs) -> None:
        return None

    def copies_by_step(self) -> list:
        """[(k, rows)]: the copies at each step k of the world (every copy at one k: a slice, no index array)."""
        k = self.world.k
        first = int(k[0])
        if self.batch == 1 or (k == first).all():  # the method: np.all's dispatch costs more at one copy
            return [(first, slice(None))]
        return [(int(step), np.flatnonzero(k == step)) for step in np.unique(k)]

    def position(self) -> np.ndarray:
        return self.estimate[..., self.pos]

    def position_cov(self) -> np.ndarray | None:
        if self.cov is None:
            return None
        key = self._pos_key
        if isinstance(key, slice):  # one strided block: a copy of a view, not two gathers
            return self.cov[..., key, key].copy()
        return self.cov[..., key, :][..., :, key]


class LeaderLinks:
    """The followers' packets to the leader, translated into fu2017's per-slot outcomes (eq. 3).

    At slot k a follower's outcome is ON_TIME if its packet of slot k arrived now (delay 0), LATE if
    its packet of slot k-1 arrives now (delay 1 at k-1), else LOST. Delays of 2 or more are dropped.
    """

    def __init__(self, network, batch: int, num_agents: int):
        self.network = network
        self.late_next = np.zeros((batch, num_agents), bool)
        listening = np.zeros((num_agents, num_agents), bool)
        listening[:, LEADER] = True
        listening[LEADER, LEADER] = False
        self.listening = np.broadcast_to(listening, (batch, num_agents, num_agents))
        self.followers = np.arange(num_agents) != LEADER
        self.senders = np.broadcast_to(self.followers, (batch, num_agents))

    def reset(self, idx) -> None:
        self.late_next[idx] = False

    def outcomes(self, floats: float, transmit: bool = True) -> np.ndarray:
        """(B, N) codes; the leader's own column is ON_TIME. ``transmit`` False sends nothing (no network call)."""
        B, N = self.late_next.shape
        if not transmit:
            out = np.full((B, N), lf.LOST, np.int8)
            out[:, LEADER] = lf.ON_TIME
            self.late_next[:] = False
            return out
        delay = self.network.packets(self.senders, self.listening, floats, slot=0)[:, :, LEADER]
        out = np.full((B, N), lf.LOST, np.int8)
        out[self.late_next] = lf.LATE
        out[delay == 0] = lf.ON_TIME  # the leader's own column too (no delay to itself: -1 there)
        out[:, LEADER] = lf.ON_TIME
        self.late_next = delay == 1
        return out


def lossy_model(world, network) -> lf.LossyModel:
    """fu2017's model of the world's system and the network's followers -> leader link statistics."""
    motion, sensor = world.motion_model, world.measurement_model
    N = world.num_agents
    a1, a2 = slot_probabilities(network, link_distances(world))
    on_time, late = a1[:, LEADER].copy(), a2[:, LEADER].copy()
    on_time[LEADER], late[LEADER] = 1.0, 0.0
    dead = np.flatnonzero(on_time + late <= 0.0)
    if len(dead):
        raise ValueError(f"the fu2017 backends need every follower's link to the leader to deliver sometimes; "
                         f"network {network.config.name} never delivers from agent(s) {dead.tolist()}")
    return lf.LossyModel(transition=motion.transition, process_noise=motion.process_noise,
                         measurement=sensor.matrix, measurement_noise=sensor.noise_of(N),
                         on_time=on_time, late=np.minimum(late, 1.0 - on_time))


class ShiftedInput:
    """c(k) of the known input (x = xt + c(k)), per copy: the fu2017 filters run on xt."""

    def __init__(self, world):
        self.world = world
        self.c = world.motion_model.known_input(world.horizon + 1)
        self.C = world.measurement_model.matrix
        self._none = not np.any(self.c)  # no known input (target_cv): xt = x

    def now(self) -> np.ndarray:
        return self.c[np.minimum(self.world.k, len(self.c) - 1)]  # (B, n)

    def measurements(self, z: np.ndarray) -> np.ndarray:
        if self._none:  # z - 0 is z exactly; a copy all the same (a backend keeps it as the previous slot's)
            return np.array(z, dtype=float)
        return z - (self.now() @ self.C.T)[:, None, :]


# --- bandwidth_fusion --------------------------------------------------------------------------------------

@BACKENDS.register
@dataclass(frozen=True)
class BandwidthFusion(PartConfig):
    name = "bandwidth_fusion"
    estimand = "target"
    motion_kinds = LINEAR
    requires = NEEDS_LINEAR
    message_kind = "components"
    message_content = "estimates"
    shared_estimate = False
    weight_logit_scale: float = 4.0

    def check(self, prefix: str) -> None:
        check_range(f"{prefix}weight_logit_scale", self.weight_logit_scale, 0.0, 1e3, low_open=True)

    def build(self, world, network, batch: int) -> Backend:
        return BandwidthFusionBackend(self, world, network, batch)


def fusion_model(motion, sensor, num_agents: int) -> bf.FusionModel:
    """The fusion estimator's model of a linear world: A, B, W of its ``motion`` (``LinearGaussian``), C and
    every agent's V_j of its ``sensor`` (``LinearObservation``)."""
    return bf.FusionModel(transition=motion.transition, drift=motion.drift, measurement=sensor.matrix,
                          process_noise=motion.process_noise, measurement_noise=sensor.noise_of(num_agents))


class BandwidthFusionBackend(TargetBackend):

    def __init__(self, config, world, network, batch):
        super().__init__(config, world, network, batch)
        N = self.num_agents
        self.model = fusion_model(world.motion_model, world.measurement_model, N)
        if hasattr(network, "set_component_dim"):
            network.set_component_dim(self.n)
        self._x0, self._P0 = world.prior()
        self.fusion = bf.initial_state(self.model, self._x0, self._P0, (self.batch,))
        neighbours = (np.arange(N)[:, None] + 1 + np.arange(N - 1)[None, :]) % N
        self.weight_order = np.concatenate([np.arange(N)[:, None], neighbours], axis=1)  # [self, neighbour 0, ...]
        self._weight_rows = np.arange(N)[:, None]
        self.weights = np.full((self.batch, N, N), 1.0 / N)
        self.delivered_selection = np.ones((self.batch, N, N, self.n), bool)
        self._sync()

    def step(self, readings, decisions) -> None:
        self._record()  # xhat_i(k), Sigma_i(k): the estimate of x(k) from y(0..k-1)
        self.update(readings, decisions)

    def decision_blocks(self) -> list[Block]:
        N = self.num_agents
        return [Block("fusion_weights", N, None, f"fusion-weight logits for [self, neighbour 0..{N - 2}] "
                      "(neighbour k = agent (i+1+k) mod N): p_i = softmax(scale * a); 0 = uniform (P1)",
                      low=-1.0, high=1.0, default=0.0)]

    def _sync(self) -> None:
        self.estimate = self.fusion.estimate
        self.cov = bf.node_covariances(self.fusion.error_cov, self.num_agents)

    def local_position_cov(self) -> np.ndarray:
        """The position block of the bound M_i (eq. 19): what node i computes itself (the observation's)."""
        return self.fusion.bound[..., self.pos, :][..., :, self.pos]

    def reset(self, rngs, idx) -> None:
        fresh = bf.initial_state(self.model, self._x0, self._P0, (len(idx),))
        self.fusion.estimate[idx] = fresh.estimate
        self.fusion.bound[idx] = fresh.bound
        self.fusion.error_cov[idx] = fresh.error_cov
        self.weights[idx] = 1.0 / self.num_agents
        self._sync()
        self._record(idx)

    def decode_weights(self, logits: np.ndarray) -> np.ndarray:
        """(B, N, N) logits in relative order -> absolute weights p_ij (the scenario's softmax)."""
        logits = self.config.weight_logit_scale * np.asarray(logits, float)
        logits = logits - logits.max(axis=-1, keepdims=True)
        relative = np.exp(logits)
        relative /= relative.sum(axis=-1, keepdims=True)
        weights = np.zeros(relative.shape[:-2] + (self.num_agents, self.num_agents))
        # put_along_axis by a fixed index: a plain scatter, without its index broadcast every step
        weights[..., self._weight_rows, self.weight_order] = relative
        return weights

    def deliver(self) -> np.ndarray:
        """(B, N, N, n) [i, j, c]: component c of agent j reached receiver i on time (diagonal True)."""
        B, N, n = self.batch, self.num_agents, self.n
        if hasattr(self.network, "component_selection"):
            selection = np.asarray(self.network.component_selection(), bool)
        else:
            selection = np.ones((B, N, N, n), bool)
        # one packet per (sender j, receiver i) link of t_ji floats, all links in one call: [t, s] = [j, i]
        count = selection.sum(axis=-1).swapaxes(-1, -2).astype(float)
        delay = self.network.packets(np.ones((B, N), bool), count > 0, count, slot=0)
        arrived = delay.swapaxes(-1, -2) == 0  # [i, j]
        arrived |= np.eye(N, dtype=bool)
        return selection & arrived[..., None]

    def update(self, readings, decisions) -> None:
        y = readings.extra["linear"]
        self.weights = self.decode_weights(decisions[..., :self.num_agents])
        self.delivered_selection = self.deliver()
        self.fusion = bf.step(self.model, self.fusion, y, self.delivered_selection, self.weights)
        self._sync()


# --- fu2017 (A): centralized_lmmse ----------------------------------------------------------------------------

@BACKENDS.register
@dataclass(frozen=True)
class CentralizedLmmse(PartConfig):
    name = "centralized_lmmse"
    estimand = "target"
    motion_kinds = LINEAR
    requires = NEEDS_LINEAR
    message_kind = "packets"
    message_content = "readings"
    shared_estimate = True
    gain: str = "optimal"
    moments: str = "derived"

    def check(self, prefix: str) -> None:
        check_choice(f"{prefix}gain", self.gain, ("optimal", "paper"))
        check_choice(f"{prefix}moments", self.moments, ("derived", "printed"))

    def build(self, world, network, batch: int) -> Backend:
        return CentralizedLmmseBackend(self, world, network, batch)


class CentralizedLmmseBackend(TargetBackend):
    """(A) at the leader; P(k|k-1) does not depend on the data, so copies at the same k share it."""

    def __init__(self, config, world, network, batch):
        super().__init__(config, world, network, batch)
        self.model = lossy_model(world, network)
        self.mats = lf.augmented_matrices(self.model)
        self.links = LeaderLinks(network, self.batch, self.num_agents)
        self.shift = ShiftedInput(world)
        self._x0, self._P0 = world.prior()
        first = lf.centralized_initial(self.model, self._x0, self._P0, (self.batch,))
        self.augmented = first.estimate  # (B, d) Xhat(k|k-1)
        self._moments = [(first.covariance, first.moment_mean, first.moment_cov)]  # per k
        p = self.model.meas_dim
        self.buffer_init = np.asarray(self.model.measurement, float) @ self._x0
        self.held = np.broadcast_to(self.buffer_init, (self.batch, self.num_agents, p)).copy()  # y(k-1)
        self.previous = self.held.copy()  # z(k-1)
        self.estimate[:] = self._x0
        self.cov[:] = self._P0

    def reset(self, rngs, idx) -> None:
        first = lf.centralized_initial(self.model, self._x0, self._P0, (len(idx),))
        self.augmented[idx] = first.estimate
        self.held[idx] = self.buffer_init
        self.previous[idx] = self.buffer_init
        self.links.reset(idx)
        self.estimate[idx] = self._x0
        self.cov[idx] = self._P0
        self._record(idx)

    def update(self, readings, decisions) -> None:
        z = self.shift.measurements(readings.extra["linear"])
        outcome = self.links.outcomes(float(self.model.meas_dim))
        self.held = lf.deliver(z, self.previous, self.held, outcome)
        self.previous = z
        offset = self.shift.now()
        for step, rows in self.copies_by_step():  # copies at the same k share P(k|k-1); one more k at a time
            cov, mean_m, cov_m = self._moments[step]
            state = lf.CentralizedState(self.augmented[rows], cov, mean_m, cov_m)
            nxt, filtered, filtered_cov = lf.centralized_step(self.model, state, self.held[rows], self.config.gain,
                                                              self.mats, self.config.moments)
            self.augmented[rows] = nxt.estimate
            if len(self._moments) == step + 1:
                self._moments.append((nxt.covariance, nxt.moment_mean, nxt.moment_cov))
            self.estimate[rows] = (filtered + offset[rows])[:, None, :]
            self.cov[rows] = filtered_cov


# --- fu2017 (B): prediction_compensation -----------------------------------------------------------------------

@BACKENDS.register
@dataclass(frozen=True)
class PredictionCompensation(PartConfig):
    name = "prediction_compensation"
    estimand = "target"
    motion_kinds = LINEAR
    requires = NEEDS_LINEAR
    message_kind = "packets"
    message_content = "estimates"
    shared_estimate = True
    weight_logit_scale: float = 3.0
    reading: str = "current"
    forward_spread: bool = True

    def check(self, prefix: str) -> None:
        check_range(f"{prefix}weight_logit_scale", self.weight_logit_scale, 0.0, 50.0, low_open=True)
        check_choice(f"{prefix}reading", self.reading, lf.READINGS)
        check_flag(f"{prefix}forward_spread", self.forward_spread)

    def build(self, world, network, batch: int) -> Backend:
        return PredictionCompensationBackend(self, world, network, batch)


# the followers' filter covariances: the same for every copy at a slot (DistributedState)
FOLLOWER_COVS = ("prediction_cov", "packet_cov")


class PredictionCompensationBackend(TargetBackend):
    """(B) at the leader. The followers' own filters read every slot whatever they send, so their covariances
    depend on the slot only: one stack (L-1, ...) for the copies at each slot k (``follower_covs[k]``, kept
    for the slots some copy is at), shown per copy in ``fusion``."""

    def __init__(self, config, world, network, batch):
        super().__init__(config, world, network, batch)
        self.model = lossy_model(world, network)
        self.compensation = lf.compensation_weights(self.model.on_time[1:], self.model.late[1:])  # (L-1, 3)
        self.links = LeaderLinks(network, self.batch, self.num_agents)
        self.shift = ShiftedInput(world)
        self._x0, self._P0 = world.prior()
        self.fusion = lf.distributed_initial(self.model, self._x0, self._P0, (self.batch,))
        first = lf.distributed_initial(self.model, self._x0, self._P0)
        self._first_covs = tuple(getattr(first, name) for name in FOLLOWER_COVS)
        self.follower_covs = {0: self._first_covs}
        self._show_follower_covs(self.copies_by_step())
        n = self.n
        self.payload = 3 * n + 3 * n * (n + 1) // 2
        self.outcome = np.zeros((self.batch, self.num_agents), np.int8)
        self.estimate[:] = self._x0
        self.cov[:] = self._P0

    def decision_blocks(self) -> list[Block]:
        N = self.num_agents
        return [Block("fusion_tilt", N, None, "leader: fusion tilt t_i for [leader, agent 1, ...]: a_i ~ "
                      "exp(scale t_i) / tr P_i (0: eq. 30)", low=-1.0, high=1.0, default=0.0),
                Block("compensation_tilt", 3 * (N - 1), None, "leader: per follower f and compensated "
                      "estimate j (the held packet's x(k|k), x(k|k-1), x(k|k-2); reading forward: predicted 0, 1, 2 "
                      "slots) at 3(f-1)+j: weights ~ c_j exp(scale t) (0: eq. 29)",
                      low=-1.0, high=1.0, default=0.0)]

    def reset(self, rngs, idx) -> None:
        fresh = lf.distributed_initial(self.model, self._x0, self._P0, (len(idx),))
        for field, value in vars(fresh).items():
            if field not in FOLLOWER_COVS:
                getattr(self.fusion, field)[idx] = value
        self.follower_covs[0] = self._first_covs
        self._show_follower_covs(self.copies_by_step())
        self.links.reset(idx)
        self.estimate[idx] = self._x0
        self.cov[idx] = self._P0
        self._record(idx)

    def decode(self, decisions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The leader's entries -> compensation weights (B, L-1, 3), fusion factors (B, L) (the scenario's)."""
        L, scale = self.num_agents, self.config.weight_logit_scale
        leader = np.asarray(decisions[:, LEADER], float)
        fusion_factors = np.exp(scale * leader[:, :L])
        tilt = leader[:, L:L + 3 * (L - 1)].reshape(-1, L - 1, 3)
        compensation = self.compensation * np.exp(scale * tilt)
        return compensation / compensation.sum(axis=-1, keepdims=True), fusion_factors

    def update(self, readings, decisions) -> None:
        z = self.shift.measurements(readings.extra["linear"])
        self.outcome = self.links.outcomes(float(self.payload))
        compensation, fusion_factors = self.decode(decisions)
        groups = self.copies_by_step()
        if len(groups) == 1:
            self.fusion = self._fuse(groups[0][0], self.fusion, z, self.outcome, compensation, fusion_factors)
        else:  # copies reset at other slots: the copies of each slot apart, then one state again
            parts = [(rows, self._fuse(k, self._rows(self.fusion, rows), z[rows], self.outcome[rows],
                                       compensation[rows], fusion_factors[rows])) for k, rows in groups]
            merged = {}
            for name, value in vars(self.fusion).items():
                if name not in FOLLOWER_COVS:  # those are shown below
                    value = np.empty((self.batch, *getattr(parts[0][1], name).shape[1:]), value.dtype)
                    for rows, part in parts:
                        value[rows] = getattr(part, name)
                merged[name] = value
            self.fusion = lf.DistributedState(**merged)
        self._show_follower_covs([(k + 1, rows) for k, rows in groups])
        self.estimate[:] = (self.fusion.fused + self.shift.now())[:, None, :]
        self.cov[:] = self.fusion.fused_cov[:, None]

    def _fuse(self, k: int, state, z, outcome, compensation, fusion_factors):
        """``estimators.lossy_fusion.distributed_step`` of the copies at slot k (``state`` theirs, which the result
        replaces) with the followers' covariances of slot k, shared; keeps those of slot k + 1."""
        state.prediction_cov, state.packet_cov = self.follower_covs[k]
        new = lf.distributed_step(self.model, state, z, outcome, None, compensation, fusion_factors,
                                  self.config.reading, self.config.forward_spread)
        self.follower_covs[k + 1] = (new.prediction_cov, new.packet_cov)
        return new

    @staticmethod
    def _rows(state, rows):
        return lf.DistributedState(**{name: value if name in FOLLOWER_COVS else value[rows]
                                      for name, value in vars(state).items()})

    def _show_follower_covs(self, groups) -> None:
        """``fusion.prediction_cov`` / ``packet_cov`` (B, L-1, ...) at each copy's slot (views of the shared stack
        when every copy is at one slot: read them, never write); the stacks of slots no copy is at are dropped."""
        if len(groups) == 1:
            k = groups[0][0]
            self.follower_covs = {k: self.follower_covs[k]}
            for shared, name in zip(self.follower_covs[k], FOLLOWER_COVS, strict=True):  # one copy: a new axis
                setattr(self.fusion, name, shared[None] if self.batch == 1 else
                        np.broadcast_to(shared, (self.batch, *shared.shape)))
            return
        self.follower_covs = {k: self.follower_covs[k] for k, _ in groups}
        for index, name in enumerate(FOLLOWER_COVS):
            shared = self.follower_covs[groups[0][0]][index]
            full = np.empty((self.batch, *shared.shape))
            for k, rows in groups:
                full[rows] = self.follower_covs[k][index]
            setattr(self.fusion, name, full)


__all__ = ["BandwidthFusion", "CentralizedLmmse", "PredictionCompensation", "TargetBackend", "slot_probabilities"]
