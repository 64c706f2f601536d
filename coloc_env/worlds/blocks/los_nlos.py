"""Two-state LOS/NLOS Markov chain per link (gao2016, docs/gao2016.md §4) [paper: one chain per
(receiver, neighbour) link; the target can be LOS to one neighbour and NLOS to another].

Transition matrix [[1 - p01, p01], [p10, 1 - p10]] (0 = LOS, 1 = NLOS), parametrised by the
stationary NLOS probability pi = p01 / (p01 + p10) and p10 (mean NLOS sojourn 1 / p10 steps);
each chain starts from pi, so it is stationary at every step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import check_range

__all__ = ["LosNlosChain"]


@dataclass(frozen=True)
class LosNlosChain:
    """LOS/NLOS chain with stationary NLOS probability ``p_nlos`` (pi) and NLOS->LOS ``p10``."""

    p_nlos: float = 0.3
    p10: float = 0.1

    @property
    def p01(self) -> float:
        """LOS -> NLOS probability pi p10 / (1 - pi) (0 when pi = 1 and p10 = 0: always NLOS)."""
        if self.p_nlos >= 1.0:
            return 1.0
        return float(self.p_nlos) * float(self.p10) / (1.0 - float(self.p_nlos))

    def validate(self, nlos_name: str = "p_nlos", p10_name: str = "p10") -> None:
        check_range(nlos_name, self.p_nlos, 0.0, 1.0)
        check_range(p10_name, self.p10, 0.0, 1.0)
        if self.p_nlos >= 1.0 and self.p10 > 0.0:
            raise ValueError(f"{nlos_name} = 1 needs {p10_name} = 0 (an always-NLOS chain never leaves NLOS)")
        if self.p01 > 1.0 + 1e-12:
            raise ValueError(f"{nlos_name} and {p10_name} give p01 = pi p10 / (1 - pi) = {self.p01:.3g} > 1; "
                             f"need pi p10 <= 1 - pi")

    @property
    def transition(self) -> np.ndarray:
        return np.array([[1.0 - self.p01, self.p01], [self.p10, 1.0 - self.p10]])

    def sample(self, rng: np.random.Generator, steps: int, size: tuple = ()) -> np.ndarray:
        """Modes (steps, *size) as int8 (1 = NLOS), one uniform u_k per link and step:

            mode_0 = [u_0 < pi],   mode_k = [u_k < 1 - p10] if mode_{k-1} = 1 else [u_k < p01].

        Computed without a loop over steps: step k maps mode_{k-1} to a constant (both tests agree), to itself
        or to its negation, so mode_k is the constant of the last constant map at or before k (mode_0 if none)
        flipped once per negating map since then (a count difference of a cumulative sum). Booleans and
        integers only: the same modes as the recursion."""
        u = rng.random((steps, *size))
        if steps == 0:
            return np.zeros((0, *size), np.int8)
        if_nlos = u < 1.0 - self.p10  # mode_k when mode_{k-1} = 1 (row 0 unused)
        if_los = u < self.p01  # mode_k when mode_{k-1} = 0
        constant = if_nlos == if_los
        constant[0] = True  # step 0 "sets" mode_0
        value = np.where(np.arange(steps).reshape(steps, *([1] * len(size))) == 0, u < self.p_nlos, if_nlos)
        negating = if_los & ~if_nlos
        negating[0] = False
        flips = np.cumsum(negating, axis=0, dtype=np.int64)
        steps_index = np.broadcast_to(np.arange(steps).reshape(steps, *([1] * len(size))), u.shape)
        last = np.maximum.accumulate(np.where(constant, steps_index, 0), axis=0)
        start = np.take_along_axis(value, last, axis=0)
        parity = (flips - np.take_along_axis(flips, last, axis=0)) & 1
        return (start ^ parity.astype(bool)).astype(np.int8)
