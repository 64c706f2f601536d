"""Trained stable-baselines3 models as policies.

A saved model ``model.zip`` has a sidecar ``model.json`` recording the
scenario and its config (the run's other weights, ``best.zip``, ``last.zip``
and ``checkpoint.zip``, are described by the same file: ``model_metadata``);
loading it for another scenario, or for spaces that differ from the ones it
was trained on, is a ``ValueError``.

Damaged files are ``ValueError`` s naming the file and what is wrong with it
(``check_model_zip``, ``read_metadata``): a truncated or non-zip
``model.zip``, one without SB3's ``data`` or ``policy.pth`` members, a
``model.json`` that is truncated, not JSON, or not an object. Without these
checks SB3 fails with an ``AssertionError`` or a ``KeyError`` that names no file.
"""

from __future__ import annotations

import json
import os
import zipfile
import zlib

import numpy as np

from agents.base import Policy
from coloc_env.config import BadInput

# the members stable-baselines3's save_to_zip_file writes and load_from_zip_file needs
REQUIRED_MEMBERS = ("data", "policy.pth")


# the weights a training run writes beside model.zip: its model.json describes them all (train.training)
RUN_WEIGHTS = ("best.zip", "last.zip", "checkpoint.zip")


def metadata_path(model_path: str) -> str:
    return os.path.splitext(model_path)[0] + ".json"


def model_metadata(path: str) -> dict | None:
    """The ``model.json`` that describes the model ``path``, as a dict: its own sidecar (``PATH.json``), else, for
    the other weights a training run writes beside ``model.zip`` (``RUN_WEIGHTS``), the run's ``model.json`` in the
    same folder; None where there is neither."""
    candidates = [metadata_path(path)]
    if os.path.basename(path) in RUN_WEIGHTS:
        candidates.append(os.path.join(os.path.dirname(path), "model.json"))
    for meta_file in candidates:
        if os.path.isfile(meta_file):
            return read_metadata(meta_file)
    return None


def samples_actions(meta: dict | None) -> bool:
    """Whether a model's ``model.json`` (``meta``; None: none) says it acts by sampled actions
    (``"actions": "sampled"``: the training settings' ``ACTIONS``)."""
    return meta is not None and meta.get("actions") == "sampled"


def check_model_zip(path: str) -> None:
    """ValueError naming ``path`` unless it is a complete zip holding SB3's ``data`` and ``policy.pth``."""
    try:
        with zipfile.ZipFile(path) as archive:
            names = archive.namelist()
            missing = [m for m in REQUIRED_MEMBERS if m not in names]
            if missing:
                shown = ", ".join(names[:5]) + (f", ... ({len(names)} members)" if len(names) > 5 else "")
                raise BadInput(f"model {path!r} is not a complete stable-baselines3 model (truncated, or not "
                                 f"saved by coloc train): the zip has no {' or '.join(missing)} (it holds {shown})")
            damaged = None
            for name in names:  # read every member: a CRC mismatch or a broken deflate stream is damage
                try:
                    with archive.open(name) as member:
                        while member.read(1 << 20):
                            pass
                except (zipfile.BadZipFile, zlib.error, EOFError) as exc:
                    damaged = f"{name!r} ({exc})"
                    break
    except zipfile.BadZipFile as exc:
        raise BadInput(f"model {path!r} is not a readable zip (truncated or not a model.zip): {exc}") from exc
    except (OSError, EOFError) as exc:
        raise BadInput(f"model {path!r} cannot be read: {exc}") from exc
    if damaged is not None:
        raise BadInput(f"model {path!r} is damaged: member {damaged} cannot be read back")


