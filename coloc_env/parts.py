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
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from coloc_env.config import (
    BadInput,
    aliases_written,
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
    aliases: ClassVar[dict[str, str]] = {}  # older field name -> current name, accepted by make_config
    # a name a user may write among this part's fields for a composition-level option of another name (relay:
    # hop_cost -> communication_cost), read by ``coloc_env.composition.compose`` from a part given as a dict
    composition_aliases: ClassVar[dict[str, str]] = {}

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
        changed = read_aliases(type(self), changes, f"{self.kind}.")
        kept = {k: v for k, v in dataclasses.asdict(self).items() if k not in changed}
        return make_config(type(self), {**kept, **changes}, self.kind)

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, **dataclasses.asdict(self)}


def make_config(cls: type, fields: dict[str, Any], kind: str) -> PartConfig:
    """``cls(**fields)`` after refusing unknown fields, then validated. A field listed in the class's
    ``aliases`` (older name -> current name) is read as its current name, and a refused value is named as the
    user wrote it (``world.num_platforms must be ...``), as ``coloc_env.config.build_config`` does for a preset."""
    prefix = f"{kind}."
    written = aliases_written(cls, fields, prefix)
    fields = read_aliases(cls, fields, prefix)
    allowed = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(fields) - allowed)
    if unknown:
        options = [f"{prefix}{name} is the composition's {cls.composition_aliases[name]}"
                   for name in unknown if name in cls.composition_aliases]
        hint = f" ({'; '.join(options)}: give it to compose, or the {kind} as a dict)" if options else ""
        raise BadInput(f"unknown {kind} field(s) {unknown} for {kind} {cls.name!r}; allowed: {sorted(allowed)}"
                       f"{hint}")
    config = cls(**fields)
    with refused_as_written(written):
        config.validate()
    return config


# what a backend's messages carry (its ``message_content``, coloc_env.backends.base)
MESSAGE_CONTENTS = ("readings", "estimates", "nothing")


class Registry(dict):
    """Name -> config class of one kind of part, filled by the ``register`` decorator."""

    def __init__(self, kind: str):
        super().__init__()
        self.kind = kind

    def register(self, cls: type) -> type:
        if cls.name in self:
            raise ValueError(f"{self.kind} {cls.name!r} registered twice")
        if self.kind == "backend":  # what the bounds read of a backend (coloc_env.backends.base)
            if getattr(cls, "message_content", None) not in MESSAGE_CONTENTS:
                raise ValueError(f"backend {cls.name!r} must declare message_content, one of "
                                 f"{list(MESSAGE_CONTENTS)}, got {getattr(cls, 'message_content', None)!r}")
            if not isinstance(getattr(cls, "shared_estimate", None), bool):
                raise ValueError(f"backend {cls.name!r} must declare shared_estimate (True or False), got "
                                 f"{getattr(cls, 'shared_estimate', None)!r}")
        cls.kind = self.kind
        self[cls.name] = cls
        return cls

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
        """``part`` without the fields its class names in ``composition_aliases`` (a part given as a dict only),
        and {composition option: (the name written, its value)} for each of them given."""
        if not isinstance(part, dict) or not isinstance(part.get("name"), str) or part["name"] not in self:
            return part, {}
        lifted = self[part["name"]].composition_aliases
        options = {option: (alias, part[alias]) for alias, option in lifted.items() if alias in part}
        return {k: v for k, v in part.items() if k not in lifted}, options

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


__all__ = ["BACKENDS", "NETWORKS", "WORLDS", "Block", "PartConfig", "Registry", "check_choice", "check_flag",
           "check_range", "make_config"]
