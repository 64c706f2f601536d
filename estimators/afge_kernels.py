"""The compiled kernels of ``estimators.afge``: the same arithmetic as its numpy reference, one element at a time.

``estimators.afge`` is the reference: every function there is written in numpy over a leading batch shape.
Where numba is installed, four of its steps run as the kernels here instead (``compiled=None`` or ``True``
in ``packet_fixes``, ``fuse_packets``, ``buffer_estimates`` and ``predictive_costs``):

| kernel            | the numpy form it follows                                                     |
|-------------------|-------------------------------------------------------------------------------|
| ``fixes_kernel``  | ``packet_fixes`` (§4, eqs. 4-6), one pass over the packets                    |
| ``fuse_kernel``   | ``known_at_lag``, ``select_strongest`` and ``fuse_fixes`` per stamp (Step 2)  |
| ``buffer_kernel`` | ``buffer_step`` then ``stack_estimates``: the buffer re-run and the estimates |
| ``costs_kernel``  | ``predictive_costs`` (AHG's one-step predictive likelihood)                   |

Each evaluates the same formulas in the same order as the numpy form (``numpy_sum`` adds the fusion
weights' normaliser in numpy's pairwise order; ``joseph_predict``, the information predict on the 2x2
blocks, is one function that both forms call), so results agree to the last bit on the tests' machine and to
1e-9 by test (tests/estimators/test_afge_fast.py). Each element's horizon slots stay in registers, the stack
is a ring so the shift moves nothing, and no (elements, S)-sized temporary is allocated per block product, the
numpy form's cost at large batches.

The sources are plain Python (``prange`` is ``range`` here); ``compiled_kernels`` compiles them on first use,
each in a copy of its function whose globals name the compiled helpers (``numba.prange``, the jitted
``numpy_sum``, ``joseph_predict`` and ``predict_slots``), and caches them on disk. ``pair(name, compiled)``
is the dispatch: the [serial, threaded] pair, or None for the numpy path.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from estimators.compiled import in_namespace

PARALLEL_ELEMENTS = 4096  # (copy, agent) elements from which threads pay for themselves
prange = range  # numba.prange in the compiled copies (the kernels' loop over elements)
INVERTIBLE_TOL = 1e-12  # relative margin of the guarded inverse (see _spd_inverse4)


def joseph_predict(y11, y12, y22, v, T, b1, b2, iq):
    """``information_predict`` on the 2x2 blocks ``y11, y12, y22`` (4-tuples (a, b, c, d) =
    [[a, b], [c, d]]) of Y and the 4-tuple y, with ``b1, b2`` = T^2/2, T and ``iq`` = 1/q: the
    blocks (p11a, p11b, p11d), (p12a, p12b, p12c, p12d), (p22a, p22b, p22d) of the symmetric
    result and its vector. Written once for arrays (the numpy form, elementwise over any leading
    shape) and for floats (the compiled kernel jits this function), so both round alike.

    The Joseph form ``L M L^T + K Q^-1 K^T`` is evaluated as ``N - E K^T`` with
    ``N = L M = M - K U^T`` (U = M B, so B^T M = U^T) and ``E = N B - K Q^-1``: since
    ``L^T = I - B K^T``, ``N L^T = N - (N B) K^T``, and the two are equal in exact arithmetic.
    E is zero in exact arithmetic; computed, it carries the rounding error of N along B, and
    ``N - E K^T`` removes it as the congruence does (``N`` alone is the short form, whose
    rounding made Y indefinite at T = 1e4 s). The upper triangle is formed once and mirrored.
    """
    y11a, y11b, y11c, y11d = y11
    y12a, y12b, y12c, y12d = y12
    y22a, y22b, y22c, y22d = y22
    # M = A^-T Y A^-1: M11 = Y11, M12 = Y12 - T Y11, M22 = Y22 - T Y12 - T Y12^T + T^2 Y11
    m11a, m11b, m11c, m11d = y11a, y11b, y11c, y11d
    m12a, m12b = y12a - T * y11a, y12b - T * y11b
    m12c, m12d = y12c - T * y11c, y12d - T * y11d
    m22a = y22a - T * y12a - T * y12a + (T * T) * y11a
    m22b = y22b - T * y12b - T * y12c + (T * T) * y11b
    m22c = y22c - T * y12c - T * y12b + (T * T) * y11c
    m22d = y22d - T * y12d - T * y12d + (T * T) * y11d
    # U = M B = [U1; U2], W = Q^-1 + B^T U, K = U W^-1 = [G1; G2]
    u1a, u1b = b1 * m11a + b2 * m12a, b1 * m11b + b2 * m12b
    u1c, u1d = b1 * m11c + b2 * m12c, b1 * m11d + b2 * m12d
    u2a, u2b = b1 * m12a + b2 * m22a, b1 * m12c + b2 * m22b
    u2c, u2d = b1 * m12b + b2 * m22c, b1 * m12d + b2 * m22d
    wa = b1 * u1a + b2 * u2a + iq
    wb = b1 * u1b + b2 * u2b
    wc = b1 * u1c + b2 * u2c
    wd = b1 * u1d + b2 * u2d + iq
    r = 1.0 / (wa * wd - wb * wc)  # one division: W^-1 = adj(W) / det W
    ia, ib, ic, id_ = wd * r, -wb * r, -wc * r, wa * r
    g1a, g1b = u1a * ia + u1b * ic, u1a * ib + u1b * id_
    g1c, g1d = u1c * ia + u1d * ic, u1c * ib + u1d * id_
    g2a, g2b = u2a * ia + u2b * ic, u2a * ib + u2b * id_
    g2c, g2d = u2c * ia + u2d * ic, u2c * ib + u2d * id_
    # the rows n_r of N = L M = M - K U^T
    n0a, n0b = m11a - (g1a * u1a + g1b * u1b), m11b - (g1a * u1c + g1b * u1d)
    n0c, n0d = m12a - (g1a * u2a + g1b * u2b), m12b - (g1a * u2c + g1b * u2d)
    n1a, n1b = m11c - (g1c * u1a + g1d * u1b), m11d - (g1c * u1c + g1d * u1d)
    n1c, n1d = m12c - (g1c * u2a + g1d * u2b), m12d - (g1c * u2c + g1d * u2d)
    n2a, n2b = m12a - (g2a * u1a + g2b * u1b), m12c - (g2a * u1c + g2b * u1d)
    n2c, n2d = m22a - (g2a * u2a + g2b * u2b), m22b - (g2a * u2c + g2b * u2d)
    n3a, n3b = m12b - (g2c * u1a + g2d * u1b), m12d - (g2c * u1c + g2d * u1d)
    n3c, n3d = m22c - (g2c * u2a + g2d * u2b), m22d - (g2c * u2c + g2d * u2d)
    # N L^T = N - (N B) K^T, so Y = N + K Q^-1 K^T - (N B) K^T = N - (N B - K Q^-1) K^T: e_r, the rows of
    # N B - K Q^-1 (zero in exact arithmetic), carry the rounding of N that the congruence corrects
    e0a, e0b = b1 * n0a + b2 * n0c - iq * g1a, b1 * n0b + b2 * n0d - iq * g1b
    e1a, e1b = b1 * n1a + b2 * n1c - iq * g1c, b1 * n1b + b2 * n1d - iq * g1d
    e2a, e2b = b1 * n2a + b2 * n2c - iq * g2a, b1 * n2b + b2 * n2d - iq * g2b
    e3a, e3b = b1 * n3a + b2 * n3c - iq * g2c, b1 * n3b + b2 * n3d - iq * g2d
    # Y[r, s] = N[r, s] - e_r . K_s, r <= s
    p00 = n0a - (e0a * g1a + e0b * g1b)
    p01 = n0b - (e0a * g1c + e0b * g1d)
    p02 = n0c - (e0a * g2a + e0b * g2b)
    p03 = n0d - (e0a * g2c + e0b * g2d)
    p11 = n1b - (e1a * g1c + e1b * g1d)
    p12 = n1c - (e1a * g2a + e1b * g2b)
    p13 = n1d - (e1a * g2c + e1b * g2d)
    p22 = n2c - (e2a * g2a + e2b * g2b)
    p23 = n2d - (e2a * g2c + e2b * g2d)
    p33 = n3d - (e3a * g2c + e3b * g2d)
    # y <- L A^-T y
    v10, v11 = v[0], v[1]
    v20, v21 = v[2] - T * v10, v[3] - T * v11
    c0, c1 = b1 * v10 + b2 * v20, b1 * v11 + b2 * v21
    y = (v10 - (g1a * c0 + g1b * c1), v11 - (g1c * c0 + g1d * c1),
         v20 - (g2a * c0 + g2b * c1), v21 - (g2c * c0 + g2d * c1))
    return (p00, p01, p11), (p02, p03, p12, p13), (p22, p23, p33), y


def numpy_sum(values):  # pragma: no cover - compiled by numba
    """Sum of a short contiguous vector in the order numpy's pairwise summation takes (eight
    running sums, then ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7)); sequential below 8;
    up to its 128-element block), so that the compiled fusion weights equal the numpy ones."""
    n = values.shape[0]
    if n < 8:
        total = 0.0
        for i in range(n):
            total += values[i]
        return total
    r = values[:8].copy()
    i = 8
    while i + 8 <= n:
        for lane in range(8):
            r[lane] += values[i + lane]
        i += 8
    total = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        total += values[i]
        i += 1
    return total


def predict_slots(Y, vec, S, T, b1, b2, iq):  # pragma: no cover - compiled by numba
    """``joseph_predict`` of every slot j of an entry-major stack (``Y[e, j]``, entry e = 4 r + c;
    ``vec[r, j]``), in place."""
    for j in range(S):
        P11, P12, P22, y = joseph_predict((Y[0, j], Y[1, j], Y[4, j], Y[5, j]), (Y[2, j], Y[3, j], Y[6, j], Y[7, j]),
                                           (Y[10, j], Y[11, j], Y[14, j], Y[15, j]),
                                           (vec[0, j], vec[1, j], vec[2, j], vec[3, j]), T, b1, b2, iq)
        Y[0, j], Y[5, j], Y[10, j], Y[15, j] = P11[0], P11[2], P22[0], P22[2]
        Y[1, j] = Y[4, j] = P11[1]
        Y[11, j] = Y[14, j] = P22[1]
        Y[2, j] = Y[8, j] = P12[0]
        Y[3, j] = Y[12, j] = P12[1]
        Y[6, j] = Y[9, j] = P12[2]
        Y[7, j] = Y[13, j] = P12[3]
        vec[0, j], vec[1, j], vec[2, j], vec[3, j] = y


def fixes_kernel(sender, rss, aoa, m, constants, z, R, r_hat):  # pragma: no cover - compiled by numba
    """Per packet: ``packet_fixes`` with the same operations in the same order, one pass over the
    packets instead of some twenty numpy temporaries of the buffer's size."""
    (sd2, nsd2, nbd2, st2, nst2, nbt2, nbias_db, nbias_theta, tx_less_ref, ten_n, d0, kappa, nav2) = constants
    for p in prange(rss.shape[0]):
        w = m[p]
        var_db = sd2 + w * nsd2 + w * (1.0 - w) * nbd2
        var_theta = st2 + w * nst2 + w * (1.0 - w) * nbt2
        r = d0 * 10.0 ** ((tx_less_ref - (rss[p] + w * nbias_db)) / ten_n)
        theta = aoa[p] - w * nbias_theta
        c, s = np.cos(theta), np.sin(theta)
        z[p, 0] = sender[p, 0] + r * c
        z[p, 1] = sender[p, 1] + r * s
        var_r = (kappa * r) ** 2 * var_db
        var_t = r**2 * var_theta
        R[p, 0, 0] = c * c * var_r + s * s * var_t + nav2
        R[p, 1, 1] = s * s * var_r + c * c * var_t + nav2
        R[p, 0, 1] = R[p, 1, 0] = c * s * (var_r - var_t)
        r_hat[p] = r


