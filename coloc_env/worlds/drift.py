"""World ``drift`` (zhao2020): one linear drift state x, observed by every agent through a linear sensor.

Zhao, Liu, Zhao, Gao 2020 (seed ``001_c743ba0d1c0e3ecf.txt``), simulation of
Sec. 2: x(k+1) = A x(k) + B + w(k) (eqs. 1, 22), y_j(k) = C x(k) + v_j(k)
(eqs. 2, 23); the paper linearizes each UAV's UWB ranges to four anchors into
C = I, so x is a 3-D position [x, y, z] (m) and B = v dt its known drift. Every
agent estimates the same x (estimand ``target``). The episode's x(0) ~ N(xhat(0),
M(0)), w(0..K-1) and v_j(0..K-1) are drawn at reset from the world's
generator by ``draw_episode``, in that order (every composition of this
world, the ``bandwidth_fusion`` preset included, sees the same episodes for
the same seed); x(0..K) is kept (K + 1 states: x(K) is the state after the
last step, which the last observation and the renderer read).

The paper does not say where the UAVs fly (its links do not depend on
distance); the agents hold a fixed ring of radius ``formation_radius`` about
the origin, which only the link state of distance-dependent networks
(``relay``, ``broadcast``) and the observation's distance entries read.

| quantity          | value                                                                             |
|-------------------|-----------------------------------------------------------------------------------|
| estimand          | ``target``: the shared state x (n = 3 by default)                                 |
| motion model      | ``estimators.linear_models.LinearGaussian`` (A, B, W), kind ``linear_gaussian`` |
| measurements      | ``linear_observation``: y_j = C x + v_j at every step, every agent                 |
| anchors           | none among the agents: the sensor C x is absolute (the paper's UWB anchors are folded into C) |
| sensing action    | none                                                                              |
| observation       | none                                                                              |
| "position"        | the first two state components (x, y of the paper's 3-D position), metres         |
| ``error``         | ||xhat_i - x||^2 over every state component (m^2): the summand of J_K, eq. (12)    |
| prior             | every agent starts from xhat(0) with covariance M(0)                              |

Arguments (``coloc_env.worlds.Drift``; defaults = the paper's Sec. 2)

| field              | default                | allowed                                         |
|--------------------|------------------------|-------------------------------------------------|
| num_agents         | 4                      | 2..16                                           |
| transition         | I_3                    | (n, n), n in 2..16, entries in [-1e6, 1e6],     |
|                    |                        | spectral radius <= 1.001                        |
| drift              | (0.5, 0.5, 0.5)        | (n,) in [-1e6, 1e6] (m per step)                |
| measurement        | I_3                    | (m, n), m in 1..16, entries in [-1e6, 1e6]      |
| process_noise      | diag(0.02, 0.05, 0.03) | (n, n) PSD, entries <= 1e12 (m^2)               |
| measurement_noise  | diag(0.03, 0.04, 0.02) | (m, m) or (num_agents, m, m) PD, <= 1e12 (m^2)  |
| initial_state      | (10, 10, 10)           | (n,) in [-1e6, 1e6]: xhat(0); x(0) ~ N(this, .) |
| initial_cov        | diag(0.19, 0.09, 0.08) | (n, n) PSD, entries <= 1e12: M(0)               |
| horizon            | 50                     | 1..100000 steps (the composition's default)     |
| formation_radius   | 10.0                   | [0, 1e6] m: the agents' fixed ring              |

Estimation problem (what ``coloc_env.pcrb`` bounds; details in ``coloc_env.bounds.models.target``): the
state is the drift state x; the prior is the world's initial covariance; the motion x(k+1) = A x + b + w
is linear with Gaussian w; every agent reads C x + v at every step. Linear and Gaussian, so the bound is
the covariance of the Kalman filter with the same information.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from coloc_env.config import as_array, check_psd, check_range, check_stable
from coloc_env.parts import WORLDS, PartConfig
from coloc_env.worlds.base import Readings, World
from coloc_env.worlds.blocks.noise import covariance_factor, sample_gaussian
from coloc_env.worlds.blocks.sensors import LinearSensor
from estimators.linear_models import LinearGaussian, LinearObservation


def _read_only(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


def _eye(n):
    return tuple(tuple(float(i == j) for j in range(n)) for i in range(n))


def _diag(*values):
    return tuple(tuple(v if i == j else 0.0 for j in range(len(values))) for i, v in enumerate(values))


def ring(num_agents: int, radius: float) -> np.ndarray:
    """(N, 2) agent positions on a ring of ``radius`` about the origin, agent 0 on the +x axis."""
    angle = 2.0 * np.pi * np.arange(num_agents) / num_agents
    return radius * np.stack([np.cos(angle), np.sin(angle)], axis=-1)


class TargetWorld(World):
    """Common runtime of the target worlds: the episode's states x(0..K) (B, K+1, n) and readings y (B, K, N, m).

    Subclasses fill ``truth``, ``observations`` in ``draw_episode`` and set ``motion_model``,
    ``measurement_model``, ``position_index`` (the two state components called "position"),
    ``metric`` (p, n) (``error`` = ||metric (xhat - x)||^2) and the prior.
    """

    position_index: tuple[int, int] = (0, 1)

    def __init__(self, config, batch: int, horizon: int, n: int, m: int, metric: np.ndarray):
        super().__init__(config, batch, horizon)
        B, N, K = self.batch, self.num_agents, self.horizon
        self.state_dim, self.measurement_dim = n, m
        self.metric = np.asarray(metric, float)
        self.truth = np.zeros((B, K + 1, n))
        self.observations = np.zeros((B, K, N, m))
        self._ring = ring(N, float(config.formation_radius))

    # --- what backends read ---------------------------------------------------------------
    def prior(self) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - interface
        """(x0 mean (n,), P0 (n, n)): what every agent knows of x(0)."""
        raise NotImplementedError

    def initial_belief(self):
        B, N = self.batch, self.num_agents
        mean, cov = self.prior()
        return (np.broadcast_to(mean, (B, N, mean.size)).copy(),
                np.broadcast_to(cov, (B, N, *cov.shape)).copy())

    def target_state(self, offset: int = 0) -> np.ndarray:
        """True x(k + offset), (B, n) (clipped to the last state drawn), a new array."""
        k = np.minimum(self.k + offset, self.horizon)
        return self.truth[self._copies, k]

    def target_position(self, offset: int = 0) -> np.ndarray:
        return self.target_state(offset)[:, list(self.position_index)]

    def error(self, estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
        """||metric (estimate - truth)||^2, (B, N): estimate (B, N, n), truth (B, n)."""
        return (((estimate - truth[:, None, :]) @ self.metric.T) ** 2).sum(axis=-1)

    def positions(self) -> np.ndarray:
        """The agents' positions (B, N, 2): the fixed ring (what the radios sense)."""
        return self._ring_positions

    @functools.cached_property
    def _ring_positions(self) -> np.ndarray:
        return np.broadcast_to(self._ring, (self.batch, self.num_agents, 2))  # read only: the ring never moves

    def readings(self, sensing: np.ndarray) -> Readings:
        k = np.minimum(self.k, self.horizon - 1)
        y = self.observations[self._copies, k]
        return Readings(**self._no_other_sensors, extra={"linear": y, "linear_valid": self._all_valid})

    @functools.cached_property
    def _copies(self) -> np.ndarray:
        return np.arange(self.batch)

    @functools.cached_property
    def _all_valid(self) -> np.ndarray:
        return _read_only(np.ones((self.batch, self.num_agents), bool))

    @functools.cached_property
    def _no_other_sensors(self) -> dict:
        """The Readings fields of sensors this world has not (read only, built once: readings runs every step)."""
        B, N = self.batch, self.num_agents
        return {"inputs": _read_only(np.zeros((B, N, 0))), "range": _read_only(np.full((B, N, N), np.nan)),
                "range_valid": _read_only(np.zeros((B, N, N), bool)), "fix": _read_only(np.zeros((B, N, 2))),
                "fix_valid": _read_only(np.zeros((B, N), bool))}

    def extent(self) -> float:
        return float(max(np.abs(self.target_position()).max(), float(self.config.formation_radius))) + 10.0


