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
