"""What the relay-chain presets share (``relay_ukf``, ``mrclam_relay``): a team that passes location information
along chains of the ``relay`` network to a joint UKF, rewarded as one.

| piece           | shared rule                                                                                 |
|-----------------|---------------------------------------------------------------------------------------------|
| keywords        | ``RelayTeamConfig``: the relay links (``comm_range``, ``max_hops``, ``loss_at_zero``,       |
|                 | ``loss_length``, ``hop_cost_per_m2``), ``communication_cost``, ``ukf_lambda``, ``reward``; the |
|                 | old ``hop_cost`` an alias of ``communication_cost``; ``cost_range`` (the composition's: each |
|                 | copy draws its cost per hop per episode at reset)                                           |
| observation     | one-hot of the agent's index (N), the preset's own features, the distance to each agent      |
|                 | / ``distance_scale`` (N, 0 for itself), log tr P_ii (m^2), the step fraction k / horizon,    |
|                 | then the composed observation's ``displacement``, ``steps_since`` and ``message_value``      |
|                 | since the agent's last relayed hop, and ``communication_cost``: the copy's cost per hop this |
|                 | episode (``communication_cost``, or the draw from ``cost_range``), m                         |
| relay decision  | the event-triggered families (``agents.event_triggered``) decide each relay entry (action    |
|                 | entries 1..): send = ``paper``'s choice (= ``always``), quiet = N, stop (``silent`` =        |
|                 | ``no_relay``); the measurement choice (entry 0) is ``paper``'s                               |
| action mask     | each relay entry: the ``relay`` network's ``next_hop`` rule without its "nearest" choice     |
| reward          | the team's, for every agent: ``"error"`` -mean_i ||xhat_i - x_i|| (m), ``"trace"``          |
|                 | -mean_i sqrt(tr P_ii) (m, the filter's own RMS error), minus the step's communication cost   |
| state           | every agent's observation, then the log of each agent's covariance diagonal                 |
| metric          | the distance error averaged over the steps and agents                                       |

Communication cost: the relay network sends one message per delivered hop, at its holder, so the
composition's per-message ``communication_cost`` is the flat cost of a hop; the network adds the hop's
energy ``hop_cost_per_m2`` d^2 (``coloc_env.networks.relay``). Both are subtracted in metres, the unit of
the reward's error; the ``hop_cost`` info key is their sum over the team.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar

import gymnasium
import numpy as np

from coloc_env.rendering import Link
from coloc_env.scenarios.binding import PresetConfig, PresetScenario, keyword


@dataclasses.dataclass(frozen=True)
class RelayTeamConfig(PresetConfig):
    """The keywords of a relay-chain preset's links, costs and filter. A subclass names its parts, the part
    fields it fixes (``fixed``: ``"<kind>.<field>"`` -> value) and its team's size (``team_size``, named
    ``team_label`` in messages)."""

    fixed: ClassVar[dict[str, Any]] = {}
    team_label: ClassVar[str]  # how a message names N (the keyword that sets it)
    aliases: ClassVar[dict[str, str]] = {"hop_cost": "communication_cost"}

    comm_range: float = keyword(float("inf"), "network.comm_range")
    max_hops: int | None = keyword(None, "network.max_hops")
    loss_at_zero: float = keyword(0.0, "network.loss_at_zero")
    loss_length: float = keyword(float("inf"), "network.loss_length")
    communication_cost: float = keyword(0.0, "composition.communication_cost")
    cost_range: tuple | None = keyword(None, "composition.cost_range")
    hop_cost_per_m2: float = keyword(0.0, "network.hop_cost_per_m2")
    ukf_lambda: float = keyword(0.0, "backend.ukf_lambda")
    reward: str = keyword("error", "composition.reward")

    @property
    def team_size(self) -> int:  # pragma: no cover - interface
        raise NotImplementedError

    def bound_fields(self, kind: str) -> dict[str, Any]:
        """The keywords' fields of part ``kind`` over the fields the preset fixes."""
        fixed = {target.split(".", 1)[1]: value for target, value in self.fixed.items()
                 if target.split(".", 1)[0] == kind}
        return {**fixed, **super().bound_fields(kind)}

    def check_preset(self) -> None:
        """The parts' rules between a field and the team's size, which a part's own check cannot see (the
        network's hop budget, the backend's UKF spread; the parts apply them again at build)."""
        _, network, backend = self.parts()
        network.check_hop_budget(self.team_size, "", self.team_label)
        backend.check_spread(self.team_size, "", self.team_label)


