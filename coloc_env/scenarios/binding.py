"""A paper scenario as a binding on the composable core.

A preset (``relay_ukf``, ...) is a ``coloc_env.scenarios.composed.ComposedScenario``
whose parts come from the preset's flat config (``PresetScenario.compose``).
The core owns what every scenario shares: the guards, the batched step of world,
network and backend, the episode generators, ``done``, and the info keys of the
contract (``position_error`` in metres, ``messages_sent`` and ``floats_sent`` as the
network counts them). A binding fills in the small hooks where its paper fixes
something the generic composition leaves open:

| hook                          | what a binding gives                                               |
|-------------------------------|--------------------------------------------------------------------|
| ``Config`` (a ``PresetConfig``)| its flat config: each keyword declared with ``keyword(default,    |
|                               | "world.field", ...)``, the part fields it sets (``parts()`` and    |
|                               | ``validate()`` are derived from the declarations)                  |
| ``action_space`` /            | its action codec: the paper's action, decoded into the parts'      |
| ``decode_actions``            | blocks                                                             |
| ``observation`` (+ ``_space``)| its observation features                                           |
| ``compute_reward``            | its reward (team or own, the paper's error, its costs)             |
| ``info``                      | the core's keys plus its own                                       |
| ``part_generators``           | which generator each part draws from (by default the world keeps   |
|                               | the episode generator itself, the network and backend its children)|
"""

from __future__ import annotations

import dataclasses
import functools
import re
from typing import Any, ClassVar

import gymnasium
import numpy as np

from coloc_env.composition import Composition
from coloc_env.config import BadInput, field_type_problem
from coloc_env.scenarios.composed import LOG_TRACE_BOUND, OWN_BOUNDS, OWN_FEATURES, ComposedScenario

TARGET_KINDS = ("world", "network", "backend", "composition", "preset")
# Part checks name a field as prefix + field; with this prefix the message's field names can be told apart
# from its prose and replaced by the preset keywords that set them.
_FIELD_MARK = "\x1f"


def keyword(default: Any, *targets: str) -> Any:
    """A preset keyword: its paper default and the part fields it sets, each ``"<kind>.<field>"`` with kind
    world, network, backend or composition, or ``"preset"`` for a keyword the preset's own codec reads
    (checked by the config's ``check_preset``). A ``dataclasses.field`` carrying the targets as metadata."""
    for target in targets:
        kind = target.split(".", 1)[0]
        if kind not in TARGET_KINDS or (kind != "preset") != ("." in target):
            raise TypeError(f"keyword target {target!r} must be '<kind>.<field>' with kind in {TARGET_KINDS[:4]} "
                            f"or 'preset'")
    return dataclasses.field(default=default, metadata={"targets": targets})


