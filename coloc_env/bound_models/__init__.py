"""Bound models: for each world, the estimation problem its filters face, as ``coloc_env.bounds.pcrb`` needs it.

One module per world (``target`` for ``drift`` and ``target_cv``, ``circles``, ``gps_denied``,
``nlos_orbit``, ``mrclam``, ``mrclam_slices``); each docstring states the problem: the state, the prior
J0 = P0^-1 (the filters' initial covariance), the motion as the filters know it (input
noise as process noise), the readings as taken. Each module's ``problem(core, record)``
returns a ``coloc_env.bounds.BoundProblem`` from the world's drawn episode (its
arrays, read, never changed) and the play's ``coloc_env.bounds.Record``.

Which backends' messages define ``delivered`` (``delivered_kind``):

| kind        | backends                                   | delivered                                     |
|-------------|--------------------------------------------|-----------------------------------------------|
| readings    | ``kalman``, ``centralized_lmmse`` (packets  | own readings + each packet's reading, at its  |
|             | of z_i(k) to the leader), ``afge``, ``dfir`` | step, from its arrival (lag-augmented)        |
|             | , ``delay_kalman`` (the neighbours' RSS/AOA |                                               |
|             | packets),                                   |                                               |
|             | ``ukf_ccl`` (each range and fix sent to the | the centre's: every odometry (its model), the |
|             | centre, agent 0)                            | readings that reached it (``centre_received``) |
| nothing     | ``dead_reckoning``                         | = local                                       |
| estimates   | every other backend                        | left out (see ``coloc_env.bounds``)           |

``kalman``, ``centralized_lmmse`` and ``ukf_ccl`` fuse at the leader (the centre) and every agent reports its
estimate: their delivered bound is the leader's, for every agent (``SHARED_AT_LEADER``). ``with_delivered``
sets a problem's delivered bound by this table; a world's module gives only its readings' recursion.
"""

from __future__ import annotations

import importlib

import numpy as np

READING_PACKETS = frozenset({"kalman", "centralized_lmmse", "afge", "dfir", "delay_kalman", "ukf_ccl"})
# backends whose one estimate is the leader's (agent 0's), reported by every agent: their delivered bound is the
# leader's for every agent (the followers' own information is not what their reported estimate uses)
SHARED_AT_LEADER = frozenset({"kalman", "centralized_lmmse", "ukf_ccl"})
CENTRE = 0  # the fusion centre of the ``central`` message kind (coloc_env.networks.base.CENTRE)
NOTHING_SENT = frozenset({"dead_reckoning"})
MODULES = {"drift": "target", "target_cv": "target", "circles": "circles", "gps_denied": "gps_denied",
           "nlos_orbit": "nlos_orbit", "mrclam": "mrclam", "mrclam_slices": "mrclam_slices"}


def delivered_kind(backend_name: str) -> str:
    """``"readings"``, ``"nothing"`` or ``"estimates"`` (the table above)."""
    if backend_name in READING_PACKETS:
        return "readings"
    if backend_name in NOTHING_SENT:
        return "nothing"
    return "estimates"


def estimates_reason(backend_name: str) -> str:
    return (f"{backend_name}'s messages carry estimates (the sender's whole history), not readings: a per-reading "
            "account of what arrived bounds no estimator that fuses them")


def with_delivered(problem, core, record, message_kind: str | None = None, shape: tuple = (), readings_bound=None):
    """``problem`` with its delivered bound set by the backend's ``delivered_kind``: ``"nothing"``, the local
    bounds; ``"readings"``, ``readings_bound(arrival, lags)`` -> (recursions, their agents), ``arrival`` the
    record's first arrival step of each ``message_kind`` message (``shape``, -1 throughout when none was sent)
    and ``lags`` the network's longest delay, or ``readings_bound()`` where ``message_kind`` is None (a bound
    that reads the record itself: ``ukf_ccl``'s centre, from the broadcasts); ``"estimates"``, none, with the
    reason. A world without a ``readings_bound`` for the backend leaves its readings out, with the reason.
    Returns ``problem``."""
    name = core.composition.backend.name
    kind = delivered_kind(name)
    if kind == "nothing":
        problem.delivered, problem.delivered_agents = problem.local, problem.local_agents
    elif kind == "readings" and readings_bound is not None:
        if message_kind is None:
            problem.delivered, problem.delivered_agents = readings_bound()
        else:
            arrival = record.first_arrival(message_kind)
            if arrival is None:
                arrival = np.full(shape, -1, dtype=np.int64)
            problem.delivered, problem.delivered_agents = readings_bound(arrival, core.network.max_delay())
    elif kind == "readings":
        problem.delivered_reason = (f"no delivered bound of {name}'s readings on the "
                                    f"{core.composition.world.name} world")
    else:
        problem.delivered_reason = estimates_reason(name)
    return problem


def centre_received(record, k: int, pairs, fixes, N: int):
    """``ukf_ccl``'s centre at step k: which of the step's range readings ``pairs`` [(m, n), ...] (in the order
    the backend sends them: row-major over the valid pairs, its broadcast slot j the j-th) and which fixes of
    ``fixes`` [i, ...] (slot N * N + i) reached agent 0; its own readings always. Returns (range flags, fix flags)."""
    calls = record.broadcasts[k]

    def reached(sender: int, slot: int) -> bool:
        return sender == CENTRE or (slot in calls and bool(calls[slot][sender, CENTRE]))

    return ([reached(m, j) for j, (m, _) in enumerate(pairs)], [reached(i, N * N + i) for i in fixes])


def stand_in(core):
    """The world's stand-in for a backend whose deliveries define ``delivered`` when the world itself sends the
    packets (``nlos_orbit``'s neighbours): ``f(readings)`` asks the network for their delivery as the backend would,
    so the backend need not run; None where the backend's own messages are the packets."""
    name = core.composition.world.name
    if name not in MODULES:
        return None
    module = importlib.import_module(f"coloc_env.bound_models.{MODULES[name]}")
    return getattr(module, "stand_in", lambda core: None)(core)


def bound_problem(core, record):
    """The ``coloc_env.bounds.BoundProblem`` of the core's world for the recorded play."""
    name = core.composition.world.name
    if name not in MODULES:
        raise ValueError(f"no bound model for world {name!r}; worlds with one: {sorted(MODULES)}")
    module = importlib.import_module(f"coloc_env.bound_models.{MODULES[name]}")
    return module.problem(core, record)