# The magnitudes the mathematics supports over a 1e5-step horizon (larger ones overflow or make the
# innovation covariance numerically singular); the Arguments tables state them.
VALUE_BOUND = 1e6   # |entries| of drift, measurement, initial_state
COV_BOUND = 1e12    # |entries| of the noise and prior covariances (m^2)


def check_linear_world(prefix: str, config) -> tuple[int, int]:
    """Checks of a (transition, measurement, noises, prior) world; returns (n, m)."""
    A = as_array(f"{prefix}transition", config.transition, ndim=2, bound=VALUE_BOUND)
    n = A.shape[0]
    if A.shape != (n, n) or not 2 <= n <= 16:
        raise ValueError(f"{prefix}transition must be a square (n, n) matrix with n in [2, 16], got shape {A.shape}")
    check_stable(f"{prefix}transition", A)
    as_array(f"{prefix}drift", config.drift, shape=(n,), bound=VALUE_BOUND)
    C = as_array(f"{prefix}measurement", config.measurement, ndim=2, bound=VALUE_BOUND)
    if C.shape[1] != n or not 1 <= C.shape[0] <= 16:
        raise ValueError(f"{prefix}measurement must have shape (m, {n}) with m in [1, 16], got {C.shape}")
    check_psd(f"{prefix}process_noise", config.process_noise, n, bound=COV_BOUND)
    V = as_array(f"{prefix}measurement_noise", config.measurement_noise, bound=COV_BOUND)
    if V.ndim not in (2, 3) or (V.ndim == 3 and V.shape[0] != config.num_agents):
        raise ValueError(f"{prefix}measurement_noise must be (m, m) or ({config.num_agents}, m, m), got {V.shape}")
    if V.shape[-2:] != (C.shape[0],) * 2:  # m is set by measurement: a mismatch names both fields
        raise ValueError(f"{prefix}measurement_noise must be (m, m) with m = {C.shape[0]}, the rows of "
                         f"{prefix}measurement (shape {C.shape}), got shape {V.shape}")
    for j, Vj in enumerate(V if V.ndim == 3 else V[None]):
        check_psd(f"{prefix}measurement_noise" + (f"[{j}]" if V.ndim == 3 else ""), Vj, C.shape[0], strict=True)
    as_array(f"{prefix}initial_state", config.initial_state, shape=(n,), bound=VALUE_BOUND)
    check_psd(f"{prefix}initial_cov", config.initial_cov, n, bound=COV_BOUND)
    return n, C.shape[0]


