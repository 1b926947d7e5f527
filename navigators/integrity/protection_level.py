"""Horizontal protection levels (HPL) every terrain navigator publishes with its estimate.

A protection level is a radius about the published horizontal position that the true position lies inside
with probability at least 1 - integrity_risk per epoch, as the navigator's own belief states it:

- grid and particle filters (pmf, pf): the radius about the belief's weighted mean outside which the
  belief holds at most `integrity_risk` of its probability mass (`weighted_mass_radius`, a numba kernel over
  the points and their weights; `weighted_mass_radius_reference` is its plain numpy twin), plus a pad for
  what the points do not resolve (a point-mass cell's half diagonal, process noise not yet convolved);
- the Rao-Blackwellized particle filter (rbpf): its marginal position posterior is a Gaussian mixture, each
  particle the Gaussian its position was drawn from at the last time update (seed 002 eq 5: its own Kalman
  covariance P reaching the position through the error model's B, N_k = B P_k B' + Q^n), weighted by the
  particle's weight; `mixture_mass_radius` bounds that mixture's mass outside a radius about the published
  position from above (numba; tests check it against Monte Carlo draws of the mixture). A point cloud's
  mass radius alone (1,000 points for a 1e-3 tail) ignores that spread and is too tight;
- Gaussian filters (ins_tercom, acq_track): `gaussian_hpl`, the radius r with P(|e| > r) <= integrity_risk
  for a zero-mean Gaussian horizontal error with covariance P: r = sigma_major sqrt(-2 ln risk),
  sigma_major^2 the largest eigenvalue of P's horizontal block (exact for a circular error; an elliptical
  one is dominated by the circle of its major axis, |A z| <= ||A|| |z|), plus the EKF's fault allowance
  (`fault_allowance_m`): the largest shift an undetected faulty position fix can make, a fix just inside
  the innovation gate d^2 <= gamma moving the state by K b with b' S^-1 b <= gamma, i.e.
  sqrt(gamma lambda_max(P S^-1 P)) for the fix's prior horizontal covariance P and innovation covariance S.

The HPL is published under one `Estimate.extra` key, EXTRA_PROTECTION_LEVEL, with the risk it was computed
for under EXTRA_INTEGRITY_RISK; the closed loop logs it (est_hpl_m) and trn_env.output.integrity_metrics
turns logs into misleading-information rates, availability and Stanford diagrams. Certification practice
(RTCA DO-229 for GNSS) is the model: misleading information = error above the HPL while the navigator says
it is healthy; hazardously misleading = error above the alert limit while the HPL is below it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

EXTRA_PROTECTION_LEVEL = "hpl_m"          # float: horizontal protection level, m (NaN: none yet)
EXTRA_INTEGRITY_RISK = "integrity_risk"   # float: the per-epoch integrity risk the HPL is computed for
DEFAULT_INTEGRITY_RISK = 1e-3             # per epoch: measurable here (1e5 epochs resolve it)
# str: "" where the navigator's HPL was validated for its condition, else why not (`set_condition`)
EXTRA_PL_NOT_VALIDATED = "pl_not_validated"


def check_integrity_risk(value, name: str = "integrity_risk") -> float:
    """float(value) if it lies in (0, 1), else ValueError naming the setting."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: must be a probability in (0, 1), got {value!r}") from None
    if isinstance(value, bool) or not (0.0 < v < 1.0):
        raise ValueError(f"{name}: must be a probability in (0, 1) per epoch, got {value!r}")
    return v


