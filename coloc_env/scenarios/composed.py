"""The scenario of any composition: world, network and backend stepped as one batched core.

Built by ``coloc_env.parallel_env(coloc_env.compose(world=..., network=..., backend=...))``.
Every agent is the same: its action concatenates the world's sensing blocks,
the network's transport blocks and the backend's decision blocks (each part's
module documents its blocks); its observation is what it can know locally.

Step k: the world reports the readings of time k (given the sensing choices);
the network takes the link state of time k (the radios sense true distances)
and the transport decisions; the backend updates its estimates of time k,
asking the network for every delivery, then predicts to k + 1; the world
moves to k + 1. The infos report time k's truth and the posterior of k.

Receive, then decide. A backend that declares ``receives_before_deciding``
(``afge``, ``dfir``: their decisions pick among the packets that have arrived)
gets the readings of time k, and the network's delivery of them, before the
agents choose the action of step k, wherever no action shapes what is read
or carried (the world has no sensing blocks and the network no transport
blocks): at reset and at the end of step k - 1 the core reads the world at
k, calls the network for step k and hands both to ``backend.receive``; the
observation then shows what arrived, and step k only updates. The network's
record of that call (``messages_sent``, ``floats_sent``, ...) is kept aside
and reported in step k's infos, so every step still reports what was sent in
it. Elsewhere the backend receives inside its update, as every other backend
does. ``receives_ahead`` says which way a composition runs.

Two estimands (the world's ``estimand``, which the backend must share):

* ``self``: each agent estimates its own position; the truth is
  ``world.positions()`` (B, N, 2).
* ``target``: every agent estimates one shared state x of the world (a
  target, a drift state); its "position" is the two state components the
  world's docstring names (``world.position_index``), repeated per agent, and
  the world's ``error`` is ||M (xhat_i - x)||^2 over the components its
  ``metric`` M names, in the unit its docstring states (the paper's metric:
  m^2). Every backend reports its estimate of x(k) at step k, so the same
  world and seed give every backend the same ``true_position``. The agents'
  own positions (``world.positions()``, the link state) are the
  world's formation.

Action (per agent, the blocks in order world, network, backend)
---------------------------------------------------------------
``MultiDiscrete(choices of every entry)`` when every block is discrete, else a
``Box`` whose discrete entries decode by rounding. The values follow one rule in
every scenario (``coloc_env.scenarios.base.Scenario.check_actions``): a
continuous block's entries are clipped to its bounds; a discrete block's entry
outside its choices (after rounding in a ``Box``; a non-integer in a
``MultiDiscrete``) and a NaN or inf anywhere are a ``ValueError`` naming the
block and the agent.

Action masks (MultiDiscrete actions; ``infos[agent]["action_mask"]``, ``vector_env(...).action_masks()``)
---------------------------------------------------------------------------------------------------------
``ComposedScenario.action_mask``: (B, N, sum(nvec)) bool, each entry's choices in order, True =
valid for the next step. A masked choice is never refused; it is one that by the part's own rule does
the same as the block's explicit "stop" / "none" choice, decided from the distances at the coming step
(the observation's link-layer knowledge). Nothing the agent cannot observe masks a choice (who is
reached before it, a spent hop budget, a loss, whom an mrclam robot recorded). A ``Box`` action has no mask.

The rules are the parts': the core asks the world (``World.sensing_masks``) and the network
(``Network.transport_masks``) for their blocks' masks, and each part's module table states its rule
(``circles``: its ``partner`` block; ``relay``: its ``next_hop`` block). A part without a rule, and
every backend decision, keeps every choice valid. A rule never masks a block's "stop" / "none" choice,
so every entry keeps a valid one. A binding with its own action codec masks nothing unless it
overrides ``action_mask`` (``relay_ukf`` does).

Observation (per agent, ``Box(float32)``; both estimands)
---------------------------------------------------------
| index             | meaning                                                        | bounds      |
|-------------------|----------------------------------------------------------------|-------------|
| ``[0, N)``        | ``index``: one-hot of the agent's own index                    | [0, 1]      |
| ``[N]``           | ``log_trace``: log tr of the position covariance the agent     | [-50, 50]   |
|                   | holds (m^2: its own position, or the target's position         |             |
|                   | components), clipped; the local one where the backend's exact  |             |
|                   | covariance is not (bandwidth_fusion: the bound M_i, eq. 19);   |             |
|                   | 0 without a covariance (``covariance_known`` tells the two     |             |
|                   | apart from tr P = 1 m^2)                                        |             |
| ``[N+1, 2N+1)``   | ``received``: 1 for each agent it received a message from last | [0, 1]      |
|                   | step                                                           |             |
| ``[2N+1, 3N+1)``  | ``distance``: to each agent / 100 m (link-layer knowledge), 0  | [0, inf)    |
|                   | itself                                                         |             |
| ``[3N+1]``        | ``step_fraction``: k / horizon                                 | [0, 1]      |
| ``[3N+2]``        | ``covariance_known``: 1 where the backend keeps the position   | [0, 1]      |
|                   | covariance the agent holds, else 0                             |             |
| ``[3N+3]``        | ``displacement``: ||xhat_i,k - xhat_i,ref|| / 100 m (the same   | [0, inf)    |
|                   | scale as the distances), its position estimate (the infos'     |             |
|                   | ``estimated_position``: its own, or the target's position      |             |
|                   | components) now against the one at its reference transmission |             |
| ``[3N+4]``        | ``steps_since``: (k - k_ref) / horizon, the steps since its    | [0, 1]      |
|                   | reference transmission                                         |             |
| ``[3N+5]``        | ``message_value``: the value of transmitting now, m^2, 0 where  | [0, inf)    |
|                   | the backend declares none (``Backend.message_value``:          |             |
|                   | max(0, tr(P_ref + (k - k_ref) Q_pos) - tr(P_i,k)))              |             |
| ``[3N+6]``        | ``communication_cost``: its copy's cost per message this       | [0, inf)    |
|                   | episode (``communication_cost``, or the draw from              |             |
|                   | ``cost_range``)                                                |             |
| then              | the world's features, then the network's                       | their own   |
|                   | (``Network.observation_features``: ``gilbert_elliott``'s       | ([0, 1] for |
|                   | ``ack`` (N,), 1 for each agent its own message of the last     | ``ack``)    |
|                   | step reached; ``contention``'s per-slot ``ack``; none for the  |             |
|                   | other networks), then the backend's                            |             |

``ComposedScenario.feature_index(name)`` gives each named feature's index (a block's first); a realizable
policy reads features by these names (``agents.event_triggered``). A preset binding observes what its
registered version does: ``contention_localization`` this whole table; the others their own entries followed
by ``PresetScenario.appended_features`` (the episode's ``communication_cost``, the ``index`` where they lack
it), which ``feature_index`` finds by the same names.

Since the last transmission. Each agent's *reference transmission* is its last transmission that was
delivered or, where the network gives no acknowledgements (``Network.acknowledged`` is None), its last
transmission: after step k the core reads the network's per-agent ``transmissions`` (> 0: it transmitted;
``coloc_env.networks.base``) and, where the network acknowledges, whether its acknowledgements of the step
name a receiver; each agent so renewed takes its estimate of time k (``estimated_position``), the
covariance it holds now (the ``log_trace`` one) and k + 1 (the step its next observation is at) as its
reference (x_ref, P_ref, k_ref). Before any, the reference is the agent's belief at reset (k_ref = 0). Only
what the agent itself holds enters: its own estimate and covariance, its own decisions and its own
acknowledgements. A copy's reset renews only its own agents' references.

Reward (per agent, its own estimate; a shared estimate gives every agent the team's)
------------------------------------------------------------------------------------
| estimand | ``reward="error"``                              | ``reward="trace"``                                 |
|----------|-------------------------------------------------|----------------------------------------------------|
| self     | minus its position error (m) at time k after    | minus sqrt(tr P_ii) (m), the backend's own RMS     |
|          | the update                                      | (the realized error without a covariance)          |
| target   | minus the world's ``error`` of its estimate     | minus tr(M P_i M^T) (m^2), the backend's own       |
|          | (m^2, the paper's metric; see the world)        | covariance over the same components (exact where  |
|          |                                                 | the backend computes it: bandwidth_fusion's Sigma_i) |

both minus its copy's communication cost (``communication_cost``, or under ``cost_range`` the cost the copy drew
at reset: ``coloc_env.composition``) per message it sent this step, and minus the cost the network itself
charges for what the agent sent (``relay``'s ``hop_cost_per_m2`` d^2 per delivered hop of length d, at
the holder that sent it; 0 for the other networks).

Termination: none; truncation after ``horizon`` steps.

``infos[agent]``: ``true_position`` (its own position, or the target's; ``true_position()`` gives
every agent's at once, (B, N, 2)), ``estimated_position`` (its estimate of time k: the posterior, or a
predictor's xhat(k)), ``position_error`` (m), ``error`` (the reward's error term: m for ``self``, the
world's unit for ``target``), ``trace`` (m^2, the position block of its covariance, nan without one),
``messages_sent``, ``floats_sent``, ``communication`` (= messages_sent), the per-link accounting
``transmissions``, ``link_attempts``, ``link_deliveries``, ``collisions`` (per sender: the table of
``coloc_env.networks.base``), ``communication_cost`` (its copy's cost per message this episode), ``step``.
"""