@WORLDS.register
@dataclass(frozen=True)
class Drift(PartConfig):
    """Config of the ``drift`` world (see the module table)."""

    name = "drift"
    bound_model = "target"  # coloc_env.bounds.models.target
    estimand = "target"
    motion_kind = LinearGaussian.kind
    measurements = frozenset({"linear_observation"})
    anchors = "none among the agents: every agent's linear sensor C x is absolute"
    num_agents: int = 4
    transition: tuple = _eye(3)
    drift: tuple = (0.5, 0.5, 0.5)
    measurement: tuple = _eye(3)
    process_noise: tuple = _diag(0.02, 0.05, 0.03)
    measurement_noise: tuple = _diag(0.03, 0.04, 0.02)
    initial_state: tuple = (10.0, 10.0, 10.0)
    initial_cov: tuple = _diag(0.19, 0.09, 0.08)
    horizon: int = 50
    formation_radius: float = 10.0

    def check(self, prefix: str) -> None:
        check_range(f"{prefix}num_agents", self.num_agents, 2, 16, integer=True)
        check_linear_world(prefix, self)
        check_range(f"{prefix}horizon", self.horizon, 1, 100_000, integer=True)
        check_range(f"{prefix}formation_radius", self.formation_radius, 0.0, 1e6)

    def models(self) -> tuple[LinearGaussian, LinearObservation]:
        """The motion model (A, B, W) and the agents' measurement model (C, V_j) the world simulates with."""
        return (LinearGaussian(self.transition, self.drift, self.process_noise),
                LinearObservation(self.measurement, np.asarray(self.measurement_noise, float)))

    def build(self, batch: int, horizon: int) -> DriftWorld:
        return DriftWorld(self, batch, horizon)


