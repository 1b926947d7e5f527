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
FLAG_STATUSES = ("degraded", "diverged", "lost", "inconsistent")   # the navigator says: do not trust it
# the log's nav_status_code values (trn_env.sim.log.NAV_STATUS_CODES): 0 is "ok"
HEALTHY_CODE = 0


def _flagged(status: np.ndarray) -> np.ndarray:
    """Rows whose status is one of FLAG_STATUSES (words or the log's nav_status_code)."""
    st = np.asarray(status)
    if st.dtype.kind in "iu":
        return np.isin(st, [2, 3, 5, 6])       # trn_env.sim.log.NAV_STATUS_CODES indexes of FLAG_STATUSES
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


# ------------------------------------------------------------------------------------ protection levels

PL_METRIC_KEYS = ("pl_epochs", "pl_misleading_epochs", "pl_misleading_rate", "pl_misleading_rate_upper95",
                  "pl_hazardous_epochs", "pl_hazardous_rate", "pl_availability", "hpl_median_m")


def clopper_pearson_upper(k: int, n: int, confidence: float = 0.95) -> float:
    """One-sided Clopper-Pearson upper bound of a binomial proportion with k successes in n trials (NaN for
    n = 0)."""
    from scipy.stats import beta
    if n <= 0:
        return float("nan")
    return 1.0 if k >= n else float(beta.ppf(confidence, k + 1, n - k))


def protection_level_metrics(err_h_m: np.ndarray, hpl_m: np.ndarray, healthy: np.ndarray,
                             alert_limit_m: float) -> dict:
    """Per-epoch integrity of a navigator's horizontal protection level (one epoch per logged row):

    pl_epochs: rows where the navigator says it is healthy and publishes a finite HPL;
    pl_misleading_epochs / _rate: of those, rows with horizontal error > HPL (misleading information), and
    pl_misleading_rate_upper95 its one-sided 95 % Clopper-Pearson bound (rows are not independent: the
    bound counts them as if they were);
    pl_hazardous_epochs / _rate: healthy rows with error > alert limit while HPL <= alert limit (hazardously
    misleading), over pl_epochs;
    pl_availability: share of all rows that are healthy with HPL <= alert limit; hpl_median_m."""
    from trn_env.navigators.integrity.protection_level import check_alert_limit
    al = check_alert_limit(alert_limit_m)
    e = np.asarray(err_h_m, float)
    h = np.asarray(hpl_m, float)
    ok = np.asarray(healthy, bool) & np.isfinite(h) & np.isfinite(e)
    n = int(ok.sum())
    mi = int(np.count_nonzero(ok & (e > h)))
    hmi = int(np.count_nonzero(ok & (e > al) & (h <= al)))
    nan = float("nan")
    return {
        "pl_epochs": n,
        "pl_misleading_epochs": mi,
        "pl_misleading_rate": mi / n if n else nan,
        "pl_misleading_rate_upper95": clopper_pearson_upper(mi, n),
        "pl_hazardous_epochs": hmi,
        "pl_hazardous_rate": hmi / n if n else nan,
        "pl_availability": float(np.mean(ok & (h <= al))) if e.size else nan,
        "hpl_median_m": float(np.median(h[ok])) if n else nan,
    }
