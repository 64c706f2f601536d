"""The compiled kernels of ``estimators.dnbp``: its numpy arithmetic one row at a time (numba).

``estimators.dnbp`` is the reference: Algorithms 1-4 written in numpy over the receivers of a batch. Where
numba is installed, its hot loops run as the kernels here instead (``compiled=True``, the default):

| kernel                                  | the numpy form it follows                                        |
|-----------------------------------------|------------------------------------------------------------------|
| ``mixture_rows``                        | ``mixture_logpdf``'s fast kernel (``exact=False``)               |
| ``velocity_rows``                       | ``_velocity_index`` (v given p, by inverse CDF)                  |
| ``importance_rows``                     | ``_importance_log_weights`` (log pi - log q)                     |
| ``belief_weights_source``               | ``belief_update``'s proposals and importance weights (fused)     |
| ``belief_resample_source``              | ``belief_update``'s resampling and regularization (fused)        |
| ``message_rows_source``                 | ``sample_messages``' centres and bandwidths (Algorithm 1)        |
| ``mixture_rows_truncated_source``       | the truncated mixture kernel (``DnbpModel.kernel="truncated"``)  |

Each reproduces the numpy path's arithmetic in its order (the same exponents, the same flat-offset
comparisons of ``_categorical``, numpy's pairwise sum by ``numpy_sum``), so its draws are the numpy path's and
its floats equal them up to rounding (tests/estimators/test_dnbp_fast.py, test_dnbp_truncated.py). The sources
are plain Python (``prange`` is ``range`` here); ``_compile`` compiles each from a copy whose globals name the
compiled helpers, on first use, and caches them on disk. ``split_rows`` runs slices of a kernel's receivers on
Python threads.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Callable

import numpy as np

from estimators.compiled import in_namespace

prange = range  # numba.prange in the compiled copies (the kernels' loop over rows)
# Exponents below this are clipped before exp: libm's exp is ~10x slower on results that underflow, and a
# term e^-600 relative to the largest one is below float64 resolution of any sum it enters.
EXP_FLOOR = -600.0


# Terms more than this below a row's largest exponent are left out of the fast kernel sums: K of them add less
# than K e^-50 ~ 2e-20 (relative), far below float64 resolution of the sum.
NEGLIGIBLE = 50.0
# Above this many kernel entries per call the compiled kernels run their rows on all cores (threads): high enough
# that the correction weights' kernel (10^5-10^6 entries per step at M = 100) stays serial, where threads cost
# more than they give on a busy 2-core machine (docs/performance.md, "dNBP kernels").
PARALLEL_ELEMENTS = 1 << 21

# --- the row kernels: one row (a point of a mixture, a receiver, a proposal) per iteration ---------------------
# Each row is computed by one thread from its own inputs only, so the results do not depend on the batch, the
# chunking or the number of threads.
def mixture_rows(scaled, point_term, centres, centre_term, log_norm, out):  # pragma: no cover - compiled by numba
    """The fast kernel of ``mixture_logpdf``, one row (point of a mixture) per iteration."""
    floor, negligible = EXP_FLOOR, NEGLIGIBLE
    # out[j, p] = log sum_k exp(clip(scaled[j, p] . c[j, k] + point_term[j, p] + centre_term[j, k])) - log_norm[j]
    J, P = scaled.shape[0], scaled.shape[1]
    K = centres.shape[1]
    threshold = 2.0 * K * math.exp(floor)
    for row in prange(J * P):
        j = row // P
        p = row - j * P
        s0, s1, pt = scaled[j, p, 0], scaled[j, p, 1], point_term[j, p]
        top = floor
        for k in range(K):
            a = (s0 * centres[j, k, 0] + s1 * centres[j, k, 1] + pt) + centre_term[j, k]
            if a > top:
                top = a
        top = min(top, 0.0)
        if top <= floor:  # every term at the floor: the sum K e^floor is not above the threshold
            out[j, p] = -np.inf
            continue
        # every term counts where the row is near the floor (its sum is compared with 2 K e^floor there)
        cut = top - negligible if top > floor + negligible else -np.inf
        total = 0.0
        for k in range(K):
            a = (s0 * centres[j, k, 0] + s1 * centres[j, k, 1] + pt) + centre_term[j, k]
            if a > cut:
                total += math.exp(min(max(a, floor), 0.0))
        out[j, p] = (math.log(total) if total > threshold else -np.inf) - log_norm[j]

def velocity_rows(positions, prior, denominator, uniform, u, out):  # pragma: no cover - compiled by numba
    """``_velocity_index``'s draws, one receiver per iteration (``velocity_row``)."""
    # velocity_row per receiver r (the flat-offset comparison of _categorical, row index r * M + i)
    for r in prange(positions.shape[0]):
        velocity_row(positions[r], prior[r], denominator[r], uniform[r], u[r], r, out[r])