@dataclass(frozen=True)
class NoiseFactors:
    """Square-root factors F (F F^T = covariance) of a ``Drift`` config's noises, computed once per world."""

    initial: np.ndarray  # (n, n), of M(0)
    process: np.ndarray  # (n, n), of W
    measurement: np.ndarray  # (N, m, m), of each V_j


def noise_factors(config: Drift) -> NoiseFactors:
    """The factors of M(0), W and every agent's V_j (``coloc_env.worlds.blocks.noise.covariance_factor``)."""
    V = np.asarray(config.measurement_noise, float)
    per_agent = V if V.ndim == 3 else np.broadcast_to(V, (config.num_agents, *V.shape))
    return NoiseFactors(initial=covariance_factor(np.asarray(config.initial_cov, float)),
                        process=covariance_factor(np.asarray(config.process_noise, float)),
                        measurement=np.stack([covariance_factor(Vj) for Vj in per_agent]))


def draw_episode(config: Drift, rng: np.random.Generator, factors: NoiseFactors | None = None,
                 horizon: int | None = None) -> dict[str, np.ndarray]:
    """One episode's randomness drawn from ``rng``, in this order: x(0) ~ N(xhat(0), M(0)), w(0..K-1),
    then v_j(0..K-1) of every agent (standard normals (K, N, m) times each F_j).

    Returns ``initial_state`` x(0) (n,), ``process_noise`` (K, n) and ``measurement_noise`` (K, N, m).
    ``factors``: ``noise_factors(config)``, when the caller has them; ``horizon``: K, by default the
    config's.
    """
    factors = noise_factors(config) if factors is None else factors
    K = config.horizon if horizon is None else horizon
    N, m = factors.measurement.shape[:2]
    x0 = np.asarray(config.initial_state, float) + sample_gaussian(rng, factors.initial, ())
    process = sample_gaussian(rng, factors.process, (K,))
    white = rng.standard_normal((K, N, m))
    measurement = (factors.measurement @ white[..., None])[..., 0]
    return {"initial_state": x0, "process_noise": process, "measurement_noise": measurement}


class DriftWorld(TargetWorld):
    position_index = (0, 1)

    def __init__(self, config: Drift, batch: int, horizon: int):
        n = np.asarray(config.transition).shape[0]
        m = np.asarray(config.measurement).shape[0]
        super().__init__(config, batch, horizon, n, m, np.eye(n))
        self.motion_model, self.measurement_model = config.models()
        self._sensor = LinearSensor(np.asarray(config.measurement, float), np.eye(m))
        self._factors = noise_factors(config)

    def prior(self):
        return np.asarray(self.config.initial_state, float), np.asarray(self.config.initial_cov, float)

    def draw_episode(self, rngs, idx) -> None:
        A = self.motion_model
        # each copy's noise from its own generator; the recursion then runs once over all of them (einsum's
        # own loops: the same bits per copy as the copy alone, whatever the batch)
        episodes = [draw_episode(self.config, rng, self._factors, self.horizon) for rng in rngs]
        if not episodes:
            return
        idx = np.asarray(idx)
        truth = np.empty((len(idx), self.horizon + 1, self.state_dim))
        truth[:, 0] = [episode["initial_state"] for episode in episodes]
        process = np.stack([episode["process_noise"] for episode in episodes])
        for k in range(self.horizon):  # x(k+1) = A x(k) + B + w(k), as LinearMotion.step computes it
            truth[:, k + 1] = np.einsum("ab,cb->ca", A.transition, truth[:, k]) + A.drift + process[:, k]
        self.truth[idx] = truth
        self.observations[idx] = self._sensor.measure(truth[:, :self.horizon, None, :],
                                                      np.stack([episode["measurement_noise"] for episode in episodes]))


__all__ = ["Drift", "DriftWorld", "NoiseFactors", "TargetWorld", "check_linear_world", "draw_episode", "noise_factors",
           "ring"]
