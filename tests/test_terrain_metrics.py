"""Terrain metrics against analytic surfaces, and the benchmark's figures."""

import numpy as np
import pytest
from trn_env.terrain import bench, geodesy, metrics
from trn_env.terrain.dem import Dem

from trn_env import terrain


def _metric_grid(h, spacing_m=30.0, lat0_deg=36.5):
    lat0 = np.radians(lat0_deg)
    dlat = spacing_m / geodesy.meridian_radius_m(lat0)
    dlon = spacing_m / (geodesy.prime_vertical_radius_m(lat0) * np.cos(lat0))
    return Dem(h, lat0, np.radians(-84.0), dlat, dlon, "analytic")


def test_plane_slope_roughness_and_information():
    n = 101
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    dem = _metric_grid(0.1 * 30.0 * i)  # 0.1 m/m towards north
    gn, ge, mag = metrics.slope(dem)
    assert np.allclose(gn, 0.1, rtol=2e-3) and np.allclose(ge, 0.0, atol=1e-9)
    # roughness of a plane in a 5-post window: std of 0.1 * 30 * (-2..2) repeated over 5 columns
    r = metrics.roughness(dem, 150.0)
    assert r[50, 50] == pytest.approx(np.std(3.0 * np.arange(-2, 3)), rel=1e-3)
    info = metrics.terrain_information(dem, sigma_m=2.0, window_m=150.0)
    # 25 posts, each contributing slope^2 / sigma^2 north, nothing east -> east unobservable
    assert info.i_nn[50, 50] == pytest.approx(25 * 0.01 / 4.0, rel=5e-3)
    assert info.crlb_sigma_n_m[50, 50] == np.inf and info.crlb_sigma_h_m[50, 50] == np.inf


def test_sinusoid_information_and_crlb():
    n = 121
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    wl = 600.0
    a = 20.0
    x_n = 30.0 * i
    x_e = 30.0 * j
    dem = _metric_grid(a * np.sin(2 * np.pi * x_n / wl) + a * np.sin(2 * np.pi * x_e / wl))
    info = metrics.terrain_information(
        dem, sigma_m=3.0, window_m=600.0 + 30.0
    )  # 21 x 21 posts = 1 wavelength
    k = 2 * np.pi / wl
    # mean of cos^2 over a whole wavelength is 1/2 (numerical derivative: sin(k d)/d instead of k)
    g = np.sin(k * 30.0) / 30.0 * a
    expected = 21 * 21 * 0.5 * g * g / 9.0
    assert info.i_nn[60, 60] == pytest.approx(expected, rel=0.06)
    assert info.i_ee[60, 60] == pytest.approx(expected, rel=0.06)
    assert abs(info.i_ne[60, 60]) < 0.05 * expected
    assert info.crlb_sigma_h_m[60, 60] == pytest.approx(np.sqrt(2.0 / expected), rel=0.06)


def test_track_acf_on_a_sinusoid():
    n = 400
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    wl = 900.0
    dem = _metric_grid(50.0 * np.sin(2 * np.pi * 30.0 * j / wl))  # varies east only
    lat, lon = dem.lat0_rad + 100 * dem.dlat_rad, dem.lon0_rad + 40 * dem.dlon_rad
    shift, pearson = metrics.track_acf(dem, lat, lon, np.pi / 2, 150, 30, "pearson", spacing_m=30.0)
    assert pearson[shift == 0][0] == pytest.approx(1.0)
    assert pearson[np.argmin(np.abs(shift - wl / 2))] == pytest.approx(-1.0, abs=0.05)  # half a period
    assert pearson[np.argmin(np.abs(shift - wl))] == pytest.approx(1.0, abs=0.05)  # a full period
    shift, mad = metrics.track_acf(dem, lat, lon, np.pi / 2, 150, 30, "mad", spacing_m=30.0)
    assert mad[shift == 0][0] == 0.0 and mad.max() == pytest.approx(mad[np.argmin(np.abs(shift - wl / 2))])
    # along north the terrain is constant: the profile has no information (Pearson undefined, MAD zero)
    _, mad_n = metrics.track_acf(dem, lat, lon, 0.0, 100, 10, "mad", spacing_m=30.0)
    assert np.allclose(mad_n, 0.0, atol=1e-9)


def test_jacksboro_metrics_are_finite_and_plausible():
    dem = terrain.load("jacksboro")
    r = metrics.roughness(dem, 1000.0)
    assert 10.0 < np.nanmedian(r) < 200.0
    info = metrics.terrain_information(dem, 3.0, 2000.0)
    assert np.isfinite(info.crlb_sigma_h_m).mean() > 0.99


def test_benchmark_reports_all_figures():
    figures = bench.benchmark(n_lookups=20_000, n_queries=50, repeats=1)
    for key in (
        "bilinear_lookups_per_s",
        "numpy_bilinear_lookups_per_s",
        "ira_queries_per_s",
        "radar_altimeter_queries_per_s",
    ):
        assert figures[key] > 0.0
