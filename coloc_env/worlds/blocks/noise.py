"""Gaussian noise from a fixed covariance, drawn as standard normals times a factor.

``rng.multivariate_normal`` factorizes the covariance (an SVD) on every call;
a scenario that draws each copy's whole episode at reset calls it thousands
of times, so the factor is computed once here instead.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg


def covariance_factor(covariance: np.ndarray) -> np.ndarray:
    """F with F F^T = covariance: the lower Cholesky factor, or an eigen-factor if only PSD."""
    covariance = np.asarray(covariance, float)
    try:
        return scipy.linalg.cholesky(covariance, lower=True)
    except np.linalg.LinAlgError:
        values, vectors = np.linalg.eigh(0.5 * (covariance + covariance.T))
        return vectors * np.sqrt(np.clip(values, 0.0, None))


def sample_gaussian(rng: np.random.Generator, factor: np.ndarray, size: tuple[int, ...]) -> np.ndarray:
    """Zero-mean samples of shape ``(*size, n)`` with covariance ``factor @ factor.T``."""
    return rng.standard_normal((*size, factor.shape[-1])) @ factor.T
