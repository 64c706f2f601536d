"""Links whose packet, every slot, arrives on time, one slot late, or is lost.

Each slot k of each link draws one outcome, i.i.d. over slots and links
(Fu, Bi, Gao 2017, eq. 3):

| outcome   | code      | probability         | the receiver then holds            |
|-----------|-----------|---------------------|------------------------------------|
| on time   | ON_TIME 0 | on_time (alpha1)    | this slot's packet                 |
| late      | LATE 1    | late (alpha2)       | the previous slot's packet         |
| lost      | LOST 2    | 1 - alpha1 - alpha2 | what it held before                |

The indicator variables xi1 = [on time], xi2 = [late] are exclusive, so
Cov(xi1, xi2) = -alpha1 alpha2 (see ``BernoulliDelayLink.indicator_cov``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.config import check_range
from estimators.lossy_fusion import LATE, LOST, ON_TIME, deliver

__all__ = ["BernoulliDelayLink", "ON_TIME", "LATE", "LOST", "deliver"]


@dataclass(frozen=True)
class BernoulliDelayLink:
    """On-time / one-slot-late / lost link.

    | field    | symbol | meaning                               | fu2017 |
    |----------|--------|---------------------------------------|--------|
    | on_time  | alpha1 | probability a packet arrives on time  | 0.4    |
    | late     | alpha2 | probability it arrives one slot late  | 0.3    |
    """

    on_time: float = 0.4
    late: float = 0.3

    def validate(self, on_time_name: str = "on_time", late_name: str = "late") -> None:
        check_range(on_time_name, self.on_time, 0.0, 1.0)
        check_range(late_name, self.late, 0.0, 1.0)
        total = float(self.on_time) + float(self.late)
        if not 0.0 < total <= 1.0 + 1e-12:
            raise ValueError(f"{on_time_name} + {late_name} must be in (0, 1] (a packet is on time, late or lost, "
                             f"and a link must deliver sometimes), got {total!r}")

    @property
    def lost(self) -> float:
        return max(0.0, 1.0 - float(self.on_time) - float(self.late))

    @property
    def probabilities(self) -> np.ndarray:
        """P(on time), P(late), P(lost)."""
        return np.array([float(self.on_time), float(self.late), self.lost])

    def indicator_cov(self) -> np.ndarray:
        """Covariance of (xi1, xi2): [[a1(1-a1), -a1 a2], [-a1 a2, a2(1-a2)]]."""
        a1, a2 = float(self.on_time), float(self.late)
        return np.array([[a1 * (1 - a1), -a1 * a2], [-a1 * a2, a2 * (1 - a2)]])

    def sample(self, rng: np.random.Generator, size: tuple[int, ...]) -> np.ndarray:
        """Outcome codes (int8) of shape ``size`` drawn from ``rng`` with one uniform per slot."""
        u = rng.random(size)
        a1, a2 = float(self.on_time), float(self.late)
        return np.where(u < a1, ON_TIME, np.where(u < a1 + a2, LATE, LOST)).astype(np.int8)
