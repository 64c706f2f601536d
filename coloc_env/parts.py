"""The three kinds of composable part (world, network, backend): configs, registries, action blocks.

A part is described by a frozen config dataclass (its defaults, its
validation) and built into a batched runtime object when an env is made. A
config names its registry entry with the class attribute ``name`` and its
kind with ``kind``; ``validate()`` raises ``ValueError`` naming the part and
field, ``network.loss_at_zero must be in [0, 1], got 1.5``.

An agent's action in a composition is the concatenation of *blocks*, in the
order world (sensing choices), network (transport decisions), backend
(estimator decisions). A block is ``Block(name, size, choices)``: ``size``
integers in ``[0, choices)`` (a discrete block) or, with ``choices=None``,
``size`` floats in ``[low, high]`` (a continuous block).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from coloc_env.config import (
    BadInput,
    check_choice,
    check_range,
    read_aliases,
    refused_as_written,
    validate_fields,
)


@dataclass(frozen=True)
class Block:
    """One named block of the action vector: ``size`` entries, each an integer in ``[0, choices)`` or,
    with ``choices`` None, a float in ``[low, high]``. ``default`` is the backend's or network's
    default decision (used by the generic ``always`` / ``silent`` policies); ``maximum`` the value
    that sends the most (``always``), ``minimum`` the one that sends nothing (``silent``)."""

    name: str
    size: int
    choices: int | None
    meaning: str
    low: float = 0.0
    high: float = 1.0
    default: float | None = None
    maximum: float | None = None
    minimum: float | None = None

    @property
    def discrete(self) -> bool:
        return self.choices is not None


class PartConfig:
    """Base of every part config (a frozen dataclass). Subclasses set ``name`` and ``kind``."""

    name: ClassVar[str]
    kind: ClassVar[str]  # "world", "network" or "backend"
    # older field name -> current name, accepted by make_config, or -> "composition.<option>": a name a user may
    # write among this part's fields for a composition-level option (relay: hop_cost -> communication_cost), read
    # by ``coloc_env.composition.compose`` from a part given as a dict (``coloc_env.config.read_aliases``)
    aliases: ClassVar[dict[str, str]] = {}

    def check(self, prefix: str) -> None:  # pragma: no cover - interface
        """Raise ``ValueError`` naming ``prefix + field`` for a bad value."""

    def validate(self) -> None:
        """``check`` with the kind as prefix; a wrongly typed field is a ``ValueError`` naming it even where
        ``check`` computes a derived value first (``coloc_env.config.validate_fields``)."""
        prefix = f"{self.kind}."
        validate_fields(self, prefix, lambda: self.check(prefix))

    def replace(self, **changes) -> PartConfig:
        """A validated copy with ``changes`` (unknown fields are a ``ValueError`` naming the part); a change may
        use an older name (``aliases``), which then replaces the current field and is named in an error."""
        changed, _, _ = read_aliases(type(self), changes, f"{self.kind}.")
        kept = {k: v for k, v in dataclasses.asdict(self).items() if k not in changed}
        return make_config(type(self), {**kept, **changes}, self.kind)

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, **dataclasses.asdict(self)}


def make_config(cls: type, fields: dict[str, Any], kind: str) -> PartConfig:
    """``cls(**fields)`` after refusing unknown fields, then validated. A field listed in the class's
    ``aliases`` (older name -> current name) is read as its current name, and a refused value is named as the
    user wrote it (``world.num_platforms must be ...``), as ``coloc_env.config.build_config`` does for a preset."""
    prefix = f"{kind}."
    fields, written, lifted = read_aliases(cls, fields, prefix)
    allowed = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(fields) - allowed)
    if unknown:
        options = [f"{prefix}{alias} is the composition's {option}" for option, (alias, _) in lifted.items()]
        hint = f" ({'; '.join(options)}: give it to compose, or the {kind} as a dict)" if options else ""
        raise BadInput(f"unknown {kind} field(s) {unknown} for {kind} {cls.name!r}; allowed: {sorted(allowed)}"
                       f"{hint}")
    config = cls(**fields)
    with refused_as_written(written):
        config.validate()
    return config


# What moves over a network (a backend's ``message_kind``, a network's ``carries``; coloc_env.networks.base).
MESSAGE_KINDS = ("none", "broadcast", "chain", "central", "packets", "components")
# What a backend's messages carry (its ``message_content``, coloc_env.backends.base).
MESSAGE_CONTENTS = ("readings", "estimates", "nothing")
ESTIMANDS = ("self", "target")


@dataclasses.dataclass(frozen=True)
class NoBound:
    """A world's ``bound_model`` where coloc_env.bounds has no model of it: why not, in words."""

    reason: str


@dataclasses.dataclass(frozen=True)
class Declaration:
    """One class-level declaration every part of a kind makes: what the core, the bounds, ``compatibility()``,
    the docs and the CLI read of the part instead of a table elsewhere. ``valid(value)`` says whether a value is
    allowed; ``allowed`` says the same in words for the error."""

    name: str
    meaning: str
    allowed: str
    valid: Callable[[Any], bool]


def _names(value) -> bool:
    return isinstance(value, frozenset) and all(isinstance(v, str) and v for v in value)


def _text(value) -> bool:
    return isinstance(value, str) and bool(value.strip())