from __future__ import annotations

import functools

import gymnasium
import numpy as np

from coloc_env.composition import draw_costs
from coloc_env.rendering import Link, Scene
from coloc_env.scenarios.base import Scenario

LOG_TRACE_BOUND = 50.0
DISTANCE_SCALE = 100.0
# the spawn key, under the world's generator's seed sequence, of a copy's episode cost: far above any child a world
# spawns itself
COST_STREAM = 2**32 - 1
# the agent's own features after the step fraction, in this order (the module's observation table)
OWN_FEATURES = ("covariance_known", "displacement", "steps_since", "message_value", "communication_cost")
# each own feature's (low, high) bounds (the module's observation table)
OWN_BOUNDS = {"covariance_known": (0.0, 1.0), "displacement": (0.0, np.inf), "steps_since": (0.0, 1.0),
              "message_value": (0.0, np.inf), "communication_cost": (0.0, np.inf)}
# the own features that read the agent's reference transmission (``_set_reference``)
REFERENCE_FEATURES = ("displacement", "steps_since", "message_value")
LINK_COUNTS = ("transmissions", "link_attempts", "link_deliveries", "collisions")  # coloc_env.networks.base


def cost_generator(world_rng: np.random.Generator) -> np.random.Generator:
    """The generator of a copy's episode cost (``cost_range``): a child of the world's generator's seed sequence
    under the spawn key ``COST_STREAM``, built without spawning (no part's generator, nor the episode's, moves)."""
    seq = world_rng.bit_generator.seed_seq
    return np.random.Generator(type(world_rng.bit_generator)(np.random.SeedSequence(
        seq.entropy, spawn_key=(*seq.spawn_key, COST_STREAM), pool_size=seq.pool_size)))