def check_alert_limit(value, name: str = "alert_limit_m") -> float:
    """float(value) if it is a finite number >= 0 (m), else ValueError naming the setting."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: must be a finite distance >= 0 m, got {value!r}") from None
    if isinstance(value, bool) or not (math.isfinite(v) and v >= 0.0):
        raise ValueError(f"{name}: must be a finite distance >= 0 m, got {value!r}")
    return v


@njit(cache=True)
def weighted_mass_radius(dn_m, de_m, w, risk):
    """Radius (m) about the weighted mean of the points (dn_m, de_m) with weights w (any positive scale)
    outside which at most `risk` of the total weight lies; NaN for no finite positive weight.

    The points are taken in increasing distance, their weights summed until the sum reaches (1 - risk) of
    the total: the distance of that point. The order comes from a bucket sort (_mass_radius_scan), linear
    in the points where a full sort of a point-mass grid's 40,000 cells dominated the filter's epoch."""
    n = dn_m.shape[0]
    tot = 0.0
    mn = 0.0
    me = 0.0
    for i in range(n):
        wi = w[i]
        if wi > 0.0 and dn_m[i] == dn_m[i] and de_m[i] == de_m[i]:
            tot += wi
            mn += wi * dn_m[i]
            me += wi * de_m[i]
    if not tot > 0.0:
        return np.nan
    mn /= tot
    me /= tot
    d = np.empty(n)
    for i in range(n):
        if w[i] > 0.0 and dn_m[i] == dn_m[i] and de_m[i] == de_m[i]:
            d[i] = math.hypot(dn_m[i] - mn, de_m[i] - me)
        else:
            d[i] = -1.0                 # left out
    return _mass_radius_scan(d, w, (1.0 - risk) * tot * (1.0 - 1e-12))


_BUCKET_SORT_MAX = 32      # a bucket with more points is sorted with np.argsort, not by insertion


@njit(cache=True)
def _mass_radius_scan(d, w, need):
    """The distance d[i] (>= 0; negative: left out) of the point at which the weights, summed in increasing
    distance, first reach `need`; the largest distance if they never do (rounding). Buckets of equal width
    in distance (about 4 points each, so the index floor(d / width) never decreases with d) are filled in
    one pass and each sorted only when the scan reaches it."""
    n = d.shape[0]
    n_ok = 0
    d_max = 0.0
    for i in range(n):
        if d[i] >= 0.0:
            n_ok += 1
            if d[i] > d_max:
                d_max = d[i]
    nb = max(n_ok // 4, 1)
    scale = nb / d_max if d_max > 0.0 else 0.0
    start = np.zeros(nb + 1, np.int64)
    for i in range(n):
        if d[i] >= 0.0:
            start[min(int(d[i] * scale), nb - 1) + 1] += 1
    for b in range(nb):
        start[b + 1] += start[b]
    fill = start[:nb].copy()
    idx = np.empty(n_ok, np.int64)
    for i in range(n):
        if d[i] >= 0.0:
            b = min(int(d[i] * scale), nb - 1)
            idx[fill[b]] = i
            fill[b] += 1
    cum = 0.0
    for b in range(nb):
        lo = start[b]
        hi = start[b + 1]
        if hi - lo > _BUCKET_SORT_MAX:     # crowded (points far from the rest stretch the buckets)
            part = idx[lo:hi].copy()
            order = np.argsort(d[part])
            for k in range(hi - lo):
                idx[lo + k] = part[order[k]]
        else:
            for k in range(lo + 1, hi):    # insertion sort
                v = idx[k]
                dv = d[v]
                m = k - 1
                while m >= lo and d[idx[m]] > dv:
                    idx[m + 1] = idx[m]
                    m -= 1
                idx[m + 1] = v
        for k in range(lo, hi):
            i = idx[k]
            cum += w[i]
            if cum >= need:
                return d[i]
    return d_max


def weighted_mass_radius_reference(dn_m, de_m, w, risk) -> float:
    """Plain numpy twin of weighted_mass_radius (for tests): the smallest point distance r about the weighted
    mean with the weight of the points farther than r at most risk * total."""
    dn_m, de_m, w = (np.asarray(x, float) for x in (dn_m, de_m, w))
    ok = (w > 0) & np.isfinite(dn_m) & np.isfinite(de_m)
    if not ok.any():
        return float("nan")
    dn_m, de_m, w = dn_m[ok], de_m[ok], w[ok]
    mn, me = np.average(dn_m, weights=w), np.average(de_m, weights=w)
    d = np.hypot(dn_m - mn, de_m - me)
    for r in np.sort(d):
        if w[d > r].sum() <= risk * w.sum() * (1 + 1e-9):
            return float(r)
    return float(d.max())


def gaussian_hpl(cov_ne: np.ndarray, risk: float) -> float:
    """sigma_major sqrt(-2 ln risk): P(|e| > HPL) <= risk for e ~ N(0, cov_ne) (2 x 2, m^2); NaN if the
    covariance is not finite."""
    c = np.asarray(cov_ne, float)[:2, :2]
    if not np.all(np.isfinite(c)):
        return float("nan")
    a, b, d = c[0, 0], 0.5 * (c[0, 1] + c[1, 0]), c[1, 1]
    lam = 0.5 * (a + d) + math.sqrt(max(0.25 * (a - d) ** 2 + b * b, 0.0))
    return math.sqrt(max(lam, 0.0)) * math.sqrt(-2.0 * math.log(risk))


def fault_allowance_m(cov_prior_ne: np.ndarray, s_innov: np.ndarray, gate_chi2: float) -> float:
    """Largest horizontal shift (m) a position fix inside the innovation gate can make: sqrt(gamma
    lambda_max(P S^-1 P)) (module docstring); P the prior horizontal covariance, S the fix's innovation
    covariance (2 x 2, m^2), gamma the gate's chi-square threshold."""
    P = np.asarray(cov_prior_ne, float)[:2, :2]
    S = np.asarray(s_innov, float)[:2, :2]
    if not (np.all(np.isfinite(P)) and np.all(np.isfinite(S))) or not math.isfinite(gate_chi2):
        return float("nan")
    M = P @ np.linalg.solve(S, P)
    lam = float(np.max(np.linalg.eigvalsh(0.5 * (M + M.T))))
    return math.sqrt(max(gate_chi2, 0.0) * max(lam, 0.0))


