"""``nlos_horizon``: adaptive finite-horizon estimation under LOS/NLOS switching and random delay (Gao et al. 2016).

Paper: Gao et al., "Adaptive finite-horizon group estimator ... mixed LOS/NLOS environments"
(seed ``004_4a0edde314525ef9.txt``); the formulas were lost in extraction, so the contract is
the reconstruction in ``docs/gao2016.md`` (labels [paper], [reconstructed], [chosen] as there;
cited as §N below).
Estimator: ``estimators.afge``.

Every agent is a target UAV ``uav_i`` that cannot localise itself directly: it fuses the
packets of its own J = 8 neighbours, each carrying the neighbour's navigation estimate
(truth + N(0, sigma_nav^2 I), as in the paper), the RSS and the AOA of the target, stamped with
the sending time. Each link switches between LOS and NLOS (a Markov chain per link, NLOS
biases the RSS and the AOA), each packet arrives after a random delay tau <= D or is lost.
The agent runs one delay-aware DFIR stack holding every window N = 1..N_max (the paper's
"horizon size"; ``horizon`` is the episode length here, as in every scenario) and decides, each
step, which window's estimate to output and which neighbours' packets to fuse; the
``paper`` policy is AHG (Algorithm 10) with the defaults of §9, so the env with ``paper``
equals AFGE. Agents do not exchange estimates, so they are independent copies of the
paper's single objective UAV with different paths (see the Arguments).

The preset is the composition ``nlos_orbit`` / ``random_delay`` / ``afge``
(``NlosHorizonConfig.parts``) with this action codec, observation, reward and info. The
world draws each episode (truth, readings, prior) from the episode's generator
(``coloc_env.worlds.nlos_orbit.draw_episode``); the packet delays are the network's
(counter-based draws from its own child generator, Assumption 3's law).

Time line of one step (copy b, time k): receive, then decide (``coloc_env.scenarios.composed``).
Before the action the agent has received every packet that arrived up to k (the backend has
filtered the buffer with the last mask), and its observation describes them; the action then
picks the window whose estimate is output as x_hat(k) (reward for time k), the world moves to
k + 1 and the packets arriving then are buffered.

Action (one per agent, the same ``MultiDiscrete`` for all)
----------------------------------------------------------
``MultiDiscrete([N_max - N_min + 1, 2, 2, ..., 2])`` (J twos), int64.

| index   | meaning                                                                                     |
|---------|---------------------------------------------------------------------------------------------|
| ``0``   | window N = N_min + a[0] (replaces AHG). If DFIR_N has no estimate (fewer than two observed  |
|         | stamps in the horizon) the output is the prediction A x_hat(k-1).                            |
| ``1+s`` | keep (1) / drop (0) the packets of the neighbour in RSS slot s: neighbours ordered by the    |
|         | RSS of their packet of the newest stamp (strongest first; neighbours with no newest packet  |
|         | follow by index). The bit applies to that neighbour's packets of every stamp in the buffer. |

[chosen] The config's ``n_strongest`` rule is applied after the mask (among the kept packets
of a stamp, the strongest ``n_strongest`` are fused), so keeping all reproduces the paper's
rule exactly; set ``n_strongest = num_neighbours`` to hand the whole selection to the agent.
A NaN/inf or a value outside the space is a ``ValueError``.

Observation (per agent, ``Box(low, high, shape=(D + 1 + 3 J + 2 M + 3 + N + 1,), float32)``; 46 by default)
-----------------------------------------------------------------------------------------------------------
The ``afge`` backend's features (``coloc_env.backends.nlos``), then the step fraction, the agent's index and
the episode's communication cost. Every entry but the cost has a finite bound (the column; the RSS, innovation
and trace entries are clipped to it).

| index                   | meaning                                                                  | bounds    |
|-------------------------|--------------------------------------------------------------------------|-----------|
| ``[0, D+1)``            | packets of stamp k - l known at time k, l = 0..D, divided by J           | [0, 1]    |
| ``D+1+3s + 0``          | slot s has a packet of the newest stamp (0/1)                            | [0, 1]    |
| ``D+1+3s + 1``          | its RSS, (RSS + 80 dBm) / 10 (0 when absent)                             | [-20, 20] |
| ``D+1+3s + 2``          | its mode: +1 NLOS, -1 LOS with ``mode_info="known"``, else 0             | [-1, 1]   |
| ``D+1+3J``              | log(1 + e^T S^-1 e) of the newest fused observation against the          | [0, 50]   |
|                         | prediction of the last output (0 without a fresh observation)            |           |
| ``D+2+3J``              | the last window used, / N_max (0 before the first output)                | [0, 1]    |
| ``[D+3+3J, D+3+3J+M)``  | log tr P_N (position block) for the M windows of an AHG group centred on | [-50, 50] |
|                         | the last window (N_c(0) before the first; clipped as AHG clips its       |           |
|                         | centre); 14 where invalid                                                |           |
| ``[D+3+3J+M, D+3+3J+2M)``| the AHG cost J_N(k) of the same M windows (``likelihood``'s: the one-   | [0, 50]   |
|                         | step predictive cost, or the in-sample residual for ``"paper"``) minus   |           |
|                         | the group's lowest: 0 marks AHG's pick; 50 where invalid (capped)        |           |
| ``[D+3+3J+2M]``         | step fraction k / horizon                                                | [0, 1]    |
| then ``N`` entries      | ``index``: one-hot of the agent's own index                              | [0, 1]    |
| ``[-1]``                | ``communication_cost``: its copy's cost per packet used this episode     | [0, inf)  |
|                         | (``communication_cost``, or the draw from ``cost_range``), m^2           |           |

The AHG costs are there so that a learning agent sees the innovation statistics AHG decides on.

``state()``: every agent's observation, then each agent's true estimation error (x, y) / 10 m.

Reward (per agent: each target has its own estimate)
----------------------------------------------------
| ``reward=`` | value for the output x_hat(k) (m^2: the unit of ``error``)                             |
|-------------|-----------------------------------------------------------------------------------------|
| ``"error"`` | -||p_hat(k) - p(k)||^2 - communication_cost * packets used                               |
| ``"trace"`` | -tr P(k)[:2, :2] (the estimator's own covariance, m^2) - communication_cost * packets used |

``error`` is squared (m^2), so ``"trace"`` is the trace itself, in the same unit; a packet used is a
neighbour's packet fused into the output (``communication``).

Termination: none; truncation after ``horizon`` steps (the paper's 1000 s flight).

``infos[agent]``: ``true_position``, ``estimated_position``, ``position_error`` (m), ``error``
(m^2), ``trace`` (m^2, tr of the output's position covariance), ``window`` (N used; 0 at
reset), ``valid`` (DFIR_N had an estimate), ``packets_received`` (packets arriving at k),
``communication`` (packets used: of those arriving at k, how many were fused),
``nlos_fraction`` (NLOS links among the neighbours in the RSA at k, the time of the output),
``messages_sent`` / ``floats_sent`` and the per-link counts ``transmissions``, ``link_attempts``,
``link_deliveries``, ``collisions`` (0: the packets come from world nodes, not from agents), ``step``.

Batching: B copies x N agents step in one set of numpy calls; the fused observations of
the D + 1 buffer stamps, the D + 1 stack advances over all windows and the AHG costs are
all arrays (B, N, ...). The only loops are over the D + 1 buffer stamps (inside the
estimator) and, at reset, over the copies being reset (each draws its whole episode from its
own generator) and over time for the LOS/NLOS chains.

Arguments (keywords of ``NlosHorizonConfig``, defaults = §9; each sets the field of the same name of
the part named)
--------------------------------------------------------------------
| field               | default                      | allowed / source                                  |
|---------------------|------------------------------|---------------------------------------------------|
| num_agents          | 4                            | 1..64 agents (targets) [chosen] (older name:      |
|                     |                              | ``num_uavs``)                                     |
| num_neighbours      | 8                            | 1..32, J [chosen]                                 |
| horizon             | 1000                         | 1..100000 steps (1000 s flight [paper])           |
| period              | 1.0                          | [1e-3, 1e4], T (s) [chosen]                       |
| accel_sigma         | 0.3                          | [1e-6, 1e3], sigma_a of the estimator's Q [chosen]|
| speed               | 20.0                         | [0, 1e4] m/s [chosen]                             |
| turn_rates_deg      | (3, -3, 3, -6)               | deg/s per turn, entries in [-1e4, 1e4] [chosen]   |
| turn_windows        | (200,260) (500,560) (700,730) (850,880) | [start, end) integer steps, <= 1e7 [chosen] |
| target_spacing      | 3000.0                       | [0, 1e7] m: uav_i starts at (0, i * spacing) [chosen] |
| schedule_shift      | 40                           | 0..100000 steps: uav_i's turns start i * shift later |
| orbit_radius        | (150, 900)                   | (low, high) m, entries in [0, 1e7], low <= high: |
|                     |                              | rho0 ~ U(.) [chosen]                              |
| orbit_wobble        | 200.0                        | [0, 1e6] m: a ~ U(0, .) [chosen]                  |
| orbit_wobble_rate   | (0.002, 0.01)                | (low, high) rad/s, entries in [0, 10], low <= high: |
|                     |                              | w ~ U(.) [chosen]                                 |
| orbit_bearing_rate  | 0.01                         | [0, 10] rad/s: om ~ U(-., .) [chosen]             |
| r_inf, r_sup        | 30, 1000                     | 0 < r_inf < r_sup (m) [chosen]                    |
| sigma_nav           | 2.0                          | (0, 1e4] m per axis [chosen]                      |
| tx_power_dbm        | 20.0                         | P_T in [-200, 200] dBm [chosen]                   |
| frequency_hz        | 2.4e9                        | f in [1, 1e13] Hz [chosen]                        |
| d0                  | 1.0                          | [1e-3, 1e6] m [chosen]                            |
| path_loss_exponent  | 2.2                          | n in [0.5, 10] (smaller: the RSS-inverted range   |
|                     |                              | overflows) [chosen]                               |
| sigma_db            | 2.0                          | (0, 100] dB, LOS [chosen]                         |
| sigma_theta_deg     | 0.1                          | [1e-6, 180] deg, LOS [paper]                      |
| nlos_bias_db        | 6.0                          | [-100, 100] dB, mu_db [chosen]                    |
| nlos_sigma_db       | 4.0                          | [0, 100] dB [chosen]                              |
| nlos_bias_deg       | 1.0                          | [-180, 180] deg, mu_theta [chosen]                |
| nlos_sigma_deg      | 1.0                          | [0, 180] deg [chosen]                             |
| p_nlos              | 0.3                          | pi in [0, 1] [chosen]                             |
| p10                 | 0.1                          | [0, 1], pi p10 <= 1 - pi [chosen]                 |
| buffer_length       | 3                            | D, 0..999 (N_min >= D + 1, N_max <= 1000) [chosen] |
| delay_probs         | (0.6, 0.2, 0.1, 0.05)        | D + 1 entries in [0, 1], sum <= 1 [chosen]        |
| n_strongest         | 4                            | 1..J [chosen] ("only the strongest" [paper])      |
| min_packets         | 1                            | n_min, 1..J [chosen]                              |
| weighting           | "distance"                   | "distance" (Def. 6), "information"                |
| mode_info           | "known"                      | "known", "mean", "blind"                          |
| window_min          | 4                            | N_min: 2..N_max and >= D + 1 [reconstructed]      |
| window_max          | 30                           | N_max: 2..1000 [chosen]                           |
| window_step         | 2                            | dN >= 1; N_max - N_min >= (M - 1) dN              |
| group_size          | 5                            | M, odd >= 1                                       |
| window_centre       | 12                           | N_c(0) in [N_min, N_max] (paper's best N)         |
| likelihood          | "predictive"                 | AHG cost for ``paper``: predictive, paper, smoothed |
| smoothing           | 0.5                          | lam in (0, 1) [chosen]                            |
| prior_std           | (50, 50, 5, 5)               | (4,) entries in (0, 1e6]: x_hat before any       |
|                     |                              | estimate = truth + N(0, P0)                       |
| reward              | "error"                      | "error", "trace"                                  |
| communication_cost  | 0.0                          | [0, 1e12] per packet used (m^2, the reward's unit) |
| cost_range          | None                         | None, or (lo, hi) with 0 <= lo <= hi <= 1e12:      |
|                     |                              | each copy draws its cost per episode at reset      |
|                     |                              | (``coloc_env.composition``'s law), replacing       |
|                     |                              | ``communication_cost``                             |

``num_agents`` .. ``p10`` and ``prior_std`` set the world's fields,
``buffer_length`` and ``delay_probs`` the network's, ``n_strongest`` .. ``smoothing`` the backend's,
``horizon``, ``reward``, ``communication_cost`` and ``cost_range`` the composition's (``horizon`` also the world's);
each is checked once, by that part, and a refused value is reported under the keyword. The rules
between parts (``n_strongest``, ``min_packets`` <= J; ``window_min`` >= D + 1) are the backend's
``check_against``. Older keywords, still accepted by ``make`` and ``parallel_env`` (give one name of a
pair): ``num_uavs`` for ``num_agents``, ``packet_cost`` for ``communication_cost``.
"horizon" is the episode length as in every scenario; the paper's horizon size N is called the
*window* here (the action's first entry, the info key ``window``).
"""

