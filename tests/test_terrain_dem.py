"""Dem model and interpolation kernels: analytic surfaces, NaN behaviour, the bundled jacksboro DEM."""

import numpy as np
import pytest
from trn_env.terrain import geodesy, kernels
from trn_env.terrain.dem import Dem

from trn_env import terrain


def _plane_dem(a=3.0, b=-2.0, c=500.0, n=40):
    """Heights linear in the grid indices: h = c + a*i + b*j (bilinear and bicubic reproduce it)."""
    i, j = np.meshgrid(np.arange(n), np.arange(n + 5), indexing="ij")
    return Dem(
        c + a * i + b * j,
        np.radians(36.0),
        np.radians(-84.0),
        np.radians(3 / 3600),
        np.radians(3 / 3600),
        "plane",
    )


def test_bilinear_and_bicubic_reproduce_a_plane():
    dem = _plane_dem()
    rng = np.random.default_rng(0)
    fi = rng.uniform(0, dem.n_lat - 1, 500)
    fj = rng.uniform(0, dem.n_lon - 1, 500)
    lat = dem.lat0_rad + fi * dem.dlat_rad
    lon = dem.lon0_rad + fj * dem.dlon_rad
    expected = 500.0 + 3.0 * fi - 2.0 * fj
    np.testing.assert_allclose(dem.height(lat, lon), expected, atol=1e-8)
    inner = (fi > 1) & (fi < dem.n_lat - 2) & (fj > 1) & (fj < dem.n_lon - 2)
    np.testing.assert_allclose(dem.height(lat, lon, "bicubic")[inner], expected[inner], atol=1e-8)


def test_bicubic_reproduces_quadratic_and_bilinear_does_not():
    i, j = np.meshgrid(np.arange(30), np.arange(30), indexing="ij")
    dem = Dem(0.5 * i**2 + 0.25 * i * j, 0.6, -1.4, 1e-5, 1e-5)
    fi, fj = 10.3, 12.7
    lat, lon = 0.6 + fi * 1e-5, -1.4 + fj * 1e-5
    exact = 0.5 * fi**2 + 0.25 * fi * fj
    assert dem.height(lat, lon, "bicubic") == pytest.approx(exact, abs=1e-6)
    assert abs(dem.height(lat, lon) - exact) > 0.05


def test_scalar_kernel_matches_batch_and_grid_tuple():
    dem = terrain.load("jacksboro")
    rng = np.random.default_rng(1)
    b = dem.bounds
    lat = rng.uniform(b[0], b[1], 200)
    lon = rng.uniform(b[2], b[3], 200)
    batch = dem.height(lat, lon)
    scalar = np.array([kernels.bilinear(*dem.grid, la, lo) for la, lo in zip(lat, lon, strict=True)])
    np.testing.assert_allclose(batch, scalar, rtol=0, atol=1e-9)
    assert isinstance(dem.height(lat[0], lon[0]), float)


def test_nan_outside_grid_and_over_voids():
    dem = _plane_dem()
    lat_max = dem.bounds[1]
    assert np.isnan(dem.height(lat_max + 1e-9, dem.lon0_rad))
    assert np.isnan(dem.height(dem.lat0_rad - 1e-9, dem.lon0_rad))
    assert np.isnan(kernels.bilinear(*dem.grid, np.nan, dem.lon0_rad))
    assert not np.isnan(dem.height(lat_max, dem.bounds[3]))  # the last post itself is inside
    h = dem.heights_m.copy()
    h[5, 5] = np.nan
    holed = dem.with_heights(h)
    lat = holed.lat0_rad + 4.5 * holed.dlat_rad
    lon = holed.lon0_rad + 4.5 * holed.dlon_rad
    assert np.isnan(holed.height(lat, lon))
    assert not np.isnan(holed.height(lat - 2 * holed.dlat_rad, lon))
    assert holed.contains(lat, lon) and not holed.contains(lat + 1.0, lon)


def test_gradient_in_metres_per_metre():
    dem = _plane_dem(a=3.0, b=-2.0)
    lat, lon = dem.center_rad
    dn, de = dem.gradient(lat, lon)
    r_n = geodesy.meridian_radius_m(lat)
    r_e = geodesy.prime_vertical_radius_m(lat) * np.cos(lat)
    assert dn == pytest.approx(3.0 / (dem.dlat_rad * r_n), rel=1e-9)
    assert de == pytest.approx(-2.0 / (dem.dlon_rad * r_e), rel=1e-9)
    gn, ge = dem.gradient(np.array([lat]), np.array([lon]), method="bicubic")
    assert gn[0] == pytest.approx(dn, rel=1e-5) and ge[0] == pytest.approx(de, rel=1e-5)


def test_offsets_round_trip_through_seed000_eq2():
    dem = _plane_dem()
    lat, lon = dem.center_rad
    la, lo = dem.offset_to_latlon(lat, lon, 1000.0, -500.0)
    dn, de = dem.latlon_to_offset(lat, lon, la, lo)
    assert dn == pytest.approx(1000.0, abs=1e-6) and de == pytest.approx(-500.0, abs=0.05)
    # against geodesy (the shared module)
    la2, lo2 = geodesy.ned_offset_to_latlon(lat, lon, 0.0, 1000.0, -500.0)
    assert la == pytest.approx(la2, abs=1e-15) and lo == pytest.approx(lo2, abs=1e-15)


