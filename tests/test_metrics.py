"""Navigation metrics (trn_env.output.metrics) against hand-computed values and chi-square bounds."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from trn_env.output import metrics as m


def _arrays(t, err, cov_diag, nav_ok=None):
    t = np.asarray(t, float)
    cov_diag = np.asarray(cov_diag, float)
    cov = np.zeros((len(t), 9, 9))
    for k in range(cov_diag.shape[1]):
        cov[:, k, k] = cov_diag[:, k]
    return {"t_s": t, "err_ned_m": np.asarray(err, float), "est_cov": cov, "est_cov_diag": cov_diag,
            "nav_ok": np.ones(len(t), bool) if nav_ok is None else np.asarray(nav_ok, bool)}


def test_rms_cep_max_final_by_hand():
    # e_h = 5, 10, 0 ; e_v = -e_d = 0, 0, -2
    a = _arrays([0, 1, 2], [[3, 4, 0], [6, 8, 0], [0, 0, 2]], [[100, 100, 100]] * 3)
    out = m.navigation_metrics(a)
    assert out["horizontal_error_rms_m"] == pytest.approx(math.sqrt((25 + 100 + 0) / 3))
    assert out["vertical_error_rms_m"] == pytest.approx(math.sqrt(4 / 3))
    # sorted e_h = 0, 5, 10: the 50th percentile is 5, the 95th lies 0.9 of the way from 5 to 10
    assert out["horizontal_error_cep50_m"] == pytest.approx(5.0)
    assert out["horizontal_error_cep95_m"] == pytest.approx(9.5)
    assert out["horizontal_error_max_m"] == pytest.approx(10.0)
    assert out["horizontal_error_final_m"] == pytest.approx(0.0)
    assert out["vertical_error_final_m"] == pytest.approx(-2.0)
    assert out["vertical_error_max_m"] == pytest.approx(2.0)


def test_nees_diagonal_and_correlated_by_hand():
    # diag(1, 4, 9) with error (1, 2, 3): 1 + 1 + 1
    nees = m.position_nees(np.array([[1.0, 2.0, 3.0]]), np.diag([1.0, 4.0, 9.0])[None])
    assert nees[0] == pytest.approx(3.0)
    # [[2, 1], [1, 2]]^-1 = [[2, -1], [-1, 2]] / 3; (1, 1) -> (2 - 1 - 1 + 2) / 3 = 2/3
    cov = np.array([[[2.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 1.0]]])
    assert m.position_nees(np.array([[1.0, 1.0, 0.0]]), cov)[0] == pytest.approx(2.0 / 3.0)
    # a singular covariance gives NaN, not an exception
    assert math.isnan(m.position_nees(np.array([[1.0, 0, 0]]), np.zeros((1, 3, 3)))[0])


def test_anees_bounds_are_the_chi_square_quantiles():
    for n in (1, 10, 250):
        lo, hi = m.anees_bounds(n)
        assert lo == pytest.approx(chi2.ppf(0.025, 3 * n) / n)
        assert hi == pytest.approx(chi2.ppf(0.975, 3 * n) / n)
        assert lo < 3.0 < hi


def test_anees_of_consistent_and_overconfident_errors():
    """2,000 rows of errors drawn from the stated covariance: the ANEES lies inside its 95 % bounds (this
    fixed seed; a consistent filter fails 5 % of seeds); errors twice the stated sigma give ANEES ~ 12, far
    above the upper bound."""
    rng = np.random.default_rng(3)
    n = 2000
    sig = np.array([20.0, 35.0, 10.0])
    err = rng.standard_normal((n, 3)) * sig
    a = _arrays(np.arange(n), err, np.tile(sig ** 2, (n, 1)))
    out = m.navigation_metrics(a)
    lo, hi = chi2.ppf([0.025, 0.975], 3 * n) / n
    assert lo <= out["anees"] <= hi
    assert out["anees_inside_bounds"] == 1.0
    a2 = _arrays(np.arange(n), 2 * err, np.tile(sig ** 2, (n, 1)))
    out2 = m.navigation_metrics(a2)
    assert out2["anees"] > hi and out2["anees_inside_bounds"] == 0.0
    assert out2["anees"] == pytest.approx(12.0, rel=0.1)


def test_time_weighting_with_uneven_rows():
    # rows hold until the next: [0,1) ok, [1,3) not, [3,6) ok, last row starts no interval
    t = [0.0, 1.0, 3.0, 6.0]
    assert m.time_fraction(t, [True, False, True, False]) == pytest.approx(4.0 / 6.0)
    assert m.time_where(t, [False, True, False, True]) == pytest.approx(2.0)


def test_within_3sigma_healthy_and_misleading_information():
    t = [0.0, 1.0, 2.0, 4.0, 5.0]
    # sigma 10 m each axis: rows 1 (|e_n| = 40) and 3 (|e_e| = 31) are outside 3 sigma
    err = [[1, 1, 0], [40, 0, 0], [0, 5, 0], [0, -31, 0], [2, 2, 0]]
    nav_ok = [True, True, False, True, False]
    out = m.navigation_metrics(_arrays(t, err, [[100, 100, 100]] * 5, nav_ok))
    assert out["fraction_within_3sigma"] == pytest.approx(3 / 5)
    # rows hold 1, 1, 2, 1, 0 s: healthy during [0,1), [1,2) and [4,5) = 3 of 5 s ([2,4) is not)
    assert out["fraction_healthy"] == pytest.approx(3.0 / 5.0)
    # healthy and outside 3 sigma: row 1 holds [1,2) = 1 s, row 3 holds [4,5) = 1 s
    assert out["misleading_information_time_s"] == pytest.approx(2.0)


def test_time_to_converge():
    t = np.arange(6.0)
    assert m.time_to_converge(t, [100, 40, 60, 40, 30, 20], 50.0) == pytest.approx(3.0)
    assert m.time_to_converge(t, [10, 10, 10, 10, 10, 10], 50.0) == 0.0
    assert math.isnan(m.time_to_converge(t, [10, 10, 10, 10, 10, 60], 50.0))
    t2 = np.array([10.0, 12.0, 15.0])       # measured from the first row, not from t = 0
    assert m.time_to_converge(t2, [80, 20, 10], 50.0) == pytest.approx(2.0)


def test_track_loss_threshold_and_k_sigma():
    t = np.arange(31.0)
    e = np.full(31, 20.0)
    e[5:17] = 400.0           # 12 s above 250 m (rows 5..16 hold until t = 17): a loss
    e[22:26] = 400.0          # 4 s: too short
    sig = np.full(31, 100.0)
    lost, first, total = m.track_loss(t, e, sig, 250.0, 0.0, 10.0)
    assert lost and first == pytest.approx(15.0) and total == pytest.approx(12.0)
    # k sigma: 60 m error with 10 m sigma exceeds 5 sigma although under the 250 m threshold
    e2 = np.full(31, 20.0)
    e2[10:25] = 60.0
    lost2, first2, total2 = m.track_loss(t, e2, np.full(31, 10.0), 250.0, 5.0, 10.0)
    assert lost2 and first2 == pytest.approx(20.0) and total2 == pytest.approx(15.0)
    lost3, first3, total3 = m.track_loss(t, e2, np.full(31, 10.0), 250.0, 0.0, 10.0)
    assert not lost3 and math.isnan(first3) and total3 == 0.0


def test_metric_settings_refuse_bad_values():
    with pytest.raises(ValueError, match="metrics.converge_threshold_m"):
        m.MetricSettings(converge_threshold_m=float("nan"))
    with pytest.raises(ValueError, match="metrics.track_loss_threshold_m"):
        m.MetricSettings(track_loss_threshold_m=-1.0)
    m.MetricSettings(track_loss_k_sigma=0.0, track_loss_min_s=0.0)   # both may be zero


def test_every_metric_key_is_returned():
    a = _arrays([0, 1, 2], [[3, 4, 0], [6, 8, 0], [0, 0, 2]], [[100, 100, 100]] * 3)
    assert set(m.navigation_metrics(a)) == set(m.METRIC_KEYS)
