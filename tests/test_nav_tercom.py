"""Batch TERCOM / MAD (seed 000 eqs 1-2): a known INS offset is recovered within one reference cell."""

import numpy as np
import pytest
from trn_env.navigators.tercom.mad import TercomBatch, correlate
from trn_env.terrain.dem import Dem
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

from trn_env import terrain


def _synthetic_dem(seed=0):
    """Smooth random terrain: a sum of random sinusoids on a 10 m grid (independent of terrain.synthetic)."""
    rng = np.random.default_rng(seed)
    lat0, lon0 = np.radians(35.0), np.radians(-100.0)
    n = 600
    dlat = 10.0 / meridian_radius_m(lat0)
    dlon = 10.0 / (prime_vertical_radius_m(lat0) * np.cos(lat0))
    y, x = np.mgrid[0:n, 0:n] * 10.0
    h = np.full((n, n), 400.0)
    for _ in range(40):
        k = rng.uniform(2 * np.pi / 2000, 2 * np.pi / 150)
        a = rng.uniform(0, 2 * np.pi)
        h += rng.uniform(2, 15) * np.sin(k * (np.cos(a) * x + np.sin(a) * y) + rng.uniform(0, 6.3))
    return Dem(h, lat0, lon0, dlat, dlon, "sines")


def _track(dem, lat_s, lon_s, heading, speed=83.0, seconds=40.0, rate=10.0):
    t = np.arange(0, seconds, 1 / rate)
    r_n = meridian_radius_m(lat_s)
    r_e = prime_vertical_radius_m(lat_s) * np.cos(lat_s)
    return t, lat_s + speed * t * np.cos(heading) / r_n, lon_s + speed * t * np.sin(heading) / r_e, r_n, r_e


@pytest.mark.parametrize("offset", [(37.0, -82.0), (-120.0, 45.0), (0.0, 0.0)])
def test_synthetic_plain_altimeter_offset_recovered(offset):
    dem = _synthetic_dem()
    lat_c, lon_c = dem.center_rad
    t, lat, lon, r_n, r_e = _track(dem, lat_c - 0.0003, lon_c - 0.0004, np.radians(30))
    h_terrain = dem.height(lat, lon)  # baro height - RA range = terrain below (eq 1)
    ins_lat, ins_lon = lat + offset[0] / r_n, lon + offset[1] / r_e
    fix = correlate(dem, t[-1], ins_lat, ins_lon, h_terrain)
    assert fix.valid and fix.reason == "ok"
    assert abs(fix.dn_m + offset[0]) <= 5.0 and abs(fix.de_m + offset[1]) <= 5.0
    assert fix.surface_m.shape == (101, 101) and fix.quality > 1.5


def test_jacksboro_ira_offset_recovered_with_closest_point_offsets():
    """Eq 2: the measured points are off the track by the closest-point offsets; using them recovers the
    INS offset, ignoring them (eq 1 on IRA data) does not."""
    dem = terrain.load("jacksboro")
    lat_c, lon_c = dem.center_rad
    rng = np.random.default_rng(5)
    t, lat, lon, r_n, r_e = _track(dem, lat_c, lon_c, np.radians(-60), rate=50.0)
    dn_rel = rng.uniform(-400, 400, t.size)
    de_rel = rng.uniform(-400, 400, t.size)
    h_meas = dem.height(lat + dn_rel / r_n, lon + de_rel / r_e)  # baro - |p_alt| = height of the point
    off = (-63.0, 141.0)
    ins_lat, ins_lon = lat + off[0] / r_n, lon + off[1] / r_e
    fix = correlate(dem, t[-1], ins_lat, ins_lon, h_meas, dn_rel, de_rel)
    assert fix.valid
    assert abs(fix.dn_m + off[0]) <= 5.0 and abs(fix.de_m + off[1]) <= 5.0
    assert fix.mad_min_m < 2.0
    wrong = correlate(dem, t[-1], ins_lat, ins_lon, h_meas)
    assert wrong.mad_min_m > 5 * fix.mad_min_m


def test_window_leaving_the_map_is_flagged_not_raised():
    dem = _synthetic_dem()
    b = dem.bounds
    r_n = meridian_radius_m(b[0])
    # along the southern edge: part of the reference matrix is off the map
    t, lat, lon, _, _ = _track(dem, b[0] + 30.0 / r_n, dem.center_rad[1], np.radians(90))
    fix = correlate(dem, t[-1], lat, lon, dem.height(lat, lon))
    assert np.isinf(fix.surface_m).any()
    assert fix.reason in ("ok_partial_map", "minimum_next_to_map_edge")
    # completely outside
    fix = correlate(dem, t[-1], lat - 0.01, lon, np.full(t.size, 300.0))
    assert not fix.valid and fix.reason == "off_map"
    # no usable samples
    fix = correlate(dem, 0.0, [np.nan], [np.nan], [np.nan])
    assert not fix.valid and fix.reason == "no_samples"


