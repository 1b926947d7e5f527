"""The DEM monitor under spatially correlated map error (navigators.integrity.correlated_disparity, the
whitened statistic in dem_monitor) and the map error's correlation model (terrain.map_error), checked
against independent computations: scipy's chi-square / noncentral chi-square, numpy linear algebra,
Monte Carlo with binomial bounds computed here."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import solve_triangular
from scipy.stats import binom, chi2, ncx2
from trn_env.navigators.integrity import correlated_disparity as cd
from trn_env.navigators.integrity import dem_monitor as dm
from trn_env.terrain import map_error
from trn_env.terrain.dem import Dem
from trn_env.terrain.geodesy import meridian_radius_m


def test_imhof_against_chi_square_and_noncentral():
    lam = np.ones(50)
    for x in (60.0, 96.0, 120.0):
        assert cd.gchi2_sf(x, lam) == pytest.approx(chi2.sf(x, 50), rel=1e-6)
    assert cd.gchi2_isf(1e-4, lam) == pytest.approx(chi2.isf(1e-4, 50), rel=1e-5)
    delta = np.full(50, 0.5)
    assert cd.gchi2_sf(96.0, lam, delta) == pytest.approx(ncx2.sf(96.0, 50, 12.5), rel=1e-6)
    # a scaled chi-square: 3 chi2(10)
    assert cd.gchi2_sf(45.0, np.full(10, 3.0)) == pytest.approx(chi2.sf(15.0, 10), rel=1e-6)


def test_imhof_against_monte_carlo_on_a_correlated_window():
    """Eq 4's sum over an exponentially correlated window (L = 500 m, 85 m spacing): the Imhof tail at 96
    against 200,000 draws, within the 99.9 % binomial band."""
    S = cd.window_covariance(np.arange(50) * 85.0, 1.0, 500.0, "exponential")
    lam = np.linalg.eigvalsh(S)
    p_exact = cd.gchi2_sf(96.0, lam)
    rng = np.random.default_rng(4)
    n = 200_000
    z = rng.standard_normal((n, 50)) @ np.linalg.cholesky(S).T
    k = int(np.count_nonzero(np.sum(z * z, axis=1) > 96.0))
    lo, hi = binom.ppf([0.0005, 0.9995], n, p_exact)
    assert lo <= k <= hi, (k, p_exact * n)
    assert p_exact > 0.03          # far above the design 1e-4: why the monitor whitens


LAT0, LON0 = math.radians(36.5), math.radians(-84.3)


def _track(n, spacing_m, lat0=LAT0, lon0=LON0):
    lat = lat0 + np.arange(n) * spacing_m / meridian_radius_m(lat0)
    return lat, np.full(n, lon0)


def test_whitened_kernel_against_numpy():
    """whitened_statistic (numba, ring buffer, own Cholesky) = p' Sigma^-1 p by numpy, with bias share,
    white variances and the navigator's common terms through the slope."""
    rng = np.random.default_rng(1)
    n = 50
    lat, lon = _track(n, 85.0)
    d = (lat - lat[0]) * meridian_radius_m(lat[0])
    p = rng.standard_normal(n) * 20.0
    white = rng.uniform(50, 150, n)
    g = rng.normal(0.0, 0.1, (n, 2))
    P = np.array([[400.0, 50.0], [50.0, 300.0]])
    ring = np.zeros((n, 11))
    ring[:, 0], ring[:, 1], ring[:, 2], ring[:, 3] = p, lat, lon, white
    ring[:, 4], ring[:, 5], ring[:, 6] = 16.0, g[:, 0], g[:, 1]
    ring[:, 7], ring[:, 8], ring[:, 9] = P[0, 0], P[0, 1], P[1, 1]
    ring[:, 10] = t = 100.0 + np.arange(n) * 1.0
    start = 13
    rolled = np.roll(ring, start, axis=0)            # oldest epoch at row `start`
    S0 = cd.window_covariance(d, 18.9 * math.sqrt(0.5), 500.0, "exponential", white, 18.9 * math.sqrt(0.5))
    dt = np.abs(t[:, None] - t[None, :])
    for tau_h, tau_v in ((0.0, 0.0), (120.0, 300.0)):
        T, Tb = cd.whitened_statistic(rolled, start, n, 0.5 * 18.9**2, 0.5 * 18.9**2, 500.0, 0, tau_h, tau_v)
        rh = np.exp(-dt / tau_h) if tau_h > 0 else 1.0
        rv = np.exp(-dt / tau_v) if tau_v > 0 else 1.0
        S = S0 + 16.0 * rv + (g @ P @ g.T) * rh
        assert T == pytest.approx(p @ np.linalg.solve(S, p), rel=1e-8)
        one = np.ones(n)
        si1 = np.linalg.solve(S, one)
        assert Tb == pytest.approx((si1 @ p) ** 2 / (one @ si1), rel=1e-8)


