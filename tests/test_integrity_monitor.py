"""Seed 003's DEM integrity monitor: eqs 1-5 against independent computations, its thresholds against
chi-square quantiles, fixed-seed false-alarm and detection counts against binomial bounds computed here,
the beam model against terrain.queries, and bad settings."""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy.stats import binom, chi2
from trn_env.navigators.frames import GnssFrame, RadarAltimeterFrame, SensorFrames
from trn_env.navigators.integrity import dem_monitor as dm
from trn_env.navigators.protocol import Estimate
from trn_env.navigators.registry import available_monitors, create_monitor
from trn_env.terrain import queries
from trn_env.terrain.dem import Dem
from trn_env.terrain.geodesy import euler_to_C_bn, meridian_radius_m

from trn_env import terrain


def _rough_dem(seed: int = 0) -> Dem:
    rng = np.random.default_rng(seed)
    h = 400.0 + np.cumsum(np.cumsum(rng.normal(0.0, 1.0, (200, 200)), 0), 1) * 0.05
    d = math.radians(3.0 / 3600.0)
    return Dem(h, math.radians(36.5), math.radians(-84.3), d, d, "rough")


def _flight(dem: Dem, n_s: int, rate_hz: float, noise_m: float, seed: int, agl_m: float = 600.0):
    """A northbound straight line at 80 m/s: per-second frames of radar-altimeter ranges (nadir truth
    agl + noise) and GNSS fixes at the same instants (so the monitor's positions are exact)."""
    rng = np.random.default_rng(seed)
    lat0, lon0 = dem.lat0_rad + 30 * dem.dlat_rad, dem.lon0_rad + 100 * dem.dlon_rad
    r_n = meridian_radius_m(lat0)
    frames = []
    for k in range(n_s):
        t = k + np.arange(int(rate_hz)) / rate_hz
        lat = lat0 + 80.0 * t / r_n
        lon = np.full(t.shape, lon0)
        h_ground = dem.height(lat, lon)
        h = h_ground + agl_m
        r = agl_m + noise_m * rng.standard_normal(t.shape)
        g = GnssFrame(t, lat, lon, h, np.tile([80.0, 0.0, 0.0], (t.size, 1)), np.ones(t.size, bool))
        ra = RadarAltimeterFrame(t, r, np.ones(t.size, bool))
        est = Estimate(float(t[-1]), float(lat[-1]), lon0, float(h[-1]), np.array([80.0, 0.0, 0.0]), 0.0, 0.0,
                       0.0, np.eye(9))
        fr = SensorFrames(float(k), float(k + 1), radar_altimeter=ra, gnss=g)
        frames.append((fr, est, t, lat, lon, h, r))
    return frames


def test_registry_lists_the_monitor():
    assert "dem_integrity" in available_monitors()
    with pytest.raises(ValueError, match="unknown monitor"):
        create_monitor("nope", dem=_rough_dem())


def test_eqs_1_to_4_against_a_direct_computation():
    """Eq 1 (h_synt = h_gnss - R - l_ar), eq 2 (p = h_synt - h_map), eq 3 and eq 4 (sum of the last N
    p^2 / sigma^2) recomputed here with numpy from the same samples."""
    dem = _rough_dem()
    n_win, lever = 10, 1.5
    mon = create_monitor("dem_integrity", dem=dem, n_window=n_win, lever_arm_m=lever, sigma_m=15.0,
                         radar_altimeter_noise_const_m=1.0, radar_altimeter_noise_fraction=0.01,
                         gnss_vertical_sigma_m=2.0)
    rows, expect_p, expect_var, t_ep = [], [], [], []
    for frames, est, t, lat, lon, h, r in _flight(dem, 40, 20.0, 3.0, 1):
        out = mon.update(frames, est)
        rows.append(out.rows)
        # one epoch per second: the first sample of each frame
        expect_p.append(h[0] - r[0] - lever - dem.height(lat[0], lon[0]))
        expect_var.append(15.0**2 + (1.0 + 0.01 * r[0]) ** 2 + 2.0**2)
        t_ep.append(t[0])
    got = np.concatenate(rows)
    p, var = np.array(expect_p), np.array(expect_var)
    np.testing.assert_allclose(got[:, 0], t_ep)
    np.testing.assert_allclose(got[:, 1], p, atol=1e-6)
    np.testing.assert_allclose(got[1:, 2], np.diff(p), atol=1e-6)
    np.testing.assert_allclose(got[:, 3], np.sqrt(var))
    T = np.convolve(p * p / var, np.ones(n_win), "valid")
    assert np.all(np.isnan(got[: n_win - 1, 4]))
    np.testing.assert_allclose(got[n_win - 1:, 4], T, rtol=1e-9)
    assert np.all(got[:, 6] == dm.SOURCE_GNSS)


