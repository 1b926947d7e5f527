"""Horizontal protection levels (navigators.integrity.protection_level) against independent computations,
their metrics (trn_env.output.integrity_metrics) against direct counting, bad settings by name, and one
short closed-loop flight that carries the HPL into the log, summary.json's figures and the report."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import binom
from trn_env.navigators import registry
from trn_env.navigators.integrity import protection_level as pl

from trn_env.output.integrity_metrics import clopper_pearson_upper, protection_level_metrics
from trn_env.output.metrics import MetricSettings


def test_mass_radius_kernel_matches_reference_and_covers_the_mass():
    rng = np.random.default_rng(0)
    for trial in range(30):
        n = int(rng.integers(5, 400))
        dn, de = rng.normal(0, 30, n), rng.normal(10, 50, n)
        w = rng.exponential(1.0, n) * (rng.random(n) > 0.1)
        risk = float(rng.choice([1e-3, 0.01, 0.1, 0.3]))
        r = pl.weighted_mass_radius(dn, de, w, risk)
        assert r == pytest.approx(pl.weighted_mass_radius_reference(dn, de, w, risk), abs=1e-9), trial
        mn, me = np.average(dn, weights=w), np.average(de, weights=w)
        d = np.hypot(dn - mn, de - me)
        assert w[d > r + 1e-6].sum() <= risk * w.sum() * (1 + 1e-9)  # at most the risk outside
        assert w[d >= r - 1e-6].sum() > risk * w.sum() * (1 - 1e-9)  # the smallest such point radius
    assert math.isnan(pl.weighted_mass_radius(np.zeros(3), np.zeros(3), np.zeros(3), 0.01))


def test_mass_radius_kernel_on_a_grid_with_ties_and_far_points():
    """A point-mass grid (61 x 61 cells of 10 m, Gaussian weights about its centre: distances tie in fours
    and eights) against the reference; then with far points (1,000 km) that crowd every other cell into one
    bucket of the kernel's sort, holding less and more than the risk."""
    g = (np.arange(61) - 30) * 10.0
    dn, de = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    w = np.exp(-0.5 * (dn**2 + de**2) / 80.0**2)
    for risk in (1e-3, 0.05, 0.5):
        assert pl.weighted_mass_radius(dn, de, w, risk) == pytest.approx(
            pl.weighted_mass_radius_reference(dn, de, w, risk), abs=1e-9)
    far_n, far_e = np.r_[dn, 1e6, -1e6, 0.0], np.r_[de, 0.0, 5e5, 1e6]
    for share in (1e-6, 1e-2):               # the far points' share of the weight, below / above the risk
        far_w = np.r_[w, np.full(3, share * w.sum() / 3)]
        r = pl.weighted_mass_radius(far_n, far_e, far_w, 1e-3)
        assert r == pytest.approx(pl.weighted_mass_radius_reference(far_n, far_e, far_w, 1e-3), abs=1e-9)
        assert (r < 1e3) if share < 1e-3 else (r > 1e5)


def test_gaussian_bound_holds_for_elliptical_errors():
    """P(|e| > HPL) <= risk for e ~ N(0, P): 400,000 draws of an elongated, rotated P; the exceedances stay
    below the 99.9 % binomial quantile at the risk, and the bound is exact (equality) for a circular P."""
    rng = np.random.default_rng(1)
    a = np.radians(30.0)
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    P = R @ np.diag([40.0**2, 8.0**2]) @ R.T
    risk = 1e-3
    h = pl.gaussian_hpl(P, risk)
    n = 400_000
    e = rng.standard_normal((n, 2)) @ np.linalg.cholesky(P).T
    k = int(np.count_nonzero(np.hypot(e[:, 0], e[:, 1]) > h))
    assert k <= binom.ppf(0.999, n, risk)
    hc = pl.gaussian_hpl(np.eye(2) * 25.0**2, risk)
    assert math.exp(-0.5 * (hc / 25.0) ** 2) == pytest.approx(risk, rel=1e-12)


def _mixture_draws(rng, mu, cov, w, n):
    k = rng.choice(len(w), size=n, p=w / w.sum())
    L = np.linalg.cholesky(cov + np.eye(2) * 1e-12)
    z = rng.standard_normal((n, 2))
    return mu[k] + np.einsum("kij,kj->ki", L[k], z)