def test_whitened_false_alarm_rate_at_design():
    """100,000 fault-free windows (map error 18.9 m exponential at L = 500 m, 85 m apart, plus 12.8 m white
    noise): the whitened statistic's alarms at 96 within the 99.9 % binomial band of 1e-4, while eq 4's sum
    at 96 alarms two orders of magnitude more. (The full study: scripts/integrity_correlated.py.)"""
    rng = np.random.default_rng(11)
    n, N, L = 100_000, 50, 500.0
    a = math.exp(-85.0 / L)
    w = rng.standard_normal((n, N))
    x = np.empty_like(w)
    x[:, 0] = w[:, 0]
    for j in range(1, N):
        x[:, j] = a * x[:, j - 1] + math.sqrt(1 - a * a) * w[:, j]
    white = 12.6**2 + 2.0**2
    p = 18.9 * x + math.sqrt(white) * rng.standard_normal((n, N))
    S = cd.window_covariance(np.arange(N) * 85.0, 18.9, L, "exponential", white)
    y = solve_triangular(np.linalg.cholesky(S), p.T, lower=True)
    k_w = int(np.count_nonzero(np.sum(y * y, axis=0) > 96.0))
    lo, hi = binom.ppf([0.0005, 0.9995], n, chi2.sf(96.0, N))
    assert lo <= k_w <= hi, k_w
    k_4 = int(np.count_nonzero(np.sum(p * p, axis=1) / (18.9**2 + white) > 96.0))
    assert k_4 > 100 * max(k_w, 1)


def _flat_dem(n=200, spacing_deg=3.0 / 3600.0):
    return Dem(np.full((n, n), 300.0), math.radians(36.4), math.radians(-84.4), math.radians(spacing_deg),
               math.radians(spacing_deg), "flat")


def test_monitor_statistic_kernel_whitens_the_window():
    """The monitor's own statistic kernel, fed epochs along a track with correlation_length_m set, reports
    p' Sigma^-1 p of its last 50 epochs (numpy), and eq 4's sum without it."""
    rng = np.random.default_rng(5)
    n = 60
    lat, lon = _track(n, 85.0)
    p = rng.standard_normal(n) * 20.0
    rows = np.zeros((n, 10))
    rows[:, 0] = np.arange(n, dtype=float)
    rows[:, 1], rows[:, 2] = lat, lon
    rows[:, 3] = 900.0                      # height; range 600 m; map height 300 - p: p = h - r - h_map
    rows[:, 4] = 600.0
    rows[:, 5] = 300.0 - p
    rows[:, 6] = 4.0                        # GNSS height variance (white)
    for L, whiten in ((700.0, True), (0.0, False)):
        mon = dm.DemIntegrityMonitor(dem=_flat_dem(), correlation_length_m=L,
                                     radar_altimeter_noise_const_m=5.0, gnss_vertical_sigma_m=2.0)
        out = np.empty((n, 7))
        m = dm._statistic_kernel(rows, rows[:0, 0], mon._cfg, mon._state, mon._ring, mon._wring,
                                 dm._est_terms(np.zeros(14)), out)
        assert m == n
        assert np.allclose(out[:, 1], p)
        w = p[-50:]
        d = (lat[-50:] - lat[-50]) * meridian_radius_m(lat[-50])
        if whiten:
            S = cd.window_covariance(d, 18.9, L, "exponential", 25.0 + 4.0)
            assert out[-1, 4] == pytest.approx(w @ np.linalg.solve(S, w), rel=1e-6)
        else:
            assert out[-1, 4] == pytest.approx(np.sum(w * w) / (18.9**2 + 25.0 + 4.0), rel=1e-9)


