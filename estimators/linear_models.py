"""Linear-Gaussian motion and measurement models (zhao2020, fu2017), in the shape of ``estimators.models``.

| model                      | kind                   | equation                                | paper eqs.         |
|----------------------------|------------------------|-----------------------------------------|--------------------|
| ``LinearGaussian``    | ``linear_gaussian``    | x(k+1) = A x(k) + b + w, w ~ N(0, Q)    | zh 1, 22; fu 1     |
| ``LinearObservation`` | ``linear_observation`` | z_j(k) = C x(k) + v_j, v_j ~ N(0, V_j)  | zh 2, 23; fu 2     |

(zh = zhao2020, fu = fu2017.)
zhao2020's drift has b = v dt (the known UAV velocity times the step); fu2017's
constant-velocity target has b = 0 and Q = Gamma q Gamma^T. The same objects
serve the simulated truth (``rvs``) and the filters (``function``,
``jacobian``, ``covar``). Noise is given as covariances (variances), the
library's one convention. Arrays carry arbitrary leading batch axes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

__all__ = ["LinearGaussian", "LinearObservation"]


def _square(name: str, value, n: int | None = None) -> np.ndarray:
    a = np.asarray(value, float)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or (n is not None and a.shape[0] != n):
        want = "square" if n is None else f"({n}, {n})"
        raise ValueError(f"{name} must be a {want} matrix, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite")
    return a


def _covariance(name: str, value, n: int, strict: bool) -> np.ndarray:
    a = _square(name, value, n)
    # tolerances relative to the matrix's scale: an absolute 1e-12 refuses the rounding of a covariance with
    # entries near 1e12 and lets a covariance of 1e-12 entries be indefinite by its own size
    scale = float(np.abs(a).max()) if a.size else 0.0
    if not np.allclose(a, a.T, atol=1e-12 * max(scale, 1e-300), rtol=0.0):
        raise ValueError(f"{name} must be symmetric")
    low = np.linalg.eigvalsh(a).min()
    # strict: numerically positive definite, so that a Cholesky factor exists (cond < 1e14)
    if low < (1e-14 * scale if strict else -1e-12 * scale) or (strict and low <= 0.0):
        raise ValueError(f"{name} must be positive {'definite' if strict else 'semi-definite'}, "
                         f"smallest eigenvalue {low:g} (largest entry {scale:g})")
    return a


def _factor(cov: np.ndarray) -> np.ndarray:
    """F with F F^T = cov for a PSD cov (eigen-decomposition, so a singular Q is fine)."""
    values, vectors = np.linalg.eigh(cov)
    return vectors * np.sqrt(np.clip(values, 0.0, None))


@dataclass(frozen=True, eq=False)
class LinearGaussian:
    """x(k+1) = A x(k) + b + w(k), w ~ N(0, Q). No input: ``inputs`` (..., 0) is accepted and ignored."""

    transition: np.ndarray
    drift: np.ndarray
    process_noise: np.ndarray
    kind: ClassVar[str] = "linear_gaussian"
    input_dim: ClassVar[int] = 0

    def __post_init__(self):
        A = _square("transition", self.transition)
        n = A.shape[0]
        b = np.asarray(self.drift, float)
        if b.shape != (n,) or not np.all(np.isfinite(b)):
            raise ValueError(f"drift must be a finite ({n},) vector, got shape {b.shape}")
        object.__setattr__(self, "transition", A)
        object.__setattr__(self, "drift", b)
        object.__setattr__(self, "process_noise", _covariance("process_noise", self.process_noise, n, strict=False))

    @property
    def state_dim(self) -> int:
        return self.transition.shape[0]

    @property
    def identity_jacobian(self) -> bool:
        return bool(np.array_equal(self.transition, np.eye(self.state_dim)))

    def function(self, state: np.ndarray, inputs: np.ndarray | None = None) -> np.ndarray:
        """A x + b for ``state`` (..., n)."""
        return np.asarray(state, float) @ self.transition.T + self.drift

    def jacobian(self, state: np.ndarray, inputs: np.ndarray | None = None) -> np.ndarray:
        return np.broadcast_to(self.transition, (*np.shape(state)[:-1], self.state_dim, self.state_dim))

    def covar(self, state: np.ndarray | None = None, inputs: np.ndarray | None = None) -> np.ndarray:
        if state is None:
            return self.process_noise
        return np.broadcast_to(self.process_noise, (*np.shape(state)[:-1], self.state_dim, self.state_dim))

    def rvs(self, rng: np.random.Generator, size: tuple[int, ...] = ()) -> np.ndarray:
        """Draws of w, shape (*size, n), from ``rng`` (one standard normal per component)."""
        white = rng.standard_normal((*size, self.state_dim))
        return white @ _factor(self.process_noise).T

    def known_input(self, steps: int) -> np.ndarray:
        """c(0..steps), c(0) = 0, c(k+1) = A c(k) + b: the part of x(k) due to the known input b.

        x(k) = xt(k) + c(k) where xt follows the input-free model xt(k+1) = A xt(k) + w(k): a
        filter written for b = 0 (fu2017's) runs on xt with measurements z - C c(k).
        """
        out = np.zeros((steps + 1, self.state_dim))
        for k in range(steps):
            out[k + 1] = self.transition @ out[k] + self.drift
        return out


@dataclass(frozen=True, eq=False)
class LinearObservation:
    """z_j = C x + v_j, v_j ~ N(0, V_j), for N sensors (agents) j; ``noise`` (N, m, m) or (m, m) for all."""

    matrix: np.ndarray
    noise: np.ndarray
    kind: ClassVar[str] = "linear_observation"

    def __post_init__(self):
        C = np.asarray(self.matrix, float)
        if C.ndim != 2 or not np.all(np.isfinite(C)):
            raise ValueError(f"matrix must be a finite (m, n) array, got shape {C.shape}")
        V = np.asarray(self.noise, float)
        per = V if V.ndim == 3 else V[None]
        checked = np.stack([_covariance(f"noise[{j}]" if V.ndim == 3 else "noise", v, C.shape[0], strict=True)
                            for j, v in enumerate(per)])
        object.__setattr__(self, "matrix", C)
        object.__setattr__(self, "noise", checked if V.ndim == 3 else checked[0])

    @property
    def dim(self) -> int:
        return self.matrix.shape[0]

    def noise_of(self, num_sensors: int) -> np.ndarray:
        """V_j of every sensor, shape (N, m, m)."""
        if self.noise.ndim == 3:
            if self.noise.shape[0] != num_sensors:
                raise ValueError(f"noise has {self.noise.shape[0]} sensors, expected {num_sensors}")
            return self.noise
        return np.broadcast_to(self.noise, (num_sensors, self.dim, self.dim)).copy()

    def function(self, state: np.ndarray) -> np.ndarray:
        return np.asarray(state, float) @ self.matrix.T

    def jacobian(self, state: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.matrix, (*np.shape(state)[:-1], *self.matrix.shape))

    def covar(self) -> np.ndarray:
        return self.noise

    def rvs(self, rng: np.random.Generator, size: tuple[int, ...], num_sensors: int) -> np.ndarray:
        """Draws of v_j, shape (*size, N, m): one standard normal per entry, coloured by each V_j."""
        white = rng.standard_normal((*size, num_sensors, self.dim))
        factors = np.linalg.cholesky(self.noise_of(num_sensors))
        return np.einsum("jab,...jb->...ja", factors, white)
