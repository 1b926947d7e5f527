"""The DEM integrity monitor's disparity sigma and thresholds (seed 003 eqs 4-5; dem_monitor.py describes
the monitor): the map error class's sigma, the chi-square threshold of eq 4 for a false-alarm probability,
and the exact threshold of eq 5's Kalman statistic (a generalised chi-square) with the steady-state filter
and the statistic's moments it rests on.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np

DTED1_DISPARITY_SIGMA_M = 18.9      # seed 003 section III: absolute disparities ~ N(0, 18.9^2), DTED-1
DTED1_SUCCESSIVE_SIGMA_M = 13.0     # seed 003 section III: successive disparities ~ N(0, 13.0^2)


def class_sigma_m(map_class: str) -> float:
    """Disparity sigma (m) of a map error class: seed 003's 18.9 m for DTED-1, else LE90 / 1.6449 of
    terrain.map_error.ACCURACY_CLASSES."""
    from ...terrain.map_error import ACCURACY_CLASSES
    key = str(map_class).strip().lower()
    if key == "dted1":
        return DTED1_DISPARITY_SIGMA_M
    if key not in ACCURACY_CLASSES:
        raise ValueError(f"map_class: unknown map error class {map_class!r}; choose from "
                         f"{sorted(ACCURACY_CLASSES)}")
    return float(ACCURACY_CLASSES[key].sigma_v_m)


def chi2_threshold(false_alarm_probability: float, n: int) -> float:
    """chi2.ppf(1 - P_fa, n): the eq 4 threshold for a false-alarm probability per test."""
    from scipy.stats import chi2
    return float(chi2.isf(false_alarm_probability, n))


def kf_steady_state(q_var: float, r_var: float) -> tuple[float, float]:
    """(gain K, posterior variance P) of the steady-state scalar random-walk Kalman filter (eq 5's filter):
    P- = P + q, K = P- / (P- + r), P = (1 - K) P-."""
    p_prior = 0.5 * (q_var + math.sqrt(q_var * q_var + 4.0 * q_var * r_var))
    k = p_prior / (p_prior + r_var)
    return k, (1.0 - k) * p_prior


def kalman_statistic_moments(n: int, process_ratio: float) -> tuple[float, float]:
    """(mean, variance) of T_KF = sum_{k=1..n} x_hat_k^2 / P under no fault for the steady-state filter
    with q = process_ratio * r: x_hat is AR(1), x_k = (1-K) x_{k-1} + K p_k, stationary variance
    v = K r / (2 - K), lag-j covariance v (1-K)^j; E T = n v / P, Var T = 2 sum_ij cov_ij^2 / P^2."""
    k, p = kf_steady_state(process_ratio, 1.0)
    v = k / (2.0 - k)
    a2 = (1.0 - k) ** 2
    lags = np.arange(n)
    weights = np.where(lags == 0, n, 2.0 * (n - lags))
    var = 2.0 * v * v * float(np.sum(weights * a2 ** lags)) / (p * p)
    return n * v / p, var


@functools.lru_cache(maxsize=32)
def kalman_threshold(false_alarm_probability: float, n: int, process_ratio: float,
                     reading: str = "rw_posterior") -> float:
    """Threshold of T_KF (eq 5 as the monitor computes it) for a false-alarm probability: the exact quantile
    of the generalised chi-square T_KF is under no fault with white disparities (its quadratic form from
    correlated_disparity.kalman_reading(reading): "rw_posterior" for variant "kalman", "innovation" for
    "kalman_innovation"; the filter in steady state; Imhof's integral takes about a second, so it is cached
    in the process and on disk: navigators.core.disk_cache)."""
    from ..core.disk_cache import cached_floats
    from .correlated_disparity import gchi2_isf, kalman_reading

    def compute() -> tuple[float]:
        M = kalman_reading(reading, int(n), 150, float(process_ratio))
        return (float(gchi2_isf(float(false_alarm_probability), np.linalg.eigvalsh(M))),)

    key = (float(false_alarm_probability), int(n), float(process_ratio), str(reading))
    return cached_floats("kalman_threshold", key, 1, compute, (str(Path(__file__).resolve().parents[1]),))[0]
