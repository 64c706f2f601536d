"""Per-scenario PPO hyperparameters, one small module each (``HYPERPARAMS``, ``ENV_CONFIG``)."""

import importlib


def load(scenario: str) -> tuple[dict, dict]:
    """(PPO keyword arguments, env config used for training) of ``scenario``."""
    try:
        module = importlib.import_module(f"train.hyperparams.{scenario}")
    except ModuleNotFoundError as exc:
        raise ValueError(f"no training hyperparameters for scenario {scenario!r}") from exc
    return dict(module.HYPERPARAMS), dict(module.ENV_CONFIG)


def budget(scenario: str, default: int) -> int:
    """The scenario's training budget in timesteps (its module's ``TIMESTEPS``, else ``default``)."""
    try:
        module = importlib.import_module(f"train.hyperparams.{scenario}")
    except ModuleNotFoundError as exc:
        raise ValueError(f"no training hyperparameters for scenario {scenario!r}") from exc
    return int(getattr(module, "TIMESTEPS", default))
