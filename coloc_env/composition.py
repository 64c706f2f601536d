"""Compositions: a world, a network and a backend combined into one environment.

>>> import coloc_env
>>> spec = coloc_env.compose(world="circles", network="relay", backend="ukf_dcl")
>>> env = coloc_env.parallel_env(spec)

A part is a name (its defaults), its validated config object
(``coloc_env.worlds.Circles(num_agents=4)``) or a dict ``{"name": ..., field:
value}``. The other keywords are composition-level:

| option              | default   | meaning                                                              |
|---------------------|-----------|----------------------------------------------------------------------|
| reward              | "error"   | "error": minus the agent's own position error (m) after this step's |
|                     |           | update; "trace": minus sqrt(tr P_ii) (m), the backend's own RMS      |
| communication_cost  | 0.0       | [0, 1e12], subtracted per message the agent sent this step           |
| cost_range          | None      | None, or (lo, hi) with 0 <= lo <= hi <= 1e12: each copy draws its    |
|                     |           | episode's communication cost at reset, log-uniform on [lo, hi] when  |
|                     |           | lo > 0 (log c uniform on [log lo, log hi]), uniform on [0, hi] when  |
|                     |           | lo = 0 (a log-uniform law has no mass at 0); it replaces             |
|                     |           | ``communication_cost`` in the reward, the observation and the infos |
| horizon             | None      | steps per episode; None = the world's                                |

A ``Composition`` is frozen and picklable (it travels to Ray workers)
and builds nothing until an env is made. A preset (``PRESETS[name]``) is a
Composition that also names the scenario binding whose action codec and
observation it carries (``Composition.preset``) and its flat config
(``Composition.preset_config``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from coloc_env.config import BadInput, check_choice, check_range, refused_as_written
from coloc_env.parts import BACKENDS, NETWORKS, WORLDS, PartConfig

COMPOSITION_OPTIONS = ("reward", "communication_cost", "cost_range", "horizon")
COST_LIMIT = 1e12  # the largest communication cost (communication_cost, cost_range's bounds)


@dataclass(frozen=True)
class Composition:
    """A validated (world, network, backend) triple plus composition-level options."""

    world: PartConfig
    network: PartConfig
    backend: PartConfig
    reward: str = "error"
    communication_cost: float = 0.0
    horizon: int | None = None
    preset: str | None = None
    preset_config: tuple = field(default=(), compare=True)
    cost_range: tuple[float, float] | None = None

    def __post_init__(self):
        if isinstance(self.cost_range, list):  # a list from a config file: the frozen Composition keeps a tuple
            object.__setattr__(self, "cost_range", tuple(self.cost_range))

    def validate(self) -> None:
        for part in (self.world, self.network, self.backend):
            part.validate()
        self.check_options()
        reason = incompatibility(self.world, self.network, self.backend)
        if reason:
            raise BadInput(reason)

    def check_options(self, prefix: str = "") -> None:
        """The composition-level fields: a ``ValueError`` naming ``prefix + field`` and its range."""
        check_choice(f"{prefix}reward", self.reward, ("error", "trace"))
        check_range(f"{prefix}communication_cost", self.communication_cost, 0.0, COST_LIMIT)
        check_cost_range(f"{prefix}cost_range", self.cost_range)
        if self.horizon is not None:
            check_range(f"{prefix}horizon", self.horizon, 1, 1_000_000, integer=True)

    @property
    def name(self) -> str:
        return self.preset or f"{self.world.name}/{self.network.name}/{self.backend.name}"

    @property
    def episode_steps(self) -> int:
        return self.world.horizon if self.horizon is None else self.horizon

    def replace(self, **changes) -> Composition:
        new = dataclasses.replace(self, **changes)
        new.validate()
        return new


def check_cost_range(name: str, value: Any) -> None:
    """``value`` is None or a pair (lo, hi) of numbers with 0 <= lo <= hi <= ``COST_LIMIT``; else a ``ValueError``
    naming ``name`` and the allowed range."""
    if value is None:
        return
    allowed = f"None or a pair (lo, hi) with 0 <= lo <= hi <= {COST_LIMIT:g}"
    if not isinstance(value, tuple) or len(value) != 2:
        raise BadInput(f"{name} must be {allowed}, got {value!r}")
    check_range(f"{name}[0] (lo)", value[0], 0.0, COST_LIMIT)
    check_range(f"{name}[1] (hi)", value[1], 0.0, COST_LIMIT)
    if float(value[0]) > float(value[1]):
        raise BadInput(f"{name} must be {allowed}, got lo = {value[0]!r} > hi = {value[1]!r}")


def draw_costs(cost_range: tuple[float, float], rngs: list) -> np.ndarray:
    """One communication cost per copy from ``cost_range`` (lo, hi) (the module's table): log-uniform on [lo, hi]
    for lo > 0, uniform on [0, hi] for lo = 0; one uniform from each copy's generator in ``rngs``."""
    lo, hi = float(cost_range[0]), float(cost_range[1])
    u = np.array([rng.random() for rng in rngs], float)
    if lo == hi:
        return np.full(len(rngs), lo)
    if lo > 0.0:
        return np.clip(np.exp(np.log(lo) + u * (np.log(hi) - np.log(lo))), lo, hi)
    return u * hi


def compose(world: Any, network: Any, backend: Any, **options) -> Composition:
    """A ``Composition`` of the three parts; ``options`` are composition-level fields only.

    A part given as a dict may hold a composition option under the name its class's ``aliases`` maps to
    ``"composition.<option>"`` (``{"name": "relay", "hop_cost": c}`` sets ``communication_cost = c``); giving
    it there and in ``options`` is refused, and a refused value is named as written (``network.hop_cost``)."""
    unknown = sorted(set(options) - set(COMPOSITION_OPTIONS))
    if unknown:
        raise BadInput(f"unknown composition option(s) {unknown}; allowed: {list(COMPOSITION_OPTIONS)} "
                         "(a part's own field goes into that part: {'name': ..., field: value})")
    parts, written = {}, {}
    for kind, registry, part in (("world", WORLDS, world), ("network", NETWORKS, network),
                                 ("backend", BACKENDS, backend)):
        parts[kind], lifted = registry.composition_options(part)
        for option, (alias, value) in lifted.items():
            if option in options:
                raise BadInput(f"{kind}.{alias} is another name of {option}; give only one of them")
            options[option] = value
            written[option] = f"{kind}.{alias}"
    with refused_as_written(written):
        spec = Composition(world=WORLDS.resolve(parts["world"]), network=NETWORKS.resolve(parts["network"]),
                           backend=BACKENDS.resolve(parts["backend"]), **options)
        spec.validate()
    return spec


def _kinds(kinds) -> str:
    return " or ".join(sorted(kinds))


def incompatibility(world: PartConfig, network: PartConfig, backend: PartConfig) -> str:
    """Why the three cannot run together, in words; "" when they can."""
    if world.estimand != backend.estimand:
        what = {"self": "each agent's own position", "target": "a shared target state"}
        return (f"{backend.name} estimates {what[backend.estimand]}; world {world.name} asks for "
                f"{what[world.estimand]}")
    if world.motion_kind not in backend.motion_kinds:
        return (f"{backend.name} runs on {_kinds(backend.motion_kinds)} motion; world {world.name} moves by "
                f"{world.motion_kind}")
    for group in backend.requires:
        if not group & world.measurements:
            return (f"{backend.name} needs {_kinds(group)} measurements; world {world.name} has "
                    f"{_kinds(world.measurements) or 'none'}")
    if backend.message_kind != "none" and backend.message_kind not in network.carries:
        why = getattr(network, "refuses", {}).get(backend.message_kind)
        return (f"{backend.name} sends {backend.message_kind} messages; network {network.name} cannot carry them"
                + (f" ({why})" if why else ""))
    return ""


def compatibility() -> list[dict[str, Any]]:
    """One row per (world, network, backend) of the registries: ``world``, ``network``, ``backend``, ``ok``,
    ``reason`` ("" where ok), on each part's defaults."""
    rows = []
    for w, wcls in WORLDS.items():
        for n, ncls in NETWORKS.items():
            for b, bcls in BACKENDS.items():
                reason = incompatibility(wcls(), ncls(), bcls())
                rows.append({"world": w, "network": n, "backend": b, "ok": not reason, "reason": reason})
    return rows
