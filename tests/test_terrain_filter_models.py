"""Terrain measurement models over hypotheses and the filters' building blocks, against independent
computations: the single-query closest-point formulas, the exact radar-altimeter search, numpy twins of the
likelihood and resampling kernels, brute-force moments; the filters' settings validation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from trn_env.navigators import registry
from trn_env.navigators.core.maps import map_record
from trn_env.navigators.core.resampling import (
    effective_sample_size,
    systematic_indices,
    systematic_indices_reference,
    systematic_kernel,
)
from trn_env.navigators.filters import _pmf_kernels as pk
from trn_env.navigators.filters.pmf_grid import _kernel_1d
from trn_env.navigators.measurements import ira, radar_altimeter
from trn_env.navigators.measurements.ira import IRA_FORMULA_CODES
from trn_env.navigators.measurements.terrain_models import (
    radii_m,
    robust_log_likelihood,
    robust_log_likelihood_reference,
)
from trn_env.terrain import queries
from trn_env.terrain.geodesy import euler_to_C_bn

from trn_env import terrain


@pytest.fixture(scope="module")
def dem():
    return terrain.load("jacksboro")


@pytest.mark.parametrize("formula", ["proposed", "conventional"])
def test_ira_closest_points_match_the_single_query_formulas(formula):
    rng = np.random.default_rng(3)
    for _ in range(6):
        C = euler_to_C_bn(rng.normal(0, 0.2), rng.normal(0, 0.1), rng.uniform(-3, 3))
        v = np.array([80 * math.cos(0.3), 80 * math.sin(0.3), rng.normal(0, 3)])
        m = 500
        dpsi = rng.normal(0, 0.02, m)
        dv = rng.normal(0, 2, (m, 2))
        theta = rng.normal(0, 0.3)
        out = np.empty((m, 3))
        n_bad = ira.closest_points(1500.0, theta, C, v, dpsi, dv, IRA_FORMULA_CODES[formula], out)
        ref = ira.closest_points_reference(1500.0, theta, C, v, dpsi, dv, formula)
        assert n_bad == int(np.isnan(ref[:, 0]).sum())
        np.testing.assert_array_equal(np.isnan(out), np.isnan(ref))
        ok = np.isfinite(ref[:, 0])
        np.testing.assert_allclose(out[ok], ref[ok], atol=1e-8)
    # a shared hypothesis (length-1 arrays) is the reference's single row
    out1 = np.empty((1, 3))
    ira.closest_points(1500.0, 0.1, C, v, np.zeros(1), np.zeros((1, 2)), 1, out1)
    ref1 = ira.closest_points_reference(1500.0, 0.1, C, v, np.zeros(1), np.zeros((1, 2)), "proposed")
    np.testing.assert_allclose(out1, ref1, atol=1e-8)


@pytest.mark.parametrize("cubic", [False, True])
def test_ira_predicted_heights_match_dem_height(dem, cubic):
    lat, lon = dem.center_rad
    r_lat, r_lon = radii_m(lat, 2000.0)
    rng = np.random.default_rng(0)
    dn, de = rng.uniform(-3000, 3000, 400), rng.uniform(-3000, 3000, 400)
    pn, pe = rng.uniform(-500, 500, 400), rng.uniform(-500, 500, 400)
    out = np.empty(400)
    rec = map_record(dem, cubic)
    assert ira.predict(rec, lat, lon, r_lat, r_lon, dn, de, pn, pe, out) == 0
    method = "bicubic" if cubic else "bilinear"
    ref = dem.height(lat + (dn + pn) / r_lat, lon + (de + pe) / r_lon, method=method)
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-9)
    # shared shift, and off the map -> NaN counted
    far = np.array([0.0, 1e6])
    out2 = np.empty(2)
    n = ira.predict(rec, lat, lon, r_lat, r_lon, far, far, np.zeros(1), np.zeros(1), out2)
    assert n == 1 and np.isnan(out2[1]) and out2[0] == pytest.approx(dem.height(lat, lon, method=method))


@pytest.mark.parametrize("roll_deg", [0.0, 5.0, 25.0])
def test_radar_altimeter_predict_against_the_exact_search(dem, roll_deg):
    """Sampled cone vs terrain.queries.radar_altimeter_return (branch and bound, exact): never shorter than
    the exact shortest in-cone range (every sample is a real in-cone terrain point) and within 1 % of it;
    banked past the half beamwidth the nadir leaves the cone and the range is a slant one."""
    lat_c, lon_c = dem.center_rad
    rng = np.random.default_rng(1)
    m = 40
    r_lat, r_lon = radii_m(lat_c, 1500.0)
    dn = rng.uniform(-8000, 8000, m)
    de = rng.uniform(-8000, 8000, m)
    lat = lat_c + dn / r_lat
    lon = lon_c + de / r_lon
    h_ant = dem.height(lat, lon) + 900.0
    C = euler_to_C_bn(math.radians(roll_deg), 0.02, 0.4)
    half = math.radians(10.0)
    exact = queries.radar_altimeter_return(dem, lat, lon, h_ant, np.broadcast_to(C, (m, 3, 3)), half)
    out = np.empty(m)
    # each hypothesis at its own antenna height: reference at h_ant[0], dh = h_ant[0] - h_ant[k]
    dh = h_ant[0] - h_ant
    radar_altimeter.predict(map_record(dem, False), lat_c, lon_c, r_lat, r_lon, float(h_ant[0]), dn, de, dh,
                            C, np.zeros(1), half, 4, 16, out)
    ok = exact.valid & np.isfinite(out)
    assert ok.sum() >= 0.9 * m
    assert np.all(out[ok] >= exact.range_m[ok] * (1 - 2e-4) - 0.05)
    assert np.all(out[ok] <= exact.range_m[ok] * 1.01)
    agl = h_ant - dem.height(lat, lon)
    if roll_deg > 10.0:
        # the attitude matters: a slant return (flat ground: 1 / cos(15 deg) = 1.035 times the height)
        assert np.median(exact.range_m[ok] / agl[ok]) > 1.02


def test_robust_log_likelihood_matches_logaddexp():
    rng = np.random.default_rng(2)
    r = rng.normal(0, 20, 1000)
    r[::97] = np.nan
    var = rng.uniform(1, 50, 1000)
    out = np.empty(1000)
    n_nan = robust_log_likelihood(r, var, 0.02, -math.log(500.0), out)
    ref = robust_log_likelihood_reference(r, var, 0.02, -math.log(500.0))
    assert n_nan == int(np.isnan(r).sum())
    np.testing.assert_allclose(out, ref, rtol=1e-12)
    # heavy tail: a 1 km residual costs no more than the outlier density
    big = np.empty(1)
    robust_log_likelihood(np.array([1000.0]), np.array([10.0]), 0.02, -math.log(500.0), big)
    assert big[0] == pytest.approx(math.log(0.02 / 500.0), rel=1e-9)


def test_systematic_resampling_equal_onehot_sparse():
    rng = np.random.default_rng(0)
    m = 1000
    idx = systematic_indices(np.ones(m), rng)
    np.testing.assert_array_equal(np.sort(idx), np.arange(m))             # equal weights: each once
    w = np.zeros(m)
    w[417] = 1.0
    assert np.all(systematic_indices(w, rng) == 417)                     # one-hot
    w = np.zeros(m)
    w[[3, 500, 900]] = [0.5, 0.25, 0.25]                                  # sparse: counts floor/ceil(M w)
    counts = np.bincount(systematic_indices(w, rng), minlength=m)
    assert set(np.nonzero(counts)[0]) == {3, 500, 900}
    assert abs(counts[3] - 500) <= 1 and abs(counts[500] - 250) <= 1
    # the kernel agrees with the searchsorted twin
    w = rng.random(m) ** 4
    out = np.empty(m, np.int64)
    for u0 in (0.0, 0.37, 0.999):
        systematic_kernel(w, u0, out)
        np.testing.assert_array_equal(out, systematic_indices_reference(w, u0))
    assert effective_sample_size(np.zeros(50)) == pytest.approx(50.0)
    with pytest.raises(ValueError):
        systematic_indices(np.array([np.nan, 1.0]), rng)


def test_pmf_kernels_against_numpy():
    rng = np.random.default_rng(4)
    n = 31
    logw = -0.5 * rng.random(n * n) * 30
    logw -= logw.max()
    dn = np.repeat(np.arange(n) * 2.0, n)
    de = np.tile(np.arange(n) * 3.0, n)
    bias = rng.normal(0, 5, n * n)
    o = np.empty(7)
    pk.grid_moments(logw, dn, de, bias, o)
    w = np.exp(logw)
    w /= w.sum()
    mn, me = w @ dn, w @ de
    np.testing.assert_allclose(o[:2], [mn, me], rtol=1e-12)
    np.testing.assert_allclose(o[2:5], [w @ (dn - mn) ** 2, w @ ((dn - mn) * (de - me)), w @ (de - me) ** 2],
                               rtol=1e-10)
    # separable convolution: mass kept (away from the border) and variance added exactly
    g = np.full(n * n, -700.0)
    g[(n // 2) * n + n // 2] = 0.0
    for var_cells in (0.3, 2.5):
        x = g.copy()
        k = _kernel_1d(var_cells)
        assert k.sum() == pytest.approx(1.0) and np.sum(k * (np.arange(k.size) - k.size // 2) ** 2) == \
            pytest.approx(var_cells, rel=1e-6 if var_cells < 0.6 else 2e-3)
        b = np.full(n * n, 3.0)
        spread = pk.convolve_separable(x, b, n, k, k, np.empty((6, n * n)), -700.0)
        w = np.exp(x).reshape(n, n)
        w /= w.sum()
        i = np.arange(n) - n // 2
        assert np.sum(w.sum(axis=1) * i ** 2) == pytest.approx(var_cells, rel=2e-3)
        np.testing.assert_allclose(b[w.ravel() > 1e-12], 3.0)            # a constant offset stays put
        assert spread == pytest.approx(0.0, abs=1e-9)
    # offsets move with their mass: two sources of different offsets mix into their weighted mean, and the
    # spread of the means (brute force: sum_j k_j (b_j - mean)^2 over the sources) is returned
    x = np.full(n * n, -700.0)
    c = (n // 2) * n + n // 2
    x[c], x[c + 1] = 0.0, math.log(0.5)
    b = np.zeros(n * n)
    b[c + 1] = 6.0
    k = _kernel_1d(0.4)
    spread = pk.convolve_separable(x, b, n, k, k, np.empty((6, n * n)), -700.0)
    wa, wb = 1.0 * k[1] * k[1], 0.5 * k[0] * k[1]        # the cell c receives from c (centre) and c + 1
    mean = wb * 6.0 / (wa + wb)
    assert b[c] == pytest.approx(mean, rel=1e-9)
    assert spread > 0.0


@pytest.mark.parametrize("name,settings,word", [
    ("pmf", {"grid_size": 0}, "grid_size"),
    ("pmf", {"grid_size": 100_000}, "grid_size"),
    ("pmf", {"spacing_min_m": -1.0}, "spacing_min_m"),
    ("pmf", {"position_noise_m_per_sqrt_s": -0.1}, "position_noise_m_per_sqrt_s"),
    ("pmf", {"accel_bias_sigma_mps2": float("nan")}, "accel_bias_sigma_mps2"),
    ("pmf", {"measurement_rate_hz": float("nan")}, "measurement_rate_hz"),
    ("pf", {"n_particles": 0}, "n_particles"),
    ("pf", {"n_particles": 10**10}, "n_particles"),
    ("pf", {"ess_threshold": 0.0}, "ess_threshold"),
    ("pf", {"ess_threshold": 1.5}, "ess_threshold"),
    ("pf", {"roughening": -1.0}, "roughening"),
    ("pf", {"map_sigma_m": -2.0}, "map_sigma_m"),
    ("pf", {"ira_formula": "magic"}, "ira_formula"),
])
def test_bad_settings_raise_value_error_naming_the_setting(dem, name, settings, word):
    with pytest.raises(ValueError, match=word):
        registry.create(name, dem=dem, **settings)


@pytest.mark.parametrize("name", ["pmf", "pf"])
def test_no_map_is_refused(name):
    with pytest.raises(ValueError, match="dem"):
        registry.create(name, dem=None)


@pytest.mark.parametrize("sign", [1, -1])
def test_pmf_diagonal_convolution_adds_the_north_east_covariance(sign):
    """_pmf_kernels.convolve_diagonal on a point mass: the grid's covariance grows by var [[1, s], [s, 1]]
    (brute-force moments with numpy), the mass and a constant vertical offset stay put."""
    from trn_env.navigators.filters.pmf_grid import _kernel_1d
    n = 41
    x = np.full(n * n, -700.0)
    x[(n // 2) * n + n // 2] = 0.0
    for var_cells in (0.3, 2.5):
        lw = x.copy()
        b = np.full(n * n, 3.0)
        spread = pk.convolve_diagonal(lw, b, n, _kernel_1d(var_cells), sign, np.empty((6, n * n)), -700.0)
        w = np.exp(lw).reshape(n, n)
        w /= w.sum()
        i = (np.arange(n) - n // 2)[:, None]
        j = (np.arange(n) - n // 2)[None, :]
        assert np.sum(w * i * i) == pytest.approx(var_cells, rel=2e-3)
        assert np.sum(w * j * j) == pytest.approx(var_cells, rel=2e-3)
        assert np.sum(w * i * j) == pytest.approx(sign * var_cells, rel=2e-3)
        np.testing.assert_allclose(b[w.ravel() > 1e-12], 3.0)
        assert spread == pytest.approx(0.0, abs=1e-9)
