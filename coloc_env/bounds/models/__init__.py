"""Bound models: for each world, the estimation problem its filters face, as ``coloc_env.bounds.pcrb`` needs it.

One module per world model (``target`` for ``drift`` and ``target_cv``, ``circles``, ``gps_denied``,
``nlos_orbit``, ``mrclam``, ``mrclam_slices``), each declaring the worlds it models (``WORLDS``); each
docstring states the problem: the state, the prior J0 = P0^-1 (the filters' initial covariance), the
motion as the filters know it (input noise as process noise), the readings as taken. Each module's
``problem(core, record)`` returns a ``coloc_env.bounds.problem.BoundProblem`` from the world's drawn episode
(its arrays, read, never changed) and the play's ``coloc_env.bounds.record.Record``, with each reading's
information tagged with its owner and step (``ReadingInformation``).

What a backend's messages carry is the backend's declaration (``message_content``, ``shared_estimate``;
``coloc_env.backends.base``), not a table here:

| message_content | backends (today)                            | delivered                                     |
|-----------------|---------------------------------------------|-----------------------------------------------|
| readings        | ``kalman``, ``centralized_lmmse`` (packets  | own readings + each packet's reading, at its  |
|                 | of z_i(k) to the leader), ``afge``, ``dfir`` | step, from its arrival (lag-augmented)        |
|                 | , ``delay_kalman`` (the neighbours' RSS/AOA |                                               |
|                 | packets),                                   |                                               |
|                 | ``ukf_ccl`` (each range and fix sent to the | the centre's: every odometry (its model), the |
|                 | centre, agent 0)                            | readings that reached it (``centre_received``) |
| nothing         | ``dead_reckoning``                          | = local                                       |
| estimates       | every other backend                         | see ``coloc_env.bounds``                      |

A backend with ``shared_estimate`` (every agent reports the centre's estimate) has the centre's delivered
bound for every agent. ``with_delivered`` sets a problem's delivered bound from these declarations; a
world's module gives only its readings' recursion.
"""

from __future__ import annotations

from coloc_env.bounds.models import circles, gps_denied, mrclam, mrclam_slices, nlos_orbit, target

MODELS = {world: module for module in (target, circles, gps_denied, nlos_orbit, mrclam, mrclam_slices)
          for world in module.WORLDS}


def has_bound_model(world_name: str) -> bool:
    """Whether ``coloc_env.pcrb`` has a bound model of the world ``world_name``."""
    return world_name in MODELS


def generative_worlds() -> list[str]:
    """The worlds whose bound is a bound of their generative model (not ``MODEL_BASED``: recorded data)."""
    return sorted(world for world, module in MODELS.items() if not getattr(module, "MODEL_BASED", False))


def _model(core):
    name = core.composition.world.name
    if name not in MODELS:
        raise ValueError(f"no bound model for world {name!r}; worlds with one: {sorted(MODELS)}")
    return MODELS[name]


def stand_in(core):
    """The world's stand-in for a backend whose deliveries define ``delivered`` when the world itself sends the
    packets (``nlos_orbit``'s neighbours): ``f(readings)`` asks the network for their delivery as the backend would,
    so the backend need not run; None where the backend's own messages are the packets."""
    model = MODELS.get(core.composition.world.name)
    return None if model is None else getattr(model, "stand_in", lambda core: None)(core)


def bound_problem(core, record):
    """The ``coloc_env.bounds.problem.BoundProblem`` of the core's world for the recorded play."""
    return _model(core).problem(core, record)