@pytest.mark.parametrize("case", ["cloud", "few_wide", "elongated"])
def test_mixture_hpl_against_monte_carlo_of_the_mixture(case):
    """The rbpf's HPL (mixture_hpl) against brute-force sampling of its Gaussian mixture: 1,000,000 draws;
    the draws beyond the HPL stay below the 99.9 % binomial quantile at the risk (it is an upper bound of the
    tail), and the HPL is not loose: at most 1.35 x the Monte Carlo (1 - risk) radius. Cases: a 1,000-point
    cloud whose components are narrower than its spread, a few wide components, elongated rotated ones."""
    rng = np.random.default_rng({"cloud": 3, "few_wide": 4, "elongated": 5}[case])
    risk = 1e-3
    if case == "cloud":
        K = 1000
        mu = rng.normal(0.0, 25.0, (K, 2))
        cov = np.broadcast_to(np.eye(2) * 12.0**2, (K, 2, 2)).copy()
    elif case == "few_wide":
        K = 5
        mu = rng.normal(0.0, 40.0, (K, 2))
        cov = np.array([np.eye(2) * s**2 for s in rng.uniform(10.0, 60.0, K)])
    else:
        K = 200
        mu = rng.normal(0.0, 15.0, (K, 2))
        cov = np.empty((K, 2, 2))
        for k in range(K):
            a = rng.uniform(0, np.pi)
            R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
            cov[k] = R @ np.diag([rng.uniform(20, 50) ** 2, rng.uniform(2, 10) ** 2]) @ R.T
    w = rng.exponential(1.0, K)
    h = pl.mixture_hpl(mu[:, 0], mu[:, 1], cov, w, risk)
    n = 1_000_000
    x = _mixture_draws(rng, mu, cov, w, n)
    r = np.hypot(x[:, 0], x[:, 1])
    k = int(np.count_nonzero(r > h))
    assert k <= binom.ppf(0.999, n, risk), (case, k, h)
    assert h <= 1.35 * float(np.quantile(r, 1.0 - risk)), (case, h, np.quantile(r, 1.0 - risk))
    # points (zero covariance): the kernel is the weighted mass radius about the origin
    d = np.hypot(mu[:, 0], mu[:, 1])
    hp = pl.mixture_hpl(mu[:, 0], mu[:, 1], np.zeros((K, 2, 2)), w, 0.05)
    assert w[d > hp + 1e-6].sum() <= 0.05 * w.sum() and w[d >= hp - 1e-3].sum() > 0.05 * w.sum()


def test_rbpf_hpl_is_its_mixture_not_its_points():
    """rbpf's published HPL: the mixture of its particles with their own Kalman covariances through eq 5's B
    (checked by sampling that mixture, 400,000 draws) and wider than the points' mass radius alone."""
    from test_rbpf import _frames, _initial
    from trn_env.navigators.measurements.ira_seed002 import predict_ira
    from trn_env.terrain.geodesy import euler_to_C_bn

    from trn_env import terrain

    dem = terrain.load("jacksboro")
    e0 = _initial(dem)
    r0 = predict_ira(dem, [e0.lat_rad], [e0.lon_rad], [e0.h_m], e0.v_ned_mps,
                     euler_to_C_bn(0.0, 0.0, e0.yaw_rad))[0, 0]
    nav = registry.create("rbpf", dem=dem, rng=np.random.default_rng(11), n_particles=300)
    nav.reset(e0)
    for k in range(5):
        est = nav.update(_frames(float(k), 1.0, rng_m=r0 + 3.0 * k, theta=0.001))
    h = est.extra[pl.EXTRA_PROTECTION_LEVEL]
    risk = est.extra[pl.EXTRA_INTEGRITY_RISK]
    B, P, xn, w = nav._pl_B, nav.P, nav.xn, nav._weights()
    cov = np.array([B @ P[k] @ B.T + np.diag(nav.qn_var[:2]) for k in range(xn.shape[0])])   # independent
    assert np.all(np.linalg.eigvalsh(cov)[:, 0] > 0.0)
    rng = np.random.default_rng(12)
    n = 400_000
    x = _mixture_draws(rng, xn[:, :2].copy(), cov, w, n)
    k = int(np.count_nonzero(np.hypot(x[:, 0], x[:, 1]) > h))
    assert k <= binom.ppf(0.999, n, risk), (k, h)
    points = pl.mixture_hpl(xn[:, 0], xn[:, 1], np.zeros_like(cov), w, risk)
    assert h > points, (h, points)


def test_fault_allowance_is_the_largest_shift_inside_the_gate():
    """sqrt(gamma lambda_max(P S^-1 P)) = max |K b| over the gate ellipse b' S^-1 b = gamma (brute force over
    directions), K = P S^-1 the position gain of a direct position fix."""
    P = np.array([[900.0, 200.0], [200.0, 400.0]])
    S = P + np.eye(2) * 100.0
    gamma = 18.4
    K = P @ np.linalg.inv(S)
    L = np.linalg.cholesky(S)
    th = np.linspace(0, 2 * np.pi, 20001)
    b = (L @ np.stack([np.cos(th), np.sin(th)])) * math.sqrt(gamma)
    brute = float(np.max(np.hypot(*(K @ b))))
    assert pl.fault_allowance_m(P, S, gamma) == pytest.approx(brute, rel=1e-6)


