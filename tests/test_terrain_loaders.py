"""DEM loaders: GeoTIFF, SRTM .hgt, DTED, NPZ written into tmp_path and read back; bad input errors."""

import numpy as np
import pytest
import rasterio
import rasterio.shutil
from rasterio.transform import Affine
from trn_env.terrain import loaders
from trn_env.terrain.dem import Dem

from trn_env import terrain


def from_origin(west, north, xsize, ysize):
    return Affine(xsize, 0.0, west, 0.0, -ysize, north)


def _write_tif(path, arr, transform, crs="EPSG:4326", nodata=None):
    with rasterio.open(
        path,
        "w",
        driver="GTiff",
        height=arr.shape[0],
        width=arr.shape[1],
        count=1,
        dtype=arr.dtype,
        crs=crs,
        transform=transform,
        nodata=nodata,
    ) as ds:
        ds.write(arr, 1)


def test_geotiff_georeferencing_and_row_order(tmp_path):
    # 30 x 40 posts, 1 arcsec, north-up: pixel (0, 0) is the NORTH-west post
    step = 1.0 / 3600.0
    arr = (np.arange(30 * 40).reshape(30, 40) % 700).astype(np.float32) + 100
    arr[3, 4] = -9999.0
    path = tmp_path / "dem.tif"
    _write_tif(path, arr, from_origin(10.0 - step / 2, 47.0 + step / 2, step, step), nodata=-9999.0)
    dem = terrain.load(path)
    assert np.degrees(dem.lat0_rad) == pytest.approx(47.0 - 29 * step, abs=1e-10)  # south-west post
    assert np.degrees(dem.lon0_rad) == pytest.approx(10.0, abs=1e-10)
    assert np.degrees(dem.dlat_rad) == pytest.approx(step) and np.degrees(dem.dlon_rad) == pytest.approx(step)
    # north-west post (raster row 0, col 0) is now the last row
    assert dem.heights_m[-1, 0] == arr[0, 0]
    assert dem.height(np.radians(47.0), np.radians(10.0)) == pytest.approx(arr[0, 0])
    assert dem.height(np.radians(47.0 - 29 * step), np.radians(10.0 + 39 * step)) == pytest.approx(
        arr[29, 39]
    )
    assert np.isnan(dem.heights_m[29 - 3, 4])  # the nodata post
    filled = terrain.load(path, fill_voids=True)
    neighbours = [arr[2, 4], arr[4, 4], arr[3, 3], arr[3, 5]]
    assert min(neighbours) <= filled.heights_m[29 - 3, 4] <= max(neighbours)


def test_srtm_hgt_written_by_hand(tmp_path):
    # SRTM 3" tile: raw big-endian int16, 1201 x 1201, the name gives the south-west corner
    n = 1201
    arr = ((np.arange(n * n) % 997).reshape(n, n) + 200).astype(">i2")
    arr[600, 700] = -32768
    arr[600, 701] = -32768
    path = tmp_path / "N36W085.hgt"
    arr.tofile(path)
    dem = terrain.load(path)
    assert dem.heights_m.shape == (n, n)
    assert np.degrees(dem.lat0_rad) == pytest.approx(36.0, abs=1e-9)
    assert np.degrees(dem.lon0_rad) == pytest.approx(-85.0, abs=1e-9)
    assert np.degrees(dem.dlat_rad) == pytest.approx(3.0 / 3600.0)
    assert dem.heights_m[0, 0] == arr[n - 1, 0]  # south-west post
    assert dem.heights_m[n - 1, n - 1] == arr[0, n - 1]  # north-east post
    assert np.isnan(dem.heights_m[n - 1 - 600, 700]) and np.isnan(dem.heights_m[n - 1 - 600, 701])
    assert dem.height(np.radians(37.0), np.radians(-85.0)) == pytest.approx(arr[0, 0])
    filled = terrain.load(path, fill_voids=True)
    assert np.isfinite(filled.heights_m).all()
    lo, hi = sorted((arr[600, 699], arr[600, 702]))
    assert lo - 1 <= filled.heights_m[n - 1 - 600, 700] <= hi + 1


def test_dted_level0(tmp_path):
    step = 30.0 / 3600.0
    arr = ((np.arange(121 * 121) % 500).reshape(121, 121) + 300).astype(np.int16)
    tif = tmp_path / "tile.tif"
    _write_tif(tif, arr, from_origin(-85.0 - step / 2, 37.0 + step / 2, step, step))
    path = tmp_path / "tile.dt0"
    rasterio.shutil.copy(tif, path, driver="DTED")
    dem = terrain.load(path)
    assert np.degrees(dem.lat0_rad) == pytest.approx(36.0, abs=1e-7)
    assert np.degrees(dem.lon0_rad) == pytest.approx(-85.0, abs=1e-7)
    assert dem.heights_m[0, 0] == arr[120, 0] and dem.heights_m[120, 37] == arr[0, 37]