class RelayTeamScenario(PresetScenario):
    """Batched core of a relay-chain preset (module table). A subclass gives ``preset_entries`` and
    ``feature_bounds`` (its observation's entries after the one-hot), ``team_error``, ``own_traces``,
    ``own_variances`` and ``true_position``, its ``estimate`` (B, N, >= 2: position first), and keeps
    ``dead_reckoning`` (B, N, >= 2)."""

    appended_features = ("displacement", "steps_since", "message_value", "communication_cost")

    distance_scale: ClassVar[float]  # metres per unit of the observation's distances
    agent_state_dim: ClassVar[int]
    dead_reckoning: np.ndarray
    estimate: np.ndarray

    # --- what a preset gives -------------------------------------------------------------------------------
    def preset_entries(self) -> np.ndarray:  # pragma: no cover - interface
        """The preset's observation entries after the one-hot (B, N, m)."""
        raise NotImplementedError

    def feature_bounds(self) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - interface
        raise NotImplementedError

    def team_error(self) -> np.ndarray:  # pragma: no cover - interface
        """||xhat_i - x_i|| (B, N), metres, of the current estimate (after a step: its prediction to k + 1)."""
        raise NotImplementedError

    def own_traces(self) -> np.ndarray:  # pragma: no cover - interface
        """tr P_ii (B, N), m^2, of each agent's position covariance in the current estimate."""
        raise NotImplementedError

    def own_variances(self) -> np.ndarray:  # pragma: no cover - interface
        """The diagonal of every agent's covariance (B, N agent_state_dim), for ``state``."""
        raise NotImplementedError

    def true_position(self) -> np.ndarray:  # pragma: no cover - interface
        """True positions (B, N, 2) at the current estimate's time (after a step: k + 1), a new array."""
        raise NotImplementedError

    def observed_distances(self) -> np.ndarray:
        """The distances between the agents the observation shows (B, N, N), metres: the world's."""
        return self.world.distances()

    # --- the shared codec ----------------------------------------------------------------------------------
    @property
    def obs_dim(self) -> int:
        return 2 * self.num_agents + self.feature_bounds()[0].size + 2 + self.appended_size()

    def observation_space(self):
        N = self.num_agents
        low, high = self.feature_bounds()
        low = np.concatenate([np.zeros(N), low, np.zeros(N), [-np.inf], [0.0]])
        high = np.concatenate([np.ones(N), high, np.full(N, np.inf), [np.inf], [1.0]])
        return self.extend_space(gymnasium.spaces.Box(low.astype(np.float32), high.astype(np.float32),
                                                      dtype=np.float32))

    def state_space(self):
        dim = self.num_agents * (self.obs_dim + self.agent_state_dim)
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(dim,), dtype=np.float32)

    def observation(self) -> np.ndarray:
        B, N = self.batch, self.num_agents
        features = self.preset_entries()
        m = features.shape[-1]
        extra = self.appended_observation()
        obs = np.empty((B, N, 2 * N + m + 2 + extra.shape[-1]), dtype=np.float32)  # cast per entry, as astype would
        obs[:, :, :N] = np.eye(N)
        obs[:, :, N:N + m] = features
        obs[:, :, N + m:2 * N + m] = self.observed_distances() / self.distance_scale
        obs[:, :, 2 * N + m] = np.log(self.own_traces())
        obs[:, :, 2 * N + m + 1] = (self.k / self.horizon)[:, None]
        obs[:, :, 2 * N + m + 2:] = extra
        return obs

    def action_vector(self, which: str) -> np.ndarray:
        """One agent's fixed action, for a tool that tiles one action over every agent (``train.frontier`` places
        its knob grids from such episodes): measurement choice 0 (the measuring agent uses platform 0, where it
        may) and every relay entry N, stop, whatever ``which`` (``default``, ``maximum``, ``minimum``). A relay
        chain depends on who measured and on the distances, which one tiled action cannot express; the preset's
        ``always`` and ``silent`` are its policies (``agents.relay_ukf``, ``agents.mrclam_relay``)."""
        size = int(np.prod(self.action_space().shape))
        return np.where(np.arange(size) >= 1, self.num_agents, 0).astype(np.int64)

    def transport_entries(self) -> tuple[np.ndarray, np.ndarray]:
        """The relay entries (1..): quiet = N, stop (``no_relay``, this preset's ``silent``)."""
        size = int(np.prod(self.action_space().shape))
        entries = np.arange(size) >= 1
        return entries, np.where(entries, float(self.num_agents), 0.0)

    def preset_feature_positions(self) -> dict[str, int]:
        """The composed table's features this observation carries among its own entries: ``index`` (the
        one-hot), ``log_trace`` (log tr P_ii) and ``step_fraction``."""
        N, m = self.num_agents, self.feature_bounds()[0].size
        return {"index": 0, "log_trace": 2 * N + m, "step_fraction": 2 * N + m + 1}

    def state(self) -> np.ndarray:
        log_var = np.log(self.own_variances())
        return np.concatenate([self.observation().reshape(self.batch, -1), log_var], axis=-1).astype(np.float32)

    def relay_masks(self) -> tuple[list, np.ndarray]:
        """(the blocks' masks, the relay entries' valid choices (B, N, entries (N + 1))): the ``relay``
        network's ``next_hop`` rule without its "nearest" choice N + 1, which the codec lacks."""
        masks = self.block_choice_masks()
        next_hop = masks[self.block_parts.index("network")]
        return masks, next_hop[..., :self.num_agents + 1].reshape(self.batch, self.num_agents, -1)

    def step_cost(self) -> np.ndarray:
        """The team's communication cost of the step (B,): every agent's ``communication_costs``, summed."""
        return self.communication_costs().sum(axis=-1)

    def compute_reward(self) -> np.ndarray:
        """The team's, for every agent: minus the mean over agents of the error (or sqrt tr P_ii) of the
        current estimate, minus the step's communication cost."""
        if self.composition.reward == "error":
            loss = self.team_error().mean(axis=-1)
        else:
            loss = np.sqrt(self.own_traces()).mean(axis=-1)
        return np.repeat((-loss - self.step_cost())[:, None], self.num_agents, axis=1)

    def team(self, values) -> np.ndarray:
        """A per-copy value (B,) repeated for every agent (B, N)."""
        return np.repeat(np.asarray(values)[:, None], self.num_agents, axis=1)

    def reported_position_cov(self) -> np.ndarray | None:
        """The covariance (B, N, 2, 2) of the infos' ``estimated_position``: the current estimate's (after a step,
        the prediction to k + 1, as the estimate and the truth the infos report)."""
        return self.backend.position_cov()

    def team_info(self) -> dict[str, np.ndarray]:
        """The infos both presets report: positions, errors (m), ``trace`` (m^2), dead reckoning's error,
        the messages and floats each agent sent, the team's ``hop_cost``, ``step``."""
        truth, error = self.true_position(), self.team_error()
        return {
            "true_position": truth,
            "estimated_position": self.estimate[..., :2].copy(),
            "position_error": error,
            "error": error.copy(),
            "trace": self.own_traces(),
            "dead_reckoning_error": np.linalg.norm(self.dead_reckoning[..., :2] - truth, axis=-1),
            "messages_sent": self.network.messages_sent.copy(),
            **self.link_counts(),
            "floats_sent": self.network.floats_sent.copy(),
            "communication": self.network.messages_sent.copy(),
            "hop_cost": self.team(self.step_cost()),
            "step": self.team(self.k),
        }

    def episode_error(self, errors: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """The mean distance error over the steps and agents (m)."""
        return np.asarray(errors, float).mean(axis=(-2, -1))


def chain_links(chain: np.ndarray, prefix: str = "") -> tuple[list[int], list[Link]]:
    """The platforms of one chain (a row of ``RelayChain.chain``) and its hops as scene links, labelled
    ``prefix`` + "range" for the measured hop and + the hop's number after it."""
    hops = [int(p) for p in chain if p >= 0]
    links = [Link(source=a, target=c, value=1.0, label=f"{prefix}range" if h == 0 else f"{prefix}{h + 1}")
             for h, (a, c) in enumerate(zip(hops[:-1], hops[1:], strict=True))]
    return hops, links