def read_metadata(meta_file: str) -> dict:
    """The ``model.json`` beside a model, as a dict; ValueError naming the file when it is not a JSON object."""
    try:
        with open(meta_file, encoding="utf-8") as fh:
            meta = json.load(fh)
    except json.JSONDecodeError as exc:
        raise BadInput(f"model metadata {meta_file!r} is not valid JSON (truncated?): {exc.msg} at line "
                         f"{exc.lineno} column {exc.colno}") from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise BadInput(f"model metadata {meta_file!r} cannot be read: {exc}") from exc
    if not isinstance(meta, dict):
        raise BadInput(f"model metadata {meta_file!r} must hold a JSON object, got {type(meta).__name__}")
    return meta


def check_spaces(path: str, env, model) -> None:
    """The model's observation and action spaces must equal the env's in full: type, shape, dtype and every
    bound (Box low/high, MultiDiscrete nvec/start, Discrete n/start), not only type and shape: a policy
    trained for ``nvec = [27, 2, ...]`` plays nonsense on ``[17, 2, ...]`` of the same shape. A model with a
    centralized critic saw ``[observation | state]``: that is the space it must match."""
    from agents.centralized_critic import critic_observation_space, is_centralized

    agent = env.possible_agents[0]
    observation_space = env.observation_space(agent)
    if is_centralized(model):
        observation_space = critic_observation_space(observation_space, env.unwrapped.state_space)
    for kind, ours, theirs in (("observation", observation_space, model.observation_space),
                               ("action", env.action_space(agent), model.action_space)):
        if ours != theirs or ours.dtype != theirs.dtype:
            raise BadInput(f"model {path!r} has {kind} space {theirs!r}, the env has {ours!r}")


def is_maskable(model) -> bool:
    """True for sb3-contrib's MaskablePPO (its ``predict`` takes the action masks)."""
    return isinstance(model, algorithm_class("maskable_ppo"))


def is_recurrent(model) -> bool:
    """True for sb3-contrib's RecurrentPPO (its ``predict`` takes and returns the LSTM's memory)."""
    return isinstance(model, algorithm_class("recurrent_ppo"))


# stable-baselines3's PPO; sb3-contrib's MaskablePPO (reads action masks) and RecurrentPPO (an LSTM policy)
ALGORITHMS = ("ppo", "maskable_ppo", "recurrent_ppo")


def algorithm_class(name: str):
    """The class of a training algorithm's name in ``ALGORITHMS``."""
    if name == "maskable_ppo":
        from sb3_contrib import MaskablePPO

        return MaskablePPO
    if name == "recurrent_ppo":
        from sb3_contrib import RecurrentPPO

        return RecurrentPPO
    if name == "ppo":
        from stable_baselines3 import PPO

        return PPO
    raise BadInput(f"algorithm must be one of {list(ALGORITHMS)}, got {name!r}")


def model_class(path: str, meta: dict | None = None):
    """The class that saved ``path``: the ``algorithm`` of ``meta`` (``model_metadata(path)`` when not given),
    else what the zip's policy class says."""
    if meta is None:
        meta = model_metadata(path)
    name = (meta or {}).get("algorithm")
    if name is None:  # a model without model.json (or from before the field): the zip names its policy class
        with zipfile.ZipFile(path) as archive:
            data = archive.read("data")
        name = "maskable_ppo" if b"Maskable" in data else "recurrent_ppo" if b"RecurrentActorCritic" in data else "ppo"
    try:
        return algorithm_class(name)
    except ValueError as exc:
        raise BadInput(f"model {path!r}: {exc}") from exc