def test_npz_round_trip(tmp_path):
    dem = Dem(np.arange(12.0).reshape(3, 4), np.radians(36.5), np.radians(-84.2), 1e-5, 2e-5, "tiny")
    path = loaders.save_npz(dem, tmp_path / "tiny.npz")
    back = terrain.load(path)
    np.testing.assert_array_equal(back.heights_m, dem.heights_m)
    assert back.lat0_rad == pytest.approx(dem.lat0_rad, abs=1e-15)
    assert back.dlon_rad == pytest.approx(dem.dlon_rad, rel=1e-12)
    assert back.name == "tiny"


def test_missing_and_unsupported_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothere.tif"):
        terrain.load(tmp_path / "nothere.tif")
    bad = tmp_path / "dem.xyz"
    bad.write_text("1 2 3\n")
    with pytest.raises(terrain.DemLoadError, match=r"dem\.xyz.*unsupported"):
        terrain.load(bad)
    junk = tmp_path / "junk.tif"
    junk.write_bytes(b"not a tiff at all")
    with pytest.raises(terrain.DemLoadError, match="junk.tif"):
        terrain.load(junk)


def test_all_void_dem_is_an_error(tmp_path):
    path = tmp_path / "void.tif"
    _write_tif(path, np.full((5, 5), -32768, np.int16), from_origin(10, 47, 0.001, 0.001), nodata=-32768)
    with pytest.raises(terrain.DemLoadError, match=r"void\.tif.*void"):
        terrain.load(path)
    with pytest.raises(terrain.DemLoadError, match=r"void\.tif.*void"):
        terrain.load(path, fill_voids=True)


def test_inconsistent_georeferencing(tmp_path):
    arr = np.ones((5, 5), np.float32)
    projected = tmp_path / "utm.tif"
    _write_tif(projected, arr, Affine(30.0, 5.0, 500000.0, 5.0, -30.0, 4000000.0), crs="EPSG:32616")
    with pytest.raises(terrain.DemLoadError, match=r"utm\.tif.*rotated"):
        terrain.load(projected)
    rotated = tmp_path / "rot.tif"
    _write_tif(rotated, arr, Affine(0.001, 0.0002, 10.0, 0.0002, -0.001, 47.0))
    with pytest.raises(terrain.DemLoadError, match=r"rot\.tif.*rotated"):
        terrain.load(rotated)
    bad = tmp_path / "shape.npz"
    np.savez(bad, elevation=np.ones((10, 10)), dx=0.001, dy=0.001, xmin=0.0, xmax=0.02, ymin=1.0, ymax=1.01)
    with pytest.raises(terrain.DemLoadError, match=r"shape\.npz.*shape"):
        terrain.load(bad)
    neg = tmp_path / "neg.npz"
    np.savez(neg, heights_m=np.ones((3, 3)), lat0_deg=36.0, lon0_deg=-84.0, dlat_deg=-0.001, dlon_deg=0.001)
    with pytest.raises(terrain.DemLoadError, match=r"neg\.npz.*spacing"):
        terrain.load(neg)
    missing = tmp_path / "keys.npz"
    np.savez(missing, heights_m=np.ones((3, 3)))
    with pytest.raises(terrain.DemLoadError, match=r"keys\.npz.*misses"):
        terrain.load(missing)


