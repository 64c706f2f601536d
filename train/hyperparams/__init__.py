"""Per-scenario PPO hyperparameters, one small module each (``HYPERPARAMS``, ``ENV_CONFIG``, ``NUM_COPIES``,
optionally ``TIMESTEPS``, ``ALGORITHM``: ``"ppo"`` (stable-baselines3's PPO, the default) or ``"maskable_ppo"``
(sb3-contrib's MaskablePPO, which never samples a choice the env's action mask rules out) or ``"recurrent_ppo"``
(sb3-contrib's RecurrentPPO: an LSTM policy that carries a memory over the episode), and ``CRITIC``:
``"decentralized"`` (the default: the critic sees what the actor sees) or ``"centralized"`` (the critic also sees
the copy's ``state()``; ``agents.centralized_critic``)), and ``CURVE_EPISODES``: how many validation episodes
score each learning-curve point, the best of which becomes ``model.zip`` (default
``train.training.CURVE_EPISODES``), and ``COST_RANGE``: ``(lo, hi)``, the range the training env draws each
episode's communication cost from (the composition option ``cost_range``: log-uniform for lo > 0), so that
``coloc train S`` trains one cost-conditioned policy (``--cost-range`` overrides it; default: none, a fixed
cost), and ``COST_REWARD_SCALE``: c_ref > 0, which divides each training step's reward by 1 + c / c_ref under a
cost range (c the episode's cost; default: none, the reward unscaled), and ``PAPER_ENTRIES``: the name of the
action entries a model leaves to the paper's rule (``agents.paper_entries``; ``--paper-entries`` overrides it;
default: none, the model decides every entry), and ``ACTIONS``: ``"deterministic"`` (the default: the model acts
by its most likely action) or ``"sampled"`` (it draws its action from its distribution, seeded, as a
random-access policy must: on a shared medium a deterministic policy shared by every agent sends or stays
silent in step with the others); the learning curve validates it so, ``model.json`` records it, and
evaluation plays it so (``train.evaluate.model_actions``), and ``COST_FEATURE``: ``"raw"`` (the default: the
network reads the observed cost c itself) or ``"scaled"`` (under a cost range it reads c's position in the range,
from -1 at lo to 1 at hi, log-scaled for lo > 0: ``agents.cost_feature``; ``model.json`` records it).

A preset's module also holds what only ``train`` needs of it: ``LEADERBOARD_TARGET`` (the leaderboard's target for
a learned policy, ``train.leaderboard.target``), and optionally ``DEMO_RUN`` (``make demo``'s budget,
``train.demo``), ``EVALUATE_EXTRA_ROWS`` (``coloc evaluate --policy all``'s extra rows,
``train.evaluate.extra_rows``), ``BENCH_BATCHES`` and ``BENCH_ONE_EPISODE`` (``coloc bench``'s batch sizes and
one-episode row, ``train.bench``). They are found by the preset's name (``setting``, ``presets_declaring``)."""

import copy
import importlib

# The PPO settings a scenario module starts from with ``ppo``: stable-baselines3's own defaults, written out
# so that each trained model's model.json records them.
PPO_DEFAULTS = {"n_epochs": 10, "learning_rate": 3e-4, "gae_lambda": 0.95, "clip_range": 0.2,
                "policy_kwargs": {"net_arch": [64, 64]}}


def ppo(**settings) -> dict:
    """PPO keyword arguments: ``settings`` over ``PPO_DEFAULTS`` (a fresh copy, so no module shares one)."""
    return {**copy.deepcopy(PPO_DEFAULTS), **settings}


def module_name(scenario: str) -> str:
    """The module of ``scenario``'s settings: the preset's name, or a composition's ``WORLD/NETWORK/BACKEND``
    with ``__`` for each ``/`` (``circles__broadcast__ukf_ccl``)."""
    return scenario.replace("/", "__")


def module(scenario: str):
    """The hyperparameter module of ``scenario`` (ValueError naming the scenario where it has none)."""
    from coloc_env.config import BadInput
    try:
        return importlib.import_module(f"train.hyperparams.{module_name(scenario)}")
    except ModuleNotFoundError as exc:
        raise BadInput(f"no training hyperparameters for scenario {scenario!r} (train/hyperparams/"
                       f"{module_name(scenario)}.py)") from exc


def load(scenario: str) -> tuple[dict, dict]:
    """(PPO keyword arguments, env config used for training) of ``scenario``."""
    settings = module(scenario)
    return dict(settings.HYPERPARAMS), dict(settings.ENV_CONFIG)


