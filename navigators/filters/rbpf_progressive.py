"""Progressive correction of the Rao-Blackwellized particle filter's IRA update (rbpf_ira_update.py).

A measurement much sharper than the cloud can sample leaves a few particles with all the weight: the
resampled copies stack and the published spread collapses below the error (seed 002 sec. II-A's
impoverishment, met here within one update). Progressive correction (Oudjane & Musso 2000, "Progressive
correction for regularized particle filters", Proc. FUSION; Musso, Oudjane & Le Gland 2001, "Improving
regularised particle filters", in Doucet, de Freitas & Gordon, Sequential Monte Carlo Methods in Practice,
sec. 12.5) applies the likelihood in stages whose exponents sum to one, resampling and regularising between
them, so each stage's weights stay representable and the cloud moves into the likelihood's support before
the next, sharper one; the posterior after the last stage is the full one.

In the RBPF a stage of share lambda is the same measurement with the noise R / lambda: each particle's
Kalman part takes the information lambda R^-1 (eqs 10-12 with R / lambda), and its weight the predictive
density N(nu; 0, H P H' + R / lambda) (eq 9). For a measurement linear in x^l the shares' information adds
up to R^-1, so the Kalman parts after the stages are the single update's; the product of the stages'
predictive densities is N(nu; 0, H P H' + R) times a factor common to the particles (the pseudo-
measurements' residuals are zero), so the weights after the stages are the single update's as well. Each
stage's share is the largest for which the conditional effective sample size (Zhou, Johansen & Aston 2016,
"Toward automatic model comparison: an adaptive sequential Monte Carlo approach", JCGS 25, eq 3.5:
N (sum W_k G_k)^2 / sum W_k G_k^2, W the weights before the stage, G the stage's likelihood) keeps at least
ess_threshold N: the filter's own resampling criterion, so one stage is one weighting and resampling cycle
(the filter resamples between stages when the effective sample size is below that threshold).
A measurement the cloud already represents (the usual case) is one stage of share 1, the plain update.
"""

from __future__ import annotations

import math

import numpy as np

MAX_STAGES = 8           # stages per update; what is left after them is not used (Health counts it)
MIN_SHARE = 1e-3         # smallest share of a stage (relative to what is left)
_BISECTIONS = 24


def predictive_loglik(S0: np.ndarray, nu: np.ndarray, r_var: np.ndarray, share: float) -> np.ndarray:
    """log N(nu_k; 0, S0_k + diag(r_var) / share) per particle (N,): S0 (N, m, m) the Kalman parts' H P H',
    nu (N, m) the innovations y - h(x^n) - H x^l, r_var (m,) the measurement variances, m = 1 or 2."""
    m = nu.shape[1]
    S = S0 + np.diag(np.asarray(r_var, float) / share)[None, :, :]
    if m == 1:
        det = S[:, 0, 0]
        q = nu[:, 0] ** 2 / det
    else:
        det = S[:, 0, 0] * S[:, 1, 1] - S[:, 0, 1] * S[:, 1, 0]
        q = (S[:, 1, 1] * nu[:, 0] ** 2 - (S[:, 0, 1] + S[:, 1, 0]) * nu[:, 0] * nu[:, 1]
             + S[:, 0, 0] * nu[:, 1] ** 2) / det
    with np.errstate(invalid="ignore", divide="ignore"):
        out = -0.5 * (q + np.log(det) + m * math.log(2.0 * math.pi))
    return np.where(det > 0.0, out, -np.inf)


def conditional_ess_fraction(w: np.ndarray, g: np.ndarray) -> float:
    """(sum W G)^2 / sum W G^2 (in (0, 1]) for weights w (normalised here) and log-likelihoods g: the
    conditional effective sample size over N (Zhou, Johansen & Aston 2016 eq 3.5); 0 if nothing is finite."""
    fin = np.isfinite(g) & (w > 0.0)
    if not fin.any():
        return 0.0
    W = w[fin] / w[fin].sum()
    G = np.exp(g[fin] - g[fin].max())
    return float(np.sum(W * G) ** 2 / np.sum(W * G * G))


def stage_share(w: np.ndarray, S0: np.ndarray, nu: np.ndarray, r_var: np.ndarray, left: float,
                target: float) -> float:
    """The share (of the measurement's information, in (0, left]) of the next stage: `left` if the
    conditional ESS fraction of the whole remainder is at least `target`, else the largest share that keeps
    it there (bisection in log share; the fraction falls as the share grows), at least MIN_SHARE * left.
    w (N,) the particles' weights before the stage (0 for particles without a prediction)."""
    if conditional_ess_fraction(w, predictive_loglik(S0, nu, r_var, left)) >= target:
        return left
    lo, hi = math.log(MIN_SHARE * left), math.log(left)
    if conditional_ess_fraction(w, predictive_loglik(S0, nu, r_var, math.exp(lo))) < target:
        return math.exp(lo)
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        if conditional_ess_fraction(w, predictive_loglik(S0, nu, r_var, math.exp(mid))) >= target:
            lo = mid
        else:
            hi = mid
    return math.exp(lo)


def innovations(H: np.ndarray, xl: np.ndarray, P: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H P H' (N, m, m), nu = e - H x^l (N, m)) of every particle's Kalman part: H (N, m, 12), xl (N, 12),
    P (N, 12, 12), e (N, m) = y - h(x^n)."""
    S0 = np.einsum("kai,kij,kbj->kab", H, P, H, optimize=True)
    return S0, e - np.einsum("kai,ki->ka", H, xl)


__all__ = ["MAX_STAGES", "MIN_SHARE", "conditional_ess_fraction", "innovations", "predictive_loglik",
           "stage_share"]