class PresetConfig:
    """Base of a preset's flat config: a frozen dataclass whose fields are ``keyword`` declarations.

    ``parts()`` builds the world, network and backend configs (classes ``World``, ``Network``, ``Backend``)
    from the keywords' targets, ``composition_options()`` the composition-level fields; ``validate()`` runs
    each part's own check once and reports a refused value under the keyword the user wrote
    (``relay_ukf: num_agents must be ...``). ``aliases`` maps older keywords to their current names
    (``make`` and ``parallel_env`` accept both)."""

    preset: ClassVar[str]
    World: ClassVar[type]
    Network: ClassVar[type]
    Backend: ClassVar[type]
    aliases: ClassVar[dict[str, str]] = {}

    @classmethod
    def bindings(cls) -> dict[str, tuple[str, ...]]:
        """Keyword -> the targets it sets, in declaration order."""
        return {f.name: f.metadata["targets"] for f in dataclasses.fields(cls) if "targets" in f.metadata}

    def bound_fields(self, kind: str) -> dict[str, Any]:
        """The fields of part ``kind`` the keywords set: {part field: value}."""
        fields = {}
        for name, targets in self.bindings().items():
            for target in targets:
                if target.startswith(kind + "."):
                    fields[target.split(".", 1)[1]] = getattr(self, name)
        return fields

    def parts(self) -> tuple:
        """The (world, network, backend) configs this flat config stands for (not yet validated)."""
        return (self.World(**self.bound_fields("world")), self.Network(**self.bound_fields("network")),
                self.Backend(**self.bound_fields("backend")))

    def composition_options(self) -> dict[str, Any]:
        """The composition-level fields (``reward``, ``communication_cost``, ``horizon``) the keywords set."""
        return self.bound_fields("composition")

    def check_preset(self) -> None:
        """Checks of the keywords only the preset reads (targets ``"preset"``); none by default."""

    def _keyword_of(self, kind: str, field: str) -> str:
        for name, targets in self.bindings().items():
            if f"{kind}.{field}" in targets:
                return name
        return f"{kind}.{field}"

    def validate(self) -> None:
        """Each part's own check under the keywords' names (a wrongly typed keyword is refused there with its
        range), then every keyword's type."""
        world, network, backend = self.parts()
        composition = Composition(world, network, backend, **self.composition_options())
        checks = {"world": world.check, "network": network.check, "backend": backend.check,
                  "composition": composition.check_options}
        for kind, check in checks.items():
            try:
                check(_FIELD_MARK)
            except ValueError as exc:
                message = re.sub(re.escape(_FIELD_MARK) + r"(\w+)", lambda m, kind=kind: self._keyword_of(kind, m[1]),
                                 str(exc))
                raise BadInput(f"{self.preset}: {message}") from exc
            except Exception as exc:  # a wrongly typed keyword broke a check's arithmetic: name its type
                problem = field_type_problem(self)
                if not problem:
                    raise
                raise BadInput(f"{self.preset}: {problem}") from exc
        problem = field_type_problem(self)
        if problem:
            raise BadInput(f"{self.preset}: {problem}")
        try:
            self.check_preset()
        except ValueError as exc:
            raise BadInput(f"{self.preset}: {exc}") from exc


