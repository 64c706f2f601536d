"""The network of a composition: who can send what to whom, what arrives, and what it cost.

A backend never decides delivery: it asks its network. Six message patterns
(a backend's *message kind*, ``coloc_env.parts.MESSAGE_KINDS``; a network's config declares the ones it
``carries``) cover the papers:

| kind        | what moves                                                        | network call           |
|-------------|-------------------------------------------------------------------|------------------------|
| ``none``    | nothing (dead reckoning)                                          | -                      |
| ``broadcast`` | one transmission per sender and round, heard by its neighbours (dNBP) | ``Network.broadcast`` |
| ``chain``   | a measurement's location information relayed holder to holder (UKF-DCL) | ``Network.relay``  |
| ``central`` | each measurement sent to the fusion centre, agent 0 (UKF-CCL)     | ``broadcast`` to agent 0 |
| ``packets`` | one stamped packet per sender and step, to the receivers it names; | ``Network.packets``  |
|             | each arrives after a delay of 0..D steps or is lost (fu2017, gao2016) |                      |
|             | from a world node (gao2016's orbiting neighbours, no agents) to an | ``Network.node_packets`` |
|             | agent: the same rule, J nodes per agent                           |                        |
| ``components`` | each receiver's selection of components of each sender's estimate, | ``Network.packets`` with |
|             | one message per link (zhao2020)                                   | per-link floats         |

Every network accounts at the sender, in one unit for every backend: a
*message* is one transmission (a broadcast heard by several neighbours is one
message; each relay hop is one message) and *floats* are the numbers it
carried (the backend states its payload). ``messages_sent`` and
``floats_sent`` are per agent and step; world nodes are no agents, so their
packets are counted per receiving agent in ``node_messages`` / ``node_floats``.

Per-link accounting. Beside ``messages_sent`` (whose meaning each call keeps:
it is what ``communication_cost`` prices, so no reward moves), every network
counts per sender and step, (B, N) floats reset by ``begin``, what it tried
and what arrived, the same way for every network (no network overrides these
rules; the kinds each carries are in its own table):

| call (kinds) | ``messages_sent``          | ``transmissions``          | ``link_attempts``    | ``link_deliveries``  |
|--------------|----------------------------|----------------------------|----------------------|----------------------|
| broadcast    | one per round in which its | one per round the sender   | its listeners within | those that received  |
| (broadcast)  | transmission reached       | wants to send, decides to  | range: the           | it                   |
|              | someone                    | transmit and has a         | (transmission,       |                      |
|              |                            | listener besides itself,   | in-range receiver)   |                      |
|              |                            | in range or not            | pairs                |                      |
| messages_to  | one per delivered message  | one per message            | the centre, if in    | delivered messages   |
| (central)    |                            | transmitted (the centre    | range                |                      |
|              |                            | sends none)                |                      |                      |
| packets      | one per sender and call    | one per sender that        | its named receivers  | those whose packet   |
| (packets,    | with a receiver in range,  | transmits to named         | within range         | arrives (delay >= 0: |
| components)  | delivered or not (per link | receivers (per named link  |                      | on time or late)     |
|              | with per-link payloads)    | with per-link payloads)    |                      |                      |
| relay        | one per delivered hop, at  | one per hop attempted, at  | = transmissions (a   | delivered hops       |
| (chain)      | its holder                 | its holder: the delivered  | hop has one          |                      |
|              |                            | ones and the lost hop that | receiver)            |                      |
|              |                            | ends a chain (any other    |                      |                      |
|              |                            | stop sends no hop)         |                      |                      |
| node_packets | none (world nodes are no   | none                       | none                 | none                 |
|              | agents: ``node_messages``) |                            |                      |                      |

``collisions`` counts link attempts lost to a collision or to a receiver
that was transmitting: 0 on every network here (none models a shared
medium). So link_deliveries <= link_attempts, messages_sent <= transmissions
for ``broadcast`` and ``packets``, and link_deliveries / link_attempts is a
link's delivery rate. A step's counts are part of the network's record that
``coloc_env.scenarios.composed`` reports in ``infos[agent]`` under the same names.

Observation. ``observation_size`` / ``observation_features`` are what an
agent observes of its own links after a step (``gilbert_elliott``'s and
``contention``'s acknowledgements); the composed observation appends them after the world's
features. 0 features by default. ``acknowledged`` says, per agent, whether those acknowledgements
report its transmission of the step reached anyone (None where the network gives none).

Packet loss is drawn by ``coloc_env.draws`` from a key the network draws
from its own generator at reset: the value for (step, round, sender,
receiver) does not depend on the batch, so a copy equals itself run alone.

Every delivery call (``DELIVERY_CALLS``: ``broadcast``, ``packets``,
``node_packets``, ``relay``, ``relay_each``, ``messages_to``) reports what it
delivered to the network's ``observer`` where one is set (None by default: then
a call costs one attribute test more): ``observer.delivery(network, call,
arguments, result)`` after the call, ``arguments`` the call's arguments by the
names of ``Network``'s signature. A subclass's own delivery methods report the
same way (``Network.__init_subclass__`` wraps them), and a call made inside
another (a subclass's ``relay`` calling the base's, ``relay_each`` calling
``relay``) is reported once, as the outermost call. ``coloc_env.bounds``
records a play through it.
"""

