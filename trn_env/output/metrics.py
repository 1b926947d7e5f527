"""Navigation metrics: pure functions of the estimate against the truth over one run.

Inputs are a run's log arrays (`trn_env.sim.SimLog.arrays`): `t_s` (s), `err_ned_m` (estimate minus truth,
NED metres, N x 3), `est_cov` (N x 9 x 9, the first three rows/columns the NED position block, m^2) or
`est_cov_diag` (N x 9), `nav_ok` (navigator health ok). The single-flight summary.json and the campaign
rows both take their figures from `navigation_metrics`, so a number means the same thing in both.

Time weighting: the rows are samples of a piecewise-constant signal, each holding until the next row. A
"fraction of time" or a "time" is therefore sum(dt_i * flag_i) over the intervals [t_i, t_i+1) (the last
row starts no interval); sample statistics (RMS, CEP, NEES means) use every row once.

Definitions (horizontal error e_h = |(e_n, e_e)|, vertical error e_v = -e_d, i.e. up positive):
- RMS: sqrt(mean(e^2)) over the rows; CEP50 / CEP95: the 50th / 95th percentile of e_h over the rows
  (linear interpolation between order statistics, numpy's default).
- max and final e_h.
- NEES_i = p_i^T P_i^-1 p_i with p the NED position error and P the 3 x 3 position covariance (dof 3);
  ANEES = mean over the rows. For a consistent filter and n independent rows, n * ANEES ~ chi2(3 n), so the
  two-sided 95 % bounds are chi2.ppf([0.025, 0.975], 3 n) / n (Bar-Shalom, Li & Kirubarajan 2001, sec.
  5.4.2). Successive rows of one run are correlated, so the per-run bounds are indicative; the campaign's
  ANEES over runs at one time is the exact form of the same test.
- inside 3 sigma: |e_n| <= 3 sigma_n and |e_e| <= 3 sigma_e (the existing summary's definition).
- time to converge: the first time (from the run's start) after which e_h stays below the threshold to the
  end of the run; NaN if the last row is not below it.
- track loss: e_h above `track_loss_threshold_m`, or above k * sigma_h (sigma_h = sqrt(P_nn + P_ee)), without
  a break for at least `track_loss_min_s`; reported as a flag, the time the first loss is declared (the
  start of the excursion + min_s) and the total time spent in such excursions.
- fraction healthy: time with nav_ok / total time.
- misleading-information time: time when the navigator reports healthy while outside 3 sigma.
- protection levels (`est_hpl_m`, navigators.integrity.protection_level): per-row misleading-information
  rate (e_h > HPL while healthy) with its Clopper-Pearson bound, hazardous rate against the alert limit,
  availability (trn_env.output.integrity_metrics.protection_level_metrics).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from trn_env.output.chunked import ChunkedRows, diagonals, iter_chunks
from trn_env.output.integrity_metrics import PL_METRIC_KEYS, protection_level_metrics


@dataclass(frozen=True)
class MetricSettings:
    """Thresholds of the run metrics (a campaign file's `[metrics]` table overrides them)."""

    converge_threshold_m: float = 50.0       # time to converge: horizontal error below this, m
    track_loss_threshold_m: float = 250.0    # track loss: horizontal error above this, m ...
    track_loss_k_sigma: float = 5.0          # ... or above k * sigma_h (0 disables the sigma test)
    track_loss_min_s: float = 10.0           # ... for at least this long, s
    alert_limit_m: float = 185.2             # horizontal alert limit of the protection-level metrics, m

    def __post_init__(self):
        for name, value in asdict(self).items():
            if not (isinstance(value, (int, float)) and math.isfinite(value)) or isinstance(value, bool):
                raise ValueError(f"metrics.{name}: must be a finite number (got {value!r})")
            if name == "alert_limit_m":
                from trn_env.navigators.integrity.protection_level import check_alert_limit
                check_alert_limit(value, "metrics.alert_limit_m")
            elif value < 0 or (name != "track_loss_k_sigma" and name != "track_loss_min_s" and value == 0):
                raise ValueError(f"metrics.{name}: must be positive (got {value!r})")


def _durations(t_s: np.ndarray) -> np.ndarray:
    """Duration each row holds: t[i+1] - t[i], 0 for the last row."""
    t = np.asarray(t_s, float)
    return np.append(np.diff(t), 0.0) if t.size else t


def rms(x: np.ndarray) -> float:
    """Root mean square of the finite values (NaN if none)."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x * x))) if x.size else float("nan")


def cep(e_h_m: np.ndarray, percent: float) -> float:
    """Circular error probable: the `percent` percentile of the horizontal error, m (NaN if empty)."""
    e = np.asarray(e_h_m, float)
    e = e[np.isfinite(e)]
    return float(np.percentile(e, percent)) if e.size else float("nan")


def time_fraction(t_s: np.ndarray, flag: np.ndarray) -> float:
    """Fraction of the run's time during which `flag` holds (rows hold until the next row)."""
    dt = _durations(t_s)
    total = float(dt.sum())
    return float(np.sum(dt * np.asarray(flag, bool)) / total) if total > 0 else float("nan")


def time_where(t_s: np.ndarray, flag: np.ndarray) -> float:
    """Seconds during which `flag` holds."""
    return float(np.sum(_durations(t_s) * np.asarray(flag, bool)))


def position_nees(err_ned_m: np.ndarray, cov_pos: np.ndarray) -> np.ndarray:
    """NEES of the NED position per row: p^T P^-1 p (dof 3); NaN where P is singular or not finite."""
    err = np.asarray(err_ned_m, float).reshape(-1, 3)
    cov = np.asarray(cov_pos, float).reshape(-1, 3, 3)
    out = np.full(err.shape[0], np.nan)
    ok = np.all(np.isfinite(cov.reshape(-1, 9)), axis=1) & np.all(np.isfinite(err), axis=1)
    if not np.any(ok):
        return out
    cov_ok = cov[ok]
    good = np.linalg.det(cov_ok) > 0
    idx = np.flatnonzero(ok)[good]
    if idx.size:
        x = np.linalg.solve(cov[idx], err[idx][..., None])[..., 0]
        out[idx] = np.einsum("ij,ij->i", err[idx], x)
    return out


def anees_bounds(n: int, dof: int = 3, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided bounds on the mean of n independent chi2(dof) values: chi2.ppf((1 -+ c) / 2, n dof) / n."""
    from scipy.stats import chi2
    if n <= 0:
        return float("nan"), float("nan")
    a = (1.0 - confidence) / 2.0
    return float(chi2.ppf(a, n * dof) / n), float(chi2.ppf(1.0 - a, n * dof) / n)


def time_to_converge(t_s: np.ndarray, e_h_m: np.ndarray, threshold_m: float) -> float:
    """Seconds from the first row to the row after which e_h stays below the threshold; NaN if the run
    ends above it."""
    t = np.asarray(t_s, float)
    below = np.asarray(e_h_m, float) < threshold_m
    if not below.size or not below[-1]:
        return float("nan")
    above = np.flatnonzero(~below)
    first = 0 if not above.size else above[-1] + 1
    return float(t[first] - t[0])


def excursions(flag: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) row indices of the runs of consecutive True values (stop exclusive)."""
    f = np.concatenate([[False], np.asarray(flag, bool), [False]])
    d = np.diff(f.astype(np.int8))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def track_loss(t_s: np.ndarray, e_h_m: np.ndarray, sigma_h_m: np.ndarray, threshold_m: float,
               k_sigma: float, min_s: float) -> tuple[bool, float, float]:
    """(lost, time of the first declared loss from the run's start (NaN if none), total seconds in loss
    excursions). An excursion lasts from its first row to the row after its last (rows hold until the
    next)."""
    t = np.asarray(t_s, float)
    e = np.asarray(e_h_m, float)
    bad = ~np.isfinite(e) | (e > threshold_m)
    if k_sigma > 0:
        bad |= e > k_sigma * np.asarray(sigma_h_m, float)
    first, total = float("nan"), 0.0
    for i0, i1 in excursions(bad):
        end = t[i1] if i1 < t.size else t[-1]
        length = end - t[i0]
        if length >= min_s and length > 0:
            total += length
            if not math.isfinite(first):
                first = float(t[i0] + min_s - t[0])
    return math.isfinite(first), first, total


def inside_3sigma(err_ned_m: np.ndarray, cov_diag: np.ndarray) -> np.ndarray:
    """Per row: |e_n| <= 3 sigma_n and |e_e| <= 3 sigma_e."""
    err = np.asarray(err_ned_m, float).reshape(-1, 3)
    sig = np.sqrt(np.clip(np.asarray(cov_diag, float)[:, :2], 0.0, None))
    return (np.abs(err[:, 0]) <= 3 * sig[:, 0]) & (np.abs(err[:, 1]) <= 3 * sig[:, 1])


# The keys `navigation_metrics` returns (campaign rows hold each as a float64 column, flags as 0/1).
METRIC_KEYS = (
    "horizontal_error_rms_m", "vertical_error_rms_m", "horizontal_error_cep50_m", "horizontal_error_cep95_m",
    "horizontal_error_max_m", "horizontal_error_final_m", "vertical_error_max_m", "vertical_error_final_m",
    "anees", "anees_lower_95", "anees_upper_95", "anees_inside_bounds", "fraction_within_3sigma",
    "time_to_converge_s", "track_lost", "track_loss_time_s", "track_lost_duration_s", "fraction_healthy",
    "misleading_information_time_s",
) + PL_METRIC_KEYS


def navigation_metrics(arrays: dict[str, np.ndarray], settings: MetricSettings | None = None) -> dict:
    """Every metric of METRIC_KEYS for one run's log arrays (definitions in the module docstring).

    Parameters
    ----------
    arrays : dict of str to ndarray
        The run's log arrays: ``t_s`` (s), ``err_ned_m`` (N x 3, estimate minus truth, m), ``est_cov`` or
        ``est_cov_diag`` (m^2), ``nav_ok`` (health flags).
    settings : MetricSettings, optional
        Thresholds of convergence and track loss (defaults: MetricSettings()).

    Returns
    -------
    dict
        One value per key of METRIC_KEYS (units in the key names; see the outputs reference).
    """
    s = settings or MetricSettings()
    t = np.asarray(arrays["t_s"], float)
    err = np.asarray(arrays["err_ned_m"], float).reshape(-1, 3)
    if "est_cov" in arrays:          # an array, or ChunkedRows read a chunk at a time (output.chunked)
        cov = arrays["est_cov"]
        if not isinstance(cov, ChunkedRows):
            cov_diag = np.diagonal(np.asarray(cov, float), axis1=1, axis2=2)
        elif "est_cov_diag" in arrays:     # (a streamed run's arrays hold the diagonal: SimLog.arrays)
            cov_diag = np.asarray(arrays["est_cov_diag"], float)
        else:
            cov_diag = diagonals(cov)
        nees = np.empty(err.shape[0])       # (row by row: the same values whatever the chunks)
        for start, block in iter_chunks(cov):
            block = np.asarray(block, float)
            rows = slice(start, start + block.shape[0])
            nees[rows] = position_nees(err[rows], block[:, :3, :3])
    else:
        cov_diag = np.asarray(arrays["est_cov_diag"], float)
        cov_pos = np.zeros((len(t), 3, 3))
        for k in range(3):
            cov_pos[:, k, k] = cov_diag[:, k]
        nees = position_nees(err, cov_pos)
    nav_ok = np.asarray(arrays.get("nav_ok", np.ones(len(t), bool)), bool)
    e_h = np.hypot(err[:, 0], err[:, 1])
    e_v = -err[:, 2]
    sig_h = np.sqrt(np.clip(cov_diag[:, 0], 0, None) + np.clip(cov_diag[:, 1], 0, None))
    nan = float("nan")
    n = int(t.size)
    finite = nees[np.isfinite(nees)]
    lo, hi = anees_bounds(finite.size)
    anees = float(finite.mean()) if finite.size else nan
    within = inside_3sigma(err, cov_diag)
    lost, loss_t, loss_total = track_loss(t, e_h, sig_h, s.track_loss_threshold_m, s.track_loss_k_sigma,
                                          s.track_loss_min_s) if n else (False, nan, 0.0)
    return {
        "horizontal_error_rms_m": rms(e_h),
        "vertical_error_rms_m": rms(e_v),
        "horizontal_error_cep50_m": cep(e_h, 50.0),
        "horizontal_error_cep95_m": cep(e_h, 95.0),
        "horizontal_error_max_m": float(np.nanmax(e_h)) if n and np.isfinite(e_h).any() else nan,
        "horizontal_error_final_m": float(e_h[-1]) if n else nan,
        "vertical_error_max_m": float(np.nanmax(np.abs(e_v))) if n and np.isfinite(e_v).any() else nan,
        "vertical_error_final_m": float(e_v[-1]) if n else nan,
        "anees": anees,
        "anees_lower_95": lo,
        "anees_upper_95": hi,
        "anees_inside_bounds": float(lo <= anees <= hi) if finite.size else nan,
        "fraction_within_3sigma": float(np.mean(within)) if n else nan,
        "time_to_converge_s": time_to_converge(t, e_h, s.converge_threshold_m),
        "track_lost": bool(lost),
        "track_loss_time_s": loss_t,
        "track_lost_duration_s": loss_total,
        "fraction_healthy": time_fraction(t, nav_ok) if n > 1 else (float(nav_ok[0]) if n else nan),
        "misleading_information_time_s": time_where(t, nav_ok & ~within),
    } | protection_level_metrics(e_h, np.asarray(arrays.get("est_hpl_m", np.full(n, np.nan)), float), nav_ok,
                                 s.alert_limit_m)


def horizontal_series(arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The per-row series a campaign keeps for its report: t_s, e_h, e_v (up positive), sigma_h, the
    horizontal protection level (NaN where none), metres; nav_ok as 0/1."""
    err = np.asarray(arrays["err_ned_m"], float).reshape(-1, 3)
    cd = np.asarray(arrays["est_cov_diag"], float)
    n = err.shape[0]
    return {
        "hpl_m": np.asarray(arrays.get("est_hpl_m", np.full(n, np.nan)), float),
        "nav_ok": np.asarray(arrays.get("nav_ok", np.ones(n, bool)), float),
        "t_s": np.asarray(arrays["t_s"], float),
        "err_h_m": np.hypot(err[:, 0], err[:, 1]),
        "err_v_m": -err[:, 2],
        "sigma_h_m": np.sqrt(np.clip(cd[:, 0], 0, None) + np.clip(cd[:, 1], 0, None)),
    }