def importance_rows(log_rho, log_m, present, valid, log_count, out):  # pragma: no cover - compiled by numba
    """``_importance_log_weights``' log pi - log q, one proposal per iteration."""
    floor = EXP_FLOOR
    # log pi - log q per proposal, the arithmetic of _importance_log_weights (sums over slots in slot order)
    R, S, C = log_m.shape
    for row in prange(R * C):
        r = row // C
        c = row - r * C
        target = 0.0
        top = log_rho[r, c]
        for s in range(S):
            if present[r, s]:
                target += log_m[r, s, c]
            if log_m[r, s, c] > top:
                top = log_m[r, s, c]
        target += log_rho[r, c]
        if not np.isfinite(top):
            top = 0.0
        total = 0.0
        for s in range(S + 1):
            a = log_rho[r, c] if s == 0 else log_m[r, s - 1, c]
            if a != -np.inf:
                total += math.exp(max(a - top, floor))
        log_q = (math.log(total) if total > 0.0 else -np.inf) + top - log_count[r]
        ok = valid[r, c] and np.isfinite(log_q) and np.isfinite(target)
        out[r, c] = target - log_q if ok else -np.inf


def row_kernel(name: str, elements: int):
    """The compiled row kernel ``name`` (``"mixture_rows"``, ``"velocity_rows"``, ``"importance_rows"``): its
    threaded form from ``PARALLEL_ELEMENTS`` kernel entries on, the serial one below; None without numba."""
    kernels = compiled_kernels()
    if kernels is None:
        return None
    serial, parallel = kernels[name]
    return parallel if elements >= PARALLEL_ELEMENTS else serial


# --- the fused belief update (compiled): Algorithm 2 one receiver per iteration ----------------------------------
# Sources compiled by numba in _compile(); each reproduces the numpy path's arithmetic in its
# order (the same exponents, the same flat-offset comparisons of _categorical, numpy's pairwise sum of the
# weights), so its draws are the numpy path's and its floats equal them up to rounding.


def block_sum(values, lo, n):  # pragma: no cover - compiled by numba
    """values[lo:lo + n], n <= 128, summed as numpy's pairwise summation sums a block (sequential below 8,
    else eight running sums combined as ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7)), then the rest)."""
    if n < 8:
        total = 0.0
        for i in range(lo, lo + n):
            total += values[i]
        return total
    r0, r1, r2, r3 = values[lo], values[lo + 1], values[lo + 2], values[lo + 3]
    r4, r5, r6, r7 = values[lo + 4], values[lo + 5], values[lo + 6], values[lo + 7]
    i = lo + 8
    end = lo + n - n % 8
    while i < end:
        r0 += values[i]
        r1 += values[i + 1]
        r2 += values[i + 2]
        r3 += values[i + 3]
        r4 += values[i + 4]
        r5 += values[i + 5]
        r6 += values[i + 6]
        r7 += values[i + 7]
        i += 8
    total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < lo + n:
        total += values[i]
        i += 1
    return total


def numpy_sum(values, n):  # pragma: no cover - compiled by numba
    """values[:n] summed in the order of numpy's pairwise summation: blocks of at most 128 (block_sum), a
    longer range split in halves at a multiple of 8, left + right; by an explicit stack (numba's disk cache
    does not hold recursive functions)."""
    if n <= 128:
        return block_sum(values, 0, n)
    depth = 64
    los, lens, stage = np.empty(depth, np.int64), np.empty(depth, np.int64), np.empty(depth, np.int64)
    sums = np.empty(depth)
    top, done = 0, 0
    los[0], lens[0], stage[0] = 0, n, 0
    while top >= 0:
        lo, m = los[top], lens[top]
        if m <= 128:
            sums[done] = block_sum(values, lo, m)
            done += 1
            top -= 1
        elif stage[top] == 0:
            stage[top] = 1
            half = m // 2
            half -= half % 8
            # the right half below the left one on the stack: the left is summed first
            los[top + 1], lens[top + 1], stage[top + 1] = lo + half, m - half, 0
            los[top + 2], lens[top + 2], stage[top + 2] = lo, half, 0
            top += 2
        else:
            done -= 1
            sums[done - 1] = sums[done - 1] + sums[done]
            top -= 1
    return sums[0]