class PresetScenario(ComposedScenario):
    """Batched core of a preset: its flat config (``self.config``) bound to the composition of its parts
    (``self.composition``).

    A preset declares, once, on its class, what the rest of coloc reads about it (``register_preset`` checks
    the declarations when the preset registers):

    | declaration            | what it is                                                                  |
    |------------------------|-----------------------------------------------------------------------------|
    | ``name``               | the preset's name (``coloc_env.SCENARIOS``, ``coloc_env.envs.<name>``)      |
    | ``paper``              | the paper key (``zhao2020``), or the data set's name                        |
    | ``Config``             | its flat config (a ``PresetConfig``)                                        |
    | ``version``            | the version of its PettingZoo id ``coloc/<name>-v<version>``                |
    | ``metric``             | what its episode metric (``episode_error``) measures, in words              |
    | ``metric_unit``        | the metric's unit (``"m"`` or ``"m^2"``)                                     |
    | ``communication``      | what its ``communication`` info counts (``"relays"``)                       |
    | ``episode_length_field``| the config field that ``max_cycles`` sets (``"horizon"`` by default)       |
    | ``policy_module``      | the module of its policies (``agents.<name>``: ``POLICIES``, optionally     |
    |                        | ``BOUNDS``, ``ALIASES``; ``STRONGEST_BASELINES``)                            |
    | ``family_send``        | where ``transport_entries`` declares a decision: the policy whose action an  |
    |                        | event-triggered family keeps when it sends (``"paper"`` by default, which is |
    |                        | ``always`` on those presets; ``"always"`` where the paper's policy is a      |
    |                        | schedule of its own), so a family's extremes are ``always`` and ``silent``   |
    """

    name: ClassVar[str]
    paper: ClassVar[str]
    Config: ClassVar[type]
    version: ClassVar[int]
    metric: ClassVar[str]
    metric_unit: ClassVar[str]
    communication: ClassVar[str]
    episode_length_field: ClassVar[str] = "horizon"
    policy_module: ClassVar[str]
    family_send: ClassVar[str] = "paper"
    # the composed observation's own features (covariance_known, displacement, ...) are a composition's; a preset
    # observes what its registered version does
    own_features: ClassVar[tuple[str, ...]] = ()
    # what a preset appends after its own observation entries, in this order (its observation table): names of the
    # composed observation's table (``index``: the N-entry one-hot of the agent's index; ``log_trace``; the features
    # of ``OWN_FEATURES``, one entry each), computed as the composition computes them (``log_trace``,
    # ``own_feature_values``)
    appended_features: ClassVar[tuple[str, ...]] = ("communication_cost",)

    @classmethod
    def compose(cls, config):
        """The validated ``coloc_env.composition.Composition`` of the flat ``config``'s parts
        (``config.parts()``), with the episode length and ``composition_options``."""
        spec = Composition(*config.parts(), horizon=config.horizon, preset=cls.name,
                           **cls.composition_options(config))
        spec.validate()
        return spec

    def part_generators(self, rng):
        """The presets' rule: the world draws from the episode's generator itself; the network and the backend
        draw from its first and second child. (``gps_denied_nbp``'s rule gives its backend the first child and
        its network the second.)"""
        network, backend = rng.spawn(2)
        return rng, network, backend

    # --- the appended observation entries ------------------------------------------------------------------
    def observed_own_features(self) -> tuple[str, ...]:
        return (*self.own_features, *(name for name in self.appended_features if name in OWN_FEATURES))

    def appended_width(self, name: str) -> int:
        """How many entries the appended feature ``name`` takes: N for the ``index`` one-hot, else 1."""
        return self.num_agents if name == "index" else 1

    def appended_size(self) -> int:
        """How many entries ``appended_features`` adds to an agent's observation."""
        return self._appended_layout[2]

    @functools.cached_property
    def _appended_layout(self) -> tuple[tuple[str, ...], tuple[tuple[str, int], ...], int]:
        """(the own features among ``appended_features``, each appended feature with its first column, the
        entries in all): facts of the class's declarations and N, computed once per env."""
        columns, start = [], 0
        for name in self.appended_features:
            columns.append((name, start))
            start += self.appended_width(name)
        own = tuple(name for name in self.appended_features if name in OWN_FEATURES)
        return own, tuple(columns), start

    def appended_observation(self) -> np.ndarray:
        """(B, N, ``appended_size()``): the entries of ``appended_features``, in order."""
        B, N = self.batch, self.num_agents
        own, columns, size = self._appended_layout
        cov = self.backend.local_covariance() if own or "log_trace" in self.appended_features else None
        values = self.own_feature_values(own, cov) if own else None
        out = np.empty((B, N, size))
        for name, start in columns:
            if name == "index":
                out[..., start:start + N] = np.eye(N)
            elif name == "log_trace":
                out[..., start] = self.log_trace(cov)
            else:
                out[..., start] = values[..., own.index(name)]
        return out

    def extend_observation(self, observation: np.ndarray) -> np.ndarray:
        """The preset's own observation entries (B, N, m) followed by the appended ones, float32."""
        return np.concatenate([observation, self.appended_observation()], axis=-1).astype(np.float32)

    def extend_space(self, space: gymnasium.spaces.Box) -> gymnasium.spaces.Box:
        """The preset's own observation space followed by the appended entries' bounds."""
        bounds = {**OWN_BOUNDS, "log_trace": (-LOG_TRACE_BOUND, LOG_TRACE_BOUND)}
        low = [np.zeros(self.num_agents) if name == "index" else [bounds[name][0]] for name in self.appended_features]
        high = [np.ones(self.num_agents) if name == "index" else [bounds[name][1]] for name in self.appended_features]
        return gymnasium.spaces.Box(np.concatenate([space.low, *low]).astype(np.float32),
                                    np.concatenate([space.high, *high]).astype(np.float32), dtype=np.float32)

    def transport_entries(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The preset's transmit (or relay) decision, where one maps onto the event-triggered families
        (``agents.event_triggered``): (entries (A,) bool, the entries of an agent's flat action that carry it;
        quiet (A,), their values when the agent keeps quiet, ``silent``'s). Sending keeps the action of the
        policy ``family_send`` names. None (the default): no decision maps."""
        return None

    def preset_feature_positions(self) -> dict[str, int]:
        """Features of the composed table that the preset's own entries carry: name -> index (none by default)."""
        return {}

    def feature_index(self, name: str) -> int:
        """The index in an agent's observation of the feature ``name`` (a block's first): an appended one (after the
        preset's own entries), one the preset's own entries carry (``preset_feature_positions``), or, for a preset
        that observes the composed table (``own_features``), the composition's. A ``ValueError`` otherwise."""
        if name in self.appended_features:
            start = self.observation_space().shape[0] - self.appended_size()
            for other in self.appended_features:
                if other == name:
                    return start
                start += self.appended_width(other)
        positions = self.preset_feature_positions()
        if name in positions:
            return positions[name]
        if self.own_features:
            return super().feature_index(name)
        raise ValueError(f"{self.name}'s observation has no feature {name!r}; it has "
                         f"{[*positions, *self.appended_features]}")

    @classmethod
    def composition_options(cls, config) -> dict:
        """Composition-level fields (``reward``, ``communication_cost``) the flat config sets: a
        ``PresetConfig``'s declared ones (its ``horizon`` is passed separately); none by default."""
        if isinstance(config, PresetConfig):
            return {k: v for k, v in config.composition_options().items() if k != "horizon"}
        return {}


# The declarations ``register_preset`` requires of a preset class: name -> (type, what it is).
DECLARATIONS: dict[str, tuple[type, str]] = {
    "name": (str, "the preset's name"), "paper": (str, "the paper key"), "Config": (type, "the flat config class"),
    "version": (int, "the PettingZoo id's version, an integer >= 1"),
    "metric": (str, "what the episode metric measures"), "metric_unit": (str, "the metric's unit"),
    "communication": (str, "what the communication info counts"),
    "episode_length_field": (str, "the config field max_cycles sets"),
    "policy_module": (str, "the module of the preset's policies"),
}


class PresetRegistry(dict):
    """Name -> preset scenario class, in registration order, filled by ``register`` (``register_preset``).

    ``subscribe(on_register, on_unregister)`` lets a view of the presets follow the registry (the PettingZoo
    ids, the ``coloc_env.envs`` modules): ``on_register`` is called for every preset registered so far and then
    for each new one, ``on_unregister`` for each preset ``unregister`` removes."""

    def __init__(self):
        super().__init__()
        self._subscribers: list[tuple] = []

    @staticmethod
    def check(cls: type) -> None:
        """TypeError naming the preset and the field where a declaration is missing or of the wrong type."""
        label = getattr(cls, "name", cls.__name__)
        if not (isinstance(cls, type) and issubclass(cls, PresetScenario)):
            raise TypeError(f"preset {label!r}: a preset is a PresetScenario subclass, got {cls!r}")
        for field, (kind, what) in DECLARATIONS.items():
            if not any(field in vars(k) for k in cls.__mro__ if issubclass(k, PresetScenario)):  # not the core's
                raise TypeError(f"preset {label!r} declares no {field} ({what})")
            value = getattr(cls, field)
            if not isinstance(value, kind) or isinstance(value, bool) or (kind is str and not value.strip()):
                raise TypeError(f"preset {label!r}: {field} must be {what}, got {value!r}")
        if cls.version < 1:
            raise TypeError(f"preset {label!r}: version must be an integer >= 1, got {cls.version!r}")
        fields = {f.name for f in dataclasses.fields(cls.Config)} if dataclasses.is_dataclass(cls.Config) else set()
        if cls.episode_length_field not in fields:
            raise TypeError(f"preset {label!r}: episode_length_field {cls.episode_length_field!r} is not a field of "
                            f"{cls.Config.__name__}")

    def register(self, cls: type) -> type:
        """Register the preset class ``cls`` under ``cls.name`` (a decorator); a missing declaration or a name
        registered twice is an error naming the preset."""
        self.check(cls)
        if cls.name in self:
            raise ValueError(f"preset {cls.name!r} registered twice")
        self[cls.name] = cls
        for on_register, _ in self._subscribers:
            on_register(cls)
        return cls

    def unregister(self, name: str) -> None:
        """Remove the preset ``name`` (and its views: ids, ``coloc_env.envs`` module); a test's clean-up."""
        if name not in self:
            raise ValueError(f"unknown preset {name!r}; registered presets: {sorted(self)}")
        cls = self.pop(name)
        for _, on_unregister in self._subscribers:
            on_unregister(cls)

    def subscribe(self, on_register, on_unregister) -> None:
        self._subscribers.append((on_register, on_unregister))
        for cls in list(self.values()):
            on_register(cls)


PRESET_SCENARIOS = PresetRegistry()
register_preset = PRESET_SCENARIOS.register
unregister_preset = PRESET_SCENARIOS.unregister