def test_publish_adds_the_maps_horizontal_error_at_half_the_risk():
    nav = type("Nav", (), {})()
    pl.configure(nav, integrity_risk=1e-3, map_horizontal_sigma_m=0.0)
    assert pl.filter_risk(nav) == 1e-3
    assert pl.publish({}, 20.0, nav)[pl.EXTRA_PROTECTION_LEVEL] == 20.0
    pl.configure(nav, integrity_risk=1e-3, map_horizontal_sigma_m=23.3)
    assert pl.filter_risk(nav) == 5e-4
    out = pl.publish({}, 20.0, nav)
    assert out[pl.EXTRA_PROTECTION_LEVEL] == pytest.approx(20.0 + 23.3 * math.sqrt(-2 * math.log(5e-4)))
    assert out[pl.EXTRA_INTEGRITY_RISK] == 1e-3


def test_bad_integrity_settings_named():
    for bad in (0.0, 1.0, -0.1, 1.5, float("nan"), "x", True):
        with pytest.raises(ValueError, match="integrity_risk"):
            pl.check_integrity_risk(bad)
    for bad in (-1.0, float("nan"), float("inf"), "far"):
        with pytest.raises(ValueError, match="alert_limit_m"):
            pl.check_alert_limit(bad)
    with pytest.raises(ValueError, match="metrics.alert_limit_m"):
        MetricSettings(alert_limit_m=-5.0)
    with pytest.raises(ValueError, match="integrity_risk"):
        registry.create("ins", integrity_risk=2.0)
    with pytest.raises(ValueError, match="map_horizontal_sigma_m"):
        registry.create("ins", map_horizontal_sigma_m=-3.0)
    with pytest.raises(ValueError, match="alert_limit_m"):
        protection_level_metrics(np.zeros(3), np.zeros(3), np.ones(3, bool), -1.0)
    nav = registry.create("ins", integrity_risk=1e-4)
    assert nav.integrity_risk == 1e-4


def test_protection_level_metrics_count_directly():
    rng = np.random.default_rng(3)
    n = 5000
    e = rng.exponential(20.0, n)
    h = rng.uniform(10, 300, n)
    h[::97] = np.nan
    ok = rng.random(n) > 0.2
    m = protection_level_metrics(e, h, ok, 185.2)
    use = ok & np.isfinite(h)
    assert m["pl_epochs"] == int(use.sum())
    assert m["pl_misleading_epochs"] == sum(1 for a, b, c in zip(e, h, use, strict=True) if c and a > b)
    assert m["pl_hazardous_epochs"] == int(np.sum(use & (e > 185.2) & (h <= 185.2)))
    assert m["pl_availability"] == pytest.approx(np.mean(use & (h <= 185.2)))
    k, nn = m["pl_misleading_epochs"], m["pl_epochs"]
    assert m["pl_misleading_rate_upper95"] == pytest.approx(clopper_pearson_upper(k, nn))
    # Clopper-Pearson: the one-sided bound p_u has P(X <= k | p_u) = 0.05
    assert binom.cdf(k, nn, m["pl_misleading_rate_upper95"]) == pytest.approx(0.05, rel=1e-6)


def test_closed_loop_flight_logs_the_protection_level(tmp_path):
    """A 40 s INS + TERCOM flight (tests/scenarios/default_short.toml): every logged row after the first
    fix carries a finite HPL, summary.json's pl_* figures agree with the log, and the campaign report's
    Stanford diagram draws from the same series."""
    from trn_env.sim.closed_loop import run_scenario
    r = run_scenario("tests/scenarios/default_short.toml", duration_s=40.0)
    a = r.arrays
    h = a["est_hpl_m"]
    assert h.shape == a["t_s"].shape and np.isfinite(h[5:]).all() and (h[5:] > 0).all()
    e = np.hypot(a["err_ned_m"][:, 0], a["err_ned_m"][:, 1])
    m = protection_level_metrics(e, h, a["nav_ok"], 185.2)
    for k in ("pl_epochs", "pl_misleading_epochs", "pl_availability"):
        assert r.summary[k] == pytest.approx(m[k])
    import pandas as pd

    from trn_env.campaign.report import stanford_plot
    df = pd.DataFrame([{"navigator": "ins_tercom", "series_err_h_m": e, "series_hpl_m": h,
                        "series_nav_ok": a["nav_ok"].astype(float)}])
    assert stanford_plot(tmp_path / "s.png", df, 185.2) and (tmp_path / "s.png").stat().st_size > 1000


def test_bench_mass_radius_figure_checks_the_kernel_against_numpy(monkeypatch):
    from trn_env.bench.integrity import mass_radius_figures
    figures = mass_radius_figures(quick=True)
    assert set(figures) == {"integrity_mass_radius_40k_ms", "integrity_mass_radius_numpy_sort_40k_ms",
                            "integrity_mass_radius_ratio_to_numpy_sort"}
    assert all(math.isfinite(v) and v > 0 for v in figures.values())
    monkeypatch.setattr(pl, "weighted_mass_radius", lambda dn, de, w, risk: 1.0)
    with pytest.raises(RuntimeError, match="differs from numpy"):
        mass_radius_figures(quick=True)
