"""Backends ``dnbp`` and ``range_ls`` (wan2014): dynamic NBP, and least squares against GPS-normal neighbours.

**dnbp** adapts ``estimators.dnbp.step`` (Algorithm 4, the paper's modified
schedule by default): per step, GPS-normal UAVs fuse their fix, then
``num_iterations`` NBP iterations run, iteration n being one
``coloc_env.networks.base.Network.broadcast`` round (``slot`` n) in which
the UAVs the schedule allows broadcast their particle message to the fault
UAVs that listen; a receiver listens only to a sender it has a range to (the
message is built from that range). Then every belief is propagated to k + 1
through the accelerometer reading. The particle randomness comes from the
backend's own generator, one per copy.

**range_ls** adapts ``estimators.range_ls.step`` (ref. [7] of wan2014): a
Kalman filter per UAV on the constant-velocity model, updated with its GPS
fix when normal; a fault UAV with at least ``min_anchors`` GPS-normal
neighbours whose estimate it received computes a Gauss-Newton fix against
their KF estimates and its ranges, gated, then used as a pseudo-measurement.
Per step one broadcast round (slot 0): every GPS-normal UAV broadcasts its
KF position estimate and its 2 x 2 covariance (5 floats) to everyone; the
delivered links with a range are the anchors of the fault UAVs. The
covariance enters each range's variance in the fix's covariance
(``estimators.range_ls``, "Reported covariance").

| quantity      | dnbp                                        | range_ls                                       |
|---------------|---------------------------------------------|------------------------------------------------|
| estimand      | self                                        | self                                           |
| motion kinds  | ``cv_accel``                                | ``cv_accel``                                   |
| needs         | ``range``                                   | ``range`` and ``position_fix``                 |
| messages      | ``broadcast``, ``num_iterations`` rounds    | ``broadcast``, 1 round                         |
| payload       | M centres (2), M log-weights, 1 bandwidth:  | a KF position estimate and its covariance:     |
|               | 3 M + 1 floats per message                  | 2 + 3 = 5 floats                               |
| lost message  | not heard in that iteration: the receiver's | that anchor cannot serve this step             |
|               | belief is not updated with it, and the      |                                                |
|               | schedule counts the sender as not heard     |                                                |
| under-determined | a fault UAV that hears nobody keeps its  | fewer than ``min_anchors`` anchors, or a fix   |
|               | prior (prediction only, dead reckoning)     | that fails the gate: the KF prediction         |
| decisions     | none (the network's ``transmit`` per round) | none (the network's ``transmit``, round 0)     |
| position cov  | the covariance of the density the belief    | a fix's Gauss-Newton covariance with the       |
|               | particles stand for: their sample           | anchors' uncertainty where the output is a     |
|               | covariance (+ h_rho^2 I2 where the belief   | fix, else the KF posterior covariance          |
|               | is its prior's particles; ``estimators.     | (``estimators.range_ls``, "Reported            |
|               | dnbp``, "Reported covariance")              | covariance")                                   |

Per-step noise and velocity (both backends): a world whose noise changes from step to step supplies
it with its readings, in ``Readings.extra``; each key present replaces, for that step, what the backend
took from the world when it was built (absent keys: the built values). ``accel_std`` and ``velocity``
act on the constant-velocity model only (``cv_accel`` worlds; other motion models carry their noise in
their inputs).

| extra key          | shape     | meaning                                                                   |
|--------------------|-----------|---------------------------------------------------------------------------|
| ``gps_std``        | (B,)      | sigma_gps (m) of this step's position fixes                               |
| ``range_std``      | (B,)      | sigma_d (m) of this step's ranges                                         |
| ``accel_std``      | (B,)      | sigma_acc (m/s^2) of the prediction k -> k + 1                            |
| ``velocity``       | (B, N, 2) | a velocity reading (m/s) for k -> k + 1, taken as exact: every particle's |
|                    |           | (the KF mean's) velocity is set to it before the step and its velocity    |
|                    |           | variance to 0, so the prediction moves by velocity dt + dt^2/2 e          |

Both take the per-step sigmas per copy: copies whose values differ (replays of different stretches of a
recording) each use their own, in one call for the batch (``estimators.dnbp.DnbpModel`` holds a (B,) array
then; ``estimators.range_ls.update`` takes (B,) arrays).

On a ``cv_accel`` world the dnbp warm start draws each agent's particles around the initial belief's mean
with the std ``World.warm_start_std()`` where the world states one (a recording's known start), else
sigma_gps (the world's ``fix_noise_var``; wan2014's last fix before the loss); on other motion models it
draws from the initial belief N(mean, cov).

Arguments (``coloc_env.backends.Dnbp``; defaults = ``gps_denied_nbp``'s)

| field              | default    | allowed                |
|--------------------|------------|------------------------|
| num_particles      | 100        | 2..5000                |
| num_iterations     | 5          | 1..20 (the rounds)     |
| oversampling       | 2          | 1..16                  |
| defensive_weight   | 0.01       | [0, 0.999]             |
| init               | "warm"     | "warm": particles from the initial belief; "cold": uniform over the |
|                    |            | world's start region (wan2014's cold start; cv_accel worlds only)   |
| box_margin         | 150        | [0, 1e7] m             |
| min_bandwidth      | 0.5        | [0.001, 1e4] m         |
| initial_threshold  | 3          | 1..64 (at most N)      |
| schedule           | "modified" | "modified", "parallel" |
| kernel             | "truncated"| "exact", "truncated": the belief update's mixture kernel |
|                    |            | (``estimators.dnbp.KERNELS``; truncated: approximate, ~2x      |
|                    |            | faster; how close to exact: docs/performance.md, "dNBP kernels")   |
| truncation         | 6.0        | [1, 10] bandwidths: r of the truncated kernel (terms below         |
|                    |            | e^(-r^2/2) of the largest left out; unused by the exact kernel)    |
| fault_message_power| 0.5        | (0, 1]: alpha, a GPS-faulty sender's message enters as m^alpha    |
|                    |            | (``estimators.dnbp``, "Messages of fault senders"); 1 = wan2014's  |
| range_gate         | None       | None (no gate) or (0, 1e12]: before a step a range d_st is dropped |
|                    |            | when (d_st - ||m_s - m_t||)^2 / (sigma_d^2 + v_s + v_t) exceeds it |
|                    |            | (m, v: mean and per-axis variance of the agent's prior particles;  |
|                    |            | 10.83 = chi-square(1) 99.9 %); dropped ranges: ``last_gated``      |

The defensive box is the world's flight area, ``[-box_margin, area + box_margin + |v_nom| dt horizon]``
per axis, as in the scenario. Warm start only: particles drawn around the world's initial belief.

Arguments (``coloc_env.backends.RangeLs``; defaults = ``estimators.range_ls.LsParams``)

| field        | default | allowed          |
|--------------|---------|------------------|
| min_anchors  | 3       | 1..64            |
| max_rms      | 3.0     | (0, 1e6] sigma_d |
| max_std      | 10.0    | (0, 1e6] sigma_d |
| gate_chi2    | 13.8    | (0, 1e12]        |
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

import estimators.dnbp as dn
import estimators.range_ls as rl
from coloc_env.backends.base import Backend
from coloc_env.config import MIN_STD
from coloc_env.parts import BACKENDS, PartConfig, check_choice, check_range
from estimators.kalman import symmetrize
from estimators.models import per_copy, predict_joint


@BACKENDS.register
@dataclass(frozen=True)
class Dnbp(PartConfig):
    name = "dnbp"
    estimand = "self"
    motion_kinds = frozenset({"cv_accel", "odometry_displacement", "se2_odometry"})
    requires = (frozenset({"range"}),)
    message_kind = "broadcast"
    message_content = "estimates"
    shared_estimate = False
    num_particles: int = 100
    num_iterations: int = 5
    oversampling: int = 2
    defensive_weight: float = 0.01
    box_margin: float = 150.0
    min_bandwidth: float = 0.5
    initial_threshold: int = 3
    schedule: str = "modified"
    init: str = "warm"
    kernel: str = "truncated"
    truncation: float = 6.0
    range_gate: float | None = None
    fault_message_power: float = 0.5

    @property
    def rounds(self) -> int:
        return self.num_iterations

    def check(self, prefix: str) -> None:
        check_range(f"{prefix}num_particles", self.num_particles, 2, 5000, integer=True)
        check_range(f"{prefix}num_iterations", self.num_iterations, 1, 20, integer=True)
        check_range(f"{prefix}oversampling", self.oversampling, 1, 16, integer=True)
        check_range(f"{prefix}defensive_weight", self.defensive_weight, 0.0, 0.999)
        check_range(f"{prefix}box_margin", self.box_margin, 0.0, 1e7)
        check_range(f"{prefix}min_bandwidth", self.min_bandwidth, MIN_STD, 1e4)
        check_range(f"{prefix}initial_threshold", self.initial_threshold, 1, 64, integer=True)
        check_choice(f"{prefix}schedule", self.schedule, ("modified", "parallel"))
        check_choice(f"{prefix}init", self.init, ("warm", "cold"))
        check_choice(f"{prefix}kernel", self.kernel, dn.KERNELS)
        check_range(f"{prefix}truncation", self.truncation, *dn.TRUNCATION_RANGE)
        check_range(f"{prefix}fault_message_power", self.fault_message_power, 0.0, 1.0, low_open=True)
        if self.range_gate is not None:
            check_range(f"{prefix}range_gate", self.range_gate, 0.0, 1e12, low_open=True)

    def build(self, world, network, batch: int) -> Backend:
        return DnbpBackend(self, world, network, batch)


@BACKENDS.register
@dataclass(frozen=True)
class RangeLs(PartConfig):
    name = "range_ls"
    estimand = "self"
    motion_kinds = frozenset({"cv_accel", "odometry_displacement", "se2_odometry"})
    requires = (frozenset({"range"}), frozenset({"position_fix"}))
    message_kind = "broadcast"
    message_content = "estimates"
    shared_estimate = False
    rounds = 1
    min_anchors: int = 3
    max_rms: float = 3.0
    max_std: float = 10.0
    gate_chi2: float = 13.8

    def check(self, prefix: str) -> None:
        check_range(f"{prefix}min_anchors", self.min_anchors, 1, 64, integer=True)
        check_range(f"{prefix}max_rms", self.max_rms, 0.0, 1e6, low_open=True)
        check_range(f"{prefix}max_std", self.max_std, 0.0, 1e6, low_open=True)
        check_range(f"{prefix}gate_chi2", self.gate_chi2, 0.0, 1e12, low_open=True)

    def build(self, world, network, batch: int) -> Backend:
        return RangeLsBackend(self, world, network, batch)


def _world_field(world, name: str):
    value = getattr(world.config, name, None)
    if value is None:
        raise ValueError(f"backend needs a world with a {name!r} field (world {world.config.name!r} has none)")
    return value


def _step_std(readings, key: str, built: float) -> np.ndarray:
    """The per-step standard deviation ``readings.extra[key]`` (B,), or the backend's built value."""
    value = readings.extra.get(key)
    return np.full(len(readings.fix_valid), built) if value is None else np.asarray(value, float).reshape(-1)