def mixture_point(x, y, inv, cx, cy, centre_term, log_norm, buffer, identical):  # pragma: no cover - compiled
    """The fast kernel of ``mixture_logpdf`` at one point (x, y) of one mixture, ``mixture_rows``' arithmetic
    (the exponent s . c_k + point term + centre term, centre_term[k] = log w_k - 0.5 ||c_k||^2 inv) on the
    centres' coordinates cx, cy (K,): the exponents are formed once into ``buffer``, those above the cut packed
    to its front without branches, and only they reach exp (in the same order). ``identical``: every component
    is the same (a GPS fix): its one exponent and exp, added K times (the same sum, bit for bit)."""
    floor, negligible = EXP_FLOOR, NEGLIGIBLE
    K = cx.shape[0]
    s0, s1 = x * inv, y * inv
    pt = -0.5 * (x * x + y * y) * inv
    if identical:
        a = (s0 * cx[0] + s1 * cy[0] + pt) + centre_term[0]
        if min(max(floor, a), 0.0) <= floor:
            return -np.inf
        term = math.exp(min(max(a, floor), 0.0))
        total = 0.0
        for _ in range(K):
            total += term
        return (math.log(total) if total > 2.0 * K * math.exp(floor) else -np.inf) - log_norm
    top = floor
    for k in range(K):
        a = (s0 * cx[k] + s1 * cy[k] + pt) + centre_term[k]
        buffer[k] = a
        top = max(top, a)
    top = min(top, 0.0)
    if top <= floor:
        return -np.inf
    cut = top - negligible if top > floor + negligible else -np.inf
    n = 0
    for k in range(K):
        a = buffer[k]
        buffer[n] = a
        n += a > cut
    total = 0.0
    for k in range(n):
        total += math.exp(min(max(buffer[k], floor), 0.0))
    return (math.log(total) if total > 2.0 * K * math.exp(floor) else -np.inf) - log_norm


def count_at_most(values, offset, target, lo, n):  # pragma: no cover - compiled by numba
    """How many of values[lo:lo + n] (non-decreasing) have values + offset <= target: the count numpy's
    searchsorted(side="right") takes on the offset rows of _categorical, by bisection (the sums are
    non-decreasing too)."""
    first, last = lo, lo + n
    while first < last:
        middle = (first + last) // 2
        if values[middle] + offset <= target:
            first = middle + 1
        else:
            last = middle
    return first - lo


def logaddexp(x, y):  # pragma: no cover - compiled by numba
    """numpy's logaddexp, in its order."""
    if x == y:
        return x + math.log(2.0)
    d = x - y
    if d > 0:
        return x + math.log1p(math.exp(-d))
    if d <= 0:
        return y + math.log1p(math.exp(d))
    return d


# --- the truncated kernel (DnbpModel.kernel = "truncated") -------------------------------------------------------
def exp_small(x):  # pragma: no cover - compiled by numba (fastmath)
    """exp(x) for x in [-50, 0] as (Taylor polynomial of degree 10 at x / 256)^(2^8): branch-free, so the loops
    that call it vectorize; relative error below 1e-12 on [-50, 0] (the truncated kernel's exponents)."""
    y = x * 0.00390625
    p = 1.0 + y * (1.0 + y * (0.5 + y * (1.0 / 6.0 + y * (1.0 / 24.0 + y * (1.0 / 120.0 + y * (
        1.0 / 720.0 + y * (1.0 / 5040.0 + y * (1.0 / 40320.0 + y * (1.0 / 362880.0 + y / 3628800.0)))))))))
    for _ in range(8):
        p = p * p
    return p


def mixture_point_truncated(x, y, inv, cx, cy, centre_term, log_norm, buffer, limit
                             ):  # pragma: no cover - compiled by numba (fastmath)
    """The truncated kernel at one point: the exponents of ``mixture_point``, then every term more than
    ``limit`` (= r^2 / 2) below the largest left out (each is < e^(-r^2/2) of it: a component more than r
    bandwidths farther than the nearest one, for equal weights) and the others summed relative to the largest
    by ``exp_small``, in any order (fastmath: the loop vectorizes)."""
    K = cx.shape[0]
    s0, s1 = x * inv, y * inv
    pt = -0.5 * (x * x + y * y) * inv
    for k in range(K):  # the exponents, then their largest, as two loops: both vectorize (one did not)
        buffer[k] = (s0 * cx[k] + s1 * cy[k] + pt) + centre_term[k]
    top = -np.inf
    for k in range(K):
        top = max(top, buffer[k])
    if top <= EXP_FLOOR:  # every component ~35 bandwidths away or more: density 0, as in the exact kernel
        return -np.inf
    total = 0.0
    for k in range(K):
        d = buffer[k] - top
        total += exp_small(d) if d >= -limit else 0.0
    return math.log(total) + top - log_norm


