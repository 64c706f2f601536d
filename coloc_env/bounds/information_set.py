"""The information-set delivered bound: what the messages that reached a receiver could have carried.

A message that carries its sender's estimate carries at most the information of every reading that had
reached the sender when it sent (its own, and what its earlier received messages carried, recursively).
Receiver r's *delivered information set* at step k is the union of those readings over every message r
received up to k, each reading counted at the step it was measured; the delivered bound is the PCRB given
exactly that set (any function of the messages is a function of the readings in the set, so it bounds any
estimator that sees those messages). The conditions it is valid under (docs/bounds.md):

(a) each message is taken to carry everything its sender held when it sent (a union: nothing counted twice);
(b) the delivery pattern and the decisions are taken as given, as in the readings' delivered bound;
(c) a reading between two agents (a range) enters a receiver's set when a message carrying it arrives:
    a directed relay chain (``Network.relay`` with a first hop) carries the range between its first two
    platforms, a broadcast or packet from s to r the ranges between s and r of its step, a message to a
    centre the ranges its sender took; the agent that measured a range does not hold it alone (as
    ``ukf_dcl`` uses it: without the partner's location information a range moves no estimate);
(d) every agent's motion inputs are known to every receiver (the receiver's recursion runs on the joint
    state with every agent's motion, as the centralized one does): valid, and looser than a receiver that
    knew only its own.

``held(readings, record, N, content)`` computes the (N, R) step at which each reading entered each agent's
set (``content`` ``"estimates"``: the sender's whole set; ``"readings"``: only the sender's own readings of
the stamped step, plus the ranges above: today's delivered bound of reading messages, which this
reproduces). ``receiver_information`` turns one receiver's row into the (K, n (L + 1), n (L + 1))
information of the lag-augmented state [x(k), ..., x(k - L)] (``problem.lag_augmented``): a reading of
step j that entered at step a enters the copy of lag a - j at step a. A relayed estimate carries its
sender's whole history, so a lag is not bounded by the network's ``max_delay()``; lags above the cap L are
credited at lag L (at step j + L: earlier than it arrived, so the bound stays valid, and exact where no
arrival exceeds L). Cost per receiver and episode: the sets, O(M R) for M messages and R readings; the
recursion, O(K (n (L + 1))^3) (``coloc bench``'s bound row).
"""

from __future__ import annotations

import numpy as np

from coloc_env.bounds.problem import ReadingInformation, position_traces
from estimators.bounds import fuse_information, predict_covariance

NEVER = np.iinfo(np.int64).max // 4  # a reading that never entered an agent's set


def held(readings: ReadingInformation, record, num_agents: int, content: str = "estimates") -> np.ndarray:
    """(N, R) int64: the step at which reading rho entered agent n's set (``NEVER``: not by the horizon; a
    delivery that arrives after the horizon is counted at its arrival step, >= K). Module docstring."""
    if content not in ("estimates", "readings"):
        raise ValueError(f"content must be 'estimates' or 'readings', got {content!r}")
    sets = _Sets(readings, int(num_agents), content == "estimates")
    for k in range(int(record.steps)):
        sets.begin(k)
        for event in record.deliveries[k]:
            sets.deliver(event)
    return sets.out


class _Sets:
    """The agents' sets, step by step: ``begin(k)`` adds the own readings of k, ``deliver`` one recorded call."""

    NONE = np.zeros(0, int)

    def __init__(self, readings: ReadingInformation, num_agents: int, estimates: bool):
        self.step, self.owner, self.partner = readings.arrays()
        self.out = np.full((num_agents, len(self.step)), NEVER, dtype=np.int64)
        self.estimates = estimates
        self.own = self.partner < 0

    def begin(self, k: int) -> None:
        self.k = k
        rows = np.flatnonzero(self.step == k)
        mine = rows[self.own[rows]]
        self.out[self.owner[mine], mine] = np.minimum(self.out[self.owner[mine], mine], k)
        self.own_rows = {int(a): mine[self.owner[mine] == a] for a in np.unique(self.owner[mine])}
        between: dict[tuple[int, int], list] = {}
        for r in rows[~self.own[rows]]:
            between.setdefault((int(self.owner[r]), int(self.partner[r])), []).append(r)
        self.between = {key: np.asarray(value, int) for key, value in between.items()}

    def _ranges(self, a: int, b: int) -> np.ndarray:
        """The ranges of this step between a and b (either took them)."""
        return np.concatenate([self.between.get((a, b), self.NONE), self.between.get((b, a), self.NONE)])

    def _carry(self, source: np.ndarray, sender: int, receiver: int, arrival: int, extra: np.ndarray) -> None:
        """A message sender -> receiver sent at this step, arriving at ``arrival``: the sender's set in ``source``
        (estimates) or its own readings of the step (readings), and the ranges ``extra``."""
        out = self.out
        if self.estimates:
            take = source[sender] <= self.k
            out[receiver] = np.where(take, np.minimum(out[receiver], arrival), out[receiver])
        else:
            sent = self.own_rows.get(sender, self.NONE)
            out[receiver, sent] = np.minimum(out[receiver, sent], arrival)
        if len(extra):
            out[receiver, extra] = np.minimum(out[receiver, extra], arrival)

    def deliver(self, event: dict) -> None:
        call, k = event["call"], self.k
        if call in ("broadcast", "packets"):
            # one round: every sender sends what it held before the round (a snapshot)
            delay = np.where(event["delivered"], 0, -1) if call == "broadcast" else event["delay"]
            snapshot = self.out.copy()
            for t, s in zip(*np.nonzero(delay >= 0), strict=True):
                self._carry(snapshot, int(t), int(s), k + int(delay[t, s]), self._ranges(int(t), int(s)))
        elif call == "messages_to":
            snapshot = self.out.copy()
            receiver = int(event["receiver"])
            for sender in np.unique(event["senders"][event["delivered"]]):
                taken = [v for (a, _), v in self.between.items() if a == sender]
                self._carry(snapshot, int(sender), receiver, k, np.concatenate(taken) if taken else self.NONE)
        elif call in ("relay", "relay_each"):
            # hop by hop: each holder passes on what it holds, with the range of a chain sent to a partner
            for chain, length, first in zip(event["chain"], event["length"], event["first"], strict=True):
                directed = first >= 0 and length >= 2
                extra = self.between.get((int(chain[0]), int(chain[1])), self.NONE) if directed else self.NONE
                for h in range(int(length) - 1):
                    self._carry(self.out, int(chain[h]), int(chain[h + 1]), k, extra)
        # node_packets: world nodes' readings, delivered as readings (their bound model's own account)