from __future__ import annotations

from dataclasses import dataclass

import gymnasium
import numpy as np

from coloc_env.backends.nlos import Afge
from coloc_env.networks.random_delay import RandomDelay
from coloc_env.rendering import Link, Scene
from coloc_env.scenarios.binding import PresetConfig, PresetScenario, keyword, register_preset
from coloc_env.worlds.nlos_orbit import NlosOrbit

_W, _B = NlosOrbit(), Afge()  # the parts' defaults are the preset's


def _world(field: str):
    """A keyword setting the world's ``field``, with the world's default."""
    return keyword(getattr(_W, field), f"world.{field}")


def _backend(field: str):
    """A keyword setting the backend's ``field``, with the backend's default."""
    return keyword(getattr(_B, field), f"backend.{field}")


@dataclass(frozen=True)
class NlosHorizonConfig(PresetConfig):
    """Configuration of ``nlos_horizon``; defaults are §9 of docs/gao2016.md (see the module docstring)."""

    preset = "nlos_horizon"
    World, Network, Backend = NlosOrbit, RandomDelay, Afge
    aliases = {"num_uavs": "num_agents", "packet_cost": "communication_cost"}

    num_agents: int = _world("num_agents")
    num_neighbours: int = _world("num_neighbours")
    horizon: int = keyword(_W.horizon, "world.horizon", "composition.horizon")
    period: float = _world("period")
    accel_sigma: float = _world("accel_sigma")
    speed: float = _world("speed")
    turn_rates_deg: tuple = _world("turn_rates_deg")
    turn_windows: tuple = _world("turn_windows")
    target_spacing: float = _world("target_spacing")
    schedule_shift: int = _world("schedule_shift")
    orbit_radius: tuple = _world("orbit_radius")
    orbit_wobble: float = _world("orbit_wobble")
    orbit_wobble_rate: tuple = _world("orbit_wobble_rate")
    orbit_bearing_rate: float = _world("orbit_bearing_rate")
    r_inf: float = _world("r_inf")
    r_sup: float = _world("r_sup")
    sigma_nav: float = _world("sigma_nav")
    tx_power_dbm: float = _world("tx_power_dbm")
    frequency_hz: float = _world("frequency_hz")
    d0: float = _world("d0")
    path_loss_exponent: float = _world("path_loss_exponent")
    sigma_db: float = _world("sigma_db")
    sigma_theta_deg: float = _world("sigma_theta_deg")
    nlos_bias_db: float = _world("nlos_bias_db")
    nlos_sigma_db: float = _world("nlos_sigma_db")
    nlos_bias_deg: float = _world("nlos_bias_deg")
    nlos_sigma_deg: float = _world("nlos_sigma_deg")
    p_nlos: float = _world("p_nlos")
    p10: float = _world("p10")
    buffer_length: int = keyword(RandomDelay().buffer_length, "network.buffer_length")
    delay_probs: tuple = keyword(RandomDelay().delay_probs, "network.delay_probs")
    n_strongest: int = _backend("n_strongest")
    min_packets: int = _backend("min_packets")
    weighting: str = _backend("weighting")
    mode_info: str = _backend("mode_info")
    window_min: int = _backend("window_min")
    window_max: int = _backend("window_max")
    window_step: int = _backend("window_step")
    group_size: int = _backend("group_size")
    window_centre: int = _backend("window_centre")
    likelihood: str = _backend("likelihood")
    smoothing: float = _backend("smoothing")
    prior_std: tuple = _world("prior_std")
    reward: str = keyword("error", "composition.reward")
    communication_cost: float = keyword(0.0, "composition.communication_cost")
    cost_range: tuple | None = keyword(None, "composition.cost_range")

    def check_preset(self) -> None:
        """The rules between the parts (the backend's ``check_against``), under the keywords' names."""
        _, network, backend = self.parts()
        names = ("n_strongest", "min_packets", "window_min", "num_neighbours", "buffer_length")
        backend.check_against(self.num_neighbours, network.buffer_length, {name: name for name in names})