def particle_hpl(dn_m, de_m, w, risk: float, pad_m: float = 0.0) -> float:
    """weighted_mass_radius of the points plus pad_m (m)."""
    r = weighted_mass_radius(np.ascontiguousarray(dn_m, dtype=np.float64),
                             np.ascontiguousarray(de_m, dtype=np.float64),
                             np.ascontiguousarray(w, dtype=np.float64), float(risk))
    return float(r) + float(pad_m)


@njit(cache=True)
def mixture_mass_radius(dn_m, de_m, var_major_m2, w, risk):
    """Radius r (m) about the origin (the published position) with sum_k w_k T_k(r) <= risk sum_k w_k for
    the Gaussian mixture sum_k w_k N((dn_k, de_k), C_k), var_major_m2[k] = lambda_max(C_k) (m^2):
    T_k(r) = exp(-max(r - d_k, 0)^2 / (2 lambda_k)) bounds P(|x_k| > r) from above (|x_k| <= d_k + |y_k|,
    d_k = |mean_k|, and P(|y_k| > s) <= exp(-s^2 / (2 lambda_k)) for y_k ~ N(0, C_k), exact for a circular
    C_k); a component with lambda_k = 0 is a point (T_k = 1 if d_k > r, else 0). Bisection on the
    decreasing sum; NaN for no finite positive weight."""
    n = dn_m.shape[0]
    tot = 0.0
    hi = 0.0
    big = math.sqrt(-2.0 * math.log(risk))
    d_k = np.empty(n)          # the finite, positively weighted components, in order, with |mean_k|
    w_k = np.empty(n)
    var_k = np.empty(n)
    m = 0
    for k in range(n):
        if w[k] > 0.0 and dn_m[k] == dn_m[k] and de_m[k] == de_m[k] and var_major_m2[k] == var_major_m2[k]:
            tot += w[k]
            d = math.hypot(dn_m[k], de_m[k])
            r_k = d + math.sqrt(max(var_major_m2[k], 0.0)) * big
            if r_k > hi:
                hi = r_k
            d_k[m] = d
            w_k[m] = w[k]
            var_k[m] = var_major_m2[k]
            m += 1
    if not tot > 0.0:
        return np.nan
    lo = 0.0
    target = risk * tot
    for _ in range(60):
        r = 0.5 * (lo + hi)
        tail = 0.0
        for k in range(m):
            if d_k[k] > r:
                tail += w_k[k]
            elif var_k[k] > 0.0:
                tail += w_k[k] * math.exp(-0.5 * (r - d_k[k]) ** 2 / var_k[k])
        if tail <= target:
            hi = r
        else:
            lo = r
        if hi - lo <= 1e-6 * max(hi, 1.0):
            break
    return hi


def major_variances(cov_ne: np.ndarray) -> np.ndarray:
    """lambda_max of each 2 x 2 block of cov_ne (K, 2, 2), m^2."""
    c = np.asarray(cov_ne, float)
    a, d = c[:, 0, 0], c[:, 1, 1]
    b = 0.5 * (c[:, 0, 1] + c[:, 1, 0])
    return 0.5 * (a + d) + np.sqrt(np.maximum(0.25 * (a - d) ** 2 + b * b, 0.0))


def mixture_hpl(dn_m, de_m, cov_ne, w, risk: float) -> float:
    """mixture_mass_radius of the mixture sum_k w_k N((dn_k, de_k), cov_ne[k]) (cov_ne (K, 2, 2), m^2)."""
    return float(mixture_mass_radius(np.ascontiguousarray(dn_m, dtype=np.float64),
                                     np.ascontiguousarray(de_m, dtype=np.float64),
                                     np.ascontiguousarray(major_variances(cov_ne), dtype=np.float64),
                                     np.ascontiguousarray(w, dtype=np.float64), float(risk)))


