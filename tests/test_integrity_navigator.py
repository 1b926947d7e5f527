"""The navigators' own integrity test (navigators.integrity.innovation_monitor) and the EKF's use of it:
bands against chi-square quantiles, fixed-seed flag rates against a binomial bound, and the EKF's degraded
state with its recovery (covariance inflation, wider TERCOM search) and return."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom, chi2
from trn_env.navigators.filters import InsTrnNavigator, initial_covariance
from trn_env.navigators.integrity.innovation_monitor import InnovationMonitor
from trn_env.navigators.protocol import Estimate

from trn_env import terrain
from trn_env.output.integrity_metrics import flag_before_error, integrity_metrics


def test_band_is_the_chi_square_quantiles():
    mon = InnovationMonitor(window=4, alpha=0.02)
    lo, hi = mon.band(8)
    assert lo == pytest.approx(chi2.ppf(0.01, 8)) and hi == pytest.approx(chi2.ppf(0.99, 8))


def test_consistent_innovations_rarely_flag():
    """1,000 independent windows of 3 NIS values of a consistent 2-dof filter: flags (upper side) within the
    99.9 % binomial quantile of alpha / 2."""
    rng = np.random.default_rng(4)
    n = 1000
    flags = 0
    for _ in range(n):
        mon = InnovationMonitor(window=3, alpha=0.01)
        for x in rng.chisquare(2, 3):
            v = mon.add(0.0, x, 2)
        flags += v.degraded
    assert flags <= binom.ppf(0.999, n, 0.005)


def test_large_nis_flags_and_clears():
    mon = InnovationMonitor(window=2, alpha=0.01)
    v = mon.add(0.0, 1.0, 2)
    assert not v.degraded and not v.changed
    v = mon.add(1.0, 60.0, 2)
    assert v.degraded and v.changed and "above" in v.message
    v = mon.add(2.0, float("nan"), 2)          # a failed update counts as infinitely large
    assert v.degraded and not v.changed
    mon.add(3.0, 1.0, 2)
    v = mon.add(4.0, 1.0, 2)
    assert not v.degraded and v.changed
    with pytest.raises(ValueError, match="integrity_window"):
        InnovationMonitor(window=0)
    with pytest.raises(ValueError, match="integrity_alpha"):
        InnovationMonitor(alpha=1.0)


def test_ekf_degrades_recovers_and_returns():
    nav = InsTrnNavigator(aiding="ira", dem=terrain.load("jacksboro"), integrity_window=2,
                          recovery_sigma_m=80.0)
    nav.reset(Estimate(0.0, np.radians(36.5), np.radians(-84.3), 1500.0, np.array([80.0, 0.0, 0.0]), 0.0, 0.0,
                       0.0, initial_covariance()))
    p0 = nav.kf.P[:2, :2].copy()
    S = np.eye(2) * 200.0
    nav._record_innovation(40.0, np.array([[150.0], [0.0]]), S, 150.0**2 / 200.0)
    assert nav.health.status == "degraded" and not nav.health.ok
    np.testing.assert_allclose(nav.kf.P[:2, :2], p0 + 80.0**2 * np.eye(2))
    assert nav.half_cells == 2 * nav.nominal_half_cells
    assert nav.batch.accumulate[0] == nav.half_cells
    assert any("recovery" in m for _, m in nav.health.events)
    assert nav.estimate().health.status == "degraded"
    for t in (80.0, 120.0):
        nav._record_innovation(t, np.array([[1.0], [1.0]]), S, 0.01)
    assert nav.health.status == "ok" and nav.half_cells == nav.nominal_half_cells
    with pytest.raises(ValueError, match="recovery_half_cells"):
        InsTrnNavigator(aiding="ira", dem=terrain.load("jacksboro"), recovery_half_cells=10)


def test_integrity_metrics_by_hand():
    t = np.arange(6.0)
    err = np.array([[0, 0, 0], [1, 0, 0], [40, 0, 0], [40, 0, 0], [1, 0, 0], [50, 0, 0]], float)
    cov = np.tile([100.0, 100.0, 1.0], (6, 1))              # 3 sigma = 30 m
    status = np.array(["ok", "ok", "ok", "degraded", "ok", "ok"])
    m = integrity_metrics(t, err, cov, status)
    assert m["status_ok_fraction"] == pytest.approx(4 / 5)     # rows 1, 2, 4, 5 hold 1 s each
    assert m["status_ok_misleading_time_s"] == pytest.approx(2.0)      # rows 2 and 5
    assert m["status_ok_misleading_fraction"] == pytest.approx(2 / 4)
    f = flag_before_error(t, err, cov, status, t_from_s=3.0)
    assert f == {"t_flag_s": 3.0, "t_error_outside_s": 3.0, "flag_first": True}
    f = flag_before_error(t, err, cov, np.array(["ok"] * 6), t_from_s=1.0)
    assert f["flag_first"] is False and f["t_error_outside_s"] == 2.0