from __future__ import annotations

import copy
import functools
import inspect
from typing import ClassVar

import numpy as np

from coloc_env.draws import draw_keys, uniforms
from coloc_env.networks import chains
from coloc_env.networks.blocks.relay_chain import RelayChain
from coloc_env.parts import Block

# the calls that deliver messages, each reported to ``Network.observer`` (module docstring)
DELIVERY_CALLS = ("broadcast", "packets", "node_packets", "relay", "relay_each", "messages_to")
CENTRE = 0  # the fusion centre of ``central`` backends
NODE_STREAM = 3  # counter of world-node packets; broadcast uses 0, relay 1, packets 2


@functools.lru_cache(maxsize=16)
def _self_links(n: int) -> np.ndarray:
    """The identity as bools (read only, one per size): no agent sends itself a packet."""
    eye = np.eye(n, dtype=bool)
    eye.flags.writeable = False
    return eye


def _reported(method, signature: inspect.Signature):
    """``method`` (a delivery call) reporting to the network's observer after it returns (module docstring);
    ``signature`` the base class's, whose parameter names key the reported arguments."""
    name = method.__name__

    @functools.wraps(method)
    def call(self, *args, **kwargs):
        if self.observer is None or self._delivering:
            return method(self, *args, **kwargs)
        self._delivering = True
        try:
            result = method(self, *args, **kwargs)
        finally:
            self._delivering = False
        bound = signature.bind(self, *args, **kwargs)
        bound.apply_defaults()
        arguments = dict(bound.arguments)
        del arguments["self"]
        self.observer.delivery(self, name, arguments, result)
        return result

    call.reports_delivery = True
    return call


