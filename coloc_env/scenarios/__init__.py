"""Scenario registry: one module per paper setting."""

from coloc_env.scenarios.bandwidth_fusion import BandwidthFusionScenario

REGISTRY = {cls.name: cls for cls in (BandwidthFusionScenario,)}

__all__ = ["REGISTRY"]
