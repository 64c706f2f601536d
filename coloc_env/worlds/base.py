"""The world of a composition: truth and sensors for B copies of N agents.

A world simulates the truth with its motion model (an object of
``estimators.models``, the one the backends assume) and draws every sensor
reading of an episode at reset from the world's own generator, so that the
same world and seed give every backend the same truth and the same readings.
At each step it hands the backend a ``Readings`` of time k, then
advances to k + 1.

A world subclass fills in small hooks (VMAS-style): ``draw_episode`` (the
episode's truth and noise for some copies), ``readings`` (time k's readings,
given the agents' sensing choices) and ``positions`` (the truth at k).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from coloc_env.parts import Block


@dataclass
class Readings:
    """What the sensors report at time k (B copies, N agents); entries outside a mask are ignored.

    | field         | shape       | meaning                                                          |
    |---------------|-------------|------------------------------------------------------------------|
    | inputs        | (B, N, u)   | motion-model input for k -> k+1 (odometry, accelerometer)        |
    | range         | (B, N, N)   | [m, n] range m measured to n (metres)                            |
    | range_valid   | (B, N, N)   | [m, n] m measured n at k                                         |
    | fix           | (B, N, 2)   | absolute position fix (GPS, anchor), metres                      |
    | fix_valid     | (B, N)      | the fix is good at k (GPS normal)                                |
    """

    inputs: np.ndarray
    range: np.ndarray
    range_valid: np.ndarray
    fix: np.ndarray
    fix_valid: np.ndarray
    extra: dict = field(default_factory=dict)

    def take(self, idx) -> Readings:
        return Readings(self.inputs[idx], self.range[idx], self.range_valid[idx], self.fix[idx],
                        self.fix_valid[idx], {k: v[idx] for k, v in self.extra.items()})


class World:
    """Batched truth and sensors. Its config class describes the world for the compatibility table:

    | attribute         | meaning                                                              |
    |-------------------|----------------------------------------------------------------------|
    | estimand          | ``"self"``: each agent localizes itself; ``"target"``: a shared state |
    | motion_kind       | the ``estimators.models`` kind the truth follows                  |
    | measurements      | the measurement kinds it provides (``range``, ``position_fix``, ...) |
    | anchors           | in words: who has absolute position information                      |
    | bound_model       | the ``coloc_env.bounds.models`` module of its bound, or ``NoBound(why)`` |
    """

    agent_prefix: ClassVar[str] = "uav"
    # True where range[m, n] and range[n, m] are one measurement known to both ends (fuse it once)
    symmetric_ranges: ClassVar[bool] = False

    def __init__(self, config, batch: int, horizon: int):
        self.config = config
        self.batch = int(batch)
        self.horizon = int(horizon)
        self.k = np.zeros(self.batch, dtype=int)
        # Whether the backend reads Readings.fix (set by the composition from Backend.reads_fixes): a world whose
        # fixes cost a computation of their own (mrclam's pseudo-fixes from its own-navigation filters) skips it.
        self.fixes_needed = True

    # --- description ------------------------------------------------------------------
    @property
    def num_agents(self) -> int:
        return self.config.num_agents

    @property
    def dt(self) -> float:
        return self.config.dt

    motion_model = None  # set by subclasses: the estimators.models object of the truth

    def sensing_blocks(self) -> list[Block]:
        """The world's part of the action (sensing choices); none by default."""
        return []

    def sensing_masks(self, distances) -> list[np.ndarray] | None:
        """The valid choices of the sensing blocks for the coming step, one (B, N, size, choices) bool per
        block, by the world's own rule (a masked choice does what the block's "none" does); ``distances()``
        gives the (B, N, N) distances between the agents now. None (the default): every choice valid."""
        return None

    def range_noise_var(self) -> float:
        """Variance of a range reading (m^2), where the world has ranges."""
        raise NotImplementedError

    def fix_noise_var(self) -> float:
        """Variance per axis of a position fix (m^2), where the world has fixes."""
        raise NotImplementedError

    def warm_start_std(self) -> float | None:
        """Std per axis (m) of a particle filter's warm start around the initial belief's positions; None (the
        default): the filter's own choice (``dnbp``: sigma_gps, wan2014's last fix before the loss)."""
        return None

    # --- dynamics ---------------------------------------------------------------------------
    def reset(self, rngs, idx: np.ndarray) -> None:
        """New episodes in copies ``idx``, one generator per copy: the whole episode is drawn here."""
        self.k[idx] = 0
        self.draw_episode(rngs, idx)

    def draw_episode(self, rngs, idx: np.ndarray) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def readings(self, sensing: np.ndarray) -> Readings:  # pragma: no cover - interface
        """Readings of time k; ``sensing`` (B, N, n) the decoded sensing block (n may be 0)."""
        raise NotImplementedError

    def advance(self) -> None:
        self.k = self.k + 1

    def positions(self) -> np.ndarray:  # pragma: no cover - interface
        """True positions at k, (B, N, 2)."""
        raise NotImplementedError

    def distances(self) -> np.ndarray:
        """True distances between the agents at k (B, N, N): ||p_i - p_j|| of ``positions`` (a world with a
        table of them returns the same floats from it)."""
        p = self.positions()
        return np.sqrt(np.sum((p[:, :, None, :] - p[:, None, :, :]) ** 2, axis=-1))

    def initial_belief(self) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - interface
        """What the agents know at k = 0: mean (B, N, d) and per-agent covariance (B, N, d, d)."""
        raise NotImplementedError

    def region(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """What the agents are told of the flight area, for estimators that need a support (dNBP's
        defensive and cold-start boxes): ``(start, episode)``, each ``(lo, hi)`` per axis (metres),
        the square holding the agents at k = 0 and the one holding them over the whole episode."""
        raise NotImplementedError(f"world {self.config.name!r} does not declare its flight region")

    def observation_features(self) -> np.ndarray:
        """(B, N, f) what each agent senses of the world at k (e.g. 'I measure now'); none by default."""
        return np.zeros((self.batch, self.num_agents, 0))

    def feature_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(0), np.zeros(0)

    def extent(self) -> float:
        """Half-width of the square the renderer shows (metres)."""
        return float(np.abs(self.positions()).max()) + 10.0