def test_a_projected_raster_is_resampled_onto_latitude_longitude(tmp_path):
    """A UTM GeoTIFF of an analytic surface h(E, N): the loaded DEM, sampled at random points whose UTM
    coordinates are transformed to latitude/longitude by PROJ (rasterio.warp.transform, independent of the
    loader's warp), matches h there within 0.5 m (two bilinear steps on 90 m posts of a 3-4 km wavelength);
    the posts are ~90 m apart in both directions; the source's nodata and the grid outside the rotated
    footprint are voids, and a projected raster in feet is read in metres of post spacing."""
    from rasterio.warp import transform

    e0, n0, res, n = 740000.0, 4060000.0, 90.0, 200
    east = e0 + res * (np.arange(n) + 0.5)
    north = n0 - res * (np.arange(n) + 0.5)

    def h(e, nn):
        return 500.0 + 100.0 * np.sin(e / 3000.0) * np.cos(nn / 4000.0)

    arr = h(*np.meshgrid(east, north)).astype(np.float64)
    arr[100:110, 100:110] = -9999.0
    path = tmp_path / "utm.tif"
    _write_tif(path, arr, from_origin(e0, n0, res, res), crs="EPSG:32616", nodata=-9999.0)
    dem = terrain.load(path)
    lat_m = np.degrees(dem.dlat_rad) * 111_320.0
    lon_m = np.degrees(dem.dlon_rad) * 111_320.0 * np.cos(dem.lat0_rad + 0.5 * (dem.n_lat - 1) * dem.dlat_rad)
    assert lat_m == pytest.approx(90.0, rel=1e-9) and lon_m == pytest.approx(90.0, rel=2e-3)
    rng = np.random.default_rng(1)
    es = rng.uniform(e0 + 500.0, e0 + res * n - 500.0, 3000)
    ns = rng.uniform(n0 - res * n + 500.0, n0 - 500.0, 3000)
    near_void = (np.abs(es - (e0 + 105 * res)) < 8 * res) & (np.abs(ns - (n0 - 105 * res)) < 8 * res)
    lon, lat = transform("EPSG:32616", "EPSG:4326", es, ns)
    got = dem.height(np.radians(lat), np.radians(lon))
    assert np.all(np.isfinite(got[~near_void]))
    assert np.max(np.abs(got[~near_void] - h(es, ns)[~near_void])) < 0.5
    lon_v, lat_v = transform("EPSG:32616", "EPSG:4326", [e0 + 105 * res], [n0 - 105 * res])
    assert np.isnan(dem.height(np.radians(lat_v[0]), np.radians(lon_v[0])))        # the source's nodata
    # the footprint is rotated against the latitude/longitude grid (grid convergence east of the zone's
    # central meridian): the grid's corners beyond it are voids, far more than the source's 100 nodata posts
    assert np.isnan(np.asarray(dem.heights_m)).mean() > 0.02
    feet = tmp_path / "feet.tif"          # NAD83 / Tennessee (ftUS): 300 ft pixels are 91.44 m posts
    _write_tif(feet, arr[:50, :50].astype(np.float32), from_origin(2_000_000.0, 600_000.0, 300.0, 300.0),
               crs="EPSG:2274")
    assert np.degrees(terrain.load(feet).dlat_rad) * 111_320.0 == pytest.approx(300 * 0.3048006, rel=1e-6)


def _hills(n_rows=40, n_cols=50):
    r, c = np.mgrid[0:n_rows, 0:n_cols]
    return 500.0 + 300.0 * np.sin(r / 6.0) * np.cos(c / 9.0) + 2.0 * r


@pytest.mark.parametrize("dtype, stored, scale, offset, unit", [
    ("int16", lambda h: np.round((h - 100.0) * 10.0), 0.1, 100.0, None),       # decimetres above 100 m
    ("float32", lambda h: h / 0.3048, 1.0, 0.0, "ft"),
    ("float32", lambda h: h / (1200.0 / 3937.0), 1.0, 0.0, "US survey foot"),
    ("float32", lambda h: h, 1.0, 0.0, "metre"),
], ids=["decimetres", "feet", "us-survey-feet", "metres"])
def test_heights_are_the_bands_values_through_its_scale_offset_and_unit(tmp_path, dtype, stored, scale,
                                                                        offset, unit):
    """GDAL's band scale and offset (applied to the stored values) and the band's unit give metres: a
    decimetre int16 DEM read 10x too high and a DEM in feet 3.3x too high."""
    step = 3.0 / 3600.0
    hills = _hills()
    path = tmp_path / "dem.tif"
    for crs, transform in (("EPSG:4326", from_origin(-84.4, 36.6, step, step)),
                           ("EPSG:32616", from_origin(700_000.0, 4_050_000.0, 90.0, 90.0))):
        _write_tif(path, stored(hills).astype(dtype), transform, crs=crs)
        with rasterio.open(path, "r+") as ds:
            ds.scales, ds.offsets = (scale,), (offset,)
            if unit is not None:
                ds.units = (unit,)
        dem = terrain.load(path)
        tol = 0.05 if dtype == "int16" else 1e-3
        if crs == "EPSG:4326":
            np.testing.assert_allclose(dem.heights_m[::-1], hills, atol=tol)
        else:           # resampled: every post within the source's range, which it spans
            h = np.asarray(dem.heights_m)[np.isfinite(dem.heights_m)]
            assert hills.min() - tol <= h.min() and h.max() <= hills.max() + tol
            assert h.max() - h.min() > 0.8 * (hills.max() - hills.min())


def test_a_band_unit_that_is_not_a_length_is_refused(tmp_path):
    path = tmp_path / "dem.tif"
    _write_tif(path, _hills().astype(np.float32), from_origin(-84.4, 36.6, 0.001, 0.001))
    with rasterio.open(path, "r+") as ds:
        ds.units = ("furlong",)
    with pytest.raises(loaders.DemLoadError, match="band 1's unit 'furlong' is not a length this loader"):
        terrain.load(path)


