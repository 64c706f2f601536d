"""Registered, versioned env ids: every preset as ``coloc/<preset>-v<N>`` in PettingZoo's registry.

Importing `coloc_env` registers each preset twice, once per PettingZoo API:

```python
import pettingzoo

import coloc_env  # registers the ids

env = pettingzoo.make("parallel", "coloc/relay_ukf-v2", num_agents=4)   # a ParallelEnv
aec = pettingzoo.make("aec", "coloc/relay_ukf-v2")                          # its AEC view
```

Keywords go to the preset's config (its dataclass fields, as for
`coloc_env.parallel_env`), plus `render_mode` and `max_cycles`; an unknown
keyword is a `ValueError`. An id without a version (`"coloc/relay_ukf"`)
resolves to the latest one.

Versions: a preset's class declares the version it is registered under (its
``version``; ``VERSIONS`` maps each preset to it). It bumps whenever the
preset's spaces or dynamics change (a different observation or action space,
or different observations, rewards or errors for the same seed and actions).
`tests/coloc_env/test_registry.py` pins each version's spaces and a short
seeded rollout's fingerprint (`fingerprint`), so a change without a bump fails
there. To bump: add 1 to the preset's ``version``, then add the new id's pin to
the test's `PINS` (the failing test prints the line to add), keeping the old
ids' pins as they were. A preset registered after import (``register_preset``)
gets its ids then; ``unregister_preset`` removes them.
Compositions keep their `WORLD/NETWORK/BACKEND` names and are not registered.
"""

from __future__ import annotations

import numpy as np
import pettingzoo

from coloc_env import envs
from coloc_env.config import module_names
from coloc_env.scenarios import REGISTRY

NAMESPACE = "coloc"


# preset -> the version it is registered under (its class's ``version``)
__getattr__ = module_names(__name__, {"VERSIONS": lambda: {preset: cls.version for preset, cls in REGISTRY.items()}})
def env_id(preset: str) -> str:
    """The registered id of a preset at its current version, e.g. `coloc/relay_ukf-v2`."""
    if not isinstance(preset, str) or preset not in REGISTRY:
        raise ValueError(f"unknown preset {preset!r}; registered presets: {sorted(REGISTRY)}")
    return f"{NAMESPACE}/{preset}-v{REGISTRY[preset].version}"


def env_ids() -> tuple[str, ...]:
    """Every preset's registered id, in `coloc_env.SCENARIOS` order."""
    return tuple(env_id(name) for name in REGISTRY)


def _register_ids(scenario_cls) -> None:
    """Register a preset with PettingZoo's `"parallel"` and `"aec"` registries (once: an id already registered is
    left as it is, so re-importing `coloc_env` warns about nothing)."""
    constructors = envs.constructors(scenario_cls.name)
    makers = {"parallel": constructors[0], "aec": constructors[2]}
    for kind, registry in (("parallel", pettingzoo.parallel_registry), ("aec", pettingzoo.aec_registry)):
        if env_id(scenario_cls.name) not in registry:
            pettingzoo.register(kind, env_id(scenario_cls.name), entry_point=makers[kind])


def _unregister_ids(scenario_cls) -> None:
    ident = f"{NAMESPACE}/{scenario_cls.name}-v{scenario_cls.version}"
    for registry in (pettingzoo.parallel_registry, pettingzoo.aec_registry):
        registry.pop(ident, None)


def register_presets() -> None:
    """Register every preset registered so far with PettingZoo (ids already there are left as they are). Importing
    this module does it, and registers each preset that registers later."""
    for scenario_cls in list(REGISTRY.values()):
        _register_ids(scenario_cls)


REGISTRY.subscribe(_register_ids, _unregister_ids)


def _space_text(space) -> str:
    """A space as text that changes whenever the space does (bounds included, not only their extremes)."""
    import gymnasium.spaces as spaces

    if isinstance(space, spaces.Box):
        return (f"Box(shape={space.shape}, dtype={space.dtype}, low={np.unique(space.low).tolist()}, "
                f"high={np.unique(space.high).tolist()})")
    if isinstance(space, spaces.MultiDiscrete):
        return f"MultiDiscrete({space.nvec.tolist()})"
    return repr(space)


def spaces_text(env) -> str:
    """The observation and action spaces of a ParallelEnv's first agent (every agent's are the same)."""
    agent = env.possible_agents[0]
    return (f"{len(env.possible_agents)} agents; observation {_space_text(env.observation_space(agent))}; "
            f"action {_space_text(env.action_space(agent))}")


def _actions(space, rng: np.random.Generator, num_agents: int) -> np.ndarray:
    """Seeded actions drawn with numpy (not the space's own sampler, whose draws gymnasium may change)."""
    import gymnasium.spaces as spaces

    if isinstance(space, spaces.MultiDiscrete):
        return rng.integers(0, space.nvec, size=(num_agents, *space.nvec.shape))
    if isinstance(space, spaces.Discrete):
        return space.start + rng.integers(0, space.n, size=num_agents)
    if isinstance(space, spaces.MultiBinary):
        return rng.integers(0, 2, size=(num_agents, *space.shape))
    if isinstance(space, spaces.Box):
        low = np.where(np.isfinite(space.low), space.low, -1.0)
        high = np.where(np.isfinite(space.high), space.high, 1.0)
        return rng.uniform(low, high, size=(num_agents, *space.shape)).astype(space.dtype)
    raise TypeError(f"no seeded actions for a {type(space).__name__} space")


def fingerprint(env, seed: int = 0, steps: int = 5) -> list[float]:
    """A short seeded rollout's fingerprint: the sums of the observations, the rewards and the position
    errors over `steps` steps of seeded random actions after `reset(seed=seed)`. Equal fingerprints
    (to floating-point rounding) mean the same dynamics on this rollout; it is what a version pins."""
    rng = np.random.default_rng(seed)
    observations, infos = env.reset(seed=seed)
    agents = list(env.possible_agents)
    space = env.action_space(agents[0])
    total_obs = float(sum(np.sum(np.asarray(observations[a], dtype=float)) for a in agents))
    total_reward = total_error = 0.0
    for _ in range(steps):
        if not env.agents:
            break
        actions = _actions(space, rng, len(agents))
        observations, rewards, _, _, infos = env.step({a: actions[i] for i, a in enumerate(agents)})
        total_obs += float(sum(np.sum(np.asarray(observations[a], dtype=float)) for a in observations))
        total_reward += float(sum(rewards.values()))
        total_error += float(sum(np.sum(infos[a]["position_error"]) for a in infos))
    return [total_obs, total_reward, total_error]
