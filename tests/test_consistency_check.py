"""The long-window NIS consistency check (navigators.integrity.consistency_check): its false-flag rate on a
consistent NIS stream within a binomial bound of its alpha, its detection of a covariance too small by a
factor against an independent numpy computation of the capped statistic, bad input, and the flag reaching a
real navigator's Health."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import binom, chi2
from trn_env.navigators.integrity.consistency_check import (
    STATUS_INCONSISTENT,
    ConsistencyCheck,
    chi2_upper,
)


def _flags_on_independent_windows(check: ConsistencyCheck, nis: np.ndarray, dof: int) -> int:
    """Feed nis (n_windows x window) and count the flags at each window's last update (the windows do
    not overlap, so the counts are independent Bernoulli trials)."""
    flags = 0
    for row in nis:
        check.reset()
        for x in row[:-1]:
            check.add(float(x), dof)
        flags += int(check.add(float(row[-1]), dof))
    return flags


@pytest.mark.parametrize("dof", [1, 2])
def test_consistent_stream_flag_rate_within_binomial_band(dof):
    # 4,000 independent windows of 30 chi-square(dof) NIS values, alpha = 0.01: the flag count must lie
    # below the 99.9 % binomial quantile at alpha (the cap only lowers the statistic) and above the 0.1 %
    # quantile at the capped statistic's own probability (computed by numpy on 2e5 other windows)
    window, alpha, cap_alpha, n = 30, 0.01, 1e-4, 4000
    rng = np.random.default_rng(11 + dof)
    check = ConsistencyCheck(window=window, alpha=alpha, cap_alpha=cap_alpha)
    flags = _flags_on_independent_windows(check, rng.chisquare(dof, (n, window)), dof)
    assert flags <= binom.ppf(0.999, n, alpha)
    cap, thr = chi2.isf(cap_alpha, dof), chi2.isf(alpha, window * dof)
    p_capped = float(np.mean(np.minimum(rng.chisquare(dof, (200_000, window)), cap).sum(axis=1) > thr))
    assert flags >= binom.ppf(0.001, n, 0.9 * p_capped)


@pytest.mark.parametrize("scale", [1.5, 2.0])
def test_inconsistent_stream_is_flagged_at_its_computed_power(scale):
    # the innovations' variance `scale` times what the covariance says (NIS = scale x chi-square(2)); at
    # the default window and alpha the flag fraction over 2,000 independent windows must lie inside the
    # 99.9 % two-sided binomial band of the power numpy computes for the capped sum (2e5 windows), which
    # itself lies below the uncapped analytic power P(chi2(60) > bound / scale)
    dof, n = 2, 2000
    check = ConsistencyCheck()
    w, alpha, cap_alpha = check.window, check.alpha, check.cap_alpha
    rng = np.random.default_rng(int(scale * 10))
    flags = _flags_on_independent_windows(check, scale * rng.chisquare(dof, (n, w)), dof)
    thr = chi2.isf(alpha, w * dof)
    sums = np.minimum(scale * rng.chisquare(dof, (200_000, w)), chi2.isf(cap_alpha, dof)).sum(axis=1)
    power = float(np.mean(sums > thr))
    assert power <= chi2.sf(thr / scale, w * dof) + 0.005
    assert binom.ppf(0.0005, n, power) <= flags <= binom.ppf(0.9995, n, power)
    assert flags >= 0.2 * n          # a 1.5x variance excess is found in at least a fifth of the windows


def test_default_alpha_on_consistent_stream():
    # the default alpha (1e-3) over 20,000 independent windows: at most the 99.9 % binomial quantile
    n, dof = 20000, 2
    check = ConsistencyCheck()
    rng = np.random.default_rng(3)
    flags = _flags_on_independent_windows(check, rng.chisquare(dof, (n, check.window)), dof)
    assert flags <= binom.ppf(0.999, n, check.alpha)


def test_nonfinite_nis_counts_as_the_cap_and_partial_window_never_flags():
    check = ConsistencyCheck(window=4, alpha=0.01, cap_alpha=1e-3)
    for _ in range(3):
        assert not check.add(math.inf, 2)          # window not full yet
    assert check.add(math.nan, 2)                  # 4 caps: 4 x 13.8 > chi2.isf(0.01, 8) = 20.1
    assert check.statistic == pytest.approx(4 * chi2_upper(1e-3, 2))
    ok, status, warning = check.apply(True, "ok", "static")
    assert (ok, status) == (False, STATUS_INCONSISTENT)
    assert warning.startswith("static; innovations inconsistent")
    # a fault the navigator already names keeps its word; the warning still says why it is not trusted
    ok, status, warning = check.apply(False, "degraded", "")
    assert (ok, status) == (False, "degraded") and warning.startswith("innovations inconsistent")
    check.reset()
    assert check.apply(True, "ok", "") == (True, "ok", "")


@pytest.mark.parametrize("kw, name", [({"window": 1}, "consistency_window"),
                                      ({"window": 2.5}, "consistency_window"),
                                      ({"alpha": 0.0}, "consistency_alpha"),
                                      ({"alpha": float("nan")}, "consistency_alpha"),
                                      ({"cap_alpha": 1.0}, "consistency_cap_alpha")])
def test_bad_settings_named(kw, name):
    with pytest.raises(ValueError, match=name):
        ConsistencyCheck(**kw)


def _pmf_windows(noise_scale: float, runs: int, seed: int) -> tuple[int, list[float]]:
    """A real PMF on the planar linear-Gaussian problem of test_terrain_filter_linear (its NIS is exactly
    chi-square(1) there when the ranges' noise is the 3.5 m it assumes): `runs` independent flights of 2
    windows of updates each, ranges noise_scale x 3.5 m; the flag read from the published Health after the
    last update (the second window, after the first's convergence), and each run's S at the second
    window's first update."""
    from test_terrain_filter_linear import (
        COMMON,
        G_E,
        G_N,
        H0,
        H_ANT,
        SIGMA_R,
        initial,
        ins_state,
        planar_dem,
    )
    from trn_env.navigators.filters.pmf import PointMassFilter
    from trn_env.navigators.protocol import EXTRA_INNOVATION_COV
    dem = planar_dem()
    flags, s_first = 0, []
    rng = np.random.default_rng(seed)
    for _ in range(runs):
        nav = PointMassFilter(dem, grid_size=81, span_sigmas=4.5, position_noise_m_per_sqrt_s=0.5, **COMMON)
        nav.reset(initial(40.0))
        w = nav._recovery.consistency.window
        x_true = np.array([rng.normal(0, 40.0), rng.normal(0, 40.0), rng.normal(0, 3.0)])
        noise = rng.normal(0.0, noise_scale * SIGMA_R, 2 * w)
        st = ins_state()
        for i in range(2 * w):
            t = 1.0 + i
            nav._predict_to(t, st)
            terrain = H0 + G_N * x_true[0] + G_E * x_true[1]
            nav._terrain_update(t, "ira", float((H_ANT - x_true[2]) - terrain + noise[i]), 0.0, st, None)
            if i == w:
                s_first.append(float(np.atleast_2d(nav.extra[EXTRA_INNOVATION_COV])[0, 0]))
        h = nav.estimate().health
        # flagged by the check: ok withdrawn with its warning (the status word may be the pmf's own
        # "degraded" when its short innovation test also fires)
        flags += int(not h.ok and "innovations inconsistent" in h.consistency_warning)
    return flags, s_first


@pytest.mark.parametrize("noise_scale", [1.0, 2.0])
def test_real_pmf_flag_on_consistent_and_inconsistent_ranges(noise_scale):
    # 30 independent runs each. Consistent (noise as assumed): flags at most the 99.9 % binomial quantile at
    # the check's alpha (1e-3; i.e. at most 1). Inconsistent (noise twice the assumed 3.5 m): each NIS is
    # r^2 / S with r ~ N(0, S + 3 sigma^2) when the prior part of S is right, so NIS ~ k chi2(1) with
    # k = 1 + 3 sigma^2 / S >= 1 + 3 sigma^2 / S_first (S falls over the window); the flag probability is
    # then at least P(chi2(30) > bound / k_min) computed here, and the flag count must reach its 0.1 %
    # binomial quantile
    from test_terrain_filter_linear import SIGMA_R
    runs = 30
    flags, s_first = _pmf_windows(noise_scale, runs, seed=int(noise_scale * 7))
    check = ConsistencyCheck()
    bound = chi2_upper(check.alpha, check.window)
    if noise_scale == 1.0:
        assert flags <= binom.ppf(0.999, runs, check.alpha)
    else:
        k_min = 1.0 + 3.0 * SIGMA_R**2 / max(s_first)
        p_low = float(chi2.sf(bound / k_min, check.window))
        assert p_low > 0.5
        assert flags >= binom.ppf(0.001, runs, p_low)
