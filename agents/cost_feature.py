"""A cost-conditioned model's view of the episode's communication cost.

Every env with a communication cost observes it as c itself, in the unit of the reward (``communication_cost``).
Over a training range [lo, hi] that number can be invisible to a network (mrclam_relay's 1e-5 to 1e-2 m per hop
moves a first layer's pre-activations by about 1 % of their spread over the observations) or dwarf every other
input (lossy_fusion's 250 to 2.5e6 m^2 per packet). ``CostScaledExtractor`` is the model's first step: it
replaces the cost entry by its position in the training range before the network reads the observation, so the
env keeps the observation it documents and the transform travels inside the saved model (stable-baselines3
stores ``policy_kwargs`` with the weights): training, validation, ``coloc evaluate`` and ``agents.make_policy``
apply the same one without knowing of it.

| range                | the network reads                                               | at lo, sqrt(lo hi), hi |
|----------------------|-----------------------------------------------------------------|------------------------|
| 0 < lo < hi          | u = 2 ln(max(c, lo / 10) / sqrt(lo hi)) / ln(hi / lo)           | -1, 0, 1               |
| lo = 0 < hi          | u = 2 c / hi - 1 (the uniform law's range)                      | -1, (0 at hi / 2), 1   |
| lo = hi > 0          | u = c / lo - 1                                                  | 0                      |
| lo = hi = 0          | u = c                                                           | 0                      |

A cost below lo / 10 reads as lo / 10 (a cost of 0 has no logarithm); costs outside [lo, hi] extrapolate the
same formula, as the network would have to anyway.
"""

from __future__ import annotations

import math

import torch
from stable_baselines3.common.torch_layers import FlattenExtractor

# the names a settings module's COST_FEATURE may take (train.hyperparams.cost_feature)
COST_FEATURES = ("raw", "scaled")


def scaled_cost(cost: torch.Tensor, cost_range: tuple[float, float]) -> torch.Tensor:
    """The table of the module docstring: what the network reads for the costs ``cost`` under ``cost_range``."""
    lo, hi = float(cost_range[0]), float(cost_range[1])
    if 0 < lo < hi:
        return 2.0 * torch.log(torch.clamp(cost, min=lo / 10) / math.sqrt(lo * hi)) / math.log(hi / lo)
    if lo == 0 < hi:
        return 2.0 * cost / hi - 1.0
    if lo == hi > 0:
        return cost / lo - 1.0
    return cost


class CostScaledExtractor(FlattenExtractor):
    """stable-baselines3's ``FlattenExtractor`` with the observation's entry ``column`` (the episode's cost) replaced
    by ``scaled_cost`` under ``cost_range`` (the module docstring)."""

    def __init__(self, observation_space, column: int, cost_range: tuple[float, float]):
        super().__init__(observation_space)
        self.column, self.cost_range = int(column), (float(cost_range[0]), float(cost_range[1]))

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        flat = super().forward(observations).clone()
        flat[:, self.column] = scaled_cost(flat[:, self.column], self.cost_range)
        return flat
