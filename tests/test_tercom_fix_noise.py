"""The TERCOM fix covariance from the batch (navigators.tercom.fix_noise) against Monte Carlo MAD fixes.

A smooth synthetic map (sums of sinusoids, 30 m posts), a straight 3 km batch of 600 samples whose measured
heights are the map's at the true positions plus white Gaussian noise, the INS offset by a known shift; each
trial correlates the batch (tercom.mad.correlate, mean-removed MAD, 5 m cells) and compares the fix's error
with the covariance lad_fix_covariance predicts from that batch alone. Over the trials the NEES sum must lie
inside the two-sided 99 % chi-square bounds (computed here), and the model must stand apart from the
least-squares bound without the LAD's pi / 2 (the factor the test would fail without).
"""

import math

import numpy as np
import pytest
from scipy import stats
from synthetic_terrain import LAT0, LON0, wave_map
from trn_env.navigators.tercom.fix_noise import NO_INFORMATION_VAR_M2, lad_fix_covariance
from trn_env.navigators.tercom.mad import correlate
from trn_env.terrain.dem import Dem
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

M = 600
TRIALS = 150
NOISE_M = 25.0
SHIFT_NE_M = (35.0, -20.0)     # INS minus true position


def _map(flat: bool = False) -> Dem:
    return wave_map(4, flat)


def _batch(dem: Dem):
    r_n = meridian_radius_m(LAT0)
    r_e = prime_vertical_radius_m(LAT0) * math.cos(LAT0)
    s = np.arange(M) * 5.0
    n_true, e_true = 2000.0 + 0.6 * s, 2000.0 + 0.8 * s
    lat, lon = LAT0 + n_true / r_n, LON0 + e_true / r_e
    lat_ins, lon_ins = LAT0 + (n_true + SHIFT_NE_M[0]) / r_n, LON0 + (e_true + SHIFT_NE_M[1]) / r_e
    return lat, lon, dem.height(lat, lon), lat_ins, lon_ins


def test_fix_covariance_matches_monte_carlo_mad_fixes():
    dem = _map()
    _, _, h_true, lat_ins, lon_ins = _batch(dem)
    rng = np.random.default_rng(11)
    zeros = np.zeros(M)
    nees, nees_ls, sig = [], [], []
    for _ in range(TRIALS):
        h_meas = h_true + rng.normal(0.0, NOISE_M, M)
        fix = correlate(dem, 0.0, lat_ins, lon_ins, h_meas, zeros, zeros, half=30, cell_m=5.0,
                        remove_bias=True)
        assert fix.valid
        err = np.array([fix.dn_m + SHIFT_NE_M[0], fix.de_m + SHIFT_NE_M[1]])   # correction = -shift
        C = lad_fix_covariance(dem, lat_ins, lon_ins, h_meas, zeros, zeros, fix.dn_m, fix.de_m, 5.0, True)
        nees.append(err @ np.linalg.solve(C, err))
        C_ls = (C - np.eye(2) * 25.0 / 12.0) / (0.5 * math.pi) + np.eye(2) * 25.0 / 12.0
        nees_ls.append(err @ np.linalg.solve(C_ls, err))
        sig.append(math.sqrt(np.trace(C) / 2.0))
    lo, hi = stats.chi2.ppf([0.005, 0.995], 2 * TRIALS)
    total, total_ls = float(np.sum(nees)), float(np.sum(nees_ls))
    print(f"\nNEES sum {total:.0f} (least squares {total_ls:.0f}) over {TRIALS} fixes; 99 % bounds "
          f"[{lo:.0f}, {hi:.0f}]; sigma per axis {np.median(sig):.2f} m")
    assert 2.0 < np.median(sig) < 10.0        # errors of a few cells: the test resolves the model
    assert lo < total < hi
    assert total_ls > hi                      # without the LAD's pi / 2 the fixes are overconfident


def test_terrain_term_and_flat_map():
    dem = _map()
    _, _, h_true, lat_ins, lon_ins = _batch(dem)
    zeros = np.zeros(M)
    h_meas = h_true + np.random.default_rng(2).normal(0.0, NOISE_M, M)
    args = (dem, lat_ins, lon_ins, h_meas, zeros, zeros, -SHIFT_NE_M[0], -SHIFT_NE_M[1], 5.0, True)
    c0, c3 = lad_fix_covariance(*args), lad_fix_covariance(*args, terrain_sigma_m=3.0)
    # the map's unresolved terrain: (pi / 2) sigma^2 n_post A^-1 on top, n_post = 30 m / 5 m samples
    # (the matched positions: INS minus the shift; 30 m posts over samples 5 m apart)
    r_n, r_e = meridian_radius_m(LAT0), prime_vertical_radius_m(LAT0) * math.cos(LAT0)
    g = np.stack(dem.gradient(lat_ins - SHIFT_NE_M[0] / r_n, lon_ins - SHIFT_NE_M[1] / r_e), 1)
    want = 0.5 * math.pi * 9.0 * 6.0 * np.linalg.inv(g.T @ g)
    np.testing.assert_allclose(c3 - c0, want, rtol=0.02)
    # a flat map carries no horizontal information
    flat = _map(flat=True)
    _, _, hf, la, lo = _batch(flat)
    c = lad_fix_covariance(flat, la, lo, hf + 1.0, zeros, zeros, 0.0, 0.0, 5.0, True)
    assert np.all(np.diag(c) >= NO_INFORMATION_VAR_M2)


