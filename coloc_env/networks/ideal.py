"""Network ``ideal``: every packet arrives at once, any distance; relay chains run nearest first to everyone.

| quantity          | value                                                  |
|-------------------|--------------------------------------------------------|
| carries           | ``broadcast``, ``chain``, ``central``, ``packets``     |
| decisions         | none                                                   |
| delivery          | every message, on time                                 |
| accounting        | messages and floats at the sender (see the base)       |

No fields.
"""

from __future__ import annotations

from dataclasses import dataclass

from coloc_env.networks.base import Network
from coloc_env.parts import NETWORKS, PartConfig


@NETWORKS.register
@dataclass(frozen=True)
class Ideal(PartConfig):
    """Config of the ``ideal`` network (no fields)."""

    name = "ideal"
    carries = frozenset({"broadcast", "chain", "central", "packets", "components"})

    def check(self, prefix: str) -> None:
        return None

    def build(self, num_agents: int, batch: int, message_kind: str, rounds: int = 1) -> Network:
        return Network(self, num_agents, batch, message_kind, rounds)
