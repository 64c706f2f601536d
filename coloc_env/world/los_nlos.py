"""Two-state LOS/NLOS Markov chain per link (gao2016, spec §4) [paper: one chain per
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
        """Modes (steps, *size) as int8 (1 = NLOS), one uniform per link and step; loops over steps only."""
        u = rng.random((steps, *size))
        modes = np.empty((steps, *size), dtype=np.int8)
        modes[0] = u[0] < self.p_nlos
        stay_nlos, enter_nlos = 1.0 - self.p10, self.p01
        for k in range(1, steps):
            modes[k] = np.where(modes[k - 1] == 1, u[k] < stay_nlos, u[k] < enter_nlos)
        return modes