class DnbpBackend(Backend):
    def __init__(self, config: Dnbp, world, network, batch):
        super().__init__(config, world, network, batch)
        B, N, M = self.batch, self.num_agents, config.num_particles
        if config.initial_threshold > N:
            raise ValueError(f"backend.initial_threshold must be <= the number of agents {N}, "
                             f"got {config.initial_threshold}")
        motion = world.motion_model
        # wan2014's own model keeps Algorithm 3 (and the gps_denied_nbp scenario's draws); any other motion
        # model propagates each particle through the model's function and one draw of its process noise
        self.constant_velocity = motion.kind == "cv_accel"
        start, episode = world.region()
        m = config.box_margin
        accel_std = float(np.sqrt(motion.accel_noise_var)) if self.constant_velocity else 0.0
        self.model = dn.DnbpModel(
            dt=world.dt, accel_noise_std=accel_std,
            gps_std=float(np.sqrt(world.fix_noise_var())) if "position_fix" in world.config.measurements else 1.0,
            range_std=float(np.sqrt(world.range_noise_var())),
            num_particles=M, num_iterations=config.num_iterations, oversampling=config.oversampling,
            defensive_weight=config.defensive_weight, defensive_box=(episode[0] - m, episode[1] + m),
            cold_box=(start[0] - m, start[1] + m), min_bandwidth=config.min_bandwidth,
            initial_threshold=config.initial_threshold, schedule=config.schedule, kernel=config.kernel,
            truncation=float(config.truncation), fault_message_power=float(config.fault_message_power))
        d = motion.state_dim
        particles = np.zeros((B, N, M, d))
        self.state = dn.DnbpState(prior=particles, prior_bandwidth=np.ones((B, N)),
                                  prior_uniform=np.zeros((B, N), bool), belief=particles.copy(),
                                  estimate=np.zeros((B, N, 2)))
        self.rngs: list = [None] * self.batch
        self.floats = 3 * M + 1
        if config.init == "cold" and not self.constant_velocity:
            raise ValueError(f"backend.init='cold' needs cv_accel motion (the nominal velocity); world "
                             f"{world.config.name!r} moves by {motion.kind}")
        # the last step's schedule outcome (estimators.dnbp.StepResult): broadcasts, deliveries per iteration
        self.last_result = None
        self.built_model = self.model  # the noise from the world at build: per-step readings replace it
        self.last_gated = np.zeros((B, N, N), bool)  # [s, t]: s's range to t dropped by range_gate last step
        # h_rho of each belief that is its prior's particle set (0 where Algorithm 2 resampled it): position_cov
        self.belief_kernel = np.zeros((B, N))

    def reset(self, rngs, idx) -> None:
        idx = np.asarray(idx)
        for b, rng in zip(idx, rngs, strict=True):
            self.rngs[b] = rng
        mean, cov = self.world.initial_belief()
        start = self.built_model
        spread = self.world.warm_start_std()
        if spread is not None:
            start = dataclasses.replace(start, gps_std=float(spread))
        if self.constant_velocity:
            velocity = mean[idx, :, 2:]
            if self.config.init == "cold":  # nothing known but the nominal velocity
                velocity = np.broadcast_to(np.asarray(_world_field(self.world, "nominal_velocity"), float),
                                           velocity.shape)
            fresh = dn.initial_state(start, list(rngs), self.config.init, mean[idx, :, :2], velocity,
                                     float(_world_field(self.world, "velocity_spread")))
        else:  # warm start: M draws from each agent's initial belief N(mean, cov)
            M = self.model.num_particles
            factor = np.linalg.cholesky(cov[idx])
            normal = np.stack([rng.standard_normal((self.num_agents, M, mean.shape[-1])) for rng in rngs])
            points = mean[idx][:, :, None, :] + np.einsum("bnij,bnmj->bnmi", factor, normal)
            fresh = dn.DnbpState(prior=points, prior_bandwidth=dn.rule_of_thumb_bandwidth(points[..., :2]),
                                 prior_uniform=np.zeros(points.shape[:2], bool), belief=points.copy(),
                                 estimate=points[..., :2].mean(axis=2))
        for name in ("prior", "prior_bandwidth", "prior_uniform", "belief", "estimate"):
            getattr(self.state, name)[idx] = getattr(fresh, name)
        self.posterior_position[idx] = fresh.estimate
        self.belief_kernel[idx] = fresh.prior_bandwidth

    def _propagate(self, inputs):
        motion = self.world.motion_model

        def propagate(belief, rngs):
            u = np.asarray(inputs, float)[:, :, None, :]
            moved = motion.function(belief, u)
            noise = np.stack([motion.rvs(rng, belief[b], u[b]) for b, rng in enumerate(rngs)])
            return moved + noise

        return propagate

    def _step_model(self, readings) -> dn.DnbpModel:
        """The model of this step: the built one with the per-step sigmas of ``readings.extra``, one float where
        the copies agree, else a (B,) array of each copy's."""
        base = self.built_model
        values = {}
        for key, field in (("gps_std", "gps_std"), ("range_std", "range_std"), ("accel_std", "accel_noise_std")):
            if key not in readings.extra:
                continue
            std = _step_std(readings, key, getattr(base, field))
            values[field] = float(std[0]) if np.all(std == std[0]) else std
        return dataclasses.replace(base, **values) if values else base

    def _gate(self, readings, range_valid: np.ndarray) -> np.ndarray:
        """``range_valid`` less the ranges that fail ``range_gate`` against the prior particles."""
        pos = self.state.prior[..., :2]
        mean, var = pos.mean(axis=2), pos.var(axis=2).mean(axis=-1)
        predicted = np.linalg.norm(mean[:, :, None] - mean[:, None], axis=-1)
        residual = np.nan_to_num(readings.range) - predicted
        range_var = per_copy("range_std", self.model.range_std, self.batch)[:, None, None] ** 2
        nu2 = residual**2 / (range_var + var[:, :, None] + var[:, None, :])
        keep = range_valid & (nu2 <= self.config.range_gate)
        self.last_gated = range_valid & ~keep
        return keep

    def update(self, readings, decisions) -> None:
        counter = [0]
        range_valid = np.asarray(readings.range_valid, bool)
        self.model = self._step_model(readings)
        velocity = readings.extra.get("velocity")
        if velocity is not None and self.constant_velocity:
            self.state.prior[..., 2:] = np.asarray(velocity, float)[:, :, None, :]
        if self.config.range_gate is not None:
            range_valid = self._gate(readings, range_valid)

        def deliver(senders: np.ndarray, listening: np.ndarray) -> np.ndarray:
            n = counter[0]
            counter[0] += 1
            # s takes t's message only if it holds the range to t the message is built from
            return self.network.broadcast(senders, listening & range_valid.transpose(0, 2, 1), self.floats, slot=n)

        # dn.step reads the range of message t -> s at [t, s]; the reading is the receiver's own, [s, t]
        held = range_valid.transpose(0, 2, 1)
        ranges = np.where(held, np.nan_to_num(readings.range).transpose(0, 2, 1), 0.0)
        propagate = None if self.constant_velocity else self._propagate(readings.inputs)
        prior_bandwidth = self.state.prior_bandwidth.copy()
        self.state, self.last_result = dn.step(self.model, self.state, readings.fix_valid, readings.fix, deliver,
                                               ranges, readings.inputs, self.rngs, propagate=propagate)
        # Algorithm 2 resampled the beliefs of the GPS-normal UAVs and of those that heard a message
        resampled = np.asarray(readings.fix_valid, bool) | (self.last_result.received > 0)
        self.belief_kernel = np.where(resampled, 0.0, prior_bandwidth)

    def predict(self, inputs) -> None:
        return None  # dn.step has propagated the beliefs to k + 1 already (with the same readings' inputs)

    def position(self) -> np.ndarray:
        return self.state.estimate

    def position_cov(self) -> np.ndarray:
        """The covariance of the density the belief particles stand for (``estimators.dnbp``, "Reported
        covariance"): their sample covariance (1/M) sum_i (p_i - p_bar)(p_i - p_bar)^T, plus h_rho^2 I2 where the
        belief is its prior's particle set (the prior's KDE kernel; a resampled belief's particles carry their
        kernel as jitter already)."""
        points = self.state.belief[..., :2]
        centred = points - points.mean(axis=2, keepdims=True)
        cov = np.einsum("bnmi,bnmj->bnij", centred, centred) / points.shape[2]
        return cov + (self.belief_kernel**2)[..., None, None] * np.eye(2)

    def particles(self, b: int) -> np.ndarray:
        return self.state.belief[b, :, :, :2]