@register_preset
class NlosHorizonScenario(PresetScenario):
    """Batched core of ``nlos_horizon``: the binding of ``NlosHorizonConfig`` on the composable core
    (``nlos_orbit`` / ``random_delay`` / ``afge``, receiving before deciding); the module docstring has the
    tables."""

    name = "nlos_horizon"
    paper = "gao2016"
    Config = NlosHorizonConfig
    version = 2
    metric = "squared position error averaged over k >= 50 and the UAVs"
    metric_unit = "m^2"
    communication = "packets"
    policy_module = "agents.nlos_horizon"
    appended_features = ("index", "communication_cost")

    def __init__(self, config: NlosHorizonConfig, batch: int = 1):
        super().__init__(config, batch)
        be = self.backend
        be.adaptive = False  # the codec never asks the backend for AHG (v = 0); the paper policy runs it
        self.D, self.J, self.S = be.D, be.J, be.S
        self.episode_id = np.zeros(self.batch, dtype=np.int64)
        self._preset_action_space = gymnasium.spaces.MultiDiscrete(
            [config.window_max - config.window_min + 1] + [2] * self.J, dtype=np.int64)
        low, high = be.feature_bounds()
        self._observation_space = self.extend_space(gymnasium.spaces.Box(
            np.r_[low, 0.0].astype(np.float32), np.r_[high, 1.0].astype(np.float32), dtype=np.float32))

    # --- description ------------------------------------------------------------
    @property
    def obs_dim(self) -> int:
        return self.D + 1 + 3 * self.J + 2 * self.config.group_size + 3 + self.appended_size()

    def observation_space(self):
        return self._observation_space

    def preset_feature_positions(self) -> dict[str, int]:
        """The composed table's features among this observation's own entries: ``step_fraction``."""
        return {"step_fraction": self.obs_dim - self.appended_size() - 1}

    def action_space(self):
        return self._preset_action_space

    def state_space(self):
        dim = self.num_agents * (self.obs_dim + 2)
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(dim,), dtype=np.float32)

    def encode_actions(self, window: np.ndarray, keep_slots: np.ndarray | None = None) -> np.ndarray:
        """Actions (..., 1 + J) int64 for windows ``window`` (...) and slot bits (..., J) (default: keep all)."""
        window = np.asarray(window, np.int64)
        keep = np.ones((*window.shape, self.J), np.int64) if keep_slots is None else np.asarray(keep_slots, np.int64)
        return np.concatenate([(window - self.config.window_min)[..., None], keep], axis=-1)

    def decode_actions(self, actions) -> np.ndarray:
        """Actions (B, N, 1 + J) -> the backend's blocks: ``window`` v = a[0] + 1 (N = N_min + a[0]; the
        preset offers no v = 0, AHG inside the backend: its ``paper`` policy runs AHG as an agent) and
        ``keep`` a[1:], the slot bits."""
        a = self.check_discrete_actions(
            actions, ("action[0] (window N - N_min)", *[f"action[1:{1 + self.J}] (keep 1 / drop 0)"] * self.J))
        return np.concatenate([a[..., :1] + 1, a[..., 1:]], axis=-1)

    # --- dynamics ----------------------------------------------------------------
    def reset(self, rngs, env_index=None) -> None:
        super().reset(rngs, env_index)
        self.episode_id[self._indices(env_index)] += 1

    def compute_reward(self) -> np.ndarray:
        be = self.backend
        if self.config.reward == "error":
            loss = np.sum((be.posterior_position - self._truth) ** 2, axis=-1)
        else:
            loss = np.trace(be.posterior_position_cov, axis1=-2, axis2=-1)
        return -loss - self.costs[:, None] * be.packets_used  # each copy's cost this episode

    # --- views -------------------------------------------------------------------
    def observation(self) -> np.ndarray:
        B, N = self.batch, self.num_agents
        frac = np.broadcast_to((self.k / self.horizon)[:, None, None], (B, N, 1))
        return self.extend_observation(np.concatenate([self.backend.observation_features(), frac], axis=-1))

    def episode_error(self, errors: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """Time-averaged squared position error over k >= min(50, horizon - 1), mean over the agents.

        The paper's time-averaged RMSE (§12, ``train/reproduce/gao2016.py``) is the square root of the
        mean of this over episodes.
        """
        warm = min(50, self.horizon - 1)
        return np.asarray(errors, float)[..., warm:, :].mean(axis=(-2, -1))

    def state(self) -> np.ndarray:
        error = (self.backend.posterior_position - self._truth) / 10.0
        return np.concatenate([self.observation().reshape(self.batch, -1), error.reshape(self.batch, -1)],
                              axis=-1).astype(np.float32)

    def info(self) -> dict[str, np.ndarray]:
        B, N = self.batch, self.num_agents
        be, w = self.backend, self.world
        rows, now = np.arange(B), np.maximum(self.k - 1, 0)  # the time of the last output
        started = (self.k > 0)[:, None]
        in_range = w.in_rsa[rows, now]
        nlos = (w.modes[rows, now] == 1) & in_range
        error = np.sum((be.posterior_position - self._truth) ** 2, axis=-1)
        return {
            "true_position": self.true_position(),
            "estimated_position": be.posterior_position.copy(),
            "position_error": np.sqrt(error),
            "error": error,
            "trace": np.trace(be.posterior_position_cov, axis1=-2, axis2=-1),
            "messages_sent": self.network.messages_sent.copy(),
            **self.link_counts(),
            "floats_sent": self.network.floats_sent.copy(),
            "window": be.window_used.copy(),
            "valid": be.valid_used.copy(),
            "packets_received": np.where(started, be.packets_arrived, 0.0),
            "communication": np.where(started, be.packets_used, 0.0),
            "nlos_fraction": nlos.sum(-1) / np.maximum(in_range.sum(-1), 1),
            "step": np.broadcast_to(self.k[:, None], (B, N)).copy(),
        }

    def scene(self, b: int) -> Scene:
        k = int(self.k[b])
        now = max(k - 1, 0)
        w, be = self.world, self.backend
        truth = w.truth[b, now]
        offsets = w.neighbours.offsets(w.orbit_parameters(b), now + 1)[now]
        used = be.used[b, 0].sum(axis=0)  # packets fused per neighbour of uav_0 over the buffer
        modes = w.modes[b, now, 0]
        J = self.J
        nodes = np.vstack([[0.0, 0.0], offsets / max(float(self.config.r_sup), 1.0)])
        links = [Link(source=j + 1, target=0, value=float(used[j]), label="N" if modes[j] else "L") for j in range(J)]
        return Scene(
            title=f"nlos_horizon (gao2016)  k = {k}/{self.horizon}",
            truth=truth[:, :2],
            estimates=be.posterior_position[b],
            covariances=be.posterior_position_cov[b],
            trails=np.swapaxes(w.truth[b, max(0, now - 30):now + 1, :, :2], 0, 1),
            node_positions=nodes,
            node_labels=["uav_0"] + [f"nb_{j}" for j in range(J)],
            links=links,
            link_value_max=float(self.D + 1),
            link_value_name="packets of uav_0's buffer fused (L/N = LOS/NLOS)",
            notes=[f"uav_0: window {int(be.window_used[b, 0])}, error "
                   f"{np.linalg.norm(be.posterior_position[b, 0] - truth[0, :2]):.1f} m"],
        )
