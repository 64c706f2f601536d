"""The posterior Cramér–Rao bound beside a reproduction's rows: its ``pcrb`` block and report section.

A reproduction whose world has a bound model (``coloc_env.bounds.models``) computes
``coloc_env.pcrb`` over seeded episodes of its composition and hands this module the bound and,
per estimator row it reports as a position error, the per-run mean squared 2-D position error
(m^2, the bound's coordinates: the world's ``position_index``, over the same steps as the bound).

``pcrb`` block of ``metrics.json`` (``pcrb_block``):

| key            | value                                                                             |
|----------------|-----------------------------------------------------------------------------------|
| centralized,   | sqrt of the bound's mean over steps and agents (m); ``delivered`` None where the  |
| local,         | composition's messages do not define it (docs/bounds.md)                          |
| delivered      |                                                                                   |
| episodes, seed | the episodes the bound was computed over (episode e reset with seed + e)          |
| same_episodes  | whether those are the episodes the rows were measured on                          |
| note           | what the bound is over, in words                                                  |
| rows           | per row: ``rmse`` (m, sqrt of the mean over runs of the per-run MSE), ``mse`` and |
|                | ``mse_se`` (m^2: the mean and its standard error over the runs), ``efficiency``   |
|                | = rmse / centralized (>= 1 up to Monte Carlo noise where the model is the world's)|
"""

from __future__ import annotations

import numpy as np


def pcrb_block(bounds: dict, rows: dict, episodes: int, seed: int, same_episodes: bool, note: str) -> dict:
    """The ``pcrb`` block (module docstring) of ``bounds`` (``coloc_env.pcrb``'s dict) and ``rows``
    {name: per-run MSE (R,) in m^2}."""
    block = {key: (float(np.sqrt(np.mean(bounds[key]))) if key in bounds else None)
             for key in ("centralized", "local", "delivered")}
    block.update(episodes=int(episodes), seed=int(seed), same_episodes=bool(same_episodes), note=note,
                 model_based=bool(bounds.get("model_based", False)))
    centralized = block["centralized"]
    block["rows"] = {}
    for name, per_run in rows.items():
        per_run = np.asarray(per_run, float).ravel()
        mse = float(per_run.mean())
        se = float(per_run.std(ddof=1) / np.sqrt(per_run.size)) if per_run.size > 1 else None
        rmse = float(np.sqrt(mse))
        block["rows"][name] = {"rmse": rmse, "mse": mse, "mse_se": se,
                               "efficiency": rmse / centralized if centralized else None}
    return block


def _metres(value) -> str:
    return "-" if value is None else f"{value:.3g}"


def report_section(blocks: dict, what: str) -> list[str]:
    """The report's "Cramér–Rao bound" section: one table of ``blocks`` {label: pcrb block} and the sentence
    ``what`` (what the numbers say)."""
    lines = ["", "## Cramér–Rao bound", "",
             "Posterior Cramér–Rao bound (`coloc_env.pcrb`, docs/bounds.md) of the 2-D position: sqrt of its mean "
             "over steps and agents, against each row's RMSE; efficiency = RMSE / sqrt(pcrb_centralized), >= 1 for "
             "any estimator where the bound model is the world's.", "",
             "| setting | row | RMSE [m] | sqrt PCRB centralized / delivered / local [m] | efficiency |",
             "|---|---|---|---|---|"]
    for label, block in blocks.items():
        bounds = " / ".join(_metres(block[k]) for k in ("centralized", "delivered", "local"))
        for name, row in block["rows"].items():
            lines.append(f"| {label} | {name} | {row['rmse']:.3g} | {bounds} | {row['efficiency']:.2f} |")
    notes = sorted({block["note"] for block in blocks.values()})
    lines += [""] + [f"* {note}" for note in notes] + ["", what]
    return lines