class RangeLsBackend(Backend):
    def __init__(self, config: RangeLs, world, network, batch):
        super().__init__(config, world, network, batch)
        c = config
        self.params = rl.LsParams(min_anchors=c.min_anchors, max_rms=c.max_rms, max_std=c.max_std,
                                  gate_chi2=c.gate_chi2)
        model = world.motion_model
        self.linear = model.kind == "cv_accel"
        if self.linear:
            self.F, self.G, self.Q = model.transition, model.input_matrix, model.process_noise
        B, N, d = self.batch, self.num_agents, model.state_dim
        self.state = rl.KalmanState(np.zeros((B, N, d)), np.zeros((B, N, d, d)))
        self.estimate = np.zeros((B, N, 2))
        self.estimate_cov = np.zeros((B, N, 2, 2))
        self.step_Q = None  # this step's process noise from readings.extra["accel_std"] (None: the world's)
        self.last_fixed = np.zeros((B, N), bool)  # the fault agents whose LS fix passed the gate last step

    def reset(self, rngs, idx) -> None:
        mean, cov = self.world.initial_belief()
        self.state.mean[idx], self.state.cov[idx] = mean[idx], cov[idx]
        self.estimate[idx] = mean[idx, :, :2]
        self.estimate_cov[idx] = cov[idx, :, :2, :2]
        self.posterior_position[idx] = mean[idx, :, :2]

    def update(self, readings, decisions) -> None:
        B, N = self.batch, self.num_agents
        normal = np.asarray(readings.fix_valid, bool)
        listening = np.broadcast_to(~np.eye(N, dtype=bool), (B, N, N))
        delivered = self.network.broadcast(normal, listening, 5.0, slot=0)  # [k, s]: k's estimate reached s
        adjacency = delivered.transpose(0, 2, 1) & np.asarray(readings.range_valid, bool)  # [s, k]
        ranges = np.where(adjacency, np.nan_to_num(readings.range), 0.0)
        fix = np.where(normal[..., None], readings.fix, np.nan)
        gps_std = _step_std(readings, "gps_std", np.sqrt(self.world.fix_noise_var()))
        range_std = _step_std(readings, "range_std", np.sqrt(self.world.range_noise_var()))
        velocity = readings.extra.get("velocity")
        if velocity is not None and self.linear:  # an exact velocity reading: the KF's velocity, variance 0
            self.state.mean[..., 2:] = velocity
            self.state.cov[..., 2:, :] = 0.0
            self.state.cov[..., :, 2:] = 0.0
        accel = readings.extra.get("accel_std")
        # this step's process noise (sigma_acc^2 G) G^T per copy, for predict (None: the world's)
        self.step_Q = None if accel is None else (
            (np.asarray(accel, float).reshape(-1, 1, 1) ** 2 * self.G) @ self.G.T)[:, None]
        posterior, self.estimate, self.estimate_cov, self.last_fixed = rl.update(
            self.params, self.state, normal, fix, adjacency, ranges, gps_std, range_std)  # each copy's sigmas
        self.state.mean[:], self.state.cov[:] = posterior.mean, posterior.cov

    def predict(self, inputs) -> None:
        if self.linear:  # wan2014's constant-velocity KF, exactly as estimators.range_ls.step predicts
            Q = self.Q if self.step_Q is None else self.step_Q
            self.state = rl.predict(self.state, inputs, self.F, self.G, Q)
            return
        # any other motion model: the EKF time update of each agent's own Gaussian
        mean, cov = predict_joint(self.world.motion_model, self.state.mean[:, :, None, :], self.state.cov,
                                  np.asarray(inputs, float)[:, :, None, :])
        self.state = rl.KalmanState(mean[:, :, 0, :], symmetrize(cov))

    def position(self) -> np.ndarray:
        return self.estimate

    def position_cov(self) -> np.ndarray:
        """The covariance of the estimate that is output (``estimators.range_ls``, "Reported covariance"): a
        fix's C_fix = (sum_k u_k u_k^T / (sigma_d^2 + u_k^T C_k u_k))^-1 where the output is a fix (the KF
        posterior fused it, but the output is the fix), else the KF posterior's position block."""
        return self.estimate_cov
