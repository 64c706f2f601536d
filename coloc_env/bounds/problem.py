"""What a world's bound model hands ``coloc_env.bounds.pcrb``: recursions, the bound problem, each reading's
information tagged with its owner and step, and the delivered bound of backends whose messages carry readings."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimators.bounds import DEFAULT_REGULARIZATION, filtering_bound

CENTRE = 0  # the fusion centre of the ``central`` message kind (coloc_env.networks.base.CENTRE)


@dataclass
class Recursion:
    """One filtering-bound recursion: prior P0 (n, n), mean reading information (K, n, n), F and Q (K-1, [E,] n, n)
    (None: identity / none), and ``positions`` (N, 2) the state indices of each reported agent's position."""

    P0: np.ndarray
    info: np.ndarray
    F: np.ndarray | None
    Q: np.ndarray | None
    positions: np.ndarray

    def run(self, regularization: float = DEFAULT_REGULARIZATION) -> np.ndarray:
        """(K, N) position traces of the bound."""
        return position_traces(filtering_bound(self.P0, self.info, self.F, self.Q, regularization), self.positions)


@dataclass
class ReadingInformation:
    """Each reading of one episode with its Fisher information, tagged (``add`` appends one):

    | field     | meaning                                                                          |
    |-----------|----------------------------------------------------------------------------------|
    | step      | k, the step it was measured at (its information is on the state x(k))            |
    | owner     | the agent that took it (a world node's reading: the agent it is about)           |
    | partner   | the other agent of a reading between two agents (a range), else -1               |
    | index     | the joint state's indices its block is on                                        |
    | block     | its information (len(index) square) at the truth                                 |

    A reading with ``partner`` -1 is its owner's own information from the step it is taken (a fix, a sighting
    of a known landmark, a target reading); one between two agents is nobody's alone (``coloc_env.bounds``,
    the information-set delivered bound, condition (c)).
    """

    size: int  # n, the joint state's dimension
    step: list = field(default_factory=list)
    owner: list = field(default_factory=list)
    partner: list = field(default_factory=list)
    index: list = field(default_factory=list)
    block: list = field(default_factory=list)

    def add(self, step: int, owner: int, partner: int, index, block: np.ndarray) -> None:
        self.step.append(int(step))
        self.owner.append(int(owner))
        self.partner.append(int(partner))
        self.index.append(np.asarray(index, int))
        self.block.append(np.asarray(block, float))

    def __len__(self) -> int:
        return len(self.step)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(step, owner, partner) as int arrays (R,)."""
        return (np.asarray(self.step, int), np.asarray(self.owner, int), np.asarray(self.partner, int))


@dataclass
class BoundProblem:
    """What a world's bound model returns: ``centralized`` one recursion over the joint state; ``local`` and
    ``delivered`` lists of recursions, each giving some agents' columns (``*_agents``: which); ``readings`` each
    reading's information on the centralized recursion's state (the information-set delivered bound reads it)."""

    centralized: Recursion
    local: list[Recursion]
    local_agents: list[np.ndarray]
    delivered: list[Recursion] | None = None
    delivered_agents: list[np.ndarray] | None = None
    model_based: bool = False
    delivered_reason: str = ""
    # each episode its own problem (a recorded window, conditioned on its trajectory): run per episode, then the
    # mean of the episodes' bounds, instead of one recursion on averaged D-terms
    per_episode: bool = False
    readings: ReadingInformation | None = None


def position_traces(P: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """(K, N): tr of P[k] over each row of ``positions`` (N, 2) state indices."""
    positions = np.asarray(positions)
    return np.stack([P[:, i, i] + P[:, j, j] for i, j in positions], axis=-1)


def lag_augmented(P0: np.ndarray, F: np.ndarray | None, Q: np.ndarray | None, lags: int):
    """(P0_a, F_a, Q_a) of the state [x(k), x(k-1), ..., x(k-lags)]: F_a shifts the copies down, Q_a = diag(Q, 0).

    F and Q (K-1, n, n), or (K-1, E, n, n) per episode (``estimators.bounds.filtering_bound`` takes either)."""
    n = P0.shape[0]
    m = n * (lags + 1)
    P0a = np.kron(np.eye(lags + 1), P0)
    if F is None and Q is None:
        return P0a, None, None
    lead = np.broadcast_shapes(*[np.shape(a)[:-2] for a in (F, Q) if a is not None])  # (K-1,) or (K-1, E)

    def spread(a):  # (K-1, n, n) over a per-episode axis where the other has one
        return a[:, None] if a.ndim == 3 and len(lead) == 2 else a

    Fa = np.zeros((*lead, m, m))
    Fa[..., :n, :n] = np.eye(n) if F is None else spread(np.asarray(F))
    for d in range(lags):
        Fa[..., (d + 1) * n:(d + 2) * n, d * n:(d + 1) * n] = np.eye(n)
    Qa = np.zeros((*lead, m, m))
    if Q is not None:
        Qa[..., :n, :n] = spread(np.asarray(Q))
    return P0a, Fa, Qa


def delivered_recursion(P0, F, Q, sender_info: np.ndarray, arrival: np.ndarray, lags: int,
                        positions: np.ndarray) -> Recursion:
    """One episode's lag-augmented recursion of one receiver: ``sender_info`` (K, S, n, n) the information of
    sender s's reading of k, ``arrival`` (K, S) its first delay at this receiver (-1: never; its own readings 0),
    ``lags`` D the network's longest delay (longer ones are dropped: they arrive after... never, for the
    networks here). The reading of k arriving after d steps enters at step k + d on the copy x(k) = lag d."""
    K, S, n, _ = sender_info.shape
    P0a, Fa, Qa = lag_augmented(P0, F, Q, lags)
    m = n * (lags + 1)
    info = np.zeros((K, m, m))
    for d in range(lags + 1):
        weight = (arrival[:K - d] == d).astype(float)  # (K - d, S): readings of k arriving at k + d
        block = np.einsum("ks,ksij->kij", weight, sender_info[:K - d])
        info[d:, d * n:(d + 1) * n, d * n:(d + 1) * n] += block
    return Recursion(P0a, info, Fa, Qa, positions)


def centre_received(record, k: int, pairs, fixes, N: int):
    """``ukf_ccl``'s centre at step k: which of the step's range readings ``pairs`` [(m, n), ...] (in the order
    the backend sends them: row-major over the valid pairs, its broadcast slot j the j-th) and which fixes of
    ``fixes`` [i, ...] (slot N * N + i) reached agent 0; its own readings always. Returns (range flags, fix flags)."""
    calls = record.broadcasts[k]

    def reached(sender: int, slot: int) -> bool:
        return sender == CENTRE or (slot in calls and bool(calls[slot][sender, CENTRE]))

    return ([reached(m, j) for j, (m, _) in enumerate(pairs)], [reached(i, N * N + i) for i in fixes])


def with_delivered(problem: BoundProblem, core, record, message_kind: str | None = None, shape: tuple = (),
                   readings_bound=None) -> BoundProblem:
    """``problem`` with its delivered bound set by the backend's declared ``message_content``
    (``coloc_env.backends.base``): ``"nothing"``, the local bounds; ``"readings"``,
    ``readings_bound(arrival, lags)`` -> (recursions, their agents), ``arrival`` the record's first arrival
    step of each ``message_kind`` message (``shape``, -1 throughout when none was sent) and ``lags`` the
    network's longest delay, or ``readings_bound()`` where ``message_kind`` is None (a bound that reads the
    record itself: ``ukf_ccl``'s centre, from the broadcasts); ``"estimates"``, none here, with the reason
    (``pcrb`` sets the information-set bound, ``coloc_env.bounds.information_set``). A world without a
    ``readings_bound`` for the backend leaves its readings out, with the reason. Returns ``problem``."""
    backend = core.composition.backend
    content = backend.message_content
    if content == "nothing":
        problem.delivered, problem.delivered_agents = problem.local, problem.local_agents
    elif content == "readings" and readings_bound is not None:
        if message_kind is None:
            problem.delivered, problem.delivered_agents = readings_bound()
        else:
            arrival = record.first_arrival(message_kind)
            if arrival is None:
                arrival = np.full(shape, -1, dtype=np.int64)
            problem.delivered, problem.delivered_agents = readings_bound(arrival, core.network.max_delay())
    elif content == "readings":
        problem.delivered_reason = (f"no delivered bound of {backend.name}'s readings on the "
                                    f"{core.composition.world.name} world")
    else:
        problem.delivered_reason = (f"{backend.name}'s messages carry estimates: their delivered bound is the "
                                    "information-set bound (coloc_env.bounds.information_set), which pcrb computes "
                                    "from the record and the readings")
    return problem
