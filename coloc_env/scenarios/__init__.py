"""Scenario registry: one module per paper setting."""

from coloc_env.scenarios.bandwidth_fusion import BandwidthFusionScenario
from coloc_env.scenarios.gps_denied_nbp import GpsDeniedNbpScenario
from coloc_env.scenarios.lossy_fusion import LossyFusionScenario
from coloc_env.scenarios.mrclam_relay import MrclamRelayScenario
from coloc_env.scenarios.nlos_horizon import NlosHorizonScenario
from coloc_env.scenarios.relay_ukf import RelayUKFScenario

REGISTRY = {cls.name: cls for cls in (BandwidthFusionScenario, LossyFusionScenario, RelayUKFScenario,
                                          GpsDeniedNbpScenario, NlosHorizonScenario, MrclamRelayScenario)}

__all__ = ["REGISTRY"]
