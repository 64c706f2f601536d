"""What the reproductions' Monte Carlo summaries, reports and figures share, written once.

| helper            | what it gives                                                                  |
|-------------------|--------------------------------------------------------------------------------|
| ``block_sizes``   | a run count split into blocks of at most ``block`` runs (independent tasks)    |
| ``mean_se``       | the mean over runs and its standard error (sample standard deviation / sqrt n)  |
| ``ci95``          | the half-width of the normal 95 % interval of a mean over runs (1.96 SE)       |
| ``claims_section``| the report's ``## Claims`` section (claim, our number, criterion, holds)       |
| ``pyplot``        | ``matplotlib.pyplot`` on the non-interactive Agg backend (PNG files only)       |
| ``PresetComposition`` | a batched core whose copies draw their episodes by the presets' rule         |
"""

from __future__ import annotations

import numpy as np

from coloc_env.config import BadInput
from coloc_env.scenarios.binding import PresetScenario
from coloc_env.scenarios.composed import ComposedScenario
from train.io import claims_table


class PresetComposition(ComposedScenario):
    """A composition whose copies draw their episodes by the presets' rule
    (``coloc_env.scenarios.binding.PresetScenario.part_generators``: the world from the episode's
    generator itself, the network and the backend from its first and second child): reset with
    ``default_rng(s)``, a backend on a preset's world and network sees the episode ``env.reset(seed=s)``
    of that preset draws, whichever backend it is."""

    part_generators = PresetScenario.part_generators


def block_sizes(runs: int, block: int) -> list[int]:
    """``runs`` split into blocks of ``block`` runs, the last one holding the rest (``[]`` for 0 runs)."""
    if block < 1:
        raise BadInput(f"block must be >= 1, got {block}")
    return [block] * (runs // block) + ([runs % block] if runs % block else [])


def mean_se(values) -> tuple[float, float]:
    """Mean of ``values`` (one per run) and its standard error, std (ddof 1) / sqrt(n); n >= 2."""
    values = np.asarray(values, float)
    if values.size < 2:
        raise BadInput(f"a standard error needs at least 2 runs, got {values.size}")
    return float(values.mean()), float(values.std(ddof=1) / np.sqrt(values.size))


def ci95(values) -> float:
    """Half-width of the normal 95 % interval of the mean of ``values``: 1.96 standard errors."""
    return 1.96 * mean_se(values)[1]


def claims_section(claims: list[dict]) -> list[str]:
    """The report lines of the ``## Claims`` section: a heading, then ``train.io.claims_table``."""
    return ["## Claims", "", *claims_table(claims)]


def pyplot():
    """``matplotlib.pyplot`` with the Agg backend selected (reproductions only write PNG files)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


__all__ = ["PresetComposition", "block_sizes", "ci95", "claims_section", "mean_se", "pyplot"]
