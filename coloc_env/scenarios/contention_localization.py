"""``contention_localization``: GPS-denied UAVs report their ranges to a fusion centre over one shared slotted medium.

A benchmark in which *when* to transmit decides the accuracy: the ``gps_denied`` world (10 UAVs in a 500 m
square, every pair within 300 m measures its range, GPS receivers fail and recover by a Markov chain), the
``contention`` network (one transmission slot per step; a frame reaches the centre only where no other UAV
within 300 m of it transmits in the slot, and the centre only listens) and the ``ukf_ccl`` backend (the
fusion centre, UAV 0, runs the joint UKF over every range and fix that reaches it; its estimate is every
UAV's). All UAVs within range of one another transmitting at once (``always``) collide: the centre hears
almost nothing and the team dead-reckons. The preset is the composition of these parts with its defaults
(``coloc_env.PRESETS["contention_localization"]``): the action, observation, reward and infos are the
composition's (``coloc_env.scenarios.composed``), the network's acknowledgements included.

| quantity     | value                                                                                   |
|--------------|-----------------------------------------------------------------------------------------|
| action       | ``MultiDiscrete([2] * slots)`` per UAV: transmit its readings in slot s (1) or not (0); |
|              | the centre's choice is masked (it only listens)                                        |
| observation  | the composition's (``coloc_env.scenarios.composed``'s table): own index, log tr P, who  |
|              | was heard, distances / 100 m, step fraction, covariance_known, displacement and steps  |
|              | since its last acknowledged frame, message_value, the episode's communication cost,    |
|              | the world's features, the per-slot acknowledgement of its frame of the step before     |
| reward       | minus the UAV's position error (m), minus its copy's cost (``communication_cost``, or   |
|              | the episode's draw from ``cost_range``) per frame it sent                               |
| metric       | position error averaged over the steps and UAVs (m)                                     |
| ``paper``    | ``round_robin`` (TDMA by index: UAV i transmits in global slot t iff t mod N = i; no    |
|              | collision, one UAV per slot), the scheduling literature's reference schedule            |
| baselines    | ``round_robin``, ``aloha`` (p = 1 / (neighbours + 1)), ``always``, ``silent``            |

Measured (``docs/contention.md``, with the command): ``always`` loses to ``round_robin`` by about a factor
two in error while it sends ten times the frames.

Arguments (fields of ``ContentionLocalizationConfig``)

| field              | default | allowed                                                       |
|--------------------|---------|---------------------------------------------------------------|
| num_agents         | 10      | 2..128 UAVs                                                   |
| horizon            | 30      | 1..10000 steps                                                |
| area               | 500     | (0, 1e7] m: the side of the start square                      |
| comm_range         | 300     | (0, 1e7] m: the ranging radius and the radio's range          |
| slots              | 1       | 1..64 transmission slots per step                             |
| interference_range | None    | [comm_range, inf] m, None = comm_range                        |
| capture            | 0.0     | 0 (off) or [1, 1e6]: the capture ratio (the network's)         |
| path_loss_exponent | 2.0     | [1, 10] (read only with capture)                               |
| gps_std            | 3.0     | [0.001, 1e4] m                                                |
| range_std          | 2.0     | [0.001, 1e4] m                                                |
| p_normal_to_fault  | 0.02    | [0, 1]                                                        |
| p_fault_to_normal  | 0.02    | [0, 1]                                                        |
| communication_cost | 0.0     | [0, 1e12] per frame sent                                      |
| cost_range         | None    | None, or (lo, hi) with 0 <= lo <= hi <= 1e12:                 |
|                    |         | each copy draws its cost per episode at reset                 |
|                    |         | (``coloc_env.composition``'s law), replacing                  |
|                    |         | ``communication_cost``                                        |
| reward             | "error" | "error", "trace" (the composition's reward table)             |
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from coloc_env.backends.ukf import UkfCcl
from coloc_env.networks.contention import Contention
from coloc_env.scenarios.binding import PresetConfig, PresetScenario, keyword, register_preset
from coloc_env.scenarios.composed import OWN_FEATURES
from coloc_env.worlds.gps_denied import GpsDenied


@dataclass(frozen=True)
class ContentionLocalizationConfig(PresetConfig):
    """Flat config of ``contention_localization`` (the module's Arguments table)."""

    preset = "contention_localization"
    World, Network, Backend = GpsDenied, Contention, UkfCcl

    num_agents: int = keyword(10, "world.num_agents")
    horizon: int = keyword(30, "world.horizon", "composition.horizon")
    area: float = keyword(500.0, "world.area")
    comm_range: float = keyword(300.0, "world.comm_range", "network.comm_range")
    slots: int = keyword(1, "network.slots")
    interference_range: float | None = keyword(None, "network.interference_range")
    capture: float = keyword(0.0, "network.capture")
    path_loss_exponent: float = keyword(2.0, "network.path_loss_exponent")
    gps_std: float = keyword(3.0, "world.gps_std")
    range_std: float = keyword(2.0, "world.range_std")
    p_normal_to_fault: float = keyword(0.02, "world.p_normal_to_fault")
    p_fault_to_normal: float = keyword(0.02, "world.p_fault_to_normal")
    communication_cost: float = keyword(0.0, "composition.communication_cost")
    cost_range: tuple | None = keyword(None, "composition.cost_range")
    reward: str = keyword("error", "composition.reward")


@register_preset
class ContentionLocalizationScenario(PresetScenario):
    """``contention_localization`` as a binding: ``gps_denied`` / ``contention`` / ``ukf_ccl`` with the
    composition's action, observation, reward and infos (module docstring)."""

    name = "contention_localization"
    paper = "-"
    Config = ContentionLocalizationConfig
    version = 2
    metric = "position error averaged over the steps and UAVs"
    metric_unit = "m"
    communication = "frames transmitted"
    policy_module = "agents.contention_localization"
    # round_robin, the paper's policy, is a schedule of its own: a family's send keeps always's action
    family_send = "always"
    # the composition's observation, whole (its own features included)
    own_features = OWN_FEATURES
    appended_features = ()

    def transport_entries(self) -> tuple[np.ndarray, np.ndarray]:
        """Every entry: transmit in a round's slot (1) or not (0); quiet: all 0 (``silent``)."""
        send, quiet = (np.asarray(self.action_vector(w), float) for w in ("maximum", "minimum"))
        return send != quiet, quiet