def test_eq5_kalman_statistic_against_filterpy():
    """Eq 5: T_KF = sum x_hat^2 / P over the window, x_hat and P from a scalar random-walk Kalman filter;
    here filterpy's KalmanFilter on the disparities the plain monitor reports."""
    dem = _rough_dem(1)
    n_win, ratio = 12, 0.05
    settings = dict(n_window=n_win, sigma_m=10.0, kf_process_ratio=ratio)
    plain = create_monitor("dem_integrity", dem=dem, **settings)
    kalm = create_monitor("dem_integrity", dem=dem, variant="kalman", **settings)
    p_all, tk = [], []
    for frames, est, *_ in _flight(dem, 30, 10.0, 4.0, 2):
        p_all.append(plain.update(frames, est).disparity_m)
        tk.append(kalm.update(frames, est).statistic)
    p, tk = np.concatenate(p_all), np.concatenate(tk)
    r = 100.0
    k_ss, p_ss = dm.kf_steady_state(ratio * r, r)
    kf = KalmanFilter(dim_x=1, dim_z=1)
    kf.x[:] = 0.0
    kf.P[:] = p_ss
    kf.F[:] = 1.0
    kf.H[:] = 1.0
    kf.Q[:] = ratio * r
    kf.R[:] = r
    terms = []
    for z in p:
        kf.predict()
        kf.update(z)
        terms.append(kf.x[0, 0] ** 2 / kf.P[0, 0])
    expect = np.convolve(terms, np.ones(n_win), "valid")
    np.testing.assert_allclose(tk[n_win - 1:], expect, rtol=1e-9)


def test_thresholds_from_false_alarm_probability():
    c = dm.DemMonitorConfig(false_alarm_probability=1e-4)
    assert c.effective_threshold == pytest.approx(chi2.isf(1e-4, 50))
    assert abs(c.effective_threshold - 96.0) < 0.1          # seed 003's pair (N = 50, 96, 1e-4)
    assert dm.DemMonitorConfig().effective_threshold == 96.0
    assert dm.DemMonitorConfig().map_sigma_m == 18.9
    # the eq 5 statistic's moments (used for its threshold) against a Monte Carlo here
    rng = np.random.default_rng(3)
    p = rng.standard_normal((4000, 300))
    w = dm.window_statistics(dm.kalman_terms(p, np.ones_like(p), 0.01), 50)[:, 150:]
    mean, var = dm.kalman_statistic_moments(50, 0.01)
    assert w.mean() == pytest.approx(mean, rel=0.03)
    assert w.var() == pytest.approx(var, rel=0.08)


def _disparity_windows(rng, n_tests: int, n_win: int, agl_m: np.ndarray):
    """Fault-free disparities of the error models: map error of the DTED-1 class (seed 003: 18.9 m),
    radar-altimeter noise 0.6 m + 2 % (trn_env's default sensor), GNSS vertical 2 m white + 3 m drift."""
    ra_sig = 0.6 + 0.02 * agl_m[:, None]
    p = (18.9 * rng.standard_normal((n_tests, n_win)) + ra_sig * rng.standard_normal((n_tests, n_win))
         + 2.0 * rng.standard_normal((n_tests, n_win)) + 3.0 * rng.standard_normal((n_tests, 1)))
    var = 18.9**2 + ra_sig**2 + (2.0**2 + 3.0**2)
    return p, np.broadcast_to(var, p.shape)


def test_false_alarm_rate_within_binomial_bound():
    """200,000 independent fault-free tests (N = 50, threshold 96): alarms at most the 99.9 % binomial
    quantile of the design probability 1e-4, and not implausibly few (the statistic is not inert)."""
    rng = np.random.default_rng(10)
    n = 200_000
    p, var = _disparity_windows(rng, n, 50, rng.uniform(300.0, 1500.0, n))
    T = dm.window_statistics(p * p / var, 50)[:, 0]
    alarms = int(np.count_nonzero(T > 96.0))
    assert alarms <= binom.ppf(0.999, n, 1e-4)
    assert alarms >= binom.ppf(0.001, n, chi2.sf(96.0, 50) / 4)