CONTRACTS: dict[str, tuple[Declaration, ...]] = {
    "world": (
        Declaration("estimand", "what its agents estimate: their own positions or a shared state",
                    f"one of {list(ESTIMANDS)}", lambda v: v in ESTIMANDS),
        Declaration("motion_kind", "the estimators.models kind its truth follows", "a model kind's name", _text),
        Declaration("measurements", "the measurement kinds its readings offer", "a frozenset of kind names",
                    _names),
        Declaration("anchors", "who has absolute position information, in words", "a non-empty text", _text),
        Declaration("bound_model", "the module of coloc_env.bounds.models that gives its posterior Cramér-Rao "
                    "bound, or NoBound(why it has none)", "a module name or NoBound(a non-empty text)",
                    lambda v: _text(v) or (isinstance(v, NoBound) and _text(v.reason))),
    ),
    "network": (
        Declaration("carries", "the message kinds it can carry", f"a non-empty frozenset of {list(MESSAGE_KINDS)}",
                    lambda v: _names(v) and bool(v) and v <= set(MESSAGE_KINDS)),
    ),
    "backend": (
        Declaration("estimand", "what it estimates", f"one of {list(ESTIMANDS)}", lambda v: v in ESTIMANDS),
        Declaration("motion_kinds", "the estimators.models kinds it can run on", "a non-empty frozenset of kind "
                    "names", lambda v: _names(v) and bool(v)),
        Declaration("requires", "groups of measurement kinds; the world must offer one kind of each group",
                    "a tuple of non-empty frozensets of kind names",
                    lambda v: isinstance(v, tuple) and all(_names(g) and g for g in v)),
        Declaration("message_kind", "what it sends over the network", f"one of {list(MESSAGE_KINDS)}",
                    lambda v: v in MESSAGE_KINDS),
        Declaration("message_content", "what a message carries (the bounds' information sets)",
                    f"one of {list(MESSAGE_CONTENTS)}", lambda v: v in MESSAGE_CONTENTS),
        Declaration("shared_estimate", "whether every agent reports the centre's (agent 0's) estimate",
                    "True or False", lambda v: isinstance(v, bool)),
    ),
}
_MISSING = object()


def check_declarations(kind: str, cls: type) -> None:
    """The part class ``cls`` makes every declaration of its kind's contract (``CONTRACTS``), each allowed; else
    a ``ValueError`` naming the part and the declaration. Run when a part registers. A declaration may be a
    property of the config's fields (afge's ``requires`` grows with ``mode_info``): it is checked on the
    part's defaults."""
    defaults = None
    for declaration in CONTRACTS[kind]:
        value = getattr(cls, declaration.name, _MISSING)
        if isinstance(value, property):
            defaults = cls() if defaults is None else defaults
            value = getattr(defaults, declaration.name)
        if value is _MISSING:
            raise ValueError(f"{kind} {cls.name!r} must declare {declaration.name} ({declaration.meaning}): "
                             f"{declaration.allowed}")
        if not declaration.valid(value):
            raise ValueError(f"{kind} {cls.name!r}: {declaration.name} must be {declaration.allowed}, got {value!r}")


class Registry(dict):
    """Name -> config class of one kind of part, filled by the ``register`` decorator."""

    def __init__(self, kind: str):
        super().__init__()
        self.kind = kind

    def register(self, cls: type) -> type:
        """Add a part class (a decorator): its ``name`` is new and it makes every declaration of its kind's
        contract (``check_declarations``), else a ``ValueError`` naming the part and what is wrong."""
        if not _text(getattr(cls, "name", None)):
            raise ValueError(f"a {self.kind} must declare its name, got {getattr(cls, 'name', None)!r}")
        if cls.name in self:
            raise ValueError(f"{self.kind} {cls.name!r} registered twice")
        check_declarations(self.kind, cls)
        cls.kind = self.kind
        self[cls.name] = cls
        return cls

    def unregister(self, name: str) -> None:
        """Remove a part added by ``register`` (a test's toy part), so that the registry is as before."""
        if name not in self:
            raise ValueError(f"no {self.kind} {name!r} registered; registered: {sorted(self)}")
        del self[name]

    def resolve(self, part: Any) -> PartConfig:
        """A validated config from a name, a config object or a dict ``{"name": ..., field: value}``."""
        if isinstance(part, str):
            return make_config(self._class(part), {}, self.kind)
        if isinstance(part, dict):
            fields = dict(part)
            if "name" not in fields:
                raise BadInput(f"a {self.kind} given as a dict needs a 'name' key, one of {sorted(self)}")
            return make_config(self._class(fields.pop("name")), fields, self.kind)
        if isinstance(part, PartConfig) and getattr(part, "kind", None) == self.kind:
            part.validate()
            return part
        raise BadInput(f"{self.kind} must be a name (one of {sorted(self)}), a {self.kind} config or a dict, "
                         f"got {part!r}")

    def composition_options(self, part: Any) -> tuple[Any, dict[str, tuple[str, Any]]]:
        """``part`` without the composition options its class names among its ``aliases`` (a part given as a dict
        only), and {composition option: (the name written, its value)} for each of them given."""
        if not isinstance(part, dict) or not isinstance(part.get("name"), str) or part["name"] not in self:
            return part, {}
        _, _, options = read_aliases(self[part["name"]], part, f"{self.kind}.")
        written = {alias for alias, _ in options.values()}
        return {k: v for k, v in part.items() if k not in written}, options

    def _class(self, name: Any) -> type:
        if not isinstance(name, str) or name not in self:
            raise BadInput(f"unknown {self.kind} {name!r}; available: {sorted(self)}")
        return self[name]


WORLDS = Registry("world")
NETWORKS = Registry("network")
BACKENDS = Registry("backend")


def check_flag(name: str, value: Any) -> None:
    if not isinstance(value, (bool, np.bool_)):
        raise BadInput(f"{name} must be True or False, got {value!r}")


__all__ = ["BACKENDS", "CONTRACTS", "MESSAGE_CONTENTS", "MESSAGE_KINDS", "NETWORKS", "WORLDS", "Block", "Declaration",
           "NoBound", "PartConfig", "Registry", "check_choice", "check_declarations", "check_flag", "check_range",
           "make_config"]