def mixture_rows_truncated_source(points, cx, cy, centre_term, inv, log_norm, limit, out
                                   ):  # pragma: no cover - compiled by numba
    """The truncated kernel (mixture_point_truncated) of J mixtures at their own points (J, P, 2): centres'
    coordinates cx, cy (J, K), centre terms log w_k - 0.5 ||c_k||^2 inv (J, K), inv = 1 / h^2 and log(2 pi h^2)
    (J,) -> out (J, P)."""
    J, P = points.shape[0], points.shape[1]
    for j in prange(J):
        buffer = np.empty(cx.shape[1])
        for p in range(P):
            out[j, p] = mixture_point_truncated(points[j, p, 0], points[j, p, 1], inv[j], cx[j], cy[j],
                                                 centre_term[j], log_norm[j], buffer, limit)


def velocity_row_truncated(positions, prior, denominator, uniform, u, limit, out
                            ):  # pragma: no cover - compiled by numba (fastmath)
    """The truncated kernel's v | p draw for the new particles of one receiver: j ~ softmax_j(-||p_i - x_j||^2 /
    denominator) with the weights below e^-limit of the largest set to 0 (the exact kernel: e^-50), by inverse
    CDF with u[i] (bisection of the running sum); a uniform pick where the prior is the cold box."""
    M, Mp = positions.shape[0], prior.shape[0]
    if uniform:
        for i in range(M):
            out[i] = min(int(u[i] * Mp), Mp - 1)
        return
    px, py = np.empty(Mp), np.empty(Mp)
    for j in range(Mp):
        px[j], py[j] = prior[j, 0], prior[j, 1]
    scale = 1.0 / denominator
    w = np.empty(Mp)
    for i in range(M):
        x, y = positions[i, 0], positions[i, 1]
        for j in range(Mp):
            dx, dy = x - px[j], y - py[j]
            w[j] = -(dx * dx + dy * dy) * scale
        top = -np.inf
        for j in range(Mp):
            top = max(top, w[j])
        for j in range(Mp):
            d = w[j] - top
            w[j] = exp_small(d) if d >= -limit else 0.0
        total = 0.0
        for j in range(Mp):
            total += w[j]
            w[j] = total
        target = u[i] * total
        first, last = 0, Mp - 1
        while first < last:  # the first running sum above the target
            middle = (first + last) // 2
            if w[middle] > target:
                last = middle
            else:
                first = middle + 1
        out[i] = first


