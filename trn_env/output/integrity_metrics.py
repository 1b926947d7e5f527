"""Navigator integrity figures of a run from its Health.status words (estimate vs truth): how long the
navigator said "ok", and how much of that time its true error lay outside its own 3 sigma (misleading
information); and, for a navigator meeting a fault, whether its flag came before its error left 3 sigma.

Pure functions of logged arrays, so summary.json and offline studies share them. trn_env/output/metrics.py
carries the campaign metrics from Health.ok (fraction_healthy, misleading_information_time_s); these
status-based figures are named apart (status_ok_*) and are meant to join them there.
"""

from __future__ import annotations

import numpy as np

HEALTHY_STATUSES = ("ok",)
FLAG_STATUSES = ("degraded", "diverged", "lost")      # the navigator says it should not be trusted
# the log's nav_status_code values (trn_env.sim.log.NAV_STATUS_CODES): 0 is "ok"
HEALTHY_CODE = 0


def _flagged(status: np.ndarray) -> np.ndarray:
    """Rows whose status is one of FLAG_STATUSES (words or the log's nav_status_code)."""
    st = np.asarray(status)
    if st.dtype.kind in "iu":
        return np.isin(st, [2, 3, 5])          # trn_env.sim.log.NAV_STATUS_CODES indexes of FLAG_STATUSES
    return np.isin(st.astype(str), FLAG_STATUSES)


def _healthy(status: np.ndarray) -> np.ndarray:
    """Healthy rows from Health.status words or the log's nav_status_code integers."""
    st = np.asarray(status)
    if st.dtype.kind in "iu":
        return st == HEALTHY_CODE
    return np.isin(st.astype(str), HEALTHY_STATUSES)


def integrity_metrics(t_s: np.ndarray, err_ned_m: np.ndarray, cov_diag: np.ndarray, status: np.ndarray,
                      k_sigma: float = 3.0) -> dict:
    """status_ok_fraction: time share of rows whose Health.status is "ok" (status: Health.status words or
    the log's nav_status_code); status_ok_misleading_fraction: share of that time with the north or east
    error outside k_sigma times its own sigma; status_ok_misleading_time_s: that time in seconds. Row i
    holds for t[i] - t[i-1] (row 0: nothing)."""
    t = np.asarray(t_s, float)
    if t.size < 2:
        return {"status_ok_fraction": None, "status_ok_misleading_fraction": None,
                "status_ok_misleading_time_s": 0.0}
    w = np.diff(t, prepend=t[0])
    healthy = _healthy(status)
    sig = np.sqrt(np.clip(np.asarray(cov_diag, float)[:, :2], 0.0, None))
    err = np.asarray(err_ned_m, float)[:, :2]
    outside = np.any(~(np.abs(err) <= k_sigma * sig), axis=1)
    total = float(w.sum())
    t_healthy = float(w[healthy].sum())
    t_mi = float(w[healthy & outside].sum())
    return {
        "status_ok_fraction": t_healthy / total if total > 0 else None,
        "status_ok_misleading_fraction": t_mi / t_healthy if t_healthy > 0 else None,
        "status_ok_misleading_time_s": t_mi,
    }


def first_time(t_s: np.ndarray, mask: np.ndarray) -> float | None:
    """The first time where mask is True (None if never)."""
    m = np.asarray(mask, bool)
    return float(np.asarray(t_s)[np.argmax(m)]) if m.any() else None


def flag_before_error(t_s: np.ndarray, err_ned_m: np.ndarray, cov_diag: np.ndarray, status: np.ndarray,
                      t_from_s: float = 0.0, k_sigma: float = 3.0) -> dict:
    """For a navigator meeting a fault at t_from_s: the first time after it that the navigator flagged
    itself (status "degraded", "diverged" or "lost"), the first time its error left k_sigma sigma, and
    whether the flag came first (True too if the error never left; False if it left unflagged)."""
    t = np.asarray(t_s, float)
    after = t >= t_from_s
    sig = np.sqrt(np.clip(np.asarray(cov_diag, float)[:, :2], 0.0, None))
    outside = np.any(~(np.abs(np.asarray(err_ned_m, float)[:, :2]) <= k_sigma * sig), axis=1)
    flagged = _flagged(status)
    t_flag = first_time(t, after & flagged)
    t_err = first_time(t, after & outside)
    if t_err is None:
        first = True
    elif t_flag is None:
        first = False
    else:
        first = t_flag <= t_err
    return {"t_flag_s": t_flag, "t_error_outside_s": t_err, "flag_first": first}