def test_a_geographic_raster_on_another_datum_is_moved_onto_wgs84(tmp_path):
    """A NAD27 latitude/longitude raster was read as WGS 84: its posts ~10 m off here. Now resampled onto
    WGS 84 through PROJ's datum shift: a plane in NAD27 coordinates, read at WGS 84 points, gives the
    plane's value at each point's NAD27 coordinates (rasterio.warp.transform, point by point). NAD83,
    which PROJ maps onto WGS 84 with no shift, is read as it is, post for post."""
    from rasterio.warp import transform
    step = 3.0 / 3600.0
    west, north, n_rows, n_cols = -84.40, 36.60, 60, 70
    lat = north - step * np.arange(n_rows)[:, None]
    lon = west + step * np.arange(n_cols)[None, :]
    plane = 800.0 + 1.0e5 * (lat - 36.55) - 0.6e5 * (lon + 84.37)      # metres; ~1 m per metre
    grid = from_origin(west - step / 2, north + step / 2, step, step)
    for crs in ("EPSG:4267", "EPSG:4269"):
        _write_tif(tmp_path / f"{crs[5:]}.tif", plane.astype(np.float64), grid, crs=crs)
    nad27, nad83 = terrain.load(tmp_path / "4267.tif"), terrain.load(tmp_path / "4269.tif")
    rng = np.random.default_rng(3)
    p_lat, p_lon = rng.uniform(36.56, 36.58, 20), rng.uniform(-84.38, -84.36, 20)
    lon27, lat27 = transform("EPSG:4326", "EPSG:4267", p_lon, p_lat)
    expected = 800.0 + 1.0e5 * (np.asarray(lat27) - 36.55) - 0.6e5 * (np.asarray(lon27) + 84.37)
    got = nad27.height(np.radians(p_lat), np.radians(p_lon))
    np.testing.assert_allclose(got, expected, atol=0.02)
    as_if_wgs84 = 800.0 + 1.0e5 * (p_lat - 36.55) - 0.6e5 * (p_lon + 84.37)
    assert np.min(np.abs(expected - as_if_wgs84)) > 2.0           # the shift matters here (~3 m)
    assert nad83.heights_m.shape == plane.shape
    np.testing.assert_array_equal(nad83.heights_m[::-1], plane)
    assert np.degrees(nad83.lat0_rad) == pytest.approx(north - step * (n_rows - 1), abs=1e-12)


def test_a_raster_with_more_posts_than_the_limit_is_refused_before_it_is_read(tmp_path, monkeypatch):
    """A national DEM given whole (30,000 x 30,000 posts) took 51 s and 19 GB to validate, and more would
    end in the system killing the process: above MAX_RASTER_POSTS it is refused, naming its size, before
    any post is read; the same holds for the grid a projected raster is resampled onto."""
    monkeypatch.setattr(loaders, "MAX_RASTER_POSTS", 40 * 50 - 1)
    geographic, projected = tmp_path / "geo.tif", tmp_path / "utm.tif"
    _write_tif(geographic, _hills().astype(np.float32), from_origin(-84.4, 36.6, 0.001, 0.001))
    _write_tif(projected, _hills().astype(np.float32), from_origin(700_000.0, 4_050_000.0, 90.0, 90.0),
               crs="EPSG:32616")
    with pytest.raises(loaders.DemLoadError, match=r"geo.tif: 40 x 50 posts \(0 M\) is more than a DEM may "
                                                   r"have here \(MAX_RASTER_POSTS = 0 M"):
        terrain.load(geographic)
    with pytest.raises(loaders.DemLoadError, match="latitude/longitude posts to resample onto"):
        terrain.load(projected)
    monkeypatch.setattr(loaders, "MAX_RASTER_POSTS", 40 * 50)
    assert terrain.load(geographic).heights_m.shape == (40, 50)


def test_longitudes_from_0_to_360_read_as_from_minus_180_to_180(tmp_path):
    """A grid wholly east of 180 deg in 0..360 longitudes (some global products) is the same grid at
    -180..180: it loaded at 275.6 deg, and every place in a scenario (-84.4) was 'outside the terrain'."""
    step = 3.0 / 3600.0
    for west, name in ((-84.4, "signed.tif"), (-84.4 + 360.0, "east.tif")):
        _write_tif(tmp_path / name, _hills().astype(np.float32), from_origin(west, 36.6, step, step))
    signed, east = terrain.load(tmp_path / "signed.tif"), terrain.load(tmp_path / "east.tif")
    assert np.degrees(east.lon0_rad) == pytest.approx(np.degrees(signed.lon0_rad), abs=1e-9)
    np.testing.assert_array_equal(east.heights_m, signed.heights_m)
    lat, lon = np.radians(36.58), np.radians(-84.39)
    assert east.height(lat, lon) == pytest.approx(signed.height(lat, lon), abs=1e-6)