@pytest.mark.parametrize("mode", ["batch", "fixed"])
def test_navigator_setting(mode):
    from trn_env.navigators import registry
    nav = registry.create("ins_tercom", dem=_map(), fix_noise=mode, fix_sigma_m=7.0)
    assert nav.fix_noise == mode
    assert (nav.terrain_model_sigma_m > 0.0) == (mode == "batch")      # auto: the map's spectrum
    with pytest.raises(ValueError, match="fix_noise"):
        registry.create("ins_tercom", dem=_map(), fix_noise="magic")


def test_height_bias_term_against_plain_mad_fixes():
    """A plain MAD (no bias removal, seed 000 eq 2) on a tilted map over heights with a common bias drawn
    per trial (N(0, 15^2) m, the barometer's) and white noise (25 m). The term is sigma_b^2 j j^T with
    j = A^-1 sum_k g_k (computed here); over 100 trials it takes the NEES sum from far above the 99 %
    chi-square bounds to within 40 % of their upper end. It is the least-squares (linear) sensitivity: the
    LAD absorbs a bias the more the smaller the noise (1.2 x j at this noise, 3.5 x j without noise,
    docs/validation/navigators.md), so the plain MAD stays somewhat overconfident; the bias-removed MAD
    (remove_bias) has no such term."""
    dem = _map()
    r_n, r_e = meridian_radius_m(LAT0), prime_vertical_radius_m(LAT0) * math.cos(LAT0)
    _, _, _, lat_ins, lon_ins = _batch(dem)
    n_lat, n_lon = dem.heights_m.shape
    tilt = Dem(np.asarray(dem.heights_m) + 0.02 * (np.arange(n_lat)[:, None] * 30.0 * 0.6
                                                   + np.arange(n_lon)[None, :] * 30.0 * 0.8),
               dem.lat0_rad, dem.lon0_rad, dem.dlat_rad, dem.dlon_rad, "tilted")
    lat_t, lon_t = lat_ins - SHIFT_NE_M[0] / r_n, lon_ins - SHIFT_NE_M[1] / r_e
    h_true = tilt.height(lat_t, lon_t)
    rng = np.random.default_rng(3)
    zeros = np.zeros(M)
    trials, bias_sigma_m = 100, 15.0
    nees, nees_no_bias = [], []
    for k in range(trials):
        h_meas = h_true + rng.normal(0.0, bias_sigma_m) + rng.normal(0.0, NOISE_M, M)
        fix = correlate(tilt, 0.0, lat_ins, lon_ins, h_meas, zeros, zeros, half=60, cell_m=5.0,
                        remove_bias=False)
        assert fix.valid
        err = np.array([fix.dn_m + SHIFT_NE_M[0], fix.de_m + SHIFT_NE_M[1]])
        args = (tilt, lat_ins, lon_ins, h_meas, zeros, zeros, fix.dn_m, fix.de_m, 5.0, False)
        C = lad_fix_covariance(*args, height_bias_sigma_m=bias_sigma_m)
        C0 = lad_fix_covariance(*args)
        if k == 0:
            lat_c = float(np.mean(lat_ins))        # the matched points as the module places them
            lat_m = lat_ins + fix.dn_m / meridian_radius_m(lat_c)
            lon_m = lon_ins + fix.de_m / (prime_vertical_radius_m(lat_c) * math.cos(lat_c))
            g = np.stack(tilt.gradient(lat_m, lon_m), 1)
            j = np.linalg.solve(g.T @ g, g.sum(axis=0))
            np.testing.assert_allclose(C - C0, bias_sigma_m**2 * np.outer(j, j), rtol=1e-6, atol=1e-9)
        nees.append(err @ np.linalg.solve(C, err))
        nees_no_bias.append(err @ np.linalg.solve(C0, err))
    lo, hi = stats.chi2.ppf([0.005, 0.995], 2 * trials)
    total, total0 = float(np.sum(nees)), float(np.sum(nees_no_bias))
    print(f"\nNEES sum {total:.0f} (without the bias term {total0:.0f}) over {trials} plain-MAD fixes; 99 % "
          f"bounds [{lo:.0f}, {hi:.0f}]")
    assert total0 > 1.5 * hi
    assert lo < total < 1.4 * hi
