"""The relay kernel: ``Network.relay``'s chains resolved one at a time (``resolve_chains``), compiled by numba where it
is installed (``compiled_resolver``), the plain function otherwise (the same chains)."""

from __future__ import annotations

import functools

import numpy as np


def resolve_chains(order, usable, all_usable, loss, u, lossy, distance, base, holder, first, choice, chosen, copies,
                    limit, links, hops, size, code):  # pragma: no cover - compiled by numba (``compiled_resolver``)
    """``Network.relay``'s chains, one at a time: n chains from ``holder`` (n,) (``links[:, 0]``), the first hop to
    ``first`` where >= 0, then each holder's choice (``chosen``: ``choice[copies[c], holder]``, N + 1 = the nearest
    unreached) or the nearest unreached platform: the first of the holder's row of ``order`` (its platforms by
    distance) the chain has not reached. A hop fails, and the chain stops, with the first of the stop reasons
    1 (hop budget ``limit``), 2 (no platform named), 3 (already reached), 4 (not ``usable``), 5 (lost:
    ``u[c, hop] < loss``) that holds. Fills ``links``, ``hops`` (hop lengths), ``size`` and ``code`` in place;
    link arrays are (rows, N) with row ``base[c] + holder``. O(hops x the reached platforms nearer than the
    nearest unreached) per chain, not O(hops x N)."""
    n, N = len(holder), order.shape[1]
    reached = np.zeros(N, np.bool_)
    for c in range(n):
        reached[:] = False
        now = holder[c]
        reached[now] = True
        for hop in range(N - 1):
            if hop >= limit:
                code[c] = 1
                break
            row = base[c] + now
            nearest = now
            for k in range(N):
                if not reached[order[row, k]]:
                    nearest = order[row, k]
                    break
            target = nearest
            if chosen:
                target = choice[copies[c], now]
                if target == N + 1:
                    target = nearest
            if hop == 0 and first[c] >= 0:
                target = first[c]
            valid = 0 <= target < N and target != now
            safe = target if valid else 0
            failed = 0
            if lossy and u[c, hop] < loss[row, safe]:
                failed = 5
            if not all_usable and not usable[row, safe]:
                failed = 4
            if reached[safe]:
                failed = 3
            if not valid:
                failed = 2
            code[c] = failed
            if failed:
                break
            links[c, hop + 1] = target
            reached[target] = True
            hops[c, hop] = distance[row, target]
            size[c] += 1
            now = target


@functools.cache
def compiled_resolver():
    """``resolve_chains`` compiled by numba (cached on disk), or None where numba is not installed (the plain
    function then runs, the same chains)."""
    try:
        import numba
    except ImportError:  # pragma: no cover - numba is a dependency
        return None
    return numba.njit(cache=True, nogil=True)(resolve_chains)