def receiver_entries(readings: ReadingInformation, arrival: np.ndarray, steps: int, lag_cap: int
                     ) -> tuple[dict, int]:
    """({(a, j): information (n, n)}, capped): one receiver's set (``arrival`` (R,) its row of ``held``) as the
    information on x(j) of the readings of step j that entered at step a, summed; a reading that entered more
    than ``lag_cap`` steps after it was taken is credited at a = j + lag_cap (``capped`` counts them)."""
    n, K = readings.size, int(steps)
    step = np.asarray(readings.step, int)
    use = np.flatnonzero(arrival < K)
    if not len(use):
        return {}, 0
    lag = arrival[use] - step[use]
    capped = int(np.sum(lag > lag_cap))
    enter = step[use] + np.minimum(lag, lag_cap)
    keys, inverse = np.unique(enter * K + step[use], return_inverse=True)
    total = np.zeros((len(keys), n, n))
    flat = total.reshape(-1)
    sizes = np.array([len(readings.index[r]) for r in use], int)
    for p in np.unique(sizes):
        group = np.flatnonzero(sizes == p)
        idx = np.stack([readings.index[r] for r in use[group]])  # (G, p)
        blocks = np.stack([readings.block[r] for r in use[group]])  # (G, p, p)
        where = inverse[group][:, None, None] * n * n + idx[:, :, None] * n + idx[:, None, :]
        np.add.at(flat, where.reshape(-1), blocks.reshape(-1))
    return {(int(key // K), int(key % K)): block for key, block in zip(keys, total, strict=True)}, capped


class SetRecursion:
    """The bound of one receiver given its set: P(k) the covariance-form filtering bound of x(k) given the
    readings of steps <= k that entered the set by k (``entries``: {(a, j): information on x(j) entering at a}).

    Each step k adds what entered at k to the steps it is about, then runs the filtering recursion again from
    the earliest step that changed: P(i) = (F P(i-1) F^T + Q)^-1 + I(i))^-1 for i = j..k, I(i) the information
    on x(i) that has entered by k (``estimators.bounds.predict_covariance`` / ``fuse_information``: exact for a
    singular Q or P0). This is the lag-augmented state's recursion without the augmentation (the forward pass
    of the block-tridiagonal information matrix of x(0..k)): O(K (L + 1) n^3) per receiver, L the longest lag
    credited, instead of O(K (n (L + 1))^3). F and Q common to the episodes (None: identity / none)."""

    def __init__(self, P0, F, Q, entries: dict, steps: int, positions: np.ndarray):
        for name, a in (("F", F), ("Q", Q)):
            if a is not None and np.ndim(a) != 3:
                raise ValueError(f"the information-set bound needs {name} common to the episodes, (K-1, n, n); got "
                                 f"shape {np.shape(a)}")
        self.P0, self.F, self.Q = np.asarray(P0, float), F, Q
        self.entries, self.steps, self.positions = entries, int(steps), np.asarray(positions)

    def run(self, regularization: float = 0.0) -> np.ndarray:
        """(K, len(positions)) position traces (``regularization`` unused: the covariance form needs none)."""
        K, n = self.steps, self.P0.shape[0]
        arriving: dict[int, list] = {}
        for (a, j), block in self.entries.items():
            arriving.setdefault(a, []).append((j, block))
        info = np.zeros((K, n, n))
        P = np.zeros((K, n, n))
        out = np.zeros((K, n, n))
        eye = np.eye(n)
        for k in range(K):
            start = k
            for j, block in arriving.get(k, []):
                info[j] += block
                start = min(start, j)
            for i in range(start, k + 1):
                if i == 0:
                    prior = self.P0
                else:
                    F = eye if self.F is None else self.F[i - 1]
                    prior = predict_covariance(P[i - 1], F, 0.0 * eye if self.Q is None else self.Q[i - 1])
                P[i] = fuse_information(prior, info[i])
            out[k] = P[k]
        return position_traces(out, self.positions)