class ComposedScenario(Scenario):
    """Batched core of a ``coloc_env.composition.Composition``."""

    name = "composed"
    paper = "-"
    Config = None
    # the agent's own features after the step fraction (the module's observation table); a preset binding keeps
    # the observation of its registered version
    own_features: tuple[str, ...] = OWN_FEATURES

    def __init__(self, config, batch: int = 1):
        super().__init__(config, batch)
        spec = self.composition = self.compose(config)
        self.name = spec.name
        self.world = spec.world.build(self.batch, spec.episode_steps)
        self.agent_prefix = self.world.agent_prefix
        self.network = spec.network.build(self.world.num_agents, self.batch, spec.backend.message_kind,
                                          getattr(spec.backend, "rounds", 1))
        self.backend = spec.backend.build(self.world, self.network, self.batch)
        self.world.fixes_needed = self.backend.reads_fixes
        # receive, then decide (the module docstring): only where no action shapes what is read or carried
        self.receives_ahead = bool(self.backend.receives_before_deciding) \
            and not self.world.sensing_blocks() and not self.network.transport_blocks()
        self._ahead_record: dict | None = None  # the network's record of the coming step's call
        self.blocks = [*self.world.sensing_blocks(), *self.network.transport_blocks(),
                       *self.backend.decision_blocks()]
        self._block_counts = (len(self.world.sensing_blocks()), len(self.network.transport_blocks()),
                              len(self.backend.decision_blocks()))
        self.block_parts = [part for part, n in zip(("world", "network", "backend"), self._block_counts,
                                                    strict=True) for _ in range(n)]
        sizes = [blk.size for blk in self.blocks]
        self._splits = np.cumsum(sizes)[:-1] if sizes else []
        self._n_world = sum(blk.size for blk in self.world.sensing_blocks())
        self._n_network = sum(blk.size for blk in self.network.transport_blocks())
        self._action_space = self._build_action_space()
        B, N = self.batch, self.num_agents
        self.estimand = spec.world.estimand
        self.k = np.zeros(B, dtype=int)
        self._truth = np.zeros((B, N, 2))
        self._truth_pose: np.ndarray | None = None  # the poses [x, y, heading] of a world that keeps headings
        self._truth_state = np.zeros((B, getattr(self.world, "state_dim", 0)))
        self._received = np.zeros((B, N, N))
        self._reward = np.zeros((B, N))
        # each copy's communication cost this episode (``cost_range``: drawn at reset)
        self.costs = np.full(B, float(spec.communication_cost))
        # each agent's reference transmission (the module's "Since the last transmission"): its estimate, the
        # covariance it held and the step k after it
        self._ref_position = np.zeros((B, N, 2))
        self._ref_cov = np.zeros((B, N, 2, 2))
        self._ref_k = np.zeros((B, N), dtype=int)
        self.readings = None
        # who is told of each step's readings and deliveries (``observe``); None: nobody
        self.observer = None
        # a callable f(readings) run in the backend's place (``observe``); None: the backend runs
        self.stand_in = None

    def observe(self, observer, stand_in=None) -> None:
        """Tell ``observer`` what each step reads and carries (None: stop): ``observer.readings(k, readings)``
        with every ``world.readings`` call the core makes (k the world's step), and the network's deliveries
        (``coloc_env.networks.base``, ``Network.observer``). ``stand_in`` f(readings), where given, runs in the
        backend's place, once per step, with the step's readings (a play that needs only what the world reads
        and the network carries: the world's readings never depend on the backend)."""
        self.observer = observer
        self.network.observer = observer
        self.stand_in = stand_in

    def _read(self, sensing) -> object:
        """The world's readings of its step under ``sensing``, reported to the observer."""
        readings = self.world.readings(sensing)
        if self.observer is not None:
            self.observer.readings(self.world.k, readings)
        return readings

    @classmethod
    def compose(cls, config):
        """The ``coloc_env.composition.Composition`` this scenario steps: the config itself here; a
        preset binding (``coloc_env.scenarios.binding``) builds it from its flat config."""
        return config

    # --- description ------------------------------------------------------------
    @property
    def num_agents(self) -> int:
        return self.world.num_agents

    @property
    def horizon(self) -> int:
        return self.composition.episode_steps

    def _build_action_space(self):
        if not self.blocks:
            return gymnasium.spaces.MultiDiscrete([1], dtype=np.int64)
        if all(blk.discrete for blk in self.blocks):
            nvec = [blk.choices for blk in self.blocks for _ in range(blk.size)]
            return gymnasium.spaces.MultiDiscrete(nvec, dtype=np.int64)
        low = [0.0 if blk.discrete else blk.low for blk in self.blocks for _ in range(blk.size)]
        high = [blk.choices - 1.0 if blk.discrete else blk.high for blk in self.blocks for _ in range(blk.size)]
        return gymnasium.spaces.Box(np.array(low, np.float32), np.array(high, np.float32), dtype=np.float32)

    def action_space(self):
        return self._action_space

    @property
    def obs_dim(self) -> int:
        return 3 * self.num_agents + 2 + len(self.own_features) + self.world.feature_bounds()[0].size \
            + self.network.observation_size() + self.backend.feature_bounds()[0].size

    def feature_index(self, name: str) -> int:
        """The index in an agent's observation of the feature ``name`` (the module's observation table): the first
        index of a block (``index``, ``received``, ``distance``: N entries each), or of a single feature
        (``log_trace``, ``step_fraction``, and those of ``own_features``). What a realizable policy reads by name
        (``agents.event_triggered``). A ``ValueError`` for a feature this scenario's observation lacks."""
        N = self.num_agents
        fixed = {"index": 0, "log_trace": N, "received": N + 1, "distance": 2 * N + 1, "step_fraction": 3 * N + 1}
        if name in fixed:
            return fixed[name]
        if name in self.own_features:
            return 3 * N + 2 + self.own_features.index(name)
        raise ValueError(f"{self.name}'s observation has no feature {name!r}; it has {[*fixed, *self.own_features]}")

    def observation_space(self):
        N = self.num_agents
        wl, wh = self.world.feature_bounds()
        nl, nh = self.network.observation_bounds()
        bl, bh = self.backend.feature_bounds()
        ol, oh = [OWN_BOUNDS[f][0] for f in self.own_features], [OWN_BOUNDS[f][1] for f in self.own_features]
        low = np.concatenate([np.zeros(N), [-LOG_TRACE_BOUND], np.zeros(N), np.zeros(N), [0.0], ol, wl, nl, bl])
        high = np.concatenate([np.ones(N), [LOG_TRACE_BOUND], np.ones(N), np.full(N, np.inf), [1.0], oh, wh, nh, bh])
        return gymnasium.spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)

    def state_space(self):
        return gymnasium.spaces.Box(-np.inf, np.inf, shape=(self.num_agents * self.obs_dim,), dtype=np.float32)

    def action_vector(self, which: str) -> np.ndarray:
        """One agent's action with every block at its ``default``, ``maximum`` or ``minimum`` (the generic
        ``always`` / ``silent`` policies: transport at its maximum / minimum, everything else at its default)."""
        values = []
        for blk, part in zip(self.blocks, self.block_parts, strict=True):
            value = blk.default
            if part == "network" and which in ("maximum", "minimum"):
                value = getattr(blk, which)
            if value is None:
                value = blk.low if not blk.discrete else 0
            values.extend([value] * blk.size)
        if not values:
            values = [0]
        return np.asarray(values, dtype=self._action_space.dtype)

    def action_mask(self) -> np.ndarray | None:
        """The valid choices of the next step's action (B, N, sum(nvec)) bool, by the rules of the module's
        "Action masks" table; None for a ``Box`` action. A binding with its own action codec (its
        ``action_space`` / ``decode_actions``) gets every choice valid unless it overrides this."""
        codec = type(self).action_space is ComposedScenario.action_space \
            and type(self).decode_actions is ComposedScenario.decode_actions
        if not codec:
            return Scenario.action_mask(self)
        if not isinstance(self._action_space, gymnasium.spaces.MultiDiscrete):
            return None
        B, N = self.batch, self.num_agents
        if not self.blocks:  # the placeholder MultiDiscrete([1]): its only action, 0
            return np.ones((B, N, 1), dtype=bool)
        return np.concatenate([m.reshape(B, N, -1) for m in self.block_choice_masks()], axis=-1)

    def block_choice_masks(self) -> list[np.ndarray | None]:
        """One (B, N, size, choices) bool per block (None for a continuous block): the valid choices of each
        entry now, by the world's and the network's own rules (``sensing_masks``, ``transport_masks``; the
        backend's decisions are all valid), from the distances at the coming step, which every agent
        observes (link-layer knowledge)."""
        B = self.batch
        distances = functools.cache(self.world.distances)  # read once, by whichever part's rule needs them
        n_world, n_network, n_backend = self._block_counts
        given = [*(self.world.sensing_masks(distances) or [None] * n_world),
                 *(self.network.transport_masks(distances) or [None] * n_network), *[None] * n_backend]
        masks: list[np.ndarray | None] = []
        for blk, mask in zip(self.blocks, given, strict=True):
            if not blk.discrete:
                mask = None
            elif mask is None:
                mask = np.ones((B, self.num_agents, blk.size, blk.choices), dtype=bool)
            masks.append(mask)
        return masks

    # --- dynamics ------------------------------------------------------------------
    def reset(self, rngs, env_index=None) -> None:
        idx = self._indices(env_index)
        if len(rngs) != len(idx):
            raise ValueError(f"reset needs one generator per copy: {len(idx)} copies, {len(rngs)} generators")
        generators = [self.part_generators(rng) for rng in rngs]
        cost_range = self.composition.cost_range
        if cost_range is not None:  # before the parts draw: its own generator, so no part's draw moves
            self.costs[idx] = draw_costs(cost_range, [cost_generator(g[0]) for g in generators])
        self.world.reset([g[0] for g in generators], idx)
        self.network.reset([g[1] for g in generators], idx)
        self.backend.reset([g[2] for g in generators], idx)
        self.backend.start(idx)
        self.k[idx] = 0
        if self.estimand == "target":
            state = self.world.target_state()
            self._truth_state[idx] = state[idx]
            self._truth[idx] = self._target_truth(state=state)[idx]
        else:
            self._truth[idx] = self.world.positions()[idx]
        poses = getattr(self.world, "poses", None)
        if poses is not None:
            if self._truth_pose is None:
                self._truth_pose = np.array(poses(), float)
            self._truth_pose[idx] = poses()[idx]
        self._received[idx] = 0.0
        self._reward[idx] = 0.0
        if self.tracks_references():
            self._set_reference(np.isin(np.arange(self.batch), idx)[:, None] & np.ones(self.num_agents, bool))
        if self.receives_ahead:
            self._receive_ahead(idx)
        self.network.clear_step_record(idx)

    def _set_reference(self, which: np.ndarray) -> None:
        """Make the current estimate, the covariance the agent holds and its step the reference of the agents
        ``which`` (B, N) bool (a reset, or a transmission delivered / sent: ``_record_transmissions``)."""
        np.copyto(self._ref_position, self.backend.posterior_position, where=which[..., None])
        cov = self.backend.local_covariance()
        if cov is not None:
            np.copyto(self._ref_cov, cov, where=which[..., None, None])
        np.copyto(self._ref_k, self.k[:, None], where=which)

    def _record_transmissions(self) -> None:
        """After step k's transport is known (the network's record) and the backend's update: an agent whose
        transmission was delivered (acknowledged to it, where the network gives acknowledgements) or, without
        acknowledgements, that transmitted (``transmissions`` > 0) takes its state now as its reference."""
        if not self.tracks_references():  # an observation without them (most presets)
            return
        sent = np.asarray(self.network.transmissions) > 0
        acknowledged = self.network.acknowledged()
        if acknowledged is not None:
            sent = sent & acknowledged
        if sent.any():
            self._set_reference(sent)

    def _receive_ahead(self, idx: np.ndarray) -> None:
        """Readings of the copies ``idx`` at their time k, and the network's step-k delivery of them, to the
        backend before the agents decide (receive, then decide). The network's record of this call is kept
        for step k's infos; what it recorded for the step just done stays visible until then. The other
        copies are read and drawn again at their own k (the draws are counter-based: the same values), and
        the backend takes only ``idx``'s."""
        B, N = self.batch, self.num_agents
        net = self.network
        done_step = net.step_record()
        none = np.zeros((B, N, 0), np.int64)
        self.readings = self._read(none)
        net.begin(self.world.k, self.world.positions().copy(), none)
        if self.stand_in is None:
            self.backend.receive(self.readings, idx)
        else:
            self.stand_in(self.readings)
        coming = net.step_record()
        if self._ahead_record is None:
            self._ahead_record = coming
        else:
            for name, value in coming.items():
                if name != "last_chain":
                    self._ahead_record[name][idx] = value[idx]
        net.restore_step_record(done_step)

    def part_generators(self, rng: np.random.Generator) -> tuple:
        """The generators of the world, the network and the backend for one copy's episode.

        Each part draws from its own child of the episode's generator, so the same world and seed give
        every backend the same truth and readings, whatever the network and the backend draw.
        """
        return tuple(rng.spawn(3))

    def decode_actions(self, actions) -> np.ndarray:
        """The agents' actions (B, N, *shape) checked and decoded into the blocks' values (B, N, total size)."""
        arr = self.check_actions(actions)
        flat = arr.reshape(self.batch, self.num_agents, -1)
        if not self.blocks:  # nothing to decide: the action space is a placeholder MultiDiscrete([1])
            if np.any(flat != 0):
                self.refuse_action(flat != 0, flat, "0 (this composition has no decisions)", ["action"])
            return flat[..., :0]
        out = []
        integral = isinstance(self._action_space, gymnasium.spaces.MultiDiscrete)
        for blk, part, values in zip(self.blocks, self.block_parts, np.split(flat, self._splits, axis=-1),
                                     strict=True):
            label = [f"{part} block {blk.name!r} ({blk.meaning})"] * blk.size
            if blk.discrete:
                if integral and np.any(values != np.round(values)):
                    self.refuse_action(values != np.round(values), values, f"an integer in [0, {blk.choices - 1}]",
                                       label)
                values = np.round(values)
                bad = (values < 0) | (values > blk.choices - 1)
                if np.any(bad):
                    self.refuse_action(bad, values, f"an integer in [0, {blk.choices - 1}]", label)
            else:  # a continuous block: clipped to its bounds (the rule of every Box action)
                values = np.clip(values, blk.low, blk.high)
            out.append(values)
        return np.concatenate(out, axis=-1) if out else flat[..., :0]

    def step(self, actions) -> None:
        if (self.k >= self.horizon).any():
            raise RuntimeError("step() on a copy whose episode is over; reset it first")
        self.advance(self.decode_actions(actions))
        self._reward = self.compute_reward()

    def advance(self, decoded: np.ndarray) -> None:
        """One step k -> k + 1 of every copy under decoded actions (B, N, total size of the blocks)."""
        nw, nn = self._n_world, self._n_network
        sensing = decoded[..., :nw].astype(np.int64)
        transport = decoded[..., nw:nw + nn].astype(np.int64)
        decisions = decoded[..., nw + nn:]
        truth = self.world.positions().copy()
        poses = getattr(self.world, "poses", None)
        self._truth_pose = None if poses is None else poses().copy()
        if self.receives_ahead:  # read, carried and received before the agents decided
            readings = self.readings
            self.network.restore_step_record(self._ahead_record)
        else:
            readings = self.readings = self._read(sensing)
            self.network.begin(self.world.k, truth, transport)
        if self.stand_in is None:
            self.backend.step(readings, decisions)
        elif not self.receives_ahead:  # a stand-in that received ahead has run for this step
            self.stand_in(readings)
        if self.estimand == "target":
            self._truth_state = self.world.target_state()  # a gather: already a copy
            self._truth = self._target_truth(state=self._truth_state)
        else:
            self._truth = truth
        self._received = self.network.delivered.transpose(0, 2, 1)  # [s, t]: s heard t
        self.world.advance()
        self.k = self.k + 1
        self._record_transmissions()  # before a receive-ahead call replaces the network's record
        if self.receives_ahead:
            live = np.flatnonzero(self.k < self.horizon)
            if live.size:
                self._receive_ahead(live)

    def compute_reward(self) -> np.ndarray:
        """The reward table of the module docstring, after ``advance``: (B, N)."""
        if self.estimand == "target":
            loss = self.target_error()
            if self.composition.reward == "trace":
                trace = self.metric_traces()
                loss = loss if trace is None else trace
        elif self.composition.reward == "error":
            loss = self.position_error()
        else:
            trace = self.posterior_traces()
            loss = self.position_error() if trace is None else np.sqrt(trace)
        return -loss - self.communication_costs()

    def communication_costs(self) -> np.ndarray:
        """What each agent's sending cost this step (B, N): its copy's communication cost (``communication_cost``, or
        the episode's draw from ``cost_range``) per message it sent, plus the cost the network itself charged it
        (``Network.sending_cost``: ``relay``'s hop costs; 0 for the other networks)."""
        return self.costs[:, None] * self.network.messages_sent + self.network.sending_cost()

    # --- views -------------------------------------------------------------------------
    def _target_truth(self, offset: int = 0, state: np.ndarray | None = None) -> np.ndarray:
        """The target's true position (B, N, 2), repeated for every agent (of ``state`` = the world's
        ``target_state(offset)`` where the caller holds it already)."""
        p = self.world.target_position(offset) if state is None else state[:, list(self.world.position_index)]
        return np.repeat(p[:, None, :], self.num_agents, axis=1)

    def true_position(self) -> np.ndarray:
        """The truth at the time of the current estimate, one row per agent (B, N, d), a new array: what
        ``infos[agent]["true_position"]`` reports (its own position, d = 2, or the target's position
        components, repeated for every agent). The whole episode's truth is the world's
        (``world.truth``, where the world keeps one; its docstring gives the shape)."""
        return self._truth.copy()

    def position_error(self) -> np.ndarray:
        return np.linalg.norm(self.backend.posterior_position - self._truth, axis=-1)

    def reported_position_cov(self) -> np.ndarray | None:
        """The covariance (B, N, 2, 2) of the infos' ``estimated_position`` against their ``true_position`` (the
        posterior's, at the truth's time); None where the backend keeps none. What ``coloc evaluate``'s position
        NEES reads."""
        return self.backend.posterior_position_cov

    def reported_pose(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """An SE(2) backend's pose at the infos' time: (estimate (B, N, 3), truth (B, N, 3), covariance (B, N, 3, 3));
        None where the backend estimates positions only or the world keeps no headings. What ``coloc
        evaluate``'s pose NEES (3 degrees of freedom) reads."""
        if self.backend.posterior_pose is None or self._truth_pose is None:
            return None
        return self.backend.posterior_pose, self._truth_pose, self.backend.posterior_pose_cov

    def target_error(self) -> np.ndarray:
        """The world's error of each agent's estimate of the target state (the unit its docstring states)."""
        return self.world.error(self.backend.posterior_state, self._truth_state)

    def metric_traces(self) -> np.ndarray | None:
        """tr(M P_i M^T) of each agent's state covariance over the world's error components (M = world.metric)."""
        cov = self.backend.posterior_state_cov
        if cov is None:
            return None
        M = self.world.metric
        return np.trace(M @ cov @ M.T, axis1=-2, axis2=-1)

    def posterior_traces(self) -> np.ndarray | None:
        cov = self.backend.posterior_position_cov
        return None if cov is None else np.trace(cov, axis1=-2, axis2=-1)

    def observation(self) -> np.ndarray:
        B, N = self.batch, self.num_agents
        identity = np.broadcast_to(np.eye(N), (B, N, N))
        # what the agent itself can compute (a backend whose exact covariance is not local says so)
        cov = self.backend.local_covariance()
        log_trace = self.log_trace(cov)
        p = self.world.positions()
        dx, dy = p[:, :, None, 0] - p[:, None, :, 0], p[:, :, None, 1] - p[:, None, :, 1]
        distance = np.sqrt(dx * dx + dy * dy) / DISTANCE_SCALE  # the norm over (x, y), on (B, N, N) planes
        frac = np.broadcast_to((self.k / self.horizon)[:, None], (B, N))
        own = self.own_observation(cov) if self.own_features else np.zeros((B, N, 0))
        obs = np.concatenate([identity, log_trace[..., None], self._received.astype(float), distance, frac[..., None],
                              own, self.world.observation_features(), self.network.observation_features(),
                              self.backend.observation_features()], axis=-1)
        return obs.astype(np.float32)

    def log_trace(self, cov: np.ndarray | None) -> np.ndarray:
        """(B, N) the ``log_trace`` feature: log tr of the covariance the agent holds (``cov``:
        ``Backend.local_covariance``), clipped to [-50, 50]; 0 without one."""
        if cov is None:
            return np.zeros((self.batch, self.num_agents))
        # minimum(maximum(.)) is np.clip's value at a fraction of its dispatch cost
        return np.minimum(np.maximum(np.log(np.maximum(cov.trace(axis1=-2, axis2=-1), 1e-300)), -LOG_TRACE_BOUND),
                          LOG_TRACE_BOUND)

    def own_observation(self, cov: np.ndarray | None = None) -> np.ndarray:
        """(B, N, len(own_features)): the features of ``own_features`` (the module's observation table), from what
        each agent holds itself: whether it keeps a covariance, the displacement of its estimate and the steps since
        its reference transmission, the value of transmitting now (``Backend.message_value``) and its copy's
        communication cost. ``cov``: the covariance the agent holds (``Backend.local_covariance``), where the caller
        has it."""
        return self.own_feature_values(self.own_features, cov)

    def own_feature_values(self, names, cov: np.ndarray | None = None) -> np.ndarray:
        """(B, N, len(names)): the features ``names`` (of ``OWN_FEATURES``) in that order; what ``own_observation``
        stacks, and what a preset appends to its own observation (``PresetScenario.appended_features``)."""
        B, N = self.batch, self.num_agents
        out = np.zeros((B, N, len(names)))
        if any(name != "communication_cost" for name in names):
            cov = self.backend.local_covariance() if cov is None else cov
            steps = self.k[:, None] - self._ref_k
        for column, name in enumerate(names):
            if name == "communication_cost":
                out[..., column] = self.costs[:, None]
            elif name == "covariance_known":
                out[..., column] = 0.0 if cov is None else 1.0
            elif name == "displacement":
                d = self.backend.posterior_position - self._ref_position
                out[..., column] = np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]) / DISTANCE_SCALE
            elif name == "steps_since":
                out[..., column] = steps / self.horizon
            elif name == "message_value" and cov is not None:
                inputs = None if self.readings is None else getattr(self.readings, "inputs", None)
                value = self.backend.message_value(self._ref_cov, steps, inputs, cov)
                if value is not None:
                    out[..., column] = value
        return out

    def observed_own_features(self) -> tuple[str, ...]:
        """The names of ``OWN_FEATURES`` this scenario's observation carries (``own_features`` here; a preset's
        appended ones: ``PresetScenario``)."""
        return self.own_features

    def tracks_references(self) -> bool:
        """Whether the observation carries a feature of the reference transmission (displacement, steps_since,
        message_value): only then does the core keep the references (``_set_reference``)."""
        return self._tracks_references

    @functools.cached_property
    def _tracks_references(self) -> bool:  # a fact of the declarations, read every step: computed once per env
        return any(name in REFERENCE_FEATURES for name in self.observed_own_features())

    def reward(self) -> np.ndarray:
        return self._reward.copy()

    def done(self) -> np.ndarray:
        return self.k >= self.horizon

    def state(self) -> np.ndarray:
        return self.observation().reshape(self.batch, -1)

    def info(self) -> dict[str, np.ndarray]:
        B, N = self.batch, self.num_agents
        trace = self.posterior_traces()
        error = self.position_error()
        return {
            "true_position": self.true_position(),
            "estimated_position": self.backend.posterior_position.copy(),
            "position_error": error,
            "error": self.target_error() if self.estimand == "target" else error.copy(),
            "trace": np.full((B, N), np.nan) if trace is None else trace,
            "messages_sent": self.network.messages_sent.copy(),
            "floats_sent": self.network.floats_sent.copy(),
            "communication": self.network.messages_sent.copy(),
            **self.link_counts(),
            "communication_cost": np.repeat(self.costs[:, None], N, axis=1),
            "step": np.repeat(self.k[:, None], N, axis=1),
        }

    def link_counts(self) -> dict[str, np.ndarray]:
        """The network's per-link accounting of this step, (B, N) per sender, copies (``transmissions``,
        ``link_attempts``, ``link_deliveries``, ``collisions``: ``coloc_env.networks.base``'s table); every
        scenario's infos report them under these names."""
        return {name: np.array(getattr(self.network, name), float) for name in LINK_COUNTS}

    def episode_error(self, errors: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """The mean position error over the steps and agents (m)."""
        return np.asarray(errors, float).mean(axis=(-2, -1))

    def scene(self, b: int) -> Scene:
        reach = self.world.extent()
        delivered = self.network.delivered[b]
        links = [Link(source=int(t), target=int(s), value=1.0) for t, s in zip(*np.nonzero(delivered), strict=True)]
        cov = self.backend.posterior_position_cov
        target = self.estimand == "target"
        return Scene(
            title=f"{self.name}  step {int(self.k[b])}",
            truth=self._truth[b, :1] if target else self._truth[b],
            estimates=self.backend.posterior_position[b],
            covariances=None if cov is None else cov[b],
            particles=self.backend.particles(b),
            node_positions=(self.world.positions()[b] if target else self._truth[b]) / reach,
            node_labels=self.agent_names,
            links=links,
            link_value_max=1.0,
            link_value_name="delivered this step",
            sensors=self.world.positions()[b] if target else None,  # the agents, beside the target they track
            extent=None if target else (-reach, reach, -reach, reach),
            notes=[f"mean error {self.position_error()[b].mean():.2f} m",
                   f"messages this step {int(self.network.messages_sent[b].sum())}"],
        )
