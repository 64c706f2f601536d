"""Bandwidth-limited distributed fusion estimator.

Zhao G. R., Liu B. Y., Zhao C. L., Gao C., "A distributed fusion estimator with
bandwidth limitation for clustered UAVs' position and attitude estimation",
Electronics Optics & Control 27(4):1-5, 2020 (seed ``001_c743ba0d1c0e3ecf.txt``).

N nodes observe one linear system

    x(k+1) = A x(k) + B + w(k),        w ~ N(0, W)                       (1), (22)
    y_j(k) = C x(k) + v_j(k),          v_j ~ N(0, V_j)                   (2), (23)

Every node j forms a Luenberger-type *intermediate estimate* (eq. 4)

    lambda_j(k) = A xhat_j(k) + B + L_j(k) (y_j(k) - C xhat_j(k)),

sends only the components selected by the diagonal 0/1 matrix T_ji (the
*component selection*) to fusion node i, which fills the missing components
with its own one-step prediction (eq. 6) and fuses with weights p_ij >= 0,
sum_j p_ij = 1 (eq. 7):

    lambda^c_ji(k) = T_ji lambda_j(k) + (I - T_ji)(A xhat_i(k) + B)
    xhat_i(k+1)    = sum_j p_ij lambda^c_ji(k).

The gains minimize the upper bound sum_k sum_i tr M_i(k) of the cost
J_K = sum_k sum_i E||e_i(k)||^2 (eqs. 12-17):

    L_j = A M_j C^T (C M_j C^T + V_j / 2)^-1                             (18)
    M_i(k+1) = sum_j p_ij { 2 T_ji A M_j A^T T_ji + 2 Tbar_ji A M_i A^T Tbar_ji
               - 2 T_ji A M_j C^T (C M_j C^T + V_j/2)^-1 C M_j A^T T_ji } + W (19)

Array conventions (a leading batch shape ``...`` is allowed everywhere):

* ``estimate``  ``(..., N, n)``      xhat_i
* ``bound``     ``(..., N, n, n)``   M_i
* ``selection`` ``(..., N, N, n)``   bool, ``selection[..., i, j, c]`` is the
  c-th diagonal entry of T_ji: receiver i gets component c of node j's
  intermediate estimate. The diagonal ``selection[..., i, i, :]`` must be all
  True (T_ii = I: a node always has its own estimate).
* ``weights``   ``(..., N, N)``      ``weights[..., i, j]`` = p_ij, the weight
  fusion node i gives node j (rows sum to 1).
* ``error_cov`` ``(..., N*n, N*n)``  exact covariance of the stacked errors
  e = [e_1; ...; e_N], e_i = x - xhat_i (eq. 10).

Departures from the printed equations
-------------------------------------
* Drift. Eq. (4) omits the known input B although the simulation model (22)
  has it; without it every intermediate estimate would be biased by B. B is
  added to the intermediate estimate and to the compensating prediction.
* Eq. (11) prints ``Tbar_ji L_j v_j``. Substituting (2), (4), (6) into (7):

      x(k+1) - lambda^c_ji = T_ji[(A - L_j C) e_j + w - L_j v_j] + Tbar_ji[A e_i + w]

  so the measurement noise of node j reaches node i only through the
  components it *sent*: the correct term is ``T_ji L_j v_j``. The noise w is
  multiplied by sum_j p_ij, which is 1 for valid weights; it is kept as the
  row sum so that the exact recursion stays exact for any weights.
* The exact error covariance is not in the paper: ``error_transition``
  builds e(k+1) = F e(k) + G [w; v_1; ...; v_N] from the corrected (11) and
  ``exact_covariance_step`` propagates Sigma(k+1) = F Sigma F^T + G Q G^T,
  so that J_K is computed without Monte Carlo.

The bound (19) is the paper's; it holds because for a convex combination
Cov(sum_j p_j a_j) <= sum_j p_j E[a_j a_j^T] and (a + b)(a + b)^T <= 2 a a^T + 2 b b^T,
and sum_j p_ij^2 <= sum_j p_ij for the noise term. A test checks M_i >= Sigma_ii.

The bound's positive semi-definiteness. Eq. (19) is eq. (15) at the gain (18):
with S_j = C M_j C^T + V_j/2 and L_j = A M_j C^T S_j^-1 (so L_j S_j = A M_j C^T),

    (A - L_j C) M_j (A - L_j C)^T + L_j (V_j/2) L_j^T
        = A M_j A^T - L_j C M_j A^T - A M_j C^T L_j^T + L_j S_j L_j^T
        = A M_j A^T - A M_j C^T S_j^-1 C M_j A^T,

the bracket of (19) (eq. 15 carries p_ij L_j V_j L_j^T = 2 p_ij L_j (V_j/2) L_j^T). The right-hand
side is a difference of two matrices of the size of A M_j A^T; where a node's bound is large
against V_j/2 (a component it keeps compensating from its own prediction while it weights its
neighbours: M_i grows by up to 2 per step, about 1e14 after 50 steps of the paper's model)
the difference is V_j/2-sized and is lost to rounding, a unit in the last place of 1e14
(0.016) either side: a negative diagonal in a receiver's M_i, the log of which the
``bandwidth_fusion`` observation takes. ``bound_step`` therefore forms the left-hand side: a
congruence of M_j plus a congruence of V_j/2, each positive semi-definite as computed, so
M_i(k+1) >= W on the diagonal whatever the weights and selections.

The paper's simulation (Sec. 2, N = 4, n = 3) fixes the selections T1..T3 and
the weights P1..P3 by hand: ``paper_selection`` and ``paper_weights``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

__all__ = [
    "FusionModel",
    "FusionState",
    "check_selection",
    "check_weights",
    "gains",
    "intermediate_estimates",
    "fuse",
    "bound_step",
    "error_transition",
    "noise_covariance",
    "node_covariances",
    "node_traces",
    "exact_covariance_step",
    "initial_state",
    "step",
    "expected_cost",
    "PAPER_SELECTIONS",
    "PAPER_WEIGHTS",
    "paper_selection",
    "paper_weights",
]


@dataclass(frozen=True)
class FusionModel:
    """The linear system shared by all nodes (eqs. 1-3, 22-23).

    Parameters
    ----------
    transition : (n, n) array
        A.
    drift : (n,) array
        B, the known constant input (the UAV velocity times the step in the
        paper's simulation).
    measurement : (m, n) array
        C, the same for every node.
    process_noise : (n, n) array
        W.
    measurement_noise : (N, m, m) array
        V_j of each node j.
    """

    transition: np.ndarray
    drift: np.ndarray
    measurement: np.ndarray
    process_noise: np.ndarray
    measurement_noise: np.ndarray

    @property
    def num_nodes(self) -> int:
        return self.measurement_noise.shape[0]

    @property
    def state_dim(self) -> int:
        return self.transition.shape[0]

    @property
    def measurement_dim(self) -> int:
        return self.measurement.shape[0]


@dataclass
class FusionState:
    """Per-node estimates, their bound matrices and (optionally) the exact covariance.

    ``error_cov`` is ``None`` when the caller does not track the exact
    covariance (it costs an (N n)^3 product per step).
    """

    estimate: np.ndarray
    bound: np.ndarray
    error_cov: np.ndarray | None = None


def check_selection(selection: np.ndarray) -> np.ndarray:
    """Return ``selection`` as a bool array after checking T_ii = I."""
    selection = np.asarray(selection, dtype=bool)
    if selection.ndim < 3 or selection.shape[-3] != selection.shape[-2]:
        raise ValueError(f"selection must have shape (..., N, N, n), got {selection.shape}")
    diagonal = np.diagonal(selection, axis1=-3, axis2=-2)
    if not diagonal.all():
        raise ValueError("selection[..., i, i, :] must be all True: a node always has its own estimate (T_ii = I)")
    return selection


def check_weights(weights: np.ndarray, atol: float = 1e-9) -> np.ndarray:
    """Return ``weights`` after checking p_ij >= 0 and sum_j p_ij = 1."""
    weights = np.asarray(weights, dtype=float)
    if not np.all(np.isfinite(weights)):
        raise ValueError("weights must be finite")
    if np.any(weights < 0):
        raise ValueError("weights p_ij must be >= 0")
    if not np.allclose(weights.sum(axis=-1), 1.0, atol=atol, rtol=0.0):
        raise ValueError("weights: each row sum_j p_ij must equal 1")
    return weights


@functools.lru_cache(maxsize=32)
def _identity(n: int) -> np.ndarray:
    """I_n, built once per size (read-only: shared by every call)."""
    eye = np.eye(n)
    eye.flags.writeable = False
    return eye


@functools.lru_cache(maxsize=32)
def _identity_bytes(n: int) -> bytes:
    return np.eye(n).tobytes()


def _is_identity(matrix: np.ndarray) -> bool:
    if matrix.ndim != 2 or matrix.shape[0] != matrix.shape[1]:
        return False
    # called several times a step on the model's A and C: comparing raw bytes settles the usual float64 I
    # without the cost of array_equal; anything else (another dtype, a -0.0) gets the value comparison
    if matrix.dtype == np.float64 and matrix.tobytes() == _identity_bytes(len(matrix)):
        return True
    return np.array_equal(matrix, _identity(len(matrix)))


def _sandwich(left: np.ndarray, middle: np.ndarray, right: np.ndarray) -> np.ndarray:
    """left @ middle @ right^T over stacks (matmul: much faster than a 3-operand einsum).

    An identity factor (the paper's A = C = I) is skipped: multiplying by it
    changes no bit, and these products dominate the step at large batch.
    """
    product = middle if _is_identity(left) else left @ middle
    return product if _is_identity(right) else product @ np.swapaxes(right, -1, -2)


def _innovation_covariance(model: FusionModel, bound: np.ndarray) -> np.ndarray:
    """S_j = C M_j C^T + V_j / 2, shape (..., N, m, m)."""
    C = model.measurement
    return _sandwich(C, bound, C) + 0.5 * model.measurement_noise


def gains(model: FusionModel, bound: np.ndarray, innovation: np.ndarray | None = None) -> np.ndarray:
    """Suboptimal gains of eq. (18): L_j = A M_j C^T (C M_j C^T + V_j/2)^-1.

    Returns an array of shape (..., N, n, m). Solved as S L^T = C M A^T
    (S symmetric) rather than by forming an inverse. ``innovation`` may pass
    S_j = C M_j C^T + V_j/2 when the caller has it.
    """
    A, C = model.transition, model.measurement
    S = _innovation_covariance(model, bound) if innovation is None else innovation
    return np.swapaxes(np.linalg.solve(S, _sandwich(C, bound, A)), -1, -2)


def intermediate_estimates(
    model: FusionModel, estimate: np.ndarray, measurements: np.ndarray, gain: np.ndarray
) -> np.ndarray:
    """lambda_j = A xhat_j + B + L_j (y_j - C xhat_j), eq. (4) with the drift."""
    A, C = model.transition, model.measurement
    innovation = measurements - (estimate if _is_identity(C) else estimate @ C.T)
    return (estimate if _is_identity(A) else estimate @ A.T) + model.drift + (gain @ innovation[..., None])[..., 0]


def fuse(
    model: FusionModel,
    estimate: np.ndarray,
    intermediate: np.ndarray,
    selection: np.ndarray,
    weights: np.ndarray,
) -> np.ndarray:
    """Compensation (6) and fusion (7): xhat_i(k+1) = sum_j p_ij lambda^c_ji(k)."""
    prediction = estimate @ model.transition.T + model.drift
    # compensated[..., i, j, :] = lambda^c_ji
    compensated = np.where(selection, intermediate[..., None, :, :], prediction[..., :, None, :])
    return np.einsum("...ij,...ijn->...in", weights, compensated)


def bound_step(
    model: FusionModel, bound: np.ndarray, selection: np.ndarray, weights: np.ndarray,
    gain: np.ndarray | None = None, innovation: np.ndarray | None = None,
) -> np.ndarray:
    """The bound recursion (19), M_i(k+1) from M(k), with the optimal gains (18) inside.

    ``gain`` (and ``innovation`` S_j) may pass what eq. (18) computed for
    ``bound``: the gain is not solved again. Each sender's corrected term
    A M_j A^T - A M_j C^T S_j^-1 C M_j A^T is formed as eq. (15) writes it at the gain (18),
    (A - L_j C) M_j (A - L_j C)^T + L_j (V_j / 2) L_j^T: the same matrix, positive semi-definite as
    computed (module docstring). With diagonal T, T X T = X * (s s^T), which is how the products are formed.
    """
    A, C = model.transition, model.measurement
    S = _innovation_covariance(model, bound) if innovation is None else innovation
    if gain is None:
        gain = gains(model, bound, S)
    AMA = _sandwich(A, bound, A)
    # A M_j A^T - A M_j C^T S_j^-1 C M_j A^T in the form of eq. (15) at the gain (18), a sum of two PSD terms
    # (module docstring, "The bound's positive semi-definiteness"): never the difference of two large matrices
    closed = A - (gain if _is_identity(C) else gain @ C)  # A - L_j C
    corrected = _sandwich(closed, bound, closed) + _sandwich(gain, 0.5 * model.measurement_noise, gain)
    sel = selection.astype(float)
    unsel = 1.0 - sel
    weighted_sel = weights[..., None, None] * sel[..., :, None] * sel[..., None, :]  # p_ij s s^T
    weighted_unsel = weights[..., None, None] * unsel[..., :, None] * unsel[..., None, :]
    received = (weighted_sel * corrected[..., None, :, :, :]).sum(axis=-3)  # T_ji (...) T_ji, sender j
    compensated = weighted_unsel.sum(axis=-3) * AMA  # Tbar_ji A M_i A^T Tbar_ji, receiver i
    M_next = 2.0 * (received + compensated) + model.process_noise
    return 0.5 * (M_next + np.swapaxes(M_next, -1, -2))


def error_transition(
    model: FusionModel, gain: np.ndarray, selection: np.ndarray, weights: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """F and G of the stacked error recursion e(k+1) = F e(k) + G [w; v_1; ...; v_N].

    From the corrected eq. (11):

        e_i(k+1) = sum_j p_ij [T_ji (A - L_j C) e_j - T_ji L_j v_j + Tbar_ji A e_i]
                   + (sum_j p_ij) w.

    Returns F of shape (..., N n, N n) and G of shape (..., N n, n + N m).
    """
    A, C = model.transition, model.measurement
    N, n, m = model.num_nodes, model.state_dim, model.measurement_dim
    sel = selection.astype(float)
    closed_loop = A - (gain if _is_identity(C) else gain @ C)  # A - L_j C
    blocks = weights[..., :, :, None, None] * sel[..., :, :, :, None] * closed_loop[..., None, :, :, :]
    own = np.einsum("...ij,...ijc->...ic", weights, 1.0 - sel)[..., :, :, None] * A  # sum_j p_ij Tbar_ji A
    idx = np.arange(N)
    blocks[..., idx, idx, :, :] += own
    batch = blocks.shape[:-4]
    F = np.swapaxes(blocks, -3, -2).reshape(*batch, N * n, N * n)

    process = np.einsum("...ij->...i", weights)[..., :, None, None] * _identity(n)  # (..., N, n, n)
    process = np.broadcast_to(process, (*batch, N, n, n))
    meas = -(weights[..., :, :, None, None] * sel[..., :, :, :, None] * gain[..., None, :, :, :])  # (..., i, j, n, m)
    meas = np.swapaxes(meas, -3, -2).reshape(*batch, N * n, N * m)
    G = np.concatenate([process.reshape(*batch, N * n, n), meas], axis=-1)
    return F, G


def noise_covariance(model: FusionModel) -> np.ndarray:
    """Q = blockdiag(W, V_1, ..., V_N), the covariance of [w; v_1; ...; v_N]."""
    n, m, N = model.state_dim, model.measurement_dim, model.num_nodes
    Q = np.zeros((n + N * m, n + N * m))
    Q[:n, :n] = model.process_noise
    for j in range(N):
        Q[n + j * m : n + (j + 1) * m, n + j * m : n + (j + 1) * m] = model.measurement_noise[j]
    return Q


def exact_covariance_step(
    model: FusionModel, error_cov: np.ndarray, gain: np.ndarray, selection: np.ndarray, weights: np.ndarray
) -> np.ndarray:
    """Sigma(k+1) = F Sigma(k) F^T + G Q G^T for the stacked errors (exact, no Monte Carlo)."""
    F, G = error_transition(model, gain, selection, weights)
    Q = noise_covariance(model)
    nxt = F @ error_cov @ np.swapaxes(F, -1, -2) + G @ Q @ np.swapaxes(G, -1, -2)
    return 0.5 * (nxt + np.swapaxes(nxt, -1, -2))


def node_covariances(error_cov: np.ndarray, num_nodes: int) -> np.ndarray:
    """Diagonal blocks Sigma_i of the stacked covariance, shape (..., N, n, n)."""
    n = error_cov.shape[-1] // num_nodes
    blocks = error_cov.reshape(*error_cov.shape[:-2], num_nodes, n, num_nodes, n)
    return np.moveaxis(np.diagonal(blocks, axis1=-4, axis2=-2), -1, -3)


def node_traces(error_cov: np.ndarray, num_nodes: int) -> np.ndarray:
    """tr Sigma_i for every node, shape (..., N)."""
    diag = np.diagonal(error_cov, axis1=-2, axis2=-1)
    return diag.reshape(*diag.shape[:-1], num_nodes, -1).sum(axis=-1)


def initial_state(
    model: FusionModel, initial_estimate: np.ndarray, initial_bound: np.ndarray, batch_shape: tuple = ()
) -> FusionState:
    """All nodes start from the same xhat(0) with M_i(0) = Sigma_i(0) = M(0).

    x(0) ~ N(xhat(0), M(0)) and every node holds the same xhat(0), so the
    initial errors e_i(0) are one and the same vector: the stacked covariance
    is ones(N, N) kron M(0).
    """
    N, n = model.num_nodes, model.state_dim
    estimate = np.broadcast_to(np.asarray(initial_estimate, float), (*batch_shape, N, n)).copy()
    bound = np.broadcast_to(np.asarray(initial_bound, float), (*batch_shape, N, n, n)).copy()
    error_cov = np.broadcast_to(np.kron(np.ones((N, N)), initial_bound), (*batch_shape, N * n, N * n)).copy()
    return FusionState(estimate=estimate, bound=bound, error_cov=error_cov)


def step(
    model: FusionModel,
    state: FusionState,
    measurements: np.ndarray,
    selection: np.ndarray,
    weights: np.ndarray,
) -> FusionState:
    """One full step k -> k+1: gains (18), intermediates (4), fusion (6)-(7), bound (19), exact Sigma.

    ``measurements`` has shape (..., N, m): y_j(k) of every node.
    """
    innovation = _innovation_covariance(model, state.bound)
    gain = gains(model, state.bound, innovation)
    intermediate = intermediate_estimates(model, state.estimate, measurements, gain)
    estimate = fuse(model, state.estimate, intermediate, selection, weights)
    bound = bound_step(model, state.bound, selection, weights, gain, innovation)
    error_cov = None
    if state.error_cov is not None:
        error_cov = exact_covariance_step(model, state.error_cov, gain, selection, weights)
    return FusionState(estimate=estimate, bound=bound, error_cov=error_cov)


def expected_cost(
    model: FusionModel,
    initial_bound: np.ndarray,
    selection: np.ndarray,
    weights: np.ndarray,
    horizon: int,
    time_varying: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-step traces of the exact covariance and of the bound, without Monte Carlo.

    ``selection`` and ``weights`` are fixed over time (``(..., N, N, n)``,
    ``(..., N, N)``), or, with ``time_varying=True``, schedules with a leading
    time axis of length ``horizon``. Returns ``(exact, bound)``, each of shape (horizon+1, ..., N):
    ``exact[k, ..., i] = tr Sigma_i(k)``, ``bound[k, ..., i] = tr M_i(k)``,
    k = 0..horizon, so that J_K = exact.sum(axis=(0, -1)) (eq. 14) and
    Jbar_K = bound.sum(axis=(0, -1)) (eq. 16).
    """
    selection = np.asarray(selection, dtype=bool)
    weights = np.asarray(weights, dtype=float)
    if time_varying and (selection.shape[0] != horizon or weights.shape[0] != horizon):
        raise ValueError(f"time_varying schedules need a leading time axis of length horizon={horizon}")
    skip = 1 if time_varying else 0
    batch_shape = np.broadcast_shapes(selection.shape[skip:-3], weights.shape[skip:-2])
    N, n = model.num_nodes, model.state_dim
    state = initial_state(model, np.zeros(n), initial_bound, batch_shape)
    exact = [node_traces(state.error_cov, N)]
    bound = [np.trace(state.bound, axis1=-2, axis2=-1)]
    for k in range(horizon):
        sel_k = selection[k] if time_varying else selection
        w_k = weights[k] if time_varying else weights
        innovation = _innovation_covariance(model, state.bound)
        gain = gains(model, state.bound, innovation)
        state.error_cov = exact_covariance_step(model, state.error_cov, gain, sel_k, w_k)
        state.bound = bound_step(model, state.bound, sel_k, w_k, gain, innovation)
        exact.append(node_traces(state.error_cov, N))
        bound.append(np.trace(state.bound, axis1=-2, axis2=-1))
    return np.stack(exact), np.stack(bound)



# --- the paper's tables (Sec. 2: N = 4 nodes, n = 3 components) ------------------------------------------------

# The component selections T1..T3. T_ji = T_ij (eq. 5), so each unordered pair {i, j} (1-based as printed)
# maps to the diagonal of T_ji.
PAPER_SELECTIONS: dict[str, dict[tuple[int, int], tuple[int, ...]]] = {
    "T1": {(1, 2): (0, 1, 0), (1, 3): (1, 1, 0), (1, 4): (0, 1, 1),
           (2, 3): (1, 1, 0), (2, 4): (0, 1, 1), (3, 4): (0, 1, 0)},
    "T2": {(1, 2): (1, 0, 0), (1, 3): (1, 0, 1), (1, 4): (1, 0, 1),
           (2, 3): (1, 0, 1), (2, 4): (1, 0, 1), (3, 4): (0, 0, 1)},
    "T3": {(1, 2): (1, 0, 0), (1, 3): (0, 1, 1), (1, 4): (1, 1, 0),
           (2, 3): (0, 1, 1), (2, 4): (1, 0, 1), (3, 4): (1, 0, 0)},
}

# The weight tables P1..P3, p_ij = the weight fusion node i gives node j (rows sum to 1; the printed tables
# are symmetric).
PAPER_WEIGHTS: dict[str, tuple[tuple[float, ...], ...]] = {
    "P1": ((0.25, 0.25, 0.25, 0.25),) * 4,
    "P2": ((0.45, 0.15, 0.15, 0.25), (0.15, 0.45, 0.25, 0.15),
           (0.15, 0.25, 0.45, 0.15), (0.25, 0.15, 0.15, 0.45)),
    "P3": ((0.65, 0.15, 0.15, 0.05), (0.15, 0.65, 0.05, 0.15),
           (0.15, 0.05, 0.65, 0.15), (0.05, 0.15, 0.15, 0.65)),
}


def paper_selection(name: str) -> np.ndarray:
    """The paper's table ``name`` (T1, T2, T3) as a ``selection`` (4, 4, 3), T_ii = I."""
    if name not in PAPER_SELECTIONS:
        raise ValueError(f"selection table must be one of {sorted(PAPER_SELECTIONS)}, got {name!r}")
    full = np.ones((4, 4, 3), dtype=bool)
    for (a, b), diag in PAPER_SELECTIONS[name].items():
        full[a - 1, b - 1] = full[b - 1, a - 1] = np.asarray(diag, bool)
    return full


def paper_weights(name: str) -> np.ndarray:
    """The paper's weight table ``name`` (P1, P2, P3) as ``weights`` (4, 4)."""
    if name not in PAPER_WEIGHTS:
        raise ValueError(f"weight table must be one of {sorted(PAPER_WEIGHTS)}, got {name!r}")
    return np.array(PAPER_WEIGHTS[name], dtype=float)
