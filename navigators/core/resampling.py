"""Particle resampling, the one module the particle filters (pf, rbpf) share: systematic resampling (numba)
with a required numpy Generator, and the effective sample size.

`systematic_indices(weights, rng)` draws one uniform u ~ U[0, 1/M) from `rng` and returns the indexes
i_k = min{i : cumsum(w)_i > u + k/M}, k = 0..M-1 (Kitagawa 1996): every particle of weight w is copied
floor(M w) or ceil(M w) times, the lowest-variance of the standard schemes. Weights need not be normalised.

Regularisation (Musso, Oudjane & Le Gland 2001, "Improving regularised particle filters", in Doucet, de
Freitas & Gordon, Sequential Monte Carlo Methods in Practice, ch. 12): resampling copies particles, and with
small process noise the copies stay together (seed 002 sec. II-A: the cloud loses its diversity). The
regularised filter resamples from a kernel density estimate of the weighted posterior instead: each copy
moves by h D eps, eps ~ N(0, I_d), D D' the weighted empirical covariance of the cloud before resampling
(the kernel follows the posterior's shape and scale), and h the bandwidth that minimises the mean integrated
squared error of a Gaussian kernel estimate of a Gaussian density (MOL sec. 12.2; Silverman 1986 ch. 4,
the normal reference bandwidth),
h_opt = A N^(-1/(d + 4)), A = (4 / (d + 2))^(1/(d + 4)): `regularisation_bandwidth`,
`regularise_gaussian`. The copies' spread adds h^2 D D' to the cloud's covariance (the kernel estimate's
variance); with `shrink` (Liu & West 2001) the copies are first drawn towards the cloud's mean so that its
mean and covariance are kept and only its diversity grows.
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


def regularisation_bandwidth(n: int, d: int) -> float:
    """Optimal bandwidth h_opt = (4 / (d + 2))^(1/(d + 4)) N^(-1/(d + 4)) of a Gaussian kernel for N
    particles in d dimensions (see the module docstring; dimensionless, multiplies the cloud's sigma)."""
    if n < 1 or d < 1:
        raise ValueError(f"regularisation_bandwidth: n and d must be >= 1, got n={n}, d={d}")
    return (4.0 / (d + 2.0)) ** (1.0 / (d + 4.0)) * float(n) ** (-1.0 / (d + 4.0))


def regularise_gaussian(x: np.ndarray, cov: np.ndarray, h: float, rng: np.random.Generator,
                        shrink: bool = False) -> np.ndarray:
    """x (N, d) of resampled (equally weighted) particles moved in place by h D eps (D D' = cov, d x d,
    eps ~ N(0, I) from rng); returns x. With shrink (Liu & West 2001, "Combined parameter and state
    estimation in simulation-based filtering", in Doucet et al. 2001, ch. 10: kernel shrinkage), each is first
    drawn towards the cloud's mean m by a = sqrt(1 - h^2): x -> a x + (1 - a) m + h D eps, so the cloud keeps
    its mean and covariance (a^2 cov + h^2 cov) and gains only diversity (h < 1 required). A covariance
    that is not positive definite (a cloud collapsed onto one point, or a flat direction) takes its
    eigen-decomposition with the negative eigenvalues clipped to 0."""
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    D = v * np.sqrt(np.clip(w, 0.0, None))[None, :]
    if shrink:
        if not 0.0 <= h < 1.0:
            raise ValueError(f"regularise_gaussian: shrink needs a bandwidth in [0, 1), got {h!r}")
        a = np.sqrt(1.0 - h * h)
        m = x.mean(axis=0)
        x *= a
        x += (1.0 - a) * m
    x += h * (rng.standard_normal(x.shape) @ D.T)
    return x


def effective_sample_size(log_weights: np.ndarray) -> float:
    """1 / sum(w^2) of the normalised weights exp(log_weights)."""
    lw = np.asarray(log_weights, float)
    w = np.exp(lw - lw.max())
    w /= w.sum()
    return float(1.0 / np.sum(w * w))