class SB3Policy(Policy):
    """The actions of a trained SB3 model, shared by all agents (parameter sharing): its most likely ones, or
    sampled ones where ``deterministic`` is False or, left None, where its ``model.json`` records
    ``"actions": "sampled"`` (a random-access policy; the draws come from torch's generator, which
    ``start_episode`` seeds with the episode's seed so that an episode repeats); a MaskablePPO
    model reads the env's action masks of the current step, as it did in training, and a model trained with a
    centralized critic gets the env's ``state()`` after each observation (its actor ignores it).

    A model trained with ``paper_entries`` (``model.json``; ``agents.paper_entries``) has those entries of its
    action filled by the paper's rule, drawing as the paper's policy does: from ``default_rng(seed)``, which an
    evaluation restarts for each episode (``start_episode``: ``agents.base.episode_generator``).

    A RecurrentPPO model carries each agent's LSTM memory from one step to the next. It starts afresh at the
    episode's first step (the env's ``step_count`` is 0), and a second call of ``act`` at the same step
    starts again from that step's memory instead of advancing it twice.
    """

    def __init__(self, env, path: str, deterministic: bool | None = None, seed: int | None = None):
        super().__init__(env)
        if not os.path.isfile(path):
            raise BadInput(f"policy model {path!r} does not exist")
        scenario_name = env.unwrapped.scenario.name
        meta = model_metadata(path)
        if meta is not None:
            if meta.get("scenario") != scenario_name:
                raise BadInput(f"model {path!r} was trained on {meta.get('scenario')!r}, not {scenario_name!r}")
        check_model_zip(path)
        try:
            self.model = model_class(path, meta).load(path, device="cpu")
        except Exception as exc:  # SB3 reports a damaged model with assorted exceptions that name no file
            # torch's message runs over many lines of advice: its first line says what failed
            first = next((line.strip() for line in str(exc).splitlines() if line.strip()), "")
            raise BadInput(f"model {path!r} cannot be loaded by stable-baselines3: "
                           f"{type(exc).__name__}: {first}") from exc
        check_spaces(path, env, self.model)
        import agents

        self.paper_entries = agents.paper_entries(scenario_name, (meta or {}).get("paper_entries"))
        self.rng = np.random.default_rng(seed)  # for the paper entries; an evaluation restarts it per episode
        self.deterministic = not samples_actions(meta) if deterministic is None else deterministic
        self.masked = is_maskable(self.model)
        from agents.centralized_critic import is_centralized

        self.centralized = is_centralized(self.model)
        self.recurrent = is_recurrent(self.model)
        self._memory_step: int | None = None  # the env step the memories below belong to
        self._memory_in = self._memory_out = None  # LSTM memory before and after that step's act

    def start_episode(self, seed: int) -> None:
        from agents.base import episode_generator

        self._memory_step = self._memory_in = self._memory_out = None
        self.rng = episode_generator(seed)
        if not self.deterministic:
            import torch

            torch.manual_seed(seed)

    def act(self, observations):
        agents = list(observations)
        batch = np.stack([observations[a] for a in agents])
        if self.centralized:  # the input it was trained on; its actor reads only the own observation
            from agents.centralized_critic import extend_observation

            batch = extend_observation(batch, self.env.unwrapped.state())
        masks = {}
        if self.masked:  # the core's masks of this step, rows in possible_agents order
            rows = np.asarray(self.env.unwrapped.scenario.action_mask(), bool)[0]
            order = list(self.env.possible_agents)
            masks["action_masks"] = rows[[order.index(a) for a in agents]]
        if self.recurrent:
            step = self.env.unwrapped.step_count
            if step != self._memory_step:  # a new step: the memory the last step produced is its input
                self._memory_in = None if step == 0 else self._memory_out
                self._memory_step = step
            starts = np.full(len(agents), self._memory_in is None)
            actions, self._memory_out = self.model.predict(batch, state=self._memory_in, episode_start=starts,
                                                           deterministic=self.deterministic)
        else:
            actions, _ = self.model.predict(batch, deterministic=self.deterministic, **masks)
        if self.paper_entries is not None:  # in possible_agents order, as the paper's policy reads them
            order, rows = self.observation_rows(observations)
            full = np.zeros((len(order), *np.shape(actions)[1:]), dtype=np.asarray(actions).dtype)
            full[[order.index(a) for a in agents]] = actions
            full = self.paper_entries.entries([self.rng], rows[None], full[None])[0]
            actions = full[[order.index(a) for a in agents]]
        return {a: actions[i] for i, a in enumerate(agents)}