def _setting_choice(scenario: str, field: str, allowed, default: str) -> str:
    """The scenario module's ``field`` (``default`` where it sets none), which must be one of ``allowed``."""
    from coloc_env.config import BadInput
    name = getattr(module(scenario), field, default)
    if name not in allowed:
        raise BadInput(f"{field} of train/hyperparams/{module_name(scenario)}.py must be one of "
                       f"{list(allowed)}, got {name!r}")
    return name


def algorithm(scenario: str) -> str:
    """The scenario's training algorithm, one of ``agents.sb3.ALGORITHMS`` (its module's ``ALGORITHM``, else
    ``"ppo"``)."""
    from agents.sb3 import ALGORITHMS

    return _setting_choice(scenario, "ALGORITHM", ALGORITHMS, "ppo")


def budget(scenario: str, default: int) -> int:
    """The scenario's training budget in timesteps (its module's ``TIMESTEPS``, else ``default``)."""
    return int(getattr(module(scenario), "TIMESTEPS", default))


def curve_episodes(scenario: str, default: int) -> int:
    """Validation episodes per learning-curve point (its module's ``CURVE_EPISODES``, else ``default``): an
    integer >= 2, since a point carries a 95 % interval."""
    from coloc_env.config import BadInput
    value = getattr(module(scenario), "CURVE_EPISODES", default)
    if isinstance(value, bool) or not isinstance(value, int) or value < 2:
        raise BadInput(f"CURVE_EPISODES of train/hyperparams/{module_name(scenario)}.py must be an integer >= 2, "
                       f"got {value!r}")
    return value


def cost_range(scenario: str) -> tuple[float, float] | None:
    """The scenario's training cost range (its module's ``COST_RANGE``, else None): None or a pair (lo, hi) with
    0 <= lo <= hi <= ``coloc_env.composition.COST_LIMIT``."""
    from coloc_env.composition import check_cost_range

    value = getattr(module(scenario), "COST_RANGE", None)
    if value is None:
        return None
    value = tuple(value) if isinstance(value, list) else value
    check_cost_range(f"COST_RANGE of train/hyperparams/{module_name(scenario)}.py", value)
    return float(value[0]), float(value[1])


def cost_reward_scale(scenario: str) -> float | None:
    """The scenario's ``COST_REWARD_SCALE`` (else None): under a cost range, each training step's reward is divided
    by 1 + c / ``COST_REWARD_SCALE`` (c: the episode's cost; ``train.training.cost_balanced_reward``), a number
    > 0 in the metric's units per message."""
    from coloc_env.config import BadInput

    value = getattr(module(scenario), "COST_REWARD_SCALE", None)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < float("inf"):
        raise BadInput(f"COST_REWARD_SCALE of train/hyperparams/{module_name(scenario)}.py must be a number > 0, "
                       f"got {value!r}")
    return float(value)


ACTIONS = ("deterministic", "sampled")


def actions(scenario: str) -> str:
    """How the scenario's model acts, one of ``ACTIONS`` (its module's ``ACTIONS``, else ``"deterministic"``)."""
    return _setting_choice(scenario, "ACTIONS", ACTIONS, "deterministic")


def cost_feature(scenario: str) -> str:
    """How a model trained over a cost range reads the observed cost, one of ``agents.cost_feature.COST_FEATURES``
    (its module's ``COST_FEATURE``, else ``"raw"``: c itself; ``"scaled"``: its position in the range,
    ``agents.cost_feature.CostScaledExtractor``)."""
    from agents.cost_feature import COST_FEATURES

    return _setting_choice(scenario, "COST_FEATURE", COST_FEATURES, "raw")


def critic(scenario: str) -> str:
    """The scenario's critic, one of ``agents.centralized_critic.CRITICS`` (its module's ``CRITIC``, else
    ``"decentralized"``)."""
    from agents.centralized_critic import CRITICS

    return _setting_choice(scenario, "CRITIC", CRITICS, "decentralized")


def setting(scenario: str, field: str, default=None):
    """``field`` of ``scenario``'s module, ``default`` where the module sets none or the scenario has no module."""
    try:
        settings = module(scenario)
    except ValueError:
        return default
    return getattr(settings, field, default)


def presets_declaring(field: str) -> dict:
    """Preset name -> its module's ``field``, for every registered preset whose module sets it (registry order)."""
    import coloc_env

    missing = object()
    values = {name: setting(name, field, missing) for name in coloc_env.SCENARIOS}
    return {name: value for name, value in values.items() if value is not missing}
