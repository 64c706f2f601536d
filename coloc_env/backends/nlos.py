"""Backends ``afge``, ``dfir`` and ``delay_kalman`` (gao2016): estimation from neighbours' delayed RSS/AOA packets.

All three adapt ``estimators.afge`` (no second copy of its math): each agent is a target that
fuses the packets of its J world neighbours (``coloc_env.worlds.nlos_orbit``'s readings). The
paper's "horizon size" N, the length of a finite-impulse-response window, is called the *window*
here (``horizon`` is the episode length). All three receive before they decide
(``receives_before_deciding``): where the composition allows it (no sensing or transport
decisions), steps 1-3 run with the last step's mask before the agent acts
(``PacketFirBackend.receive``, the core's "receive, then decide"), so its observation and the
AHG costs describe the packets of stamp k, and step k re-filters only if the agent changes the
mask. Per step k, for each agent:

1. the packets stamped k (one per neighbour that measured the target) go to the network
   (``coloc_env.networks.base.Network.node_packets``, slot 0), which returns each one's
   delay tau (or lost); the backend buffers stamps k-D..k (D = the network's
   ``coloc_env.networks.base.Network.max_delay``), a packet becoming known at k when
   tau <= k - s (Step 1, ``estimators.afge.known_at_lag``);
2. the known packets of each buffered stamp are fused (Step 2, eqs. 21-27, Def. 6:
   ``estimators.afge.fuse_packets``, the ``n_strongest`` by RSS among the kept ones);
3. the DFIR stack of every window N = 1..S (Lemma 7 in recursive form) is re-run from the
   last final stamp k - D (``estimators.afge.buffer_step``, ``estimators.afge.stack_estimates``);
4. the output x_hat(k) is the chosen window's estimate; without one (fewer than two
   observed stamps in it) the prediction A x_hat(k-1) (``afge``: window chosen by AHG,
   Algorithm 10, ``estimators.afge.ahg_select``, or by the agent; ``dfir``: ``window``);
5. ``predict``: x_hat <- A x_hat, P <- A P A^T + Gam (docs/gao2016.md §2), the fallback of step k + 1.

With the ``always`` policy (window decision 0 = AHG, every neighbour kept) ``afge`` is the
``nlos_horizon`` scenario under its ``paper`` policy: the same estimates to 1e-9 given the
same episode and the same delays (``tests/coloc_env/test_nlos_composition.py``).

| quantity        | afge                                           | dfir                                       |
|-----------------|------------------------------------------------|--------------------------------------------|
| estimand        | self (each target its own state [p; v])        | self                                       |
| motion kinds    | ``cv_white_accel``                             | ``cv_white_accel``                         |
| needs           | ``rss`` and ``aoa`` (+ ``los_nlos`` with ``mode_info="known"``) | the same                  |
| messages        | ``packets``: one per neighbour that measured, world node -> agent; the agents send none | the same |
| payload         | nav estimate 2 + RSS 1 + AOA 1 + stamp 1 (+ mode flag 1 with ``known``) floats | the same   |
| lost message    | never known: that stamp is fused without it; a stamp with fewer than ``min_packets`` | the same |
|                 | packets has gamma = 0 (no observation)         |                                            |
| late message    | buffered: stamp s is re-fused when it arrives (tau <= D) and the last D stamps are | the same |
|                 | re-filtered from the final stamp k - D (the delay-aware re-run, §6)      |                  |
| under-determined | a window with fewer than two observed stamps, or whose information is singular to | the same |
|                 | rounding (a fix with ~1e-20 of another's information at sigma_db = 100), has no |        |
|                 | estimate: the output is the prediction A x_hat(k-1) (AHG: a group without a valid member) | |
| decisions       | ``window`` Discrete(N_max - N_min + 2): 0 = AHG (default), v = window N_min + v - 1;   | none |
|                 | ``keep`` MultiDiscrete([2] * J): keep (1, default) / drop (0) the packets of RSS slot s |   |
| position cov    | P of the output's window (or the predicted P);  | the same; mean NEES 0.57 (distance) and   |
|                 | with the model matched the mean position NEES   | 2.05 (information)                        |
|                 | (2 DOF) is 0.60 with ``weighting="distance"``   |                                           |
|                 | (conservative: P about 3.5x the error           |                                           |
|                 | covariance, a covariance-intersection bound)    |                                           |
|                 | and 2.15 with ``"information"`` (docs/gao2016.md, section 15) |                             |
| observation     | packets of stamp k - l known / J (l = 0..D); per RSS slot: present, | packets of stamp k - l   |
|                 | (RSS + 80) / 10, mode (+1 NLOS / -1 LOS with ``known``, else 0);    | known / J (l = 0..D);    |
|                 | log(1 + NIS); last window / N_max; log tr P_N over the AHG group    | 1 if the output had an   |
|                 | of the last window (14 where invalid); each member's AHG cost J_N   | estimate of its own      |
|                 | minus the group's lowest (0 = AHG's pick; 50 where invalid or       |                          |
|                 | without a fresh observation, capped)                                |                          |

RSS slots (``keep``): the neighbours ordered by the RSS of their packet of the newest stamp
as the agent's observation showed it (strongest first, then the neighbours without one, by
index): stamp k where it received before deciding, else stamp k - 1; the bit applies to that
neighbour's packets of every buffered stamp. As in the scenario, ``n_strongest`` is applied after the
mask. AHG's centre runs every step, also while the agent overrides the window (a binding whose codec
never offers v = 0 turns it off: ``AfgeBackend.adaptive``).

Arguments (``coloc_env.backends.Afge``; defaults = ``nlos_horizon``'s, docs/gao2016.md §9)

| field          | default      | allowed                                           |
|----------------|--------------|---------------------------------------------------|
| n_strongest    | 4            | 1..32 (at most J)                                 |
| min_packets    | 1            | 1..32 (at most J), n_min                          |
| weighting      | "distance"   | "distance" (Def. 6), "information"                |
| mode_info      | "known"      | "known", "mean", "blind"                          |
| window_min     | 4            | N_min: 2..N_max and >= D + 1 (checked at build)   |
| window_max     | 30           | N_max: 2..1000                                    |
| window_step    | 2            | dN >= 1; N_max - N_min >= (M - 1) dN              |
| group_size     | 5            | M, odd                                            |
| window_centre  | 12           | N_c(0) in [N_min, N_max]                          |
| likelihood     | "predictive" | "predictive", "paper", "smoothed"                 |
| smoothing      | 0.5          | lam in (0, 1)                                     |
| constant_windows | False      | True: keep ``constant_x`` (below)                 |

With ``constant_windows`` every backend here keeps ``constant_x`` (B, N, S, 4): the output dfir with
window N would give, for every N = 1..S of its stack (the window's estimate, else the prediction of that
output at k - 1), so one run gives the whole constant-window curve. It is off by default: it updates a
(B, N, S, 4) array every step (its cost: docs/performance.md).

``delay_kalman`` is the Kalman baseline on the same fused packets: one window that never drops a stamp,
started from the world's prior (``estimators.afge.prior_stack``), the last D stamps re-filtered from
the posterior at k - D as packets arrive (``estimators.afge.run_kalman``'s filter); its sigma_a is the
world's ``accel_sigma``. Decisions, observation and payload as ``dfir``; its fields are ``dfir``'s
without ``window``.

Arguments (``coloc_env.backends.Dfir``; ``DelayKalman``: the same rows but ``window``)

| field          | default      | allowed                                           |
|----------------|--------------|---------------------------------------------------|
| window         | 12           | N: 2..1000 (the paper's best constant N)          |
| n_strongest, min_packets, weighting, mode_info, constant_windows | as ``afge`` | as ``afge`` |

``dfir`` also reads ``horizon`` as the older name of ``window`` (``Dfir.aliases``: a dict config or
``coloc study --sweep backend.horizon=...`` keeps working); give only one of them.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

import estimators.afge as af
from coloc_env.backends.base import Backend
from coloc_env.config import BadInput
from coloc_env.networks.blocks.bounded_delay import NEVER
from coloc_env.parts import BACKENDS, Block, PartConfig, check_choice, check_flag, check_range

INVALID_LOG_TRACE = 14.0  # log tr P shown for a window without an estimate (~ a 1 km spread)
LOG_BOUND = 50.0
RSS_BOUND = 20.0
COST_BOUND = 50.0  # an AHG cost's excess over the group's best, shown up to this (and where invalid)


@dataclass(frozen=True)
class _PacketFirConfig(PartConfig):
    """The packet fields and declarations ``afge``, ``dfir`` and ``delay_kalman`` share."""

    estimand = "self"
    motion_kinds = frozenset({"cv_white_accel"})
    message_kind = "packets"
    message_content = "readings"
    shared_estimate = False
    n_strongest: int = 4
    min_packets: int = 1
    weighting: str = "distance"
    mode_info: str = "known"
    constant_windows: bool = False

    @property
    def requires(self) -> tuple:
        groups = (frozenset({"rss"}), frozenset({"aoa"}))
        return groups + ((frozenset({"los_nlos"}),) if self.mode_info == "known" else ())

    @property
    def payload(self) -> float:
        """Floats per packet: nav estimate 2, RSS 1, AOA 1, stamp 1, and the mode flag with ``known``."""
        return 5.0 + (self.mode_info == "known")

    def check(self, prefix: str) -> None:
        check_range(f"{prefix}n_strongest", self.n_strongest, 1, 32, integer=True)
        check_range(f"{prefix}min_packets", self.min_packets, 1, 32, integer=True)
        check_choice(f"{prefix}weighting", self.weighting, af.WEIGHTINGS)
        check_choice(f"{prefix}mode_info", self.mode_info, af.MODE_INFOS)
        check_flag(f"{prefix}constant_windows", self.constant_windows)

    def check_against(self, neighbours: int, max_delay: int, names: dict | None = None) -> None:
        """The checks that need the other parts: ``n_strongest`` and ``min_packets`` at most the world's J
        neighbours (``afge``: ``window_min`` at least the network's longest delay D + 1). ``names``: how a
        message calls ``n_strongest``, ``min_packets``, ``window_min``, ``num_neighbours`` and
        ``buffer_length`` (default: ``backend.<field>``, "the number of neighbours", "the network's buffer
        length")."""
        names = {"n_strongest": "backend.n_strongest", "min_packets": "backend.min_packets",
                 "num_neighbours": "the number of neighbours", **(names or {})}
        for field in ("n_strongest", "min_packets"):
            if getattr(self, field) > neighbours:
                raise BadInput(f"{names[field]} must be <= {names['num_neighbours']} = {neighbours}, "
                               f"got {getattr(self, field)}")


@BACKENDS.register
@dataclass(frozen=True)
class Afge(_PacketFirConfig):
    name = "afge"
    window_min: int = 4
    window_max: int = 30
    window_step: int = 2
    group_size: int = 5
    window_centre: int = 12
    likelihood: str = "predictive"
    smoothing: float = 0.5

    @property
    def ahg(self) -> af.AHGParams:
        return af.AHGParams(self.window_min, self.window_max, self.window_step, self.group_size,
                            self.window_centre, self.likelihood, float(self.smoothing))

    def check(self, prefix: str) -> None:
        p = prefix
        super().check(p)
        check_range(f"{p}window_max", self.window_max, 2, 1000, integer=True)
        check_range(f"{p}window_min", self.window_min, 2, self.window_max, integer=True, high_label=f"{p}window_max")
        check_range(f"{p}window_step", self.window_step, 1, 1000, integer=True)
        check_range(f"{p}group_size", self.group_size, 1, 999, integer=True)
        if self.group_size % 2 != 1:
            raise ValueError(f"{p}group_size must be odd (M = 2h + 1), got {self.group_size}")
        if self.window_max - self.window_min < (self.group_size - 1) * self.window_step:
            raise ValueError(f"{p}window_max - window_min must be >= (group_size - 1) * window_step = "
                             f"{(self.group_size - 1) * self.window_step}, got {self.window_max - self.window_min}")
        check_range(f"{p}window_centre", self.window_centre, self.window_min, self.window_max, integer=True)
        check_choice(f"{p}likelihood", self.likelihood, af.LIKELIHOODS)
        check_range(f"{p}smoothing", self.smoothing, 0.0, 1.0, low_open=True, high_open=True)

    def check_against(self, neighbours: int, max_delay: int, names: dict | None = None) -> None:
        super().check_against(neighbours, max_delay, names)
        names = {"window_min": "backend.window_min", "buffer_length": "the network's buffer length", **(names or {})}
        if self.window_min < max_delay + 1:
            raise BadInput(f"{names['window_min']} must be >= {names['buffer_length']} + 1 = {max_delay + 1} "
                           f"(the group reflects the possible delay, docs/gao2016.md §7), got {self.window_min}")

    def build(self, world, network, batch: int) -> Backend:
        return AfgeBackend(self, world, network, batch)


@BACKENDS.register
@dataclass(frozen=True)
class Dfir(_PacketFirConfig):
    name = "dfir"
    aliases = {"horizon": "window"}
    window: int = 12

    def check(self, prefix: str) -> None:
        super().check(prefix)
        check_range(f"{prefix}window", self.window, 2, 1000, integer=True)

    def build(self, world, network, batch: int) -> Backend:
        return DfirBackend(self, world, network, batch)


def episode_delays(world, network, payload: float) -> np.ndarray:
    """(B, K + 1, N, J) int64: the delay ``network`` gives the packet of stamp s from neighbour j to target i,
    -1 where none was sent (outside the receive-search area) or it was lost, for every stamp of the episode
    ``world`` drew: the question these backends ask each step (``Network.node_packets``, slot 0), asked for
    every stamp at once on a copy of the network (its draws are counter-based, fixed at reset)."""
    net = copy.deepcopy(network)
    B, K1, N = world.batch, world.horizon + 1, world.num_agents
    out = np.empty((B, K1, N, world.num_neighbours), np.int64)
    for s in range(K1):
        net.begin(np.full(B, s), world.truth[:, s, :, :2], np.zeros((B, N, 0), np.int64))
        out[:, s] = net.node_packets(world.in_rsa[:, s], world.distance[:, s], payload, slot=0)
    return out


class PacketFirBackend(Backend):
    """Buffer, fusion and DFIR stack of ``estimators.afge`` for B copies x N targets; ``_choose`` picks N."""

    receives_before_deciding = True
    finite_horizons = True  # the stack of finite horizons (False: one growing horizon from the prior, a Kalman filter)
    min_stamps = 2  # a horizon with fewer observed stamps has no estimate

    def __init__(self, config, world, network, batch: int, stack_size: int):
        super().__init__(config, world, network, batch)
        J = getattr(world, "num_neighbours", None)
        if J is None:
            raise ValueError(f"backend {config.name} needs a world with neighbour packets (world "
                             f"{world.config.name!r} has none)")
        config.check_against(int(J), int(network.max_delay()))
        self.J, self.S = int(J), int(stack_size)
        self.D = int(network.max_delay())
        self.motion = world.motion_model.afge
        self.signal = world.signal
        B, N, D1 = self.batch, self.num_agents, self.D + 1
        self.rss = np.zeros((B, N, D1, J))
        self.aoa = np.zeros((B, N, D1, J))
        self.nav = np.zeros((B, N, D1, J, 2))
        self.modes = np.zeros((B, N, D1, J), np.int8)
        self.delays = np.full((B, N, D1, J), NEVER, np.int64)
        self.last_delays = np.full((B, N, J), -1, np.int64)  # the network's answer for stamp k (-1: none)
        self.final = af.empty_stack((B, N), self.S)
        self.prev_x = np.zeros((B, N, self.S, 4))
        self.prev_P = np.broadcast_to(np.eye(4), (B, N, self.S, 4, 4)).copy()
        self.prev_valid = np.zeros((B, N, self.S), bool)
        self.pred_x, self.out_x = np.zeros((B, N, 4)), np.zeros((B, N, 4))
        self.pred_P = np.broadcast_to(np.eye(4), (B, N, 4, 4)).copy()
        self.out_P = self.pred_P.copy()
        # constant-window outputs (``constant_windows``): what dfir with window N would output, for every
        # N = 1..S of the stack
        shape = (B, N, self.S, 4) if config.constant_windows else (B, N, 0, 4)
        self.constant_x, self.constant_pred = np.zeros(shape), np.zeros(shape)
        self.slots = np.broadcast_to(np.arange(J), (B, N, J)).copy()
        self.mask = np.ones((B, N, J), bool)  # the keep mask of the last update (the pending filter's)
        self._taken = np.zeros(B, bool)  # stamp k's packets are in the buffer
        self.pending: dict | None = None
        self.used = np.zeros((B, N, D1, J), bool)
        self.window_used = np.zeros((B, N), np.int64)
        self.valid_used = np.zeros((B, N), bool)
        self.packets_used = np.zeros((B, N))
        self.packets_arrived = np.zeros((B, N))
        self._features = np.zeros((B, N, self.feature_bounds()[0].size))
        self._features[:] = self.feature_defaults()
        self._view: tuple | None = None  # (filter, prediction) the features describe, until built
        # index grids: a[copy, agent, j] gathers along the last axis with a (B, N, ...) index in one fancy
        # index (take_along_axis builds these grids on every call)
        self._copy, self._agent = np.arange(B)[:, None], np.arange(N)[None, :]
        self._copy3, self._agent3 = self._copy[..., None], self._agent[..., None]

    # --- episode -------------------------------------------------------------------------
    def reset(self, rngs, idx) -> None:
        idx = np.asarray(idx)
        mean, cov = self.world.initial_belief()
        n, N = len(idx), self.num_agents
        empty = af.empty_stack((n, N), self.S)
        self.final.info[idx], self.final.vector[idx], self.final.stamps[idx] = empty.info, empty.vector, empty.stamps
        self.prev_x[idx], self.prev_P[idx], self.prev_valid[idx] = 0.0, np.eye(4), False
        self.pred_x[idx], self.pred_P[idx] = mean[idx], cov[idx]
        self.out_x[idx], self.out_P[idx] = mean[idx], cov[idx]
        self.constant_x[idx] = self.constant_pred[idx] = mean[idx][:, :, None, :]
        self.delays[idx] = NEVER
        self.last_delays[idx] = -1
        self.mask[idx] = True
        self._taken[idx] = False
        self.slots[idx] = np.arange(self.J)
        self.window_used[idx], self.valid_used[idx] = 0, False
        self.packets_used[idx], self.packets_arrived[idx] = 0.0, 0.0
        self.used[idx] = False
        self._build_view()  # the other copies' view, before this one's defaults
        self._features[idx] = self.feature_defaults()
        self.posterior_position[idx] = mean[idx, :, :2]
        if self.posterior_position_cov is None:
            self.posterior_position_cov = np.zeros((self.batch, N, 2, 2))
        self.posterior_position_cov[idx] = cov[idx, :, :2, :2]
        self._reset_choice(idx)

    def _reset_choice(self, idx) -> None:
        return None

    # --- step -----------------------------------------------------------------------------
    def receive(self, readings, idx) -> None:
        """Receive, then decide: stamp k's packets of the copies ``idx`` into the buffer, the buffer filtered
        with the last mask (``pending``: what the agent knows before it acts; the costs of the horizons
        come from it) and the observation of what arrived, RSS slots included."""
        self._take(readings, np.asarray(idx))
        self._prepare()
        self._refresh_view(self.pending)

    def _take(self, readings, rows: np.ndarray) -> None:
        """Stamp k's packets of the copies ``rows`` to the network, into the buffer (oldest first)."""
        extra = readings.extra
        sending = np.asarray(extra["measured"], bool)
        delay = self.network.node_packets(sending, self.world.neighbour_distances(), self.config.payload, slot=0)
        every = rows.dtype != bool and len(np.unique(rows)) == self.batch  # every copy: slices, not index arrays
        rows = slice(None) if every else rows
        self.last_delays[rows] = delay[rows]
        for name, new in (("rss", extra["rss"]), ("aoa", extra["aoa"]), ("nav", extra["nav"]),
                          ("modes", extra.get("mode", np.zeros(sending.shape, np.int8))),
                          ("delays", np.where(delay >= 0, delay, NEVER))):
            buf = getattr(self, name)
            buf[rows, :, :-1] = buf[rows, :, 1:]  # overlapping slices: numpy copies through a buffer
            buf[rows, :, -1] = new[rows]
        self._taken[rows] = True

    def _lags(self) -> np.ndarray:
        """(B, N, D+1): k - s for the buffer stamps s = k-D..k, -1 for stamps before 0."""
        k = np.asarray(self.world.k)[:, None]
        stamps = k + np.arange(-self.D, 1)
        lags = np.where(stamps >= 0, k - stamps, -1)
        return np.broadcast_to(lags[:, None, :], (self.batch, self.num_agents, self.D + 1))

    def _prepare(self) -> None:
        """``pending``: the buffer at k filtered with the last mask (recomputed whole: the copies that did
        not receive anew get the same values again)."""
        c = self.config
        fixes = af.packet_fixes(self.signal, self.nav, self.rss, self.aoa,
                                af.mode_weight(c.mode_info, self.modes, self.signal.p_nlos))
        self.pending = self._filter(self.mask, self._lags(), fixes)

    def _filter(self, mask: np.ndarray, lags: np.ndarray, fixes: tuple) -> dict:
        """Steps 2-3 at k with ``mask`` (B, N, J): the fused buffer, the re-run stacks, every horizon's
        estimate; ``fixes`` are the buffer's packet fixes (they depend on neither the mask nor the lag)."""
        c = self.config
        Y, y, gamma, used = af.fuse_packets(self.signal, self.rss, self.aoa, self.nav, self.modes, self.delays, lags,
                                            mask[:, :, None, :], c.n_strongest, c.mode_info, c.weighting,
                                            c.min_packets, fixes=fixes)
        k = np.asarray(self.world.k)[:, None]
        final, x, P, valid = af.buffer_estimates(self.motion, self.final, k, Y, y, gamma, shift=self.finite_horizons,
                                                 min_stamps=self.min_stamps)
        fresh = gamma[..., -1]
        z, R = af.fused_fix(Y[..., -1, :, :], y[..., -1, :], fresh)
        return {"mask": mask.copy(), "lags": lags, "fixes": fixes, "final": final, "x": x, "P": P, "valid": valid,
                "fresh": fresh, "z": z, "R": R, "used": used}

    def costs(self, t: dict, likelihood: str) -> np.ndarray:
        """AHG costs J_N(k) (B, N, S) of a filter ``t`` (``predictive``: each horizon's last estimate
        predicted to k against the fused fix of k; ``paper``: in-sample), computed once per filter."""
        if likelihood not in t:
            if likelihood == "paper":
                t[likelihood] = af.in_sample_costs(t["x"], t["valid"], t["z"], t["R"], t["fresh"])
            else:
                t[likelihood] = af.predictive_costs(self.motion, self.prev_x, self.prev_P, self.prev_valid, t["z"],
                                                    t["R"], fresh=t["fresh"])
        return t[likelihood]

    def update(self, readings, decisions) -> None:
        if not self._taken.all():  # not received ahead: the agent decided on the view of the last step
            self._take(readings, np.flatnonzero(~self._taken))
            self._prepare()
        mask = self._mask(decisions)
        pending = self.pending
        t = pending if np.array_equal(mask, pending["mask"]) else self._filter(mask, pending["lags"],
                                                                               pending["fixes"])
        window = self._choose(decisions, t)
        at = (self._copy, self._agent, window - 1)
        valid_w, x_w, P_w = t["valid"][at], t["x"][at], t["P"][at]
        self.out_x = np.where(valid_w[..., None], x_w, self.pred_x)
        self.out_P = np.where(valid_w[..., None, None], P_w, self.pred_P)
        if self.config.constant_windows:
            self.constant_x = np.where(t["valid"][..., None], t["x"], self.constant_pred)
        self.window_used, self.valid_used = np.asarray(window, np.int64), valid_w
        lags = t["lags"]
        arrived = (self.delays == lags[..., None]) & (lags[..., None] >= 0)
        self.packets_used = (t["used"] & arrived).sum(axis=(-1, -2)).astype(float)
        self.packets_arrived = arrived.sum(axis=(-1, -2)).astype(float)
        self.used = t["used"]
        self._refresh_view(t)  # before prev_* move on: t's costs compare with the estimates of k - 1
        self.final = t["final"]
        self.prev_x, self.prev_P, self.prev_valid = t["x"], t["P"], t["valid"]
        self.mask = mask.copy()
        self._taken[:] = False

    def _refresh_view(self, t: dict) -> None:
        """The RSS slots (neighbours by the RSS of their packet of the newest stamp, strongest first) and the
        observation features of filter ``t``, the innovation measured against the current prediction."""
        newest = self.delays[..., -1, :] == 0
        key = np.where(newest, self.rss[..., -1, :], -np.inf)
        self.slots = np.argsort(-key, axis=-1, kind="stable")
        # built when observed: after an update the core usually receives (and refreshes) again first
        self._view = (t, self.pred_x, self.pred_P)

    def _build_view(self) -> None:
        if self._view is None:
            return
        t, pred_x, pred_P = self._view
        self._view = None
        e = t["z"] - pred_x[..., :2]
        nis = np.einsum("...a,...ab,...b->...", e, np.linalg.inv(pred_P[..., :2, :2] + t["R"]), e)
        self._features = self._make_features(t, np.where(t["fresh"], nis, 0.0))

    def _mask(self, decisions) -> np.ndarray:
        return np.ones((self.batch, self.num_agents, self.J), bool)

    def _choose(self, decisions, t: dict) -> np.ndarray:  # pragma: no cover - interface
        """The window N (B, N) to output, given filter ``t``."""
        raise NotImplementedError

    def predict(self, inputs) -> None:
        A = self.motion.transition
        self.pred_x = self.out_x @ A.T
        self.pred_P = A @ self.out_P @ A.T + self.motion.process_cov
        if self.config.constant_windows:
            self.constant_pred = self.constant_x @ A.T

    def position(self) -> np.ndarray:
        return self.out_x[..., :2]

    def position_cov(self) -> np.ndarray:
        return self.out_P[..., :2, :2]

    # --- observation ------------------------------------------------------------------------
    def _per_lag(self, lags) -> np.ndarray:
        known = (self.delays <= lags[..., None]) & (lags[..., None] >= 0)
        return known.sum(axis=-1)[..., ::-1] / self.J  # lag 0 first

    def feature_defaults(self) -> np.ndarray:
        return np.zeros(self.feature_bounds()[0].size)

    def observation_features(self) -> np.ndarray:
        self._build_view()
        return self._features.copy()


class AfgeBackend(PacketFirBackend):
    def __init__(self, config: Afge, world, network, batch):
        self.ahg = config.ahg
        self.M = config.group_size
        super().__init__(config, world, network, batch, config.window_max)
        B, N = self.batch, self.num_agents
        self.centre = np.full((B, N), config.window_centre, np.int64)
        self.raw = np.zeros((B, N, self.S))
        self.count = np.zeros((B, N, self.S), np.int64)
        # whether AHG runs here: a binding whose action codec never offers v = 0 turns it off
        self.adaptive = True

    def decision_blocks(self) -> list[Block]:
        c = self.config
        n = c.window_max - c.window_min + 2
        return [Block("window", 1, n, f"0 = AHG (Algorithm 10), v = window N_min + v - 1 (N_min = {c.window_min})",
                      default=0, maximum=0, minimum=0),
                Block("keep", self.J, 2, "keep (1) / drop (0) the packets of RSS slot s", default=1, maximum=1,
                      minimum=1)]

    def _reset_choice(self, idx) -> None:
        self.centre[idx] = self.config.window_centre
        self.raw[idx], self.count[idx] = 0.0, 0

    def _mask(self, decisions) -> np.ndarray:
        bits = np.asarray(decisions)[..., 1:1 + self.J] == 1
        mask = np.zeros((self.batch, self.num_agents, self.J), bool)
        mask[self._copy3, self._agent3, self.slots] = bits
        return mask

    @property
    def feature_likelihood(self) -> str:
        """The AHG cost the observation shows (``smoothed`` shows its unsmoothed predictive cost)."""
        return "paper" if self.config.likelihood == "paper" else "predictive"

    def _refresh_view(self, t: dict) -> None:
        self.costs(t, self.feature_likelihood)  # now, while prev_* are the estimates t's costs compare with
        super()._refresh_view(t)

    def _choose(self, decisions, t: dict) -> np.ndarray:
        c = self.config
        pick = np.asarray(decisions)[..., 0].astype(np.int64)
        if not self.adaptive:  # a codec without v = 0 (the nlos_horizon preset: its agent runs AHG itself)
            return c.window_min + pick - 1
        costs = self.costs(t, "paper" if c.likelihood == "paper" else "predictive")
        if c.likelihood == "smoothed":
            self.raw, self.count, costs = af.smooth_costs(self.raw, self.count, costs, c.smoothing)
        chosen, centre = af.ahg_select(self.ahg, self.centre, costs, t["valid"], t["fresh"])
        # chosen = 0: no group member has an estimate; the centre (also without one) outputs the prediction
        adaptive = np.where(chosen > 0, chosen, self.centre)
        self.centre = centre
        return np.where(pick == 0, adaptive, c.window_min + pick - 1)

    def feature_bounds(self):
        D1, J, M = self.D + 1, self.J, self.M
        low = np.concatenate([np.zeros(D1), np.tile([0.0, -RSS_BOUND, -1.0], J), [0.0, 0.0],
                              np.full(M, -LOG_BOUND), np.zeros(M)])
        high = np.concatenate([np.ones(D1), np.tile([1.0, RSS_BOUND, 1.0], J), [LOG_BOUND, 1.0],
                               np.full(M, LOG_BOUND), np.full(M, COST_BOUND)])
        return low, high

    def feature_defaults(self) -> np.ndarray:
        out = np.zeros(self.feature_bounds()[0].size)
        M = self.M
        out[-2 * M:-M] = INVALID_LOG_TRACE
        out[-M:] = COST_BOUND
        return out

    def _make_features(self, t, nis) -> np.ndarray:
        c = self.config
        P, valid = t["P"], t["valid"]
        B, N, J, M, D1 = self.batch, self.num_agents, self.J, self.M, self.D + 1
        out = np.empty((B, N, D1 + 3 * J + 2 + 2 * M))
        out[..., :D1] = self._per_lag(t["lags"])
        by_slot = (self._copy3, self._agent3, self.slots)
        present = (self.delays[..., -1, :] == 0)[by_slot]
        slots = out[..., D1:D1 + 3 * J].reshape(B, N, J, 3)  # a view: present, RSS, mode per slot
        slots[..., 0] = present
        # np.minimum(np.maximum(.)) is np.clip's value without its Python dispatch (a third of this method)
        slots[..., 1] = np.where(present, np.minimum(np.maximum((self.rss[..., -1, :][by_slot] + 80.0) / 10.0,
                                                                -RSS_BOUND), RSS_BOUND), 0.0)
        if c.mode_info == "known":
            slots[..., 2] = np.where(present, np.where(self.modes[..., -1, :][by_slot] == 1, 1.0, -1.0), 0.0)
        else:
            slots[..., 2] = 0.0
        h = self.ahg.half * c.window_step
        centre = np.minimum(np.maximum(np.where(self.window_used > 0, self.window_used, c.window_centre),
                                       c.window_min + h), c.window_max - h)  # before the first output: N_c(0)
        by_member = (self._copy3, self._agent3, af.ahg_group(self.ahg, centre) - 1)
        last = D1 + 3 * J
        out[..., last] = np.minimum(np.log1p(nis), LOG_BOUND)
        out[..., last + 1] = self.window_used / c.window_max
        # gathered to the M members before the arithmetic: the other S - M horizons' logs would be discarded
        member_valid = valid[by_member]
        trace = P[..., 0, 0][by_member] + P[..., 1, 1][by_member]
        out[..., last + 2:last + 2 + M] = np.where(
            member_valid, np.minimum(np.maximum(np.log(np.maximum(trace, 1e-300)), -LOG_BOUND), LOG_BOUND),
            INVALID_LOG_TRACE)
        cost = np.where(member_valid, t[self.feature_likelihood][by_member], np.inf)
        best = np.min(cost, axis=-1, keepdims=True)
        out[..., last + 2 + M:] = np.where(np.isfinite(cost),
                                           np.minimum(cost - np.where(np.isfinite(best), best, 0.0), COST_BOUND),
                                           COST_BOUND)  # 0 marks the member AHG would pick
        return out


class DfirBackend(PacketFirBackend):
    def __init__(self, config: Dfir, world, network, batch):
        super().__init__(config, world, network, batch, config.window)

    def _choose(self, decisions, t: dict) -> np.ndarray:
        return np.full((self.batch, self.num_agents), self.config.window, np.int64)

    def feature_bounds(self):
        D1 = self.D + 1
        return np.zeros(D1 + 1), np.ones(D1 + 1)

    def _make_features(self, t, nis) -> np.ndarray:
        return np.concatenate([self._per_lag(t["lags"]), self.valid_used[..., None].astype(float)], axis=-1)


@BACKENDS.register
@dataclass(frozen=True)
class DelayKalman(_PacketFirConfig):
    name = "delay_kalman"

    def build(self, world, network, batch: int) -> Backend:
        return DelayKalmanBackend(self, world, network, batch)


class DelayKalmanBackend(DfirBackend):
    """gao2016's Kalman baseline: the stack of one horizon that never drops a stamp, started from the
    world's prior (``estimators.afge.prior_stack``; ``shift=False``: ``estimators.afge.run_kalman``)."""

    finite_horizons = False
    min_stamps = 0

    def __init__(self, config: DelayKalman, world, network, batch):
        PacketFirBackend.__init__(self, config, world, network, batch, 1)

    def reset(self, rngs, idx) -> None:
        super().reset(rngs, idx)
        idx = np.asarray(idx)
        mean, _ = self.world.initial_belief()
        prior = af.prior_stack(mean[idx], self.world.prior_cov)
        self.final.info[idx], self.final.vector[idx], self.final.stamps[idx] = prior.info, prior.vector, prior.stamps

    def _choose(self, decisions, t: dict) -> np.ndarray:
        return np.ones((self.batch, self.num_agents), np.int64)