def belief_weights_source(prior, prior_bandwidth, prior_uniform, centres, log_weights, bandwidth, present, pick,
                           box, noise, oversampling, eps, box_lo, box_hi, cold_lo, cold_hi, radius, row0, proposals,
                           log_w):  # pragma: no cover - compiled by numba
    """Algorithm 2's proposals and fast importance log-weights, one receiver r per iteration (``row0`` + r its row
    in the whole update, for the flat offsets: a slice of the receivers computes what the whole call computes).

    proposals (R, C, 2) and log_w (R, C) are filled as ``belief_update``'s numpy path fills them: every
    column's proposal (the invalid ones too, they are drawable by the clipped resampling index), the weights
    log pi - log q of the valid ones (-inf elsewhere, as in _importance_log_weights).
    """
    floor = EXP_FLOOR
    R, M = prior.shape[0], prior.shape[1]
    S, K = centres.shape[1], centres.shape[2]
    C = proposals.shape[1]
    log_m_weight = -math.log(M)
    log_cold = -2.0 * math.log(cold_hi - cold_lo)
    log_eps = math.log(eps) if eps > 0.0 else -np.inf
    log_box = log_eps - 2.0 * math.log(box_hi - box_lo)
    log_keep = math.log1p(-eps)
    for r in prange(R):
        count = 0
        for s in range(S):
            if present[r, s]:
                count += 1
        per = (oversampling * M + count) // (count + 1)  # ceil(k_is M / (K+1))
        total = per * (count + 1)
        slots = np.empty(count + 1, np.int64)
        n = 1
        for s in range(S):
            if present[r, s]:
                slots[n] = s
                n += 1
        # the present messages' component CDFs (_normalized_cdf) and kernel terms; the prior's KDE terms
        cdf = np.empty((S, K))
        terms, xs, ys = np.empty((S, K)), np.empty((S, K)), np.empty((S, K))
        inv_m, norm_m = np.empty(S), np.empty(S)
        identical = np.zeros(S, np.bool_)
        for s in range(S):
            if not present[r, s]:
                continue
            top = -np.inf
            for k in range(K):
                if log_weights[r, s, k] > top:
                    top = log_weights[r, s, k]
            ok = np.isfinite(top)
            shift = top if ok else 0.0
            run = 0.0
            for k in range(K):
                lw = log_weights[r, s, k]
                if ok:
                    w = math.exp(max(lw - shift, floor)) if lw != -np.inf else 0.0
                else:
                    w = 1.0
                run += w
                cdf[s, k] = run
            last = cdf[s, K - 1]
            for k in range(K - 1):
                cdf[s, k] /= last
            cdf[s, K - 1] = 1.0
            b = bandwidth[r, s]
            inv = 1.0 / (b * b)
            inv_m[s], norm_m[s] = inv, math.log(2.0 * np.pi * (b * b))
            for k in range(K):
                cx, cy = centres[r, s, k, 0], centres[r, s, k, 1]
                xs[s, k], ys[s, k] = cx, cy
                terms[s, k] = log_weights[r, s, k] - 0.5 * (cx * cx + cy * cy) * inv
            same = True
            for k in range(1, K):
                same = same and xs[s, k] == xs[s, 0] and ys[s, k] == ys[s, 0] and terms[s, k] == terms[s, 0]
            identical[s] = same
        h = prior_bandwidth[r]
        inv_rho = 1.0 / (h * h)
        norm_rho = math.log(2.0 * np.pi * (h * h))
        rho_terms, px, py = np.empty(M), np.empty(M), np.empty(M)
        for k in range(M):
            cx, cy = prior[r, k, 0], prior[r, k, 1]
            px[k], py[k] = cx, cy
            rho_terms[k] = log_m_weight - 0.5 * (cx * cx + cy * cy) * inv_rho
        buffer = np.empty(max(M, K))
        log_count = math.log(count + 1.0)
        truncated = radius > 0.0
        limit = 0.5 * radius * radius
        log_m = np.empty(S)
        # truncated: a proposal whose log-weight is certainly below the best so far by more than ``prune`` is left
        # out (-inf) before its remaining messages are evaluated; a mixture's density is at most its peak
        # sum_k w_k / (2 pi h^2) (``upper``), and q >= (K+1)^-1 times any evaluated term
        upper = np.zeros(S)
        upper_total, best, prune = 0.0, -np.inf, limit + math.log(C)
        if truncated:
            for s in range(S):
                if present[r, s]:
                    peak = -np.inf
                    for k in range(K):
                        peak = max(peak, log_weights[r, s, k])
                    mass = 0.0
                    for k in range(K):
                        mass += math.exp(log_weights[r, s, k] - peak)
                    upper[s] = peak + math.log(mass) - norm_m[s]
                    upper_total += upper[s]
        for j in range(C):
            rank = min(j // per, count)
            if rank == 0:
                if prior_uniform[r]:
                    x = cold_lo + (cold_hi - cold_lo) * box[r, j, 1]
                    y = cold_lo + (cold_hi - cold_lo) * box[r, j, 2]
                elif box[r, j, 0] < eps:
                    x = box_lo + (box_hi - box_lo) * box[r, j, 1]
                    y = box_lo + (box_hi - box_lo) * box[r, j, 2]
                else:
                    i = min(int(pick[r, j] * M), M - 1)
                    x = prior[r, i, 0] + h * noise[r, j, 0]
                    y = prior[r, i, 1] + h * noise[r, j, 1]
            else:
                s = slots[rank]
                offset = float((row0 + r) * S + s)  # the flat-offset comparison of the numpy path's searchsorted
                target = offset + pick[r, j]
                comp = min(count_at_most(cdf[s], offset, target, 0, K), K - 1)
                x = centres[r, s, comp, 0] + bandwidth[r, s] * noise[r, j, 0]
                y = centres[r, s, comp, 1] + bandwidth[r, s] * noise[r, j, 1]
            proposals[r, j, 0] = x
            proposals[r, j, 1] = y
            if j >= total:
                log_w[r, j] = -np.inf
                continue
            # log rho (prior_logpdf)
            if prior_uniform[r]:
                inside = cold_lo <= x <= cold_hi and cold_lo <= y <= cold_hi
                log_rho = log_cold if inside else -np.inf
            else:
                if truncated:
                    kde = mixture_point_truncated(x, y, inv_rho, px, py, rho_terms, norm_rho, buffer, limit)
                else:
                    kde = mixture_point(x, y, inv_rho, px, py, rho_terms, norm_rho, buffer, False)
                inside = box_lo <= x <= box_hi and box_lo <= y <= box_hi
                log_rho = logaddexp(log_keep + kde, log_box if inside else -np.inf)
            # log m_s at the proposal, then the combination of importance_rows
            target = 0.0
            top = log_rho
            partial, rest, pruned = log_rho, upper_total, False
            for s in range(S):
                if present[r, s]:
                    if truncated:
                        if partial == -np.inf or partial + rest - top + log_count < best - prune:
                            pruned = True  # pi = 0, or the weight is certainly negligible
                            break
                        if identical[s]:  # a GPS fix: K equal terms, their sum K e^a (the exact kernel adds K times)
                            a = (x * inv_m[s] * xs[s, 0] + y * inv_m[s] * ys[s, 0] - 0.5 * (x * x + y * y) * inv_m[s]
                                 ) + terms[s, 0]
                            value = a + math.log(K) - norm_m[s] if a > EXP_FLOOR else -np.inf
                        else:
                            value = mixture_point_truncated(x, y, inv_m[s], xs[s], ys[s], terms[s], norm_m[s],
                                                             buffer, limit)
                        partial += value
                        rest -= upper[s]
                    else:
                        value = mixture_point(x, y, inv_m[s], xs[s], ys[s], terms[s], norm_m[s], buffer,
                                               identical[s])
                    target += value
                else:
                    value = -np.inf
                log_m[s] = value
                if value > top:
                    top = value
            if pruned:
                log_w[r, j] = -np.inf
                continue
            target += log_rho
            if not np.isfinite(top):
                top = 0.0
            q = math.exp(max(log_rho - top, floor)) if log_rho != -np.inf else 0.0
            for s in range(S):
                if log_m[s] != -np.inf:
                    q += math.exp(max(log_m[s] - top, floor))
            log_q = (math.log(q) if q > 0.0 else -np.inf) + top - log_count
            fine = np.isfinite(log_q) and np.isfinite(target)
            log_w[r, j] = target - log_q if fine else -np.inf
            if truncated and log_w[r, j] > best:
                best = log_w[r, j]


def velocity_row(positions, prior, denominator, uniform, u, r, out):  # pragma: no cover - compiled by numba
    """``velocity_rows`` for the new particles of one receiver r (flat row offsets r * M + i)."""
    M, Mp = positions.shape[0], prior.shape[0]
    negligible = NEGLIGIBLE
    w = np.empty(Mp)
    for i in range(M):
        top = -np.inf
        for j in range(Mp):
            if uniform:
                w[j] = 0.0
            else:
                dx = positions[i, 0] - prior[j, 0]
                dy = positions[i, 1] - prior[j, 1]
                w[j] = -(dx * dx + dy * dy) / denominator
            if w[j] > top:
                top = w[j]
        ok = np.isfinite(top)
        total = 0.0
        for j in range(Mp):
            if ok:
                value = math.exp(w[j] - top) if w[j] - top > -negligible else 0.0
            else:
                value = 1.0
            total += value
            w[j] = total
        offset = float(r * M + i)
        target = u[i] + offset
        first, last = 0, Mp  # bisection of the CDF w[j] / total (1 at the end), non-decreasing
        while first < last:
            middle = (first + last) // 2
            c = 1.0 if middle == Mp - 1 else w[middle] / total
            if c + offset <= target:
                first = middle + 1
            else:
                last = middle
        out[i] = min(first, Mp - 1)


def belief_resample_source(prior, prior_bandwidth, prior_uniform, proposals, log_w, ok, resample, jitter, velocity,
                            radius, row0, out):  # pragma: no cover - compiled by numba
    """Algorithm 2's normalization, systematic resampling, jitter and velocity completion, one receiver per
    iteration (the numpy path's order: pairwise weight sum, sequential CDF, flat row offsets r of _categorical)."""
    R, d = prior.shape[0], prior.shape[2]
    C = proposals.shape[1]
    M = jitter.shape[1]
    for r in prange(R):
        if not ok[r]:  # every weight vanished: the belief stays the prior
            for i in range(M):
                for e in range(d):
                    out[r, i, e] = prior[r, i, e]
            continue
        weights = np.empty(C)
        top = -np.inf
        for j in range(C):
            if log_w[r, j] > top:
                top = log_w[r, j]
        for j in range(C):
            weights[j] = math.exp(log_w[r, j] - top)
        norm = numpy_sum(weights, C)
        for j in range(C):
            weights[j] /= norm
        cdf = np.empty(C)
        run = 0.0
        for j in range(C):
            run += weights[j]
            cdf[j] = run
        last = cdf[C - 1]
        for j in range(C - 1):
            cdf[j] /= last
        cdf[C - 1] = 1.0
        # h_rot of the weighted proposals (rule_of_thumb_bandwidth)
        mx, my, ss = 0.0, 0.0, 0.0
        for j in range(C):
            mx += weights[j] * proposals[r, j, 0]
            my += weights[j] * proposals[r, j, 1]
            ss += weights[j] * weights[j]
        var = 0.0
        for j in range(C):
            dx = proposals[r, j, 0] - mx
            dy = proposals[r, j, 1] - my
            var += weights[j] * (dx * dx) + weights[j] * (dy * dy)
        var /= 2.0
        h_rot = math.sqrt(max(var, 0.0)) * (1.0 / ss) ** (-1.0 / 6.0)
        positions = np.empty((M, 2))
        offset = float(row0 + r)
        idx = 0  # the targets do not decrease with i: the count only grows (a merge of the two sorted lists)
        for i in range(M):
            target = (resample[r] + i) / M + offset
            while idx < C and cdf[idx] + offset <= target:
                idx += 1
            pick = min(idx, C - 1)
            positions[i, 0] = proposals[r, pick, 0] + h_rot * jitter[r, i, 0]
            positions[i, 1] = proposals[r, pick, 1] + h_rot * jitter[r, i, 1]
        index = np.empty(M, np.int64)
        if radius > 0.0:
            velocity_row_truncated(positions, prior[r], 2.0 * (prior_bandwidth[r] * prior_bandwidth[r]),
                                    prior_uniform[r], velocity[r], 0.5 * radius * radius, index)
        else:
            velocity_row(positions, prior[r], 2.0 * (prior_bandwidth[r] * prior_bandwidth[r]), prior_uniform[r],
                          velocity[r], row0 + r, index)
        for i in range(M):
            out[r, i, 0] = positions[i, 0]
            out[r, i, 1] = positions[i, 1]
            for e in range(2, d):
                out[r, i, e] = prior[r, index[i], e]


def message_rows_source(points, distance, weights, permutation, offset, range_noise, range_std, centres, var,
                         square_sum):  # pragma: no cover - compiled by numba
    """Algorithm 1 step 2 for E messages in ``sample_messages``' numpy arithmetic, each row from its own inputs:
    centres c_i = p_i + (d + sigma_d nu_i) [cos theta_i, sin theta_i] (sigma_d = ``range_std``, the range noise's
    standard deviation, m), theta_i = 2 pi (pi_i + U_i) / M (cos and sin are libm's in both), and the sums of
    h_rot (rule_of_thumb_bandwidth) in einsum's orders: the weighted mean summed over i, the variance as
    sum_i w_i ((x_i - mx)^2 + (y_i - my)^2) (einsum's order for "p,pd->"), sum_i w_i^2 in numpy's pairwise
    order (numpy_sum). The exp of the weights and the power of the ESS stay numpy's (its exp and pow round
    differently from libm's)."""
    E, M = points.shape[0], points.shape[1]
    two_pi = 2.0 * np.pi
    squares = np.empty(M)
    for e in range(E):
        d = distance[e]
        for i in range(M):
            theta = two_pi * (permutation[e, i] + offset[e, i]) / M
            radius = d + range_std[e] * range_noise[e, i]
            centres[e, i, 0] = points[e, i, 0] + radius * math.cos(theta)
            centres[e, i, 1] = points[e, i, 1] + radius * math.sin(theta)
        mx, my = 0.0, 0.0
        for i in range(M):
            mx += weights[e, i] * points[e, i, 0]
        for i in range(M):
            my += weights[e, i] * points[e, i, 1]
        total = 0.0
        for i in range(M):
            dx = points[e, i, 0] - mx
            dy = points[e, i, 1] - my
            total = total + weights[e, i] * (dx * dx + dy * dy)
            squares[i] = weights[e, i] * weights[e, i]
        var[e] = total / 2.0
        square_sum[e] = numpy_sum(squares, M)


# The fused kernels' threaded form (over receivers; the truncated correction weights' over messages) is off:
# libgomp's waiting threads spin, so it loses beside a busy process what it gains on an idle machine
# (docs/performance.md, "dNBP kernels"); OMP_WAIT_POLICY=passive would help but is process-wide (torch's OpenMP
# too), so it is not set here. It gives the same bits (tests/estimators/test_dnbp_fast.py, test_dnbp_truncated.py)
# for a machine where it pays.
FUSED_THREADS = False
# kernel entries (proposals x mixtures x components, points x components) of one call from which the threaded
# form runs when FUSED_THREADS is on
FUSED_THREAD_ELEMENTS = 8 * PARALLEL_ELEMENTS


def fused_kernels() -> dict | None:
    """{name: (serial, threaded)} of the fused belief update (``"weights"``, ``"resample"``,
    ``"mixture_truncated"``; ``"messages"``: the serial one; ``"chunks"``: ``numba.parallel_chunksize``), None
    without numba."""
    return _compile().get("fused") or None


def compiled_kernels() -> dict | None:
    """{name: (serial, threaded)} of the row kernels (``row_kernel``), None without numba."""
    return _compile().get("rows") or None


@functools.cache
def _compile() -> dict:
    """Every kernel, compiled on first use and cached on disk: {"rows": ..., "fused": ...}, empty without numba.

    Each source is compiled from a copy of the function whose globals are one namespace, this module's with
    the compiled forms of the helpers over them (``prange`` is ``numba.prange`` there): the sources call the
    helpers by name, and the module's own names stay the plain Python functions.
    """
    try:
        import numba
    except ImportError:  # pragma: no cover - numba is a dependency; the numpy path stays for other installs
        return {}
    options = {"cache": True, "nogil": True, "boundscheck": False}
    namespace = {**globals(), "prange": numba.prange}

    def jit(fn, threaded: bool = False, **extra):
        # the threaded form is a renamed copy, with its own on-disk cache entry (estimators.compiled.in_namespace)
        return numba.njit(parallel=threaded, **options, **extra)(
            in_namespace(fn, namespace, "_threaded" if threaded else ""))

    helpers = {}
    for helper in (block_sum, numpy_sum, mixture_point, count_at_most, logaddexp, velocity_row):
        helpers[helper.__name__] = namespace[helper.__name__] = jit(helper)
    # the truncated kernel only (the exact one is compiled without fastmath: it keeps the numpy path's bits)
    for helper in (exp_small, mixture_point_truncated, velocity_row_truncated):
        helpers[helper.__name__] = namespace[helper.__name__] = jit(helper, fastmath=True)
    fused = {name: (jit(fn), jit(fn, threaded=True))
             for name, fn in (("weights", belief_weights_source), ("resample", belief_resample_source),
                              ("mixture_truncated", mixture_rows_truncated_source))}
    fused["chunks"] = numba.parallel_chunksize
    fused["messages"] = jit(message_rows_source)
    rows = {name: (jit(fn), jit(fn, threaded=True)) for name, fn in
            (("mixture_rows", mixture_rows), ("velocity_rows", velocity_rows), ("importance_rows", importance_rows))}
    return {"rows": rows, "fused": fused, "helpers": helpers}


def compiled_helper(name: str):
    """The compiled form of the helper ``name`` the kernels call (``numpy_sum``, ``exp_small``, ...), None
    without numba."""
    return _compile().get("helpers", {}).get(name)


# Slices of a fused kernel's rows run on Python threads (the kernels release the GIL): a thread waiting for work
# sleeps (unlike libgomp's spinning threads, see FUSED_THREADS). SPLIT_WORKERS threads (at most the cores and
# numba's thread count; 1: no split), the calling one included; a call is split from SPLIT_RECEIVERS receivers
# and SPLIT_ELEMENTS kernel entries on, into SPLIT_PER_WORKER slices per worker (one: more slices mean more
# wake-ups than balance; the split's gain and loss are in docs/performance.md, "dNBP kernels").
SPLIT_WORKERS: int | None = None
SPLIT_RECEIVERS = 4
SPLIT_ELEMENTS = 1 << 20
SPLIT_PER_WORKER = 1


def split_workers() -> int:
    """``SPLIT_WORKERS`` where set, else the cores and numba's thread count, whichever is fewer."""
    return SPLIT_WORKERS if SPLIT_WORKERS is not None else _default_workers()


@functools.cache
def _default_workers() -> int:
    try:
        import numba

        threads = int(numba.config.NUMBA_NUM_THREADS)
    except ImportError:  # pragma: no cover - numba is a dependency
        threads = 1
    return max(1, min(os.cpu_count() or 1, threads))


@functools.cache
def _pool(workers: int):
    from concurrent.futures import ThreadPoolExecutor

    return ThreadPoolExecutor(max_workers=workers, thread_name_prefix="dnbp")


def split_pieces(rows: int, elements: int) -> int:
    workers = split_workers()
    if workers < 2 or rows < SPLIT_RECEIVERS or elements < SPLIT_ELEMENTS:
        return 1
    return min(rows, workers * SPLIT_PER_WORKER)


def split_rows(call: Callable[[int, int], None], rows: int, pieces: int) -> None:
    """call(a, b) for ``pieces`` consecutive slices [a, b) of range(rows): on the worker threads when pieces > 1."""
    if pieces <= 1:
        call(0, rows)
        return
    pool = _pool(split_workers() - 1)
    edges = [rows * i // pieces for i in range(pieces + 1)]
    futures = [pool.submit(call, a, b) for a, b in zip(edges[:-2], edges[1:-1], strict=True) if b > a]
    call(edges[-2], rows)  # the last slice on this thread
    for future in futures:
        future.result()

