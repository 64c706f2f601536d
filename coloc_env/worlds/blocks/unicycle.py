"""Planar unicycle kinematics and platforms flying circles.

A unicycle moves ``dt * speed`` along its heading, then turns by
``dt * turn_rate`` (forward Euler, the discretization of eq. (1) of wang2019):

    p(k+1) = p(k) + dt v(k) [cos phi(k); sin phi(k)],   phi(k+1) = phi(k) + dt omega(k).

With constant v and omega the vertices p(k) lie exactly on a circle (a
regular polygon) when the start heading is the tangent turned by
dt omega / 2; ``CircularTracks`` sets that up, so "ideal circles" hold
at every step, not only in the limit dt -> 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import as_array, check_range


@dataclass(frozen=True)
class UnicycleMotion:
    """Forward-Euler unicycle with step ``dt`` (seconds); batched over any leading axes."""

    dt: float = 0.5

    def validate(self, prefix: str = "") -> None:
        check_range(f"{prefix}dt", self.dt, 0.0, 3600.0, low_open=True)

    def step(self, position: np.ndarray, heading: np.ndarray, speed: np.ndarray, turn_rate: np.ndarray):
        """One step: ``position`` (..., 2), ``heading``/``speed``/``turn_rate`` (...). Returns (position, heading)."""
        heading = np.asarray(heading, float)
        move = self.dt * np.asarray(speed, float)[..., None] * np.stack([np.cos(heading), np.sin(heading)], axis=-1)
        return np.asarray(position, float) + move, heading + self.dt * np.asarray(turn_rate, float)

    def headings(self, initial_heading: np.ndarray, turn_rate: np.ndarray) -> np.ndarray:
        """phi(0..K-1) from phi(0) (...) and omega(0..K-1) (..., K): the heading used in each step."""
        turn_rate = np.asarray(turn_rate, float)
        turned = np.cumsum(self.dt * turn_rate, axis=-1) - self.dt * turn_rate  # exclusive prefix sum
        return np.asarray(initial_heading, float)[..., None] + turned

    def rollout(self, initial_position: np.ndarray, initial_heading: np.ndarray, speed: np.ndarray,
                turn_rate: np.ndarray):
        """Positions (..., K+1, 2) and headings (..., K+1) for speeds and turn rates (..., K), no Python loop."""
        speed = np.asarray(speed, float)
        heading = self.headings(initial_heading, turn_rate)
        moves = self.dt * speed[..., None] * np.stack([np.cos(heading), np.sin(heading)], axis=-1)
        start = np.asarray(initial_position, float)[..., None, :]
        positions = np.concatenate([start, start + np.cumsum(moves, axis=-2)], axis=-2)
        last = heading[..., -1:] + self.dt * np.asarray(turn_rate, float)[..., -1:]
        return positions, np.concatenate([heading, last], axis=-1)


@dataclass(frozen=True)
class CircularTracks:
    """N platforms on circles at constant speed and turn rate.

    | field        | shape  | meaning                                                         |
    |--------------|--------|-----------------------------------------------------------------|
    | centres      | (N, 2) | circle centres [m]                                              |
    | start_angles | (N,)   | polar angle of each start point about its centre [rad]          |
    | directions   | (N,)   | +1 counter-clockwise, -1 clockwise                              |
    | speed        | ()     | v [m/s], the same for all                                       |
    | turn_rate    | ()     | |omega| [rad/s]; radius = dt v / (2 sin(dt |omega| / 2)) ~ v/|omega| |
    | dt           | ()     | step [s]                                                        |
    """

    centres: np.ndarray
    start_angles: np.ndarray
    directions: np.ndarray
    speed: float = 1.0
    turn_rate: float = 0.015
    dt: float = 0.5

    @property
    def count(self) -> int:
        return np.asarray(self.centres).shape[0]

    def validate(self, prefix: str = "") -> None:
        centres = as_array(f"{prefix}centres", self.centres, ndim=2)
        if centres.shape[1] != 2:
            raise ValueError(f"{prefix}centres must have shape (N, 2), got {centres.shape}")
        as_array(f"{prefix}start_angles", self.start_angles, shape=(centres.shape[0],))
        directions = as_array(f"{prefix}directions", self.directions, shape=(centres.shape[0],))
        if not np.all(np.isin(directions, (-1.0, 1.0))):
            raise ValueError(f"{prefix}directions must be +1 (counter-clockwise) or -1 (clockwise), "
                             f"got {self.directions}")
        check_range(f"{prefix}speed", self.speed, 0.0, 1e4, low_open=True)
        UnicycleMotion(self.dt).validate(prefix)
        check_range(f"{prefix}turn_rate", self.turn_rate, 0.0, np.pi / self.dt, low_open=True)

    @property
    def radius(self) -> float:
        half_turn = 0.5 * self.dt * self.turn_rate
        return float(self.dt * self.speed / (2.0 * np.sin(half_turn)))

    @property
    def turn_rates(self) -> np.ndarray:
        """Signed omega_i (N,)."""
        return np.asarray(self.directions, float) * self.turn_rate

    def initial_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Start positions (N, 2) on the circles and headings (N,) (tangent + dt omega / 2)."""
        angles = np.asarray(self.start_angles, float)
        directions = np.asarray(self.directions, float)
        position = np.asarray(self.centres, float) + self.radius * np.stack([np.cos(angles), np.sin(angles)], axis=-1)
        heading = angles + directions * np.pi / 2 + 0.5 * self.dt * self.turn_rates
        return position, heading

    def trajectory(self, steps: int):
        """True positions (steps+1, N, 2), headings (steps+1, N), and the constant speeds/turn rates (N,)."""
        position, heading = self.initial_pose()
        N = self.count
        speed = np.full((N, steps), float(self.speed))
        turn = np.broadcast_to(self.turn_rates[:, None], (N, steps))
        positions, headings = UnicycleMotion(self.dt).rollout(position, heading, speed, turn)
        return np.swapaxes(positions, 0, 1), headings.T, np.full(N, float(self.speed)), self.turn_rates