def _denied_rows(rng, n, slope=(0.08, -0.05)):
    """Monitor epochs along a track with the navigator as the height source (source 1) over a map slope."""
    lat, lon = _track(n, 85.0)
    p = rng.standard_normal(n) * 20.0
    rows = np.zeros((n, 10))
    rows[:, 0] = np.arange(n, dtype=float)
    rows[:, 1], rows[:, 2], rows[:, 3], rows[:, 4] = lat, lon, 900.0, 600.0
    rows[:, 5] = 300.0 - p
    rows[:, 7] = 1.0
    rows[:, 8], rows[:, 9] = slope
    return rows, p, lat


def test_denied_path_whitens_the_navigators_correlated_error():
    """GNSS denied (the navigator's position, source 1), white map: the monitor's kernel whitens the window
    with the navigator's error Gauss-Markov in time (time constants from the settings) through the map's
    slope, p' Sigma^-1 p by numpy; and with the bias GLRT on, an alarm comes from T_b alone when only it
    passes its chi2(1) threshold."""
    rng = np.random.default_rng(8)
    n = 60
    rows, p, lat = _denied_rows(rng, n)
    est = np.zeros(14)
    est[7], est[8], est[9], est[10] = 900.0, 100.0, 400.0, 25.0     # P_nn, P_ne, P_ee, P_dd of the navigator
    g = np.array([0.08, -0.05])
    P = np.array([[900.0, 100.0], [100.0, 400.0]])
    for tau_h, tau_v in ((0.0, 0.0), (120.0, 300.0)):
        mon = dm.DemIntegrityMonitor(dem=_flat_dem(), radar_altimeter_noise_const_m=5.0,
                                     navigator_error_time_constant_s=tau_h,
                                     navigator_height_time_constant_s=tau_v)
        out = np.empty((n, 7))
        dm._statistic_kernel(rows, rows[:0, 0], mon._cfg, mon._state, mon._ring, mon._wring,
                             dm._est_terms(est), out)
        w = p[-50:]
        dt = np.abs(np.subtract.outer(np.arange(50.0), np.arange(50.0)))
        rh = np.exp(-dt / tau_h) if tau_h else 1.0
        rv = np.exp(-dt / tau_v) if tau_v else 1.0
        S = np.eye(50) * (18.9**2 + 25.0) + 25.0 * rv + (g @ P @ g) * rh
        assert out[-1, 4] == pytest.approx(w @ np.linalg.solve(S, w), rel=1e-6)
    # a bias of 3 sigma of the window mean: T_b far above chi2(1)'s 1e-4 threshold, T_w below 96
    rows2, _, _ = _denied_rows(np.random.default_rng(9), n, slope=(0.0, 0.0))
    rows2[:, 5] = 300.0 - 0.3 * rng.standard_normal(n) - 12.0
    outs = {}
    for pfa_b in (0.0, 1e-4):
        mon = dm.DemIntegrityMonitor(dem=_flat_dem(), radar_altimeter_noise_const_m=5.0,
                                     map_bias_fraction=0.0, bias_glrt_false_alarm_probability=pfa_b)
        out = np.empty((n, 7))
        dm._statistic_kernel(rows2, rows2[:0, 0], mon._cfg, mon._state, mon._ring, mon._wring,
                             dm._est_terms(np.zeros(14)), out)
        outs[pfa_b] = out[-1]
        assert mon.bias_threshold == (pytest.approx(chi2.isf(1e-4, 1)) if pfa_b else 0.0)
    assert outs[0.0][4] < 96.0 and outs[0.0][5] == 0.0
    assert outs[1e-4][5] == 1.0


