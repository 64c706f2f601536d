"""A paper scenario as a binding on the composable core.

A preset (``relay_ukf``, ...) is a ``coloc_env.scenarios.composed.ComposedScenario``
whose parts come from the preset's flat config (``PresetScenario.compose``).
The core owns what every scenario shares: the guards, the batched step of world,
network and backend, the episode generators, ``done``, and the info keys of the
contract (``position_error`` in metres, ``messages_sent`` and ``floats_sent`` as the
network counts them). A binding fills in the small hooks where its paper fixes
something the generic composition leaves open:

| hook                          | what a binding gives                                               |
|-------------------------------|--------------------------------------------------------------------|
| ``Config.parts()``            | the world, network and backend configs of its flat config          |
| ``composition_options``       | composition-level fields its flat config sets (``reward``, ...)    |
| ``action_space`` /            | its action codec: the paper's action, decoded into the parts'      |
| ``decode_actions``            | blocks                                                             |
| ``observation`` (+ ``_space``)| its observation features                                           |
| ``compute_reward``            | its reward (team or own, the paper's error, its costs)             |
| ``info``                      | the core's keys plus its own                                       |
| ``part_generators``           | which generator each part draws from (by default the world keeps   |
|                               | the episode generator itself, the network and backend its children)|
"""

from __future__ import annotations

from typing import ClassVar

from coloc_env.composition import Composition
from coloc_env.scenarios.composed import ComposedScenario


class PresetScenario(ComposedScenario):
    """Batched core of a preset: its flat config (``self.config``) bound to the composition of its parts
    (``self.composition``)."""

    name: ClassVar[str]
    paper: ClassVar[str]
    Config: ClassVar[type]

    @classmethod
    def compose(cls, config):
        """The validated ``coloc_env.composition.Composition`` of the flat ``config``'s parts
        (``config.parts()``), with the episode length and ``composition_options``."""
        spec = Composition(*config.parts(), horizon=config.horizon, preset=cls.name,
                           **cls.composition_options(config))
        spec.validate()
        return spec

    def part_generators(self, rng):
        """The presets' rule: the world draws from the episode's generator itself, in the order the hand-wired
        scenario it replaced drew (so seeded episodes keep their truth and readings); the network and the
        backend draw from its first and second child. (gps_denied_nbp gives its backend the first child, as
        its scenario always did.)"""
        network, backend = rng.spawn(2)
        return rng, network, backend

    @classmethod
    def composition_options(cls, config) -> dict:
        """Composition-level fields (``reward``, ``communication_cost``) the flat config sets; none by default."""
        return {}