class Network:
    """Batched delivery and accounting; subclasses set the link rules (``usable``, ``loss``, decisions)."""

    # loss_probability reads each copy's link state at this step besides the distance (``gilbert_elliott``): it is
    # then asked with the full (B, N, N) distances only (no copy stands for others, no gathered links)
    loss_reads_links: ClassVar[bool] = False
    # who is told of every delivery (``observer.delivery(network, call, arguments, result)``); None: nobody
    observer = None
    _delivering = False  # inside a reported call (a nested one is not reported again)

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        for name in DELIVERY_CALLS:
            method = cls.__dict__.get(name)
            if method is not None and not getattr(method, "reports_delivery", False):
                setattr(cls, name, _reported(method, _BASE_SIGNATURES[name]))

    def __init__(self, config, num_agents: int, batch: int, message_kind: str, rounds: int = 1):
        self.config = config
        self.num_agents = int(num_agents)
        self.batch = int(batch)
        self.message_kind = message_kind
        self.rounds = int(rounds)
        self.keys = np.zeros(self.batch, dtype=np.uint64)
        B, N = self.batch, self.num_agents
        self.messages_sent = np.zeros((B, N))
        self.floats_sent = np.zeros((B, N))
        self.delivered = np.zeros((B, N, N), dtype=bool)  # union over this step's rounds, for the renderer
        self.node_messages = np.zeros((B, N))  # world-node packets sent to each agent this step
        self.node_floats = np.zeros((B, N))
        self.transmissions = np.zeros((B, N))  # the per-link accounting of the module's table
        self.link_attempts = np.zeros((B, N))
        self.link_deliveries = np.zeros((B, N))
        self.collisions = np.zeros((B, N))
        self.last_chain: RelayChain | None = None
        self._positions = np.zeros((B, N, 2))
        self._decisions = np.zeros((B, N, 0), dtype=np.int64)
        self._k = np.zeros(B, dtype=int)
        self._distance: np.ndarray | None = None  # the cache of distances()
        self._stream = 2  # the counter stream of the packets being drawn (node_packets sets NODE_STREAM)
        # which rules the subclass overrides, read once (packets runs every step): the base's rules (every link
        # usable, none lost, on time) read no distance, nor does a delay rule of the uniforms alone
        # (``_delays_read_distance`` False): then packets computes none
        cls = type(self)
        self._plain_delays = cls.packet_delays is Network.packet_delays
        self._own_usable = cls.usable is not Network.usable
        self._base_rules = self._plain_delays and not self._own_usable \
            and cls.loss_probability is Network.loss_probability
        self._reads_distance = self._own_usable or (
            cls.loss_probability is not Network.loss_probability if self._plain_delays
            else getattr(self, "_delays_read_distance", True))

    # --- description ---------------------------------------------------------------------
    def transport_blocks(self) -> list[Block]:
        """The network's part of the action for this backend's message kind; none by default."""
        return []

    def transport_masks(self, distances) -> list[np.ndarray] | None:
        """The valid choices of the transport blocks for the coming step, one (B, N, size, choices) bool per
        block, by the network's own rule (a masked choice does what the block's "stop" does); ``distances()``
        gives the (B, N, N) distances between the agents now. None (the default): every choice valid."""
        return None

    # --- rules (subclasses) -------------------------------------------------------------------
    def usable(self, distance: np.ndarray) -> np.ndarray:
        """Links that can carry a packet at this distance (range limit); all by default."""
        return np.ones(np.shape(distance), dtype=bool)

    def loss_probability(self, distance: np.ndarray) -> np.ndarray:
        return np.zeros(np.shape(distance))

    def packet_delays(self, distance: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Delay in steps (int, 0 = on time) of packets over links at ``distance``, or -1 for a lost one,
        given one uniform ``u`` per packet; by default lost with ``loss_probability``, else on time."""
        return np.where(u < self.loss_probability(distance), -1, 0)

    def max_delay(self) -> int:
        """The longest delay ``packet_delays`` can give (a receiver's buffer length D)."""
        return 0

    def max_hops(self) -> int:
        return self.num_agents - 1

    def transmits(self, round_index: int) -> np.ndarray:
        """(B, N) bool: the agents' decision to transmit in this round (always, by default)."""
        return np.ones((self.batch, self.num_agents), dtype=bool)

    def next_hop_choice(self) -> np.ndarray | None:
        """(B, N) the holders' relay choices (N = stop, N + 1 = nearest not yet reached); None = nearest first."""
        return None

    # --- per episode and step ------------------------------------------------------------------
    def reset(self, rngs, idx: np.ndarray) -> None:
        self.keys[idx] = draw_keys(rngs)

    def begin(self, k: np.ndarray, positions: np.ndarray, decisions: np.ndarray) -> None:
        """Start step k: the link state (true positions, which the radios sense) and the decisions."""
        self._k = np.asarray(k)
        self._positions = np.asarray(positions, float)
        self._decisions = decisions
        self._distance = None  # this step's link distances, computed on first use
        # fresh arrays, not zeroed in place: the step before may still hold them (a view of delivered, a record)
        B, N = self.batch, self.num_agents
        self.messages_sent = np.zeros((B, N))
        self.floats_sent = np.zeros((B, N))
        self.delivered = np.zeros((B, N, N), dtype=bool)
        self.node_messages = np.zeros((B, N))
        self.node_floats = np.zeros((B, N))
        self.transmissions = np.zeros((B, N))
        self.link_attempts = np.zeros((B, N))
        self.link_deliveries = np.zeros((B, N))
        self.collisions = np.zeros((B, N))
        self.last_chain = None

    # --- the step's record ---------------------------------------------------------------
    # the (B, ...) arrays that describe one step's sending (the infos report them); a subclass that keeps more
    # (relay's ``cost_sent``) names them too
    STEP_RECORD = ("messages_sent", "floats_sent", "delivered", "node_messages", "node_floats", "transmissions",
                   "link_attempts", "link_deliveries", "collisions")

    def step_record(self) -> dict:
        """A copy of what this step sent (``STEP_RECORD`` and the last relay chain): a core that receives
        ahead (``coloc_env.scenarios.composed``) keeps one step's record while the network runs the next."""
        record = {name: np.array(getattr(self, name)) for name in self.STEP_RECORD}
        record["last_chain"] = copy.deepcopy(self.last_chain)
        return record

    def restore_step_record(self, record: dict) -> None:
        """Make ``record`` (``step_record``'s) the step's record again."""
        for name, value in record.items():
            setattr(self, name, copy.deepcopy(value) if name == "last_chain" else value.copy())

    def clear_step_record(self, idx: np.ndarray) -> None:
        """No sending in the copies ``idx``: a copy that starts anew reports no messages and no chain, not
        those of the episode before."""
        for name in self.STEP_RECORD:
            getattr(self, name)[idx] = 0
        if self.last_chain is not None:
            self.last_chain.clear(idx)

    def sending_cost(self) -> np.ndarray:
        """(B, N) what the network itself charged each sender this step, beside the composition's
        ``communication_cost`` per message: 0 here (``relay`` charges its hops' energy)."""
        return np.zeros((self.batch, self.num_agents))

    def distances(self) -> np.ndarray:
        """(B, N, N) distances between the agents at this step (read only: computed once per step and shared
        by every delivery call; copies at the same positions, like the circles world's, share one matrix)."""
        if self._distance is None:
            p = self._positions
            shared = len(p) > 1 and bool((p == p[:1]).all())
            q = p[:1] if shared else p
            if q.shape[-1] == 2:  # sqrt(dx^2 + dy^2): the same float operations as the sum over the last axis
                x, y = q[..., 0], q[..., 1]
                dx, dy = x[:, :, None] - x[:, None, :], y[:, :, None] - y[:, None, :]
                dx *= dx
                dy *= dy
                dx += dy
                distance = np.sqrt(dx, out=dx)
            else:
                distance = np.sqrt(np.sum((q[:, :, None, :] - q[:, None, :, :]) ** 2, axis=-1))
            self._distance = np.broadcast_to(distance, (len(p),) + distance.shape[1:]) if shared else distance
            self._distance.flags.writeable = False
        return self._distance

    def broadcast(self, senders: np.ndarray, listening: np.ndarray, floats: float, slot: int = 0) -> np.ndarray:
        """One round: senders (B, N) that want to transmit, listening (B, N, N) [t, s] = s takes t's message.

        ``slot`` names the round within the step (0, 1, ... for a backend's iterations; any fixed
        number for one-off messages): the loss draws depend on (step, slot), never on how many
        calls the other copies of the batch made, and ``transmit`` decisions are read at ``slot``.
        Returns delivered (B, N, N) [t, s]. The agents' transmit decision, the range limit and the
        loss apply here; a sender whose transmission reaches nobody is not counted.
        """
        N = self.num_agents
        distance = self.distances()
        want = (np.asarray(senders, bool) & self.transmits(slot))[:, :, None] & np.asarray(listening, bool)
        want &= ~_self_links(N)
        self.transmissions += want.any(axis=-1)
        want &= self.usable(distance)
        self.link_attempts += want.sum(axis=-1)
        loss = self.loss_probability(distance)
        if (loss <= 0.0).all():  # lossless: every uniform passes u >= 0, none needs drawing (counter-based draws)
            delivered = want
        else:
            delivered = want & (uniforms(self.keys, (self._k, 0, slot), (N, N)) >= loss)
        self.link_deliveries += delivered.sum(axis=-1)
        sent = delivered.any(axis=-1)
        self.messages_sent += sent
        self.floats_sent += floats * sent
        self.delivered |= delivered
        return delivered

    def packets(self, senders: np.ndarray, listening: np.ndarray, floats: float | np.ndarray,
                slot: int = 0) -> np.ndarray:
        """One stamped packet per sender at this step: senders (B, N), listening (B, N, N) [t, s] = t sends to s.

        Returns delay (B, N, N) int [t, s]: the packet of t reaches s after that many steps (0 = this
        step), or -1 (not sent, out of range, or lost); the receiver buffers what arrives late. The
        loss and delay draws depend on (step, slot) only, as in ``broadcast``; the transmit
        decision is read at ``slot``. Unlike a broadcast, a packet counts as sent (one message per
        sender, ``floats`` floats: a number, or (B, N) per sender) when it is transmitted, whether it
        arrives or not: the radio spent the air time. ``floats`` (B, N, N) [t, s] makes every link its
        own message instead (t sends s a packet of that many floats, e.g. the components s selected):
        one message per link that carries a packet.
        """
        N = self.num_agents
        distance = self.distances() if self._reads_distance else None
        want = (np.asarray(senders, bool) & self.transmits(slot))[:, :, None] & np.asarray(listening, bool)
        want &= ~_self_links(N)
        per_link = isinstance(floats, np.ndarray) and floats.ndim == 3
        self.transmissions += want.sum(axis=-1) if per_link else want.any(axis=-1)
        if self._own_usable:
            want &= self.usable(distance)
        self.link_attempts += want.sum(axis=-1)
        if self._plain_delays and (self._base_rules or not np.any(self.loss_probability(distance) > 0)):
            delay = np.where(want, 0, -1).astype(np.int64)  # lossless and on time: no draw decides anything
        else:
            delay = np.where(want, self._link_delays(distance, slot), -1).astype(np.int64)
        self.link_deliveries += (delay >= 0).sum(axis=-1)
        if per_link:
            self.messages_sent += want.sum(axis=-1)
            self.floats_sent += np.where(want, floats, 0.0).sum(axis=-1)
        else:
            sent = want.any(axis=-1)
            self.messages_sent += sent
            self.floats_sent += floats * sent
        self.delivered |= delay == 0
        return delay

    def node_packets(self, sending: np.ndarray, distance: np.ndarray, floats: float, slot: int = 0) -> np.ndarray:
        """World node -> agent packets of this step: ``sending`` (B, N, J) bool [i, j] node j of agent i sends a
        packet to agent i, over a link of true length ``distance`` (B, N, J) m.

        Returns delay (B, N, J) int64: the packet of node j reaches agent i after that many steps (0 = this
        step), -1 if not sent, out of range (``usable``) or lost (``packet_delays`` of one counter-based
        uniform per packet, hashing (step, ``NODE_STREAM``, slot, agent, node) with the network's key: a
        stream of its own, so a copy equals itself run alone). Counts ``node_messages`` (packets sent to
        agent i) and ``node_floats`` when transmitted; a call with ``slot`` 0 (the step's first node round)
        restarts the step's count, as ``begin`` does. ``ideal`` delivers every packet at once,
        ``relay`` loses it with p_loss(d), ``broadcast`` drops it beyond its range, ``random_delay`` delays it.
        """
        sending = np.asarray(sending, bool)
        distance = np.asarray(distance, float)
        N, J = sending.shape[1:]
        want = sending & self.usable(distance)
        u = uniforms(self.keys, (self._k, NODE_STREAM, slot), (N, J))
        self._stream = NODE_STREAM  # a delay rule that draws more (bernoulli_delay's next slot) draws from this stream
        try:
            delay = np.where(want, self.packet_delays(distance, u), -1).astype(np.int64)
        finally:
            self._stream = 2
        if slot == 0:
            self.node_messages = np.zeros_like(self.node_messages)
            self.node_floats = np.zeros_like(self.node_floats)
        sent = want.sum(axis=-1)
        self.node_messages = self.node_messages + sent
        self.node_floats = self.node_floats + floats * sent
        return delay

    def _link_delays(self, distance: np.ndarray | None, slot: int) -> np.ndarray:
        """(B, N, N) [t, s] the delay of every link's packet at this step in ``slot`` (before the transmit
        decision and range apply): ``packet_delays`` of the uniforms of counters (k, 2, slot), the
        step's packet stream. A network may hand back values it drew ahead (they depend on the counters only)."""
        return self.packet_delays(distance, uniforms(self.keys, (self._k, 2, slot), (self.num_agents, self.num_agents)))

    def relay(self, source: np.ndarray, first: np.ndarray, floats_per_hop, slot=0) -> RelayChain:
        """Relay chains source -> first -> ... (B,), following the holders' choices (or nearest first).

        ``first`` < 0: the first hop follows the source's choice too.
        Stop reasons are those of ``coloc_env.networks.blocks.relay_chain.STOP_REASONS``. ``floats_per_hop(h)``
        is the payload of hop h (0-based). A copy with ``source < 0`` has no chain. ``slot`` names the
        chain within the step (see ``broadcast``). ``source`` and ``first`` (B, J) with ``slot``
        (J,) resolve J chains per copy in one call (chain j in slot[j]; the chains of one step do not
        depend on each other): the same chains and accounting as J calls in that order, returned with
        a leading (B, J) shape; ``last_chain`` is then chain J - 1's, as after the J calls.
        """
        B, N = self.batch, self.num_agents
        many = np.ndim(source) == 2
        source, first = (np.asarray(x, int) for x in (source, first))
        J = source.shape[1] if many else 1
        source, first = (np.broadcast_to(x if many else np.broadcast_to(x, (B,))[:, None], (B, J)).reshape(-1)
                         for x in (source, first))
        slots = np.tile(np.broadcast_to(np.asarray(slot, int), (J,)), B)
        copy_of = np.repeat(np.arange(B), J)
        chain = np.full((B * J, N), -1)
        length = np.zeros(B * J, dtype=int)
        hop_distance = np.full((B * J, max(N - 1, 1)), np.nan)
        stop = np.full(B * J, -1)
        rows = np.flatnonzero(source >= 0)  # the chains that exist; the others keep the empty one
        n = len(rows)
        if n:
            copies = copy_of[rows]
            distance = self.distances()
            choice = self.next_hop_choice()
            # the link rules are elementwise: copies that share one distance matrix share their results
            shared = distance.strides[0] == 0 and not self.loss_reads_links
            usable = self.usable(distance[:1] if shared else distance)
            loss = self.loss_probability(distance[:1] if shared else distance)
            lossy = bool(np.any(loss > 0))
            if shared:
                usable, loss = np.broadcast_to(usable, distance.shape), np.broadcast_to(loss, distance.shape)
            # a lossless network needs no draws (u < 0 never holds): the same chains, without the hashing
            u = None
            if lossy:
                k = self._k if np.ndim(self._k) == 0 else self._k[copies]
                u = uniforms(self.keys[copies], (k, 1, slots[rows] if many else int(np.ravel(slot)[0])), (N,))
            holder = source[rows]
            links = np.full((n, N), -1)  # this chain's platforms, in order (the rows of ``chain``)
            links[:, 0] = holder
            # each holder's platforms by distance (ties in index order: argmin's choice): the nearest unreached is
            # the first one of its row the chain has not reached
            order = np.argsort(distance[:1] if shared else distance, axis=-1, kind="stable")
            size = np.ones(n, dtype=int)
            hops = np.full((n, max(N - 1, 1)), np.nan)
            code = np.zeros(n, dtype=int)
            first = first[rows]
            limit = self.max_hops()
            # each chain's rows of the (B, N, N) link arrays: row base + holder
            flat_distance = distance[0] if shared else distance.reshape(B * N, N)
            base = np.zeros(n, dtype=int) if shared else copies * N
            all_usable = bool(np.all(usable))
            flat_usable = usable[0] if shared else usable.reshape(B * N, N)
            flat_loss = loss[0] if shared else loss.reshape(B * N, N)
            resolve = chains.compiled_resolver() or chains.resolve_chains
            resolve(order.reshape(-1, N), flat_usable, all_usable, flat_loss, u if u is not None else np.zeros((n, 1)),
                    u is not None, flat_distance, base, np.ascontiguousarray(holder),
                    np.ascontiguousarray(first), choice if choice is not None else np.zeros((1, 1), int),
                    choice is not None, copies, min(limit, N - 1), links, hops, size, code)
            code[size == N] = 0
            chain[rows], length[rows], hop_distance[rows], stop[rows] = links, size, hops, code
            # the accounting, at each delivered hop's holder, chain by chain in order (one sum per (copy, holder):
            # a platform holds several of the copy's chains)
            sent = links[:, 1:] >= 0
            c, h = np.nonzero(sent)
            holders = links[c, h]
            where = copies[c] * N + holders
            self.messages_sent += np.bincount(where, minlength=B * N).reshape(B, N)
            self.floats_sent += np.bincount(where, np.array([floats_per_hop(j) for j in range(N - 1)], float)[h],
                                            minlength=B * N).reshape(B, N)
            self.delivered[copies[c], holders, links[c, h + 1]] = True
            # a hop attempted is a delivered one or the lost one that stopped its chain (stop reason 5), at its holder
            hops_sent = np.bincount(where, minlength=B * N)
            lost = np.flatnonzero(code == 5)
            hops_lost = np.bincount(copies[lost] * N + links[lost, size[lost] - 1], minlength=B * N)
            self.transmissions += (hops_sent + hops_lost).reshape(B, N)
            self.link_attempts += (hops_sent + hops_lost).reshape(B, N)
            self.link_deliveries += hops_sent.reshape(B, N)
        shape = (B, J) if many else (B,)
        result = RelayChain(chain=chain.reshape(*shape, N), length=length.reshape(shape),
                            hop_distance=hop_distance.reshape(*shape, -1), stop=stop.reshape(shape))
        self.last_chain = RelayChain(chain=result.chain[:, -1].copy(), length=result.length[:, -1].copy(),
                                     hop_distance=result.hop_distance[:, -1].copy(), stop=result.stop[:, -1].copy()
                                     ) if many else result
        return result

    def relay_each(self, source: np.ndarray, first: np.ndarray, floats_per_hop, slots) -> RelayChain:
        """J chains per copy, ``source`` and ``first`` (B, J), chain j in ``slots[j]``: the result of J
        ``relay`` calls in that order, stacked to (B, J, ...). One call when the network keeps the base
        class's relay (its chains do not depend on each other); J calls where a subclass adds to it."""
        if type(self).relay is Network.relay:
            return self.relay(source, first, floats_per_hop, slot=np.asarray(slots, int))
        parts = [self.relay(source[:, j], first[:, j], floats_per_hop, slot=int(slot)) for j, slot in enumerate(slots)]
        return RelayChain(*(np.stack([getattr(p, name) for p in parts], axis=1)
                            for name in ("chain", "length", "hop_distance", "stop")))

    def messages_to(self, senders: np.ndarray, receiver: int, floats: float, slots) -> np.ndarray:
        """J one-off messages per copy to one ``receiver`` (a fusion centre): ``senders`` (B, J) (-1: none), message
        j in ``slots[j]``. Returns delivered (B, J) bool.

        The same outcome, draws and accounting as J ``broadcast`` calls in that order, call j with sender
        ``senders[:, j]`` alone and only ``receiver`` listening (a sender's message to itself is not sent);
        one call for the step instead of J.
        """
        senders = np.asarray(senders, int)
        B, J = senders.shape
        N = self.num_agents
        slots = np.broadcast_to(np.asarray(slots, int), (J,))
        rows = np.arange(B)[:, None]
        sender = np.maximum(senders, 0)
        want = (senders >= 0) & (senders != receiver)
        if not want.any():
            return want
        for value in np.unique(slots):  # the transmit decision read at each message's slot
            at = slots == value
            want[:, at] &= self.transmits(int(value))[rows, sender[:, at]]
        self.transmissions += self._per_sender(want, sender)
        distance = self.distances()[rows, sender, receiver]  # (B, J)
        want &= self.usable(distance)
        self.link_attempts += self._per_sender(want, sender)
        loss = self.loss_probability(self.distances())[rows, sender, receiver] if self.loss_reads_links \
            else self.loss_probability(distance)
        if not (loss <= 0.0).all():
            u = np.empty((B, J))
            for j, value in enumerate(slots):
                u[:, j] = uniforms(self.keys, (self._k, 0, int(value)), (N, N))[rows[:, 0], sender[:, j], receiver]
            want &= u >= loss
        b, j = np.nonzero(want)
        sent = self._per_sender(want, sender)
        self.messages_sent += sent
        self.floats_sent += floats * sent
        self.link_deliveries += sent
        self.delivered[b, sender[b, j], receiver] = True
        return want

    def _per_sender(self, mask: np.ndarray, sender: np.ndarray) -> np.ndarray:
        """(B, N) how many of the (B, J) messages ``mask`` each sender (``sender`` (B, J)) sent."""
        B, N = self.batch, self.num_agents
        b, j = np.nonzero(mask)
        return np.bincount(b * N + sender[b, j], minlength=B * N).reshape(B, N).astype(float)

    def observation_size(self) -> int:
        """f, the features each agent observes of the network (``observation_features``); 0 by default."""
        return 0

    def observation_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) (f,) of the features: [0, 1] by default (acknowledgements)."""
        f = self.observation_size()
        return np.zeros(f), np.ones(f)

    def observation_features(self) -> np.ndarray:
        """(B, N, f) what each agent observes of its own links (after the step: its acknowledgements); none by
        default. No agent observes another's link state or this step's decisions."""
        return np.zeros((self.batch, self.num_agents, 0))

    def acknowledged(self) -> np.ndarray | None:
        """(B, N) bool: whether each agent's acknowledgements of this step (its ``observation_features``) report its
        transmission reached at least one receiver; None (the default) where the network gives no
        acknowledgements. The composed observation's since-last-transmission features read it."""
        return None


_BASE_SIGNATURES = {name: inspect.signature(getattr(Network, name)) for name in DELIVERY_CALLS}
for _name in DELIVERY_CALLS:
    setattr(Network, _name, _reported(getattr(Network, _name), _BASE_SIGNATURES[_name]))