def test_batch_buffer_shift():
    b = TercomBatch()
    b.add([0.0, 1.0], [0.1, 0.1], [0.2, 0.2], [5.0, 6.0])
    b.add(2.0, 0.1, 0.2, 7.0, 3.0, 4.0)
    b.shift(1e-6, -2e-6)
    s = b.samples
    assert len(b) == 3 and s.shape == (3, 6)
    np.testing.assert_allclose(s[:, 1], 0.1 + 1e-6)
    np.testing.assert_allclose(s[2, 4:], [3.0, 4.0])


def test_mean_removed_mad_tolerates_a_height_bias():
    """A 25 m baro bias: the mean-removed variant still recovers the offset and reports a small MAD; the
    plain MAD of eq 1 sees the bias as its floor."""
    dem = _synthetic_dem(3)
    lat_c, lon_c = dem.center_rad
    t, lat, lon, r_n, r_e = _track(dem, lat_c - 0.0002, lon_c, np.radians(-20))
    h_meas = dem.height(lat, lon) + 25.0
    off = (48.0, 71.0)
    fix = correlate(dem, t[-1], lat + off[0] / r_n, lon + off[1] / r_e, h_meas, remove_bias=True)
    assert fix.valid and abs(fix.dn_m + off[0]) <= 5.0 and abs(fix.de_m + off[1]) <= 5.0
    assert fix.mad_min_m < 2.0
    plain = correlate(dem, t[-1], lat + off[0] / r_n, lon + off[1] / r_e, h_meas)
    assert plain.mad_min_m > 10.0


@pytest.mark.parametrize("k", [1, 3, 5])
def test_batch_average_enters_group_means(k):
    """average=k: rows added in uneven chunks (one not finite: dropped for k > 1; kept as it came for k = 1,
    the correlation drops it) enter as the means of k consecutive finite rows, the last partial group's
    mean at finish(); shift() moves the waiting rows too; the accumulator is fed exactly the batch's
    samples (its surface equals correlate()'s own on them)."""
    dem = _synthetic_dem(5)
    lat_c, lon_c = dem.center_rad
    t, lat, lon, _, _ = _track(dem, lat_c, lon_c, 0.7, seconds=4.7, rate=10.0)
    rng = np.random.default_rng(2)
    rows = np.stack([t, lat, lon, rng.uniform(300, 500, t.size), rng.uniform(-50, 50, t.size),
                     rng.uniform(-50, 50, t.size)], 1)
    rows[7, 3] = np.nan
    b = TercomBatch((8, 5.0, True, dem), average=k)
    for a, e in ((0, 3), (3, 4), (4, 20), (20, t.size)):
        b.add_rows(rows[a:e].copy())           # add_rows takes the rows as they are (shift moves them)
    b.shift(1e-7, -2e-7)
    b.finish()
    good = (rows if k == 1 else rows[np.isfinite(rows).all(axis=1)]).copy()
    good[:, 1] += 1e-7
    good[:, 2] -= 2e-7
    expected = np.array([good[i:i + k].mean(axis=0) for i in range(0, good.shape[0], k)])
    np.testing.assert_allclose(b.samples, expected, rtol=1e-12, atol=1e-12)
    assert len(b) == -(-good.shape[0] // k)
    b2 = TercomBatch((8, 5.0, True, dem), average=k)
    b2.add_rows(rows)
    b2.finish()
    s = b2.samples
    fix = correlate(dem, 1.0, s[:, 1], s[:, 2], s[:, 3], s[:, 4], s[:, 5], half=8, remove_bias=True,
                    lat_ref_rad=b2.accumulator.lat_ref_rad, accumulator=b2.accumulator)
    own = correlate(dem, 1.0, s[:, 1], s[:, 2], s[:, 3], s[:, 4], s[:, 5], half=8, remove_bias=True,
                    lat_ref_rad=b2.accumulator.lat_ref_rad)
    assert np.array_equal(fix.surface_m, own.surface_m)


@pytest.mark.parametrize("bad", [0, -1, 2.5, True, "3"])
def test_batch_average_must_be_a_positive_integer(bad):
    with pytest.raises(ValueError, match="average"):
        TercomBatch(average=bad)