def test_bias_glrt_setting_declared_and_checked():
    for bad in (-0.1, 1.0, float("nan")):
        with pytest.raises(ValueError, match="bias_glrt_false_alarm_probability"):
            dm.DemIntegrityMonitor(dem=_flat_dem(), bias_glrt_false_alarm_probability=bad)
    for name in ("navigator_error_time_constant_s", "navigator_height_time_constant_s"):
        with pytest.raises(ValueError, match=name):
            dm.DemIntegrityMonitor(dem=_flat_dem(), **{name: -1.0})


@pytest.mark.slow
def test_denied_path_false_alarm_rate():
    """100,000 fault-free GNSS-denied windows through the monitor's kernel (whitened_statistic): map error
    18.9 m exponential at 1,070 m, the navigator's horizontal error 30 m per axis Gauss-Markov at 120 s and
    vertical 5 m at 300 s, through a map slope drawn per epoch (0.1 rms per axis); the monitor given those
    time constants. Alarms at the 1e-2 and 1e-3 chi2(50) thresholds inside their 99.9 % binomial bands."""
    rng = np.random.default_rng(21)
    n, N, L, batch = 100_000, 50, 1070.0, 10_000

    def gm(m, k, sigma, tau):
        a = math.exp(-1.0 / tau)
        x = np.empty((m, k))
        x[:, 0] = rng.standard_normal(m)
        w = rng.standard_normal((m, k))
        for j in range(1, k):
            x[:, j] = a * x[:, j - 1] + math.sqrt(1 - a * a) * w[:, j]
        return sigma * x

    lat, lon = _track(N, 85.0)
    T = []
    for _ in range(n // batch):
        rings = np.zeros((batch, N, 11))
        rings[:, :, 1], rings[:, :, 2], rings[:, :, 3], rings[:, :, 4] = lat, lon, 12.6**2, 25.0
        g = rng.normal(0.0, 0.1, (batch, N, 2))
        rings[:, :, 5], rings[:, :, 6] = g[..., 0], g[..., 1]
        rings[:, :, 7] = rings[:, :, 9] = 900.0
        rings[:, :, 10] = np.arange(N, dtype=float)
        rings[:, :, 0] = (gm(batch, N, 18.9, L / 85.0) + gm(batch, N, 5.0, 300.0)
                          + g[..., 0] * gm(batch, N, 30.0, 120.0) + g[..., 1] * gm(batch, N, 30.0, 120.0)
                          + 12.6 * rng.standard_normal((batch, N)))
        T += [cd.whitened_statistic(rings[k], 0, N, 18.9**2, 0.0, L, 0, 120.0, 300.0)[0]
              for k in range(batch)]
    T = np.asarray(T)
    for pfa in (1e-2, 1e-3):
        k = int(np.count_nonzero(T > chi2.isf(pfa, N)))
        lo, hi = binom.ppf([0.0005, 0.9995], n, pfa)
        assert lo <= k <= hi, (pfa, k, lo, hi)


def test_kalman_reading_matches_the_monitors_filter():
    """kalman_reading("rw_posterior") as a quadratic form = the monitor's eq 5 terms summed (kalman_terms +
    window_statistics) on the same disparities."""
    rng = np.random.default_rng(2)
    burn, N = 150, 50
    p = rng.standard_normal((20, burn + N))
    M = cd.kalman_reading("rw_posterior", N, burn, 0.01)
    direct = dm.window_statistics(dm.kalman_terms(p, np.ones_like(p), 0.01), N)[:, burn]
    assert np.allclose(np.einsum("ij,jk,ik->i", p, M, p), direct, rtol=1e-9)
    with pytest.raises(ValueError, match="reading"):
        cd.kalman_reading("smoothed", N, burn, 0.01)


def test_innovation_variant_of_the_monitor_is_the_innovation_reading():
    """variant "kalman_innovation": the monitor's statistic over a window = kalman_reading("innovation") as
    a quadratic form of the same disparities (the filter started at steady state 100 epochs earlier)."""
    rng = np.random.default_rng(6)
    burn, N = 100, 50
    n = burn + N
    p = rng.standard_normal(n) * 18.9
    lat, lon = _track(n, 85.0)
    rows = np.zeros((n, 10))
    rows[:, 0] = np.arange(n, dtype=float)
    rows[:, 1], rows[:, 2], rows[:, 3], rows[:, 4] = lat, lon, 900.0, 600.0
    rows[:, 5] = 300.0 - p
    mon = dm.DemIntegrityMonitor(dem=_flat_dem(), variant="kalman_innovation", kf_process_ratio=0.1)
    out = np.empty((n, 7))
    dm._statistic_kernel(rows, rows[:0, 0], mon._cfg, mon._state, mon._ring, mon._wring,
                         dm._est_terms(np.zeros(14)), out)
    z = p / 18.9
    assert out[-1, 4] == pytest.approx(z @ cd.kalman_reading("innovation", N, burn, 0.1) @ z, rel=1e-6)


def test_map_correlation_settings_rejected_by_name():
    for bad in (-10.0, float("nan"), 0.0, "long"):
        with pytest.raises(ValueError, match="correlation_length_m"):
            map_error.MapErrorModel(random_sigma_m=5.0, correlation_length_m=bad)
    with pytest.raises(ValueError, match="correlation_function"):
        map_error.MapErrorModel(correlation_function="spherical")
    dem = _flat_dem(60)
    with pytest.raises(ValueError, match="correlation_length_m.*longer than the map"):
        map_error.apply(dem, map_error.MapErrorModel(random_sigma_m=5.0, correlation_length_m=50_000.0))
    for bad in (-1.0, float("nan")):
        with pytest.raises(ValueError, match="correlation_length_m"):
            dm.DemIntegrityMonitor(dem=dem, correlation_length_m=bad)
    with pytest.raises(ValueError, match="correlation_length_m.*longer than the map"):
        dm.DemIntegrityMonitor(dem=dem, correlation_length_m=50_000.0)
    with pytest.raises(ValueError, match="map_bias_fraction"):
        dm.DemIntegrityMonitor(dem=dem, map_bias_fraction=1.5)


def test_class_defaults_carry_a_source_and_exponential_field_correlates_as_stated():
    for name, c in map_error.ACCURACY_CLASSES.items():
        assert c.correlation_length_m > 0 and c.correlation_source, name
    m = map_error.model_for_class("dted1", 0)
    assert m.correlation_function == "exponential" and m.correlation_length_m == 1070.0
    # the exponential field's sample correlation at lag L along rows is near exp(-1) (many fields averaged)
    rng = np.random.default_rng(0)
    lag = 10
    vals = []
    for _ in range(6):
        f = map_error.correlated_field((256, 256), 50.0, 50.0, 1.0, lag * 50.0, rng, "exponential")
        vals.append(np.mean(f[:, :-lag] * f[:, lag:]) / np.mean(f * f))
    assert abs(np.mean(vals) - math.exp(-1.0)) < 0.08
    rho = map_error.correlation(np.array([0.0, 500.0]), 500.0, "exponential")
    assert rho[0] == 1.0 and rho[1] == pytest.approx(math.exp(-1))