def test_bad_dem_fields_raise():
    with pytest.raises(ValueError, match="positive"):
        Dem(np.zeros((3, 3)), 0.6, -1.4, -1e-5, 1e-5, "neg")
    with pytest.raises(ValueError, match="void"):
        Dem(np.full((3, 3), np.nan), 0.6, -1.4, 1e-5, 1e-5, "voids")
    with pytest.raises(ValueError, match="2-D"):
        Dem(np.zeros(5), 0.6, -1.4, 1e-5, 1e-5)
    with pytest.raises(ValueError, match="method"):
        _plane_dem().height(0.6, -1.4, method="cubic-spline")


def test_jacksboro_is_the_bundled_real_dem():
    dem = terrain.load("jacksboro")
    assert dem.heights_m.shape == (344, 403)
    assert np.nanmin(dem.heights_m) == 236.0 and np.nanmax(dem.heights_m) == 1076.0
    lat_min, lat_max, lon_min, lon_max = np.degrees(dem.bounds)
    assert lat_min == pytest.approx(36.44625 + 0.5 / 1200, abs=1e-9)
    assert lat_max == pytest.approx(36.73291666 - 0.5 / 1200, abs=1e-6)
    assert lon_min == pytest.approx(-84.41375 + 0.5 / 1200, abs=1e-9)
    assert dem.spacing_m[0] == pytest.approx(92.5, abs=0.2)
    # Row order: south-east corner is the low Powell Valley, south-west the high Cumberland Mountains,
    # and the long Pine Mountain ridge runs SW-NE (north-west of the valley). With the rows the other way
    # round the south-east corner would be the 500 m hills of the north-east.
    h = dem.heights_m
    assert h[:50, -50:].mean() < 350.0
    assert h[:50, :50].mean() > 650.0
    # Pine Mountain's south-west end: a narrow straight ridge through about (row 235, col 280) and
    # (row 295, col 370) after the flip, i.e. running south-west -> north-east, standing well above the
    # terrain 15 rows either side. With unflipped rows this line crosses no ridge.
    cols = np.arange(280, 380)
    rows = np.round(235 + (cols - 280) * 60 / 90).astype(int)
    crest = np.array([h[r - 3 : r + 4, c].max() for r, c in zip(rows, cols, strict=True)])
    beside = np.array([0.5 * (h[r - 15, c] + h[r + 15, c]) for r, c in zip(rows, cols, strict=True)])
    assert np.mean(crest - beside) > 80.0


def test_bilinear_cell_is_the_formula_written_out_and_radii_pair_the_two_radii():
    """kernels.bilinear_cell against the bilinear formula written out in numpy over random cells and
    fractions (height and the gradient terms), cell_index against the cell choice by hand (inside, on the
    last post, outside), and geodesy.radii_m against meridian_radius_m / prime_vertical_radius_m."""
    rng = np.random.default_rng(4)
    h = rng.normal(400.0, 80.0, (9, 11))
    for _ in range(50):
        i, j = int(rng.integers(0, 8)), int(rng.integers(0, 10))
        u, v = rng.random(), rng.random()
        got, a, b, ea, eb = kernels.bilinear_cell(h, i, j, u, v)
        ref = (1 - u) * (1 - v) * h[i, j] + (1 - u) * v * h[i, j + 1] + u * (1 - v) * h[i + 1, j] \
            + u * v * h[i + 1, j + 1]
        assert got == pytest.approx(ref, rel=1e-12)
        dref_du = (1 - v) * (h[i + 1, j] - h[i, j]) + v * (h[i + 1, j + 1] - h[i, j + 1])
        dref_dv = (1 - u) * (h[i, j + 1] - h[i, j]) + u * (h[i + 1, j + 1] - h[i + 1, j])
        assert b - a == pytest.approx(dref_du, rel=1e-9, abs=1e-9)
        assert ea + u * (eb - ea) == pytest.approx(dref_dv, rel=1e-9, abs=1e-9)
    assert kernels.cell_index(9, 11, 3.25, 7.5) == (3, 7, 0.25, 0.5)
    assert kernels.cell_index(9, 11, 8.0, 10.0) == (7, 9, 1.0, 1.0)  # the last post: the cell before it
    assert kernels.cell_index(9, 11, -0.01, 2.0)[0] == -1 and kernels.cell_index(9, 11, 2.0, 10.01)[0] == -1
    for lat in np.radians([-80.0, -12.5, 0.0, 36.4, 89.0]):
        assert geodesy.radii_m(lat) == (geodesy.meridian_radius_m(lat), geodesy.prime_vertical_radius_m(lat))


def test_heights_are_read_only_and_the_callers_array_is_not():
    """A Dem's heights are read-only (queries cache tables derived from them; a changed map is a new Dem),
    also after a pickle round trip (a spawned worker's copy); the array given keeps its own flags."""
    import pickle
    given = np.arange(12.0).reshape(3, 4)
    dem = Dem(given, 0.5, -1.7, 1e-4, 1e-4, name="t")
    assert not dem.heights_m.flags.writeable and np.shares_memory(dem.heights_m, given)
    with pytest.raises(ValueError, match="read-only"):
        dem.heights_m[0, 0] = 1.0
    given[0, 0] = 7.0                                # the caller's array is still theirs
    assert given.flags.writeable
    _, bmax, _ = dem.block_bounds(2)
    back = pickle.loads(pickle.dumps(dem))
    assert not back.heights_m.flags.writeable and np.array_equal(back.heights_m, dem.heights_m)
    assert np.array_equal(back.block_bounds(2)[1], bmax)      # the cached bounds travel with the heights
    changed = dem.with_heights(dem.heights_m + 1.0)
    assert not changed.heights_m.flags.writeable and changed.heights_m[1, 1] == dem.heights_m[1, 1] + 1.0
