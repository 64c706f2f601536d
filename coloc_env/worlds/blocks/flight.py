"""Flight paths for ``nlos_horizon``: a target of straight legs and coordinated turns, and
neighbours orbiting it ([chosen] values of docs/gao2016.md, section 9).

A coordinated turn keeps the speed and turns the heading at a constant rate omega; within
one step of length T the exact arc is flown,

    p(k+1) = p(k) + (v / omega) [sin(h + omega T) - sin h, cos h - cos(h + omega T)],
    h(k+1) = h(k) + omega T,

and the straight-line limit v T [cos h, sin h] when omega = 0. Velocity at k is
v [cos h(k), sin h(k)].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import as_array, check_range

__all__ = ["TurnSchedulePath", "OrbitingNeighbours", "OrbitParameters"]


@dataclass(frozen=True)
class TurnSchedulePath:
    """Straight legs joined by coordinated turns [chosen].

    | field          | meaning                               | default                                 |
    |----------------|---------------------------------------|-----------------------------------------|
    | speed          | v [m/s], constant                     | 20                                      |
    | heading        | initial heading [rad] (0 = east)      | 0                                       |
    | turn_rates     | omega of each turn [rad/s]            | 3, -3, 3, -6 deg/s                      |
    | turn_windows   | [start, end) step of each turn        | (200,260) (500,560) (700,730) (850,880) |
    | period         | T [s]                                 | 1                                       |
    """

    speed: float = 20.0
    heading: float = 0.0
    turn_rates: tuple = tuple(np.deg2rad([3.0, -3.0, 3.0, -6.0]).tolist())
    turn_windows: tuple = ((200, 260), (500, 560), (700, 730), (850, 880))
    period: float = 1.0

    def validate(self, prefix: str = "") -> None:
        check_range(f"{prefix}speed", self.speed, 0.0, 1e4)
        check_range(f"{prefix}heading", self.heading, -1e3, 1e3)
        rates = as_array(f"{prefix}turn_rates", self.turn_rates, ndim=1)
        windows = as_array(f"{prefix}turn_windows", self.turn_windows)
        if windows.shape != (len(rates), 2):
            raise ValueError(f"{prefix}turn_windows must have shape ({len(rates)}, 2), one [start, end) per "
                             f"turn rate, got {windows.shape}")
        if np.any(windows[:, 1] <= windows[:, 0]) or np.any(windows < 0):
            raise ValueError(f"{prefix}turn_windows must be [start, end) with 0 <= start < end, "
                             f"got {self.turn_windows}")
        check_range(f"{prefix}period", self.period, 0.0, 1e4, low_open=True)

    def turn_profile(self, steps: int, shift: int = 0) -> np.ndarray:
        """omega(k) for k = 0..steps-1 with every window delayed by ``shift`` steps."""
        omega = np.zeros(steps)
        for rate, (start, end) in zip(self.turn_rates, self.turn_windows, strict=True):
            omega[max(0, start + shift):max(0, min(steps, end + shift))] = rate
        return omega

    def in_turn(self, steps: int, shift: int = 0) -> np.ndarray:
        """True where the target turns, (steps,)."""
        return self.turn_profile(steps, shift) != 0.0

    def trajectory(self, steps: int, start=(0.0, 0.0), shift: int = 0) -> np.ndarray:
        """States [p_x, p_y, v_x, v_y] at k = 0..steps-1, shape (steps, 4), no Python loop over steps."""
        T, v = float(self.period), float(self.speed)
        omega = self.turn_profile(steps, shift)
        heading = self.heading + np.concatenate([[0.0], np.cumsum(omega[:-1] * T)])
        turning = omega != 0.0
        safe = np.where(turning, omega, 1.0)
        after = heading + omega * T
        arc = np.stack([(np.sin(after) - np.sin(heading)) / safe, (np.cos(heading) - np.cos(after)) / safe], -1)
        line = T * np.stack([np.cos(heading), np.sin(heading)], -1)
        moves = v * np.where(turning[:, None], arc, line)
        position = np.asarray(start, float) + np.concatenate([np.zeros((1, 2)), np.cumsum(moves[:-1], axis=0)])
        velocity = v * np.stack([np.cos(heading), np.sin(heading)], -1)
        return np.concatenate([position, velocity], axis=-1)


@dataclass
class OrbitParameters:
    """Per-neighbour orbit parameters, each (..., J): rho0, a, w, phi0, om (see ``OrbitingNeighbours``)."""

    radius: np.ndarray
    wobble: np.ndarray
    wobble_rate: np.ndarray
    phase: np.ndarray
    bearing_rate: np.ndarray


@dataclass(frozen=True)
class OrbitingNeighbours:
    """J neighbours on moving orbits about a target [chosen].

    Offset of neighbour j from the target at time t = k T: radius ``rho0 + a sin(w t + phi0)``,
    bearing ``phi0 + om t``, with rho0 ~ U(radius_range), a ~ U(0, wobble_max),
    w ~ U(wobble_rate_range), stratified phi0_j = 2 pi (j + U(0, 1)) / J, om ~ U(-bearing_rate_max,
    bearing_rate_max).
    """

    count: int = 8
    radius_range: tuple = (150.0, 900.0)
    wobble_max: float = 200.0
    wobble_rate_range: tuple = (0.002, 0.01)
    bearing_rate_max: float = 0.01
    period: float = 1.0

    def validate(self, prefix: str = "") -> None:
        check_range(f"{prefix}count", self.count, 1, 64, integer=True)
        for name, pair in (("radius_range", self.radius_range), ("wobble_rate_range", self.wobble_rate_range)):
            arr = as_array(f"{prefix}{name}", pair, shape=(2,))
            if arr[0] < 0 or arr[1] < arr[0]:
                raise ValueError(f"{prefix}{name} must be (low, high) with 0 <= low <= high, got {pair}")
        check_range(f"{prefix}wobble_max", self.wobble_max, 0.0, 1e6)
        check_range(f"{prefix}bearing_rate_max", self.bearing_rate_max, 0.0, 10.0)
        check_range(f"{prefix}period", self.period, 0.0, 1e4, low_open=True)

    def sample(self, rng: np.random.Generator, size: tuple = ()) -> OrbitParameters:
        """Parameters of shape (*size, J), drawn from ``rng`` in a fixed order."""
        shape = (*size, self.count)
        u = rng.random((5, *shape))
        lo, hi = self.radius_range
        wlo, whi = self.wobble_rate_range
        return OrbitParameters(
            radius=lo + (hi - lo) * u[0],
            wobble=self.wobble_max * u[1],
            wobble_rate=wlo + (whi - wlo) * u[2],
            phase=2.0 * np.pi * (np.arange(self.count) + u[3]) / self.count,
            bearing_rate=self.bearing_rate_max * (2.0 * u[4] - 1.0),
        )

    def offsets(self, params: OrbitParameters, steps: int) -> np.ndarray:
        """Offsets from the target, shape (steps, *size, J, 2)."""
        t = (np.arange(steps) * float(self.period)).reshape(steps, *([1] * params.radius.ndim))
        rho = params.radius + params.wobble * np.sin(params.wobble_rate * t + params.phase)
        bearing = params.phase + params.bearing_rate * t
        return rho[..., None] * np.stack([np.cos(bearing), np.sin(bearing)], axis=-1)
