"""A radio broadcast medium that counts what it carries.

A sender's one transmission (a *broadcast*) reaches every neighbour that the
protocol lets listen; each (sender -> receiver) delivery is one *message*.
A sender with no eligible listener transmits nothing and is not counted.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from coloc_env.config import check_range


@dataclass(frozen=True)
class BroadcastMedium:
    """Delivers broadcasts over an adjacency and counts broadcasts and messages.

    | field             | meaning                                                    |
    |-------------------|------------------------------------------------------------|
    | payload_per_item  | floats per message item (wan2014: a particle message has   |
    |                   | M centres (2) + M weights (1), plus one bandwidth)         |
    """

    payload_per_item: int = 3

    def validate(self, prefix: str = "") -> None:
        check_range(f"{prefix}payload_per_item", self.payload_per_item, 0, 10**6, integer=True)

    @staticmethod
    def deliver(senders: np.ndarray, adjacency: np.ndarray, listening: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
        """(delivered (..., N, N) with [t, s] = t's broadcast reaches s, broadcasts (..., N) 0/1).

        ``listening`` (..., N, N) [t, s]: s may take t's message (the schedule's rule); None = all.
        """
        delivered = np.asarray(senders, bool)[..., :, None] & np.asarray(adjacency, bool)
        if listening is not None:
            delivered &= np.asarray(listening, bool)
        return delivered, delivered.any(axis=-1).astype(int)

    def over(self, adjacency: np.ndarray) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
        """The ``deliver(senders, listening) -> delivered`` of one step's ``adjacency`` (..., N, N).

        senders (..., N) bool, listening (..., N, N) bool [t, s]; delivered (..., N, N) bool [t, s] =
        t sends, s is adjacent to t and listens (``deliver``). This is the network an estimator
        such as ``estimators.dnbp.step`` is handed.
        """
        adjacency = np.asarray(adjacency, bool)

        def deliver(senders: np.ndarray, listening: np.ndarray) -> np.ndarray:
            return self.deliver(senders, adjacency, listening)[0]

        return deliver

    def payload(self, messages: np.ndarray, items: int) -> np.ndarray:
        """Floats carried by ``messages`` deliveries of ``items`` items each (plus one bandwidth each)."""
        return np.asarray(messages) * (self.payload_per_item * items + 1)