def configure(navigator, integrity_risk=DEFAULT_INTEGRITY_RISK, map_horizontal_sigma_m=0.0) -> None:
    """Set a navigator's integrity_risk and map_horizontal_sigma_m (validated, ValueError naming the
    setting); navigators.registry.create does it for every navigator."""
    navigator.integrity_risk = check_integrity_risk(integrity_risk)
    try:
        sh = float(map_horizontal_sigma_m)
    except (TypeError, ValueError):
        sh = float("nan")
    if not (math.isfinite(sh) and sh >= 0.0):
        raise ValueError(f"map_horizontal_sigma_m: must be a finite sigma >= 0 m, got "
                         f"{map_horizontal_sigma_m!r}")
    navigator.map_horizontal_sigma_m = sh


def set_condition(navigator, condition: str, validated: tuple[str, ...] = (),
                  settings_differ: tuple[str, ...] = (), declared: tuple[str, ...] = ()) -> None:
    """State the condition a navigator runs under ("<IMU grade>/<map class>", see
    navigators.core.capabilities.Capabilities.pl_validated) against the conditions its protection level was
    validated on (`validated`, at DEFAULT_INTEGRITY_RISK): from then on `publish` puts
    EXTRA_PL_NOT_VALIDATED into every estimate, "" when the condition is one of them at the default risk,
    else a sentence naming the condition. With `settings_differ` (Capabilities.pl_declaration: settings
    other than the campaign's) the sentence names them and the conditions `declared` for the campaign's.
    The scenario build calls it (trn_env.scenario.navigation)."""
    condition = str(condition)
    risk = float(getattr(navigator, "integrity_risk", DEFAULT_INTEGRITY_RISK))
    name = getattr(navigator, "name", type(navigator).__name__)
    tried = ", ".join(validated) if validated else "none"
    if settings_differ:
        on = ", ".join(declared) if declared else "none"
        navigator.pl_not_validated = (f"{name}: protection level not validated under {condition} with "
                                      f"{', '.join(settings_differ)} (with the campaign's settings, "
                                      f"validated at {DEFAULT_INTEGRITY_RISK:g} per epoch on: {on})")
    elif condition not in validated:
        navigator.pl_not_validated = (f"{name}: protection level not validated under {condition} (validated "
                                      f"at {DEFAULT_INTEGRITY_RISK:g} per epoch on: {tried})")
    elif risk != DEFAULT_INTEGRITY_RISK:
        navigator.pl_not_validated = (f"{name}: protection level validated under {condition} at "
                                      f"{DEFAULT_INTEGRITY_RISK:g} per epoch, not at {risk:g}")
    else:
        navigator.pl_not_validated = ""


def filter_risk(navigator) -> float:
    """The share of the navigator's integrity risk its filter's HPL is computed for: all of it, or half when
    the map's horizontal error takes the other half (union bound, `publish`)."""
    risk = float(getattr(navigator, "integrity_risk", DEFAULT_INTEGRITY_RISK))
    return 0.5 * risk if getattr(navigator, "map_horizontal_sigma_m", 0.0) > 0.0 else risk


def publish(extra: dict, filter_hpl_m: float, navigator) -> dict:
    """Put the navigator's HPL and its risk into an Estimate.extra dict (returned): the filter's HPL
    (computed at filter_risk) plus, when the map has a horizontal error of sigma map_horizontal_sigma_m per
    axis (its accuracy class's CE90 / 2.146; a map shifted by s moves every terrain fix by s, and the
    filter's belief cannot see it), the Gaussian bound of that error at the other half of the risk; and,
    once `set_condition` has stated the navigator's condition, EXTRA_PL_NOT_VALIDATED."""
    risk = float(getattr(navigator, "integrity_risk", DEFAULT_INTEGRITY_RISK))
    sh = float(getattr(navigator, "map_horizontal_sigma_m", 0.0))
    hpl = float(filter_hpl_m)
    if sh > 0.0:
        hpl += gaussian_hpl(np.eye(2) * sh * sh, 0.5 * risk)
    extra[EXTRA_PROTECTION_LEVEL] = hpl
    extra[EXTRA_INTEGRITY_RISK] = risk
    statement = getattr(navigator, "pl_not_validated", None)
    if statement is not None:
        extra[EXTRA_PL_NOT_VALIDATED] = statement
    return extra
