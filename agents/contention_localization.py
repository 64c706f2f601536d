"""Policies of the ``contention_localization`` preset: the medium-access baselines of ``agents.contention``.

``paper`` is ``round_robin`` (TDMA by index, the scheduling literature's reference schedule; the preset's
module says why); ``aloha`` (``aloha:p``), ``always`` (transmit in every slot) and ``silent``; and the
event-triggered families (``agents.event_triggered``: ``periodic``, ``send_on_delta``, ``uncertainty``,
``value``), each deciding whether a UAV transmits in every slot of the step or in none. Listed apart, the
schedules of a polled medium, which the contention network cannot carry (``bound_polled``,
``bound_polled_error``, ``bound_polled_age``: ``agents.contention.PolledPolicy``).
"""

from __future__ import annotations

from agents import event_triggered
from agents.contention import PRESET_POLICIES, bound_polled, bound_polled_age, bound_polled_error

# the event-triggered families decide each UAV's slots (agents.event_triggered; a send keeps always's slots)
POLICIES = {**PRESET_POLICIES, **event_triggered.POLICIES}
STRONGEST_BASELINES = ("paper", "aloha")
# a polled medium (the centre picks who sends; agents.contention.PolledPolicy): what a schedule could buy
BOUNDS = {"bound_polled": bound_polled, "bound_polled_error": bound_polled_error,
          "bound_polled_age": bound_polled_age}
