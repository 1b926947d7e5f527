"""Particle resampling, the one module the particle filters (pf, rbpf) share: systematic resampling (numba)
with a required numpy Generator, and the effective sample size.

`systematic_indices(weights, rng)` draws one uniform u ~ U[0, 1/M) from `rng` and returns the indexes
i_k = min{i : cumsum(w)_i > u + k/M}, k = 0..M-1 (Kitagawa 1996): every particle of weight w is copied
floor(M w) or ceil(M w) times, the lowest-variance of the standard schemes. Weights need not be normalised.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, fastmath=False, error_model="numpy")
def systematic_kernel(weights, u0, out):
    """Indexes of systematic resampling for offsets (u0 + k) / M (u0 in [0, 1)) into out (M,) int64."""
    m = weights.shape[0]
    total = 0.0
    for i in range(m):
        total += weights[i]
    step = total / m
    u = u0 * step
    c = weights[0]
    i = 0
    for k in range(m):
        while u > c and i < m - 1:
            i += 1
            c += weights[i]
        out[k] = i
        u += step


def systematic_indices(weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Systematic resampling indexes (int64, same length as weights) with the one uniform from rng."""
    w = np.ascontiguousarray(weights, dtype=np.float64)
    if w.ndim != 1 or w.shape[0] == 0 or not np.all(np.isfinite(w)) or np.any(w < 0) or not w.sum() > 0:
        raise ValueError("weights must be a non-empty 1-D array of finite non-negative numbers, not all 0")
    out = np.empty(w.shape[0], np.int64)
    systematic_kernel(w, float(rng.random()), out)
    return out


def systematic_indices_u0(weights: np.ndarray, u0: float) -> np.ndarray:
    """Systematic resampling indexes (int64) of finite non-negative weights for the uniform u0 in [0, 1)
    the caller drew from its Generator (no checks: the filters' hot path)."""
    out = np.empty(weights.shape[0], np.int64)
    systematic_kernel(np.ascontiguousarray(weights, dtype=np.float64), u0, out)
    return out


def systematic_indices_reference(weights: np.ndarray, u0: float) -> np.ndarray:
    """systematic_kernel in numpy (searchsorted on the cumulative weights)."""
    w = np.asarray(weights, float)
    m = w.shape[0]
    c = np.cumsum(w / w.sum())
    u = (u0 + np.arange(m)) / m
    return np.minimum(np.searchsorted(c, u, side="left"), m - 1)


def effective_sample_size(log_weights: np.ndarray) -> float:
    """1 / sum(w^2) of the normalised weights exp(log_weights)."""
    lw = np.asarray(log_weights, float)
    w = np.exp(lw - lw.max())
    w /= w.sum()
    return float(1.0 / np.sum(w * w))
