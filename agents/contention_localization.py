"""Policies of the ``contention_localization`` preset: the medium-access baselines of ``agents.contention``.

``paper`` is ``round_robin`` (TDMA by index, the scheduling literature's reference schedule; the preset's
module says why); ``aloha`` (``aloha:p``), ``always`` (transmit in every slot) and ``silent``.
"""

from __future__ import annotations

from agents.contention import PRESET_POLICIES

POLICIES = PRESET_POLICIES
STRONGEST_BASELINES = ("paper", "aloha")