def test_60m_bias_detected_within_50_samples():
    """A 60 m map bias under all 50 samples of the window at 1,500 m above ground (sigma ~ 36 m): missed
    detections within the 99.9 % binomial quantile of P_md = 1e-3 over 20,000 windows."""
    rng = np.random.default_rng(11)
    n = 20_000
    p, var = _disparity_windows(rng, n, 50, np.full(n, 1500.0))
    T = dm.window_statistics((p - 60.0) ** 2 / var, 50)[:, 0]
    missed = int(np.count_nonzero(T <= 96.0))
    assert missed <= binom.ppf(0.999, n, 1e-3)


def test_beam_model_matches_the_maps_own_cone_return():
    """With beam_half_angle_deg the disparity of a range equal to the map's exact cone return
    (terrain.queries, the estimate's attitude) is zero, and the nadir model sees the beam's shortening as a
    positive bias."""
    dem = _rough_dem(2)
    roll, pitch, yaw = 0.03, -0.02, 0.4
    C = euler_to_C_bn(roll, pitch, yaw)
    cone = create_monitor("dem_integrity", dem=dem, beam_half_angle_deg=8.5, n_window=5)
    nadir = create_monitor("dem_integrity", dem=dem, n_window=5)
    for frames, est, t, lat, lon, h, _ in _flight(dem, 8, 5.0, 0.0, 0):
        ret = queries.radar_altimeter_return(dem, lat, lon, h, C, math.radians(8.5), 5000.0)
        frames.radar_altimeter = RadarAltimeterFrame(t, ret.range_m, ret.valid)
        est.roll_rad, est.pitch_rad, est.yaw_rad = roll, pitch, yaw
        np.testing.assert_allclose(cone.update(frames, est).disparity_m, 0.0, atol=1e-6)
        assert np.all(nadir.update(frames, est).disparity_m >= -1e-6)


def test_navigator_source_when_gnss_is_denied():
    """Without GNSS the monitor takes the navigator's position and height (dead-reckoned to the sample) and
    says so; its sigma then carries the estimate's own vertical variance."""
    dem = _rough_dem()
    mon = create_monitor("dem_integrity", dem=dem, n_window=3, sigma_m=10.0)
    frames, est, t, lat, lon, h, r = _flight(dem, 1, 20.0, 0.0, 0)[0]
    frames.gnss = None
    est.covariance = np.diag([25.0, 25.0, 64.0, 0, 0, 0, 0, 0, 0]) + 1e-9 * np.eye(9)
    out = mon.update(frames, est)
    assert out.source_names == ["navigator"]
    # the estimate is at t[-1]; the epoch at t[0] is its dead-reckoned position there
    assert out.disparity_m[0] == pytest.approx(h[-1] - r[0] - dem.height(lat[0], lon[0]), abs=0.5)
    assert out.sigma_m[0] > math.sqrt(100.0 + 64.0) - 1e-9


@pytest.mark.parametrize("settings, field", [
    ({"n_window": 1}, "n_window"),
    ({"sigma_m": 0.0}, "sigma_m"),
    ({"sigma_m": -3.0}, "sigma_m"),
    ({"threshold": 0.0}, "threshold"),
    ({"threshold": float("nan")}, "threshold"),
    ({"false_alarm_probability": 0.0}, "false_alarm_probability"),
    ({"false_alarm_probability": 1.0}, "false_alarm_probability"),
    ({"map_class": "dted9"}, "map_class"),
    ({"variant": "median"}, "variant"),
    ({"wobble": 1}, "wobble"),
])
def test_bad_settings_name_the_field(settings, field):
    with pytest.raises(ValueError, match=field):
        create_monitor("dem_integrity", dem=terrain.load("jacksboro"), **settings)


def test_bad_data_is_skipped_not_raised():
    """A NaN estimate (GNSS denied) or NaN ranges skip epochs; later epochs are unharmed."""
    dem = _rough_dem()
    mon = create_monitor("dem_integrity", dem=dem, n_window=3, sigma_m=10.0)
    flight = _flight(dem, 6, 10.0, 1.0, 3)
    frames, est, *_ = flight[0]
    frames.gnss = None
    est.covariance = np.full((9, 9), np.nan)
    assert mon.update(frames, est).rows.shape[0] == 0
    frames, est, *_ = flight[1]
    frames.radar_altimeter.range_m[:] = np.nan
    assert mon.update(frames, est).rows.shape[0] == 0
    outs = [mon.update(f, e) for f, e, *_ in flight[2:]]
    assert np.isfinite(outs[-1].statistic).all()