def fuse_kernel(z, R, r_hat, rss, delays, lags, keep, n_strongest, distance, min_packets,
                        out_Y, out_y, out_gamma, out_used):  # pragma: no cover - compiled by numba
    """Per stamp m: ``known_at_lag``, ``select_strongest`` (rank by RSS, ties to the
    lower index) and ``fuse_fixes`` on the packets' fixes, without the (M, J, 2, 2)
    temporaries of the numpy form."""
    M, J = rss.shape[0], rss.shape[1]
    for m in prange(M):
        lag = lags[m]
        usable = np.zeros(J, np.bool_)
        for j in range(J):
            usable[j] = lag >= 0 and delays[m, j] <= lag and keep[m, j]
        selected = np.zeros(J, np.bool_)
        for j in range(J):
            if usable[j]:
                rank = 0
                for i in range(J):
                    if usable[i] and (rss[m, i] > rss[m, j] or (rss[m, i] == rss[m, j] and i < j)):
                        rank += 1
                selected[j] = rank < n_strongest
        count = 0
        dist = np.zeros(J)
        for j in range(J):
            out_used[m, j] = selected[j]
            if selected[j]:
                count += 1
                dist[j] = r_hat[m, j]
        total = numpy_sum(dist)
        gamma = count >= min_packets
        out_gamma[m] = gamma
        Y00 = Y01 = Y10 = Y11 = 0.0
        y0 = y1 = 0.0
        if gamma:
            for j in range(J):
                if selected[j]:
                    if distance:
                        w = r_hat[m, j] / (total if total > 0 else 1.0)
                    else:
                        w = 1.0
                    det = R[m, j, 0, 0] * R[m, j, 1, 1] - R[m, j, 0, 1] * R[m, j, 1, 0]
                    i00, i11 = R[m, j, 1, 1] / det, R[m, j, 0, 0] / det
                    i01, i10 = -R[m, j, 0, 1] / det, -R[m, j, 1, 0] / det
                    Y00 += w * i00
                    Y01 += w * i01
                    Y10 += w * i10
                    Y11 += w * i11
                    y0 += w * i00 * z[m, j, 0] + w * i01 * z[m, j, 1]
                    y1 += w * i10 * z[m, j, 0] + w * i11 * z[m, j, 1]
        out_Y[m, 0, 0], out_Y[m, 0, 1], out_Y[m, 1, 0], out_Y[m, 1, 1] = Y00, Y01, Y10, Y11
        out_y[m, 0], out_y[m, 1] = y0, y1


