"""Small linear-algebra checks the filters share."""

from __future__ import annotations

import numpy as np


def is_positive_definite(P: np.ndarray) -> bool:
    """True when P is finite and its symmetric part has a Cholesky factor (positive definite)."""
    if not np.all(np.isfinite(P)):
        return False
    try:
        np.linalg.cholesky(0.5 * (P + P.T))
        return True
    except np.linalg.LinAlgError:
        return False


def floored_psd(cov: np.ndarray, what: str, floor: float = 1e-10) -> np.ndarray:
    """`cov` when positive definite; a positive semi-definite one (a perfectly known start: zero sigmas) with
    its symmetric part's eigenvalues floored at `floor`, so a filter's algebra stays defined. ValueError
    naming `what` for a negative eigenvalue (beyond round-off)."""
    if is_positive_definite(cov):
        return cov
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    if w.min() < -1e-9 * max(1.0, float(np.abs(w).max())):
        raise ValueError(f"{what} must be positive semi-definite (it has a negative eigenvalue "
                         f"{w.min():.3g})")
    return (V * np.maximum(w, floor)) @ V.T