def buffer_kernel(final_info, final_vector, final_stamps, buffer_info, buffer_vector, buffer_success,
                          k, shift, inv_q, T, min_stamps, out_info, out_vector, out_stamps, out_x, out_P,
                          out_valid):  # pragma: no cover - compiled by numba; the numpy path is the reference
    """Per element m: the D+1 ``stack_advance`` calls of ``buffer_step``, then
    ``stack_estimates``, with the same formulas in the same order on the 2x2 blocks (the predict
    is ``joseph_predict`` itself), so its numbers are the numpy form's.

    An element's stack is held entry-major (``Y[e, j]`` is entry e = 4 r + c of slot j's
    information matrix, ``vec[r, j]``) in arrays local to the element, a ring whose shift
    moves no data, and no (M, S, 4, 4) temporary is allocated as in the numpy form.
    """
    M, S = final_stamps.shape[0], final_stamps.shape[1]
    D1 = buffer_success.shape[1]
    D = D1 - 1
    b1, b2 = 0.5 * T * T, T
    tol = INVERTIBLE_TOL
    for m in prange(M):
        # a ring: logical slot j lives at (head + j) % S, so the shift moves no data
        Y = np.empty((16, S))
        vec = np.empty((4, S))
        for j in range(S):
            for e in range(16):
                Y[e, j] = final_info[m, j, e // 4, e % 4]
            for r in range(4):
                vec[r, j] = final_vector[m, j, r]
        st = final_stamps[m].copy()
        iq = inv_q[m]  # 1 / q, as 1.0 / q in the numpy form
        head = 0
        for i in range(D1):
            stamp = k[m] - D + i
            if stamp >= 0:
                if shift:
                    head = head - 1 if head > 0 else S - 1
                    for e in range(16):
                        Y[e, head] = 0.0
                    for r in range(4):
                        vec[r, head] = 0.0
                    st[head] = 0
                if stamp > 0:
                    predict_slots(Y, vec, S, T, b1, b2, iq)
                f0, f1, f4, f5 = buffer_info[m, i, 0, 0], buffer_info[m, i, 0, 1], buffer_info[m, i, 1, 0], \
                    buffer_info[m, i, 1, 1]
                g0, g1 = buffer_vector[m, i, 0], buffer_vector[m, i, 1]
                s = buffer_success[m, i]
                for j in range(S):
                    Y[0, j] += f0
                    Y[1, j] += f1
                    Y[4, j] += f4
                    Y[5, j] += f5
                    vec[0, j] += g0
                    vec[1, j] += g1
                    st[j] += s
            if i == 0:
                for j in range(S):
                    slot = head + j if head + j < S else head + j - S
                    for e in range(16):
                        out_info[m, j, e // 4, e % 4] = Y[e, slot]
                    for r in range(4):
                        out_vector[m, j, r] = vec[r, slot]
                    out_stamps[m, j] = st[slot]
        for j in range(S):
            slot = head + j if head + j < S else head + j - S
            valid = st[slot] >= min_stamps
            out_valid[m, j] = valid
            if valid:
                y11a, y11b, y11c, y11d = Y[0, slot], Y[1, slot], Y[4, slot], Y[5, slot]
                y12a, y12b, y12c, y12d = Y[2, slot], Y[3, slot], Y[6, slot], Y[7, slot]
                y22a, y22b, y22c, y22d = Y[10, slot], Y[11, slot], Y[14, slot], Y[15, slot]
                ya, yb, yc, yd = vec[0, slot], vec[1, slot], vec[2, slot], vec[3, slot]
            else:
                y11a, y11b, y11c, y11d = 1.0, 0.0, 0.0, 1.0
                y12a, y12b, y12c, y12d = 0.0, 0.0, 0.0, 0.0
                y22a, y22b, y22c, y22d = 1.0, 0.0, 0.0, 1.0
                ya, yb, yc, yd = 0.0, 0.0, 0.0, 0.0
            # the guarded inverse of _spd_inverse4: no estimate where Y is not numerically invertible
            det = y22a * y22d - y22b * y22c
            tr = y22a + y22d
            ok = tr > 0.0 and det > tol * tr * tr
            if not ok:
                y22a, y22b, y22c, y22d = 1.0, 0.0, 0.0, 1.0
                det = 1.0
            i22a, i22b, i22c, i22d = y22d / det, -y22b / det, -y22c / det, y22a / det
            t1a, t1b = y12a * i22a + y12b * i22c, y12a * i22b + y12b * i22d
            t1c, t1d = y12c * i22a + y12d * i22c, y12c * i22b + y12d * i22d
            sa = y11a - (t1a * y12a + t1b * y12b)
            sb = y11b - (t1a * y12c + t1b * y12d)
            sc = y11c - (t1c * y12a + t1d * y12b)
            sd = y11d - (t1c * y12c + t1d * y12d)
            det = sa * sd - sb * sc
            tr = sa + sd
            ok = ok and tr > 0.0 and det > tol * tr * (y11a + y11d)
            if not ok:
                sa, sb, sc, sd = 1.0, 0.0, 0.0, 1.0
                det = 1.0
            if valid and not ok:  # placeholders, as the numpy form's: P = I, x = 0
                valid = False
                out_valid[m, j] = False
                y12a, y12b, y12c, y12d = 0.0, 0.0, 0.0, 0.0
                t1a, t1b, t1c, t1d = 0.0, 0.0, 0.0, 0.0
                i22a, i22b, i22c, i22d = 1.0, 0.0, 0.0, 1.0
                ya, yb, yc, yd = 0.0, 0.0, 0.0, 0.0
            s1a, s1b, s1c, s1d = sd / det, -sb / det, -sc / det, sa / det
            q12a, q12b = -(s1a * t1a + s1b * t1c), -(s1a * t1b + s1b * t1d)
            q12c, q12d = -(s1c * t1a + s1d * t1c), -(s1c * t1b + s1d * t1d)
            # P22 = Y22^-1 - T1^T P12
            q22a = i22a - (t1a * q12a + t1c * q12c)
            q22b = i22b - (t1a * q12b + t1c * q12d)
            q22c = i22c - (t1b * q12a + t1d * q12c)
            q22d = i22d - (t1b * q12b + t1d * q12d)
            P = out_P[m, j]
            P[0, 0], P[1, 1] = s1a, s1d
            P[0, 1] = P[1, 0] = 0.5 * (s1b + s1c)
            P[2, 2], P[3, 3] = q22a, q22d
            P[2, 3] = P[3, 2] = 0.5 * (q22b + q22c)
            P[0, 2] = P[2, 0] = q12a
            P[0, 3] = P[3, 0] = q12b
            P[1, 2] = P[2, 1] = q12c
            P[1, 3] = P[3, 1] = q12d
            for r in range(4):
                out_x[m, j, r] = P[r, 0] * ya + P[r, 1] * yb + P[r, 2] * yc + P[r, 3] * yd


def costs_kernel(prev_x, prev_P, prev_valid, z, R, T, G, out):  # pragma: no cover - compiled by numba
    """Per element m and horizon j: ``predictive_costs`` with the same sums in the same order
    (S's six terms left to right, as ``_lin`` adds them), on the rows of ``prev_P`` where they lie
    instead of the strided 2x2 views the numpy form multiplies 48 times over the batch."""
    M, S = prev_valid.shape
    TT = T * T
    for m in prange(M):
        z0, z1 = z[m, 0], z[m, 1]
        r0, r1, r2, r3 = R[m, 0, 0], R[m, 0, 1], R[m, 1, 0], R[m, 1, 1]
        for j in range(S):
            if not prev_valid[m, j]:
                out[m, j] = np.inf
                continue
            x = prev_x[m, j]
            P = prev_P[m, j]
            e0 = z0 - (x[0] + T * x[2])
            e1 = z1 - (x[1] + T * x[3])
            s0 = P[0, 0] + T * P[0, 2] + T * P[0, 2] + TT * P[2, 2] + G[0, 0] + r0
            s1 = P[0, 1] + T * P[0, 3] + T * P[1, 2] + TT * P[2, 3] + G[0, 1] + r1
            s2 = P[1, 0] + T * P[1, 2] + T * P[0, 3] + TT * P[3, 2] + G[1, 0] + r2
            s3 = P[1, 1] + T * P[1, 3] + T * P[1, 3] + TT * P[3, 3] + G[1, 1] + r3
            det = s0 * s3 - s1 * s2
            quad = (s3 * e0 * e0 - (s1 + s2) * e0 * e1 + s0 * e1 * e1) / det
            out[m, j] = quad + np.log(det)


def _with_globals(fn, scope: dict, suffix: str = ""):
    """A copy of ``fn`` (``estimators.compiled.in_namespace`` with ``suffix``: its own name and qualified name,
    so the threaded form has its own disk-cache entry) whose globals are its module's with ``scope`` over them:
    the compiled helpers the copy calls, where the source calls the Python ones."""
    return in_namespace(fn, {**fn.__globals__, **scope}, suffix)


@functools.cache
def compiled_kernels() -> dict:
    """name -> [serial, threaded] numba forms of the kernels (``"buffer"``: ``buffer_kernel``, ``"fuse"``:
    ``fuse_kernel``, ``"costs"``: ``costs_kernel``, ``"fixes"``: ``fixes_kernel``), compiled on first use and
    cached on disk; empty where numba is not installed."""
    try:
        import numba
    except ImportError:  # pragma: no cover - numba is a dependency; the numpy path stays for other installs
        return {}
    options = {"cache": True, "nogil": True, "boundscheck": False}
    # the buffer kernel's divisors are positive definite determinants or guarded: numpy's error model drops the
    # zero-division branch of every division
    buffer = {**options, "error_model": "numpy"}
    scope = {"prange": numba.prange, "numpy_sum": numba.njit(**options)(_with_globals(numpy_sum, {})),
             "joseph_predict": numba.njit(inline="always", **buffer)(_with_globals(joseph_predict, {}))}
    scope["predict_slots"] = numba.njit(**buffer)(_with_globals(predict_slots, scope))
    # the threaded form compiles a renamed copy: with the same name it shares the serial form's disk-cache entry,
    # and one of them loads the other's code (estimators.compiled.in_namespace)
    return {key: [numba.njit(**opts)(_with_globals(fn, scope)),
                  numba.njit(parallel=True, **opts)(_with_globals(fn, scope, "_threaded"))]
            for key, fn, opts in (("buffer", buffer_kernel, buffer), ("fuse", fuse_kernel, options),
                                  ("costs", costs_kernel, options), ("fixes", fixes_kernel, options))}


def compiled(name: str):
    """The [serial, threaded] pair of the kernel ``name``, or None where numba is not installed."""
    return compiled_kernels().get(name)


def pair(name: str, use: bool | None):
    """``compiled(name)`` where ``use`` asks for it (None: where numba is installed), else None (the numpy
    reference path); ``use=True`` without numba is refused."""
    kernels = compiled(name) if use in (None, True) else None
    if use and kernels is None:
        raise ValueError("compiled=True needs numba, which is not installed")
    return kernels


def for_size(pair, elements: int):
    """The threaded form from ``PARALLEL_ELEMENTS`` elements on, the serial one below."""
    return pair[1] if elements >= PARALLEL_ELEMENTS else pair[0]


def flat(a, batch: tuple, tail: tuple, dtype) -> np.ndarray:
    """``a`` broadcast to (*batch, *tail) as a C-ordered (prod(batch), *tail) array of ``dtype``: the kernels'
    row layout."""
    rows, shape = math.prod(batch), (*batch, *tail)
    if isinstance(a, np.ndarray) and a.shape == shape and a.dtype == dtype and a.flags.c_contiguous:
        return a.reshape(rows, *tail)  # the common case, without broadcast_to's cost at small B
    return np.ascontiguousarray(np.broadcast_to(a, shape), dtype).reshape(rows, *tail)


# --- the calls: flatten the batch to the kernels' rows, run, restore the shape ---------------------------------
def packet_fixes(pair, signal, sender_position, rss, aoa, m):
    """``estimators.afge.packet_fixes`` by ``fixes_kernel``: (z, R, r_hat) of every packet."""
    shape = np.broadcast_shapes(np.shape(sender_position)[:-1], np.shape(rss), np.shape(aoa), np.shape(m))
    P = math.prod(shape)
    sender = flat(sender_position, shape, (2,), float)
    rows = [flat(a, shape, (), float) for a in (rss, aoa, m)]
    constants = (signal.sigma_db**2, signal.nlos_sigma_db**2, signal.nlos_bias_db**2, signal.sigma_theta**2,
                 signal.nlos_sigma_theta**2, signal.nlos_bias_theta**2, float(signal.nlos_bias_db),
                 float(signal.nlos_bias_theta), signal.tx_power_dbm - signal.reference_loss_db,
                 10.0 * signal.exponent, float(signal.d0), np.log(10.0) / (10.0 * signal.exponent),
                 signal.sigma_nav**2)
    z, R, r_hat = np.empty((P, 2)), np.empty((P, 2, 2)), np.empty(P)
    for_size(pair, P)(sender, *rows, tuple(float(v) for v in constants), z, R, r_hat)
    return z.reshape(*shape, 2), R.reshape(*shape, 2, 2), r_hat.reshape(shape)


def fuse_packets(pair, z, R, r_hat, rss, delays, lags, keep, n_strongest: int, distance: bool, min_packets: int):
    """``estimators.afge.fuse_packets`` from the packets' fixes by ``fuse_kernel``: (Y, y, gamma, used)."""
    batch = np.broadcast_shapes(np.shape(rss)[:-1], np.shape(lags), np.shape(keep)[:-1])
    J = np.shape(rss)[-1]
    M = math.prod(batch)

    def rows(a, tail, dtype):
        return flat(a, batch, tail, dtype)

    out_Y, out_y = np.empty((M, 2, 2)), np.empty((M, 2))
    out_gamma, out_used = np.empty(M, bool), np.empty((M, J), bool)
    for_size(pair, M)(
        rows(z, (J, 2), float), rows(R, (J, 2, 2), float), rows(r_hat, (J,), float), rows(rss, (J,), float),
        rows(delays, (J,), np.int64), rows(lags, (), np.int64), rows(keep, (J,), bool), int(n_strongest),
        bool(distance), int(min_packets), out_Y, out_y, out_gamma, out_used)
    return (out_Y.reshape(*batch, 2, 2), out_y.reshape(*batch, 2), out_gamma.reshape(batch),
            out_used.reshape(*batch, J))


def buffer_estimates(pair, final_info, final_vector, final_stamps, k, buffer_info, buffer_vector, buffer_success,
                     shift: bool, accel_var, period: float, min_stamps: int):
    """``estimators.afge.buffer_estimates`` by ``buffer_kernel``: the final stack's (info, vector, stamps) and
    the current stack's estimates (x, P, valid). ``accel_var`` is sigma_a^2 (a scalar or one per element)."""
    batch, S = np.shape(final_stamps)[:-1], np.shape(final_stamps)[-1]
    D1 = np.shape(buffer_success)[-1]
    M = math.prod(batch)
    inv_q = flat(1.0 / np.asarray(accel_var, float), batch, (), float)
    info = flat(final_info, batch, (S, 4, 4), float)
    vector = flat(final_vector, batch, (S, 4), float)
    stamps = flat(final_stamps, batch, (S,), np.int64)
    Yb = flat(buffer_info, batch, (D1, 2, 2), float)
    yb = flat(buffer_vector, batch, (D1, 2), float)
    gb = flat(buffer_success, batch, (D1,), np.int64)
    kk = flat(np.asarray(k, np.int64), batch, (), np.int64)
    out_info, out_vector = np.empty_like(info), np.empty_like(vector)
    out_stamps = np.empty_like(stamps)
    x, P, valid = np.empty((M, S, 4)), np.empty((M, S, 4, 4)), np.empty((M, S), bool)
    for_size(pair, M)(info, vector, stamps, Yb, yb, gb, kk, bool(shift), inv_q, float(period), int(min_stamps),
                      out_info, out_vector, out_stamps, x, P, valid)
    return (out_info.reshape(*batch, S, 4, 4), out_vector.reshape(*batch, S, 4), out_stamps.reshape(*batch, S),
            x.reshape(*batch, S, 4), P.reshape(*batch, S, 4, 4), valid.reshape(*batch, S))


def predictive_costs(pair, prev_x, prev_P, prev_valid, z, R, period: float, process_cov):
    """``estimators.afge.predictive_costs`` (without ``fresh``) by ``costs_kernel``: (..., S) costs."""
    batch = np.broadcast_shapes(np.shape(prev_valid)[:-1], np.shape(z)[:-1], np.shape(R)[:-2])
    S = np.shape(prev_valid)[-1]
    M = math.prod(batch)
    rows = [flat(a, batch, tail, dtype) for a, tail, dtype in ((prev_x, (S, 4), float), (prev_P, (S, 4, 4), float),
                                                                (prev_valid, (S,), bool), (z, (2,), float),
                                                                (R, (2, 2), float))]
    out = np.empty((M, S))
    for_size(pair, M)(*rows, float(period), np.ascontiguousarray(process_cov, float), out)
    return out.reshape(*batch, S)
