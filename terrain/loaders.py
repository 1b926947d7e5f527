"""DEM loaders: GeoTIFF, DTED (.dt0/.dt1/.dt2) and SRTM .hgt through rasterio, our NPZ, the bundled default.

NPZ format (our own; `save_npz` writes it):
    heights_m  (n_lat, n_lon) float, metres above MSL, row 0 = southmost, NaN = void
    lat0_deg, lon0_deg   latitude/longitude of post [0, 0] (the south-west post), degrees
    dlat_deg, dlon_deg   post spacing, degrees (> 0)
    name                 optional string
An NPZ with matplotlib's sample-data keys (elevation, dx, dy, xmin, xmax, ymin, ymax) is also read.

Voids (the raster's nodata value, SRTM/DTED -32768, NaN) become NaN, or are filled by interpolation from
the surrounding valid posts when fill_voids=True. Every problem raises an error naming the file.

Rasters: heights are the stored values times the band's scale plus its offset (GDAL's scale/offset, e.g.
decimetres in int16), in the band's unit (metres when none is stated; feet and US survey feet converted,
any other unit refused). A geographic CRS on the WGS 84 datum (EPSG:4326, or one PROJ maps onto it with no
shift, e.g. NAD83) is read as it is; a projected CRS or a geographic one on another datum (NAD27, ED50)
is resampled onto a WGS 84 latitude/longitude grid (_load_projected).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .dem import Dem

RASTER_SUFFIXES = (".tif", ".tiff", ".gtiff", ".hgt", ".dt0", ".dt1", ".dt2")
NPZ_SUFFIXES = (".npz",)
SRTM_VOID = -32768
# the most posts a raster (or the latitude/longitude grid it is resampled onto) may have: reading one takes
# ~20 bytes a post at its peak (its stored values, the float64 heights, the void mask), so 250 M posts is
# ~5 GB; a 1 x 1 degree tile at 1/3" (10 m) has 117 M. Larger: crop it to the flight's area first.
MAX_RASTER_POSTS = 250_000_000

# a raster band's vertical unit (GDAL's unit type, lower case) -> metres per unit
_VERTICAL_UNITS_M = {"": 1.0, "m": 1.0, "metre": 1.0, "meter": 1.0, "metres": 1.0, "meters": 1.0,
                     "ft": 0.3048, "foot": 0.3048, "feet": 0.3048, "international foot": 0.3048,
                     "us-ft": 1200.0 / 3937.0, "ftus": 1200.0 / 3937.0, "us survey foot": 1200.0 / 3937.0,
                     "us_survey_foot": 1200.0 / 3937.0, "foot_us": 1200.0 / 3937.0}


class DemLoadError(ValueError):
    """A DEM file that cannot be read or is not a usable geodetic elevation grid."""


def fill_voids(heights_m: np.ndarray, source: str = "dem") -> np.ndarray:
    """Fill NaN posts by linear interpolation (Delaunay over the valid posts bordering the voids).

    Posts outside the convex hull of those border posts take the nearest valid value. Raises if every post
    is a void.
    """
    from scipy import interpolate, ndimage

    h = np.array(heights_m, dtype=np.float64)
    void = ~np.isfinite(h)
    if not void.any():
        return h
    if void.all():
        raise DemLoadError(f"{source}: every post is a void; nothing to fill from")
    ring = ndimage.binary_dilation(void, iterations=2) & ~void
    pts = np.argwhere(ring).astype(np.float64)
    vals = h[ring]
    targets = np.argwhere(void).astype(np.float64)
    if pts.shape[0] >= 3 and np.linalg.matrix_rank(pts - pts.mean(axis=0)) == 2:
        filled = interpolate.griddata(pts, vals, targets, method="linear")
    else:
        filled = np.full(targets.shape[0], np.nan)
    missing = ~np.isfinite(filled)
    if missing.any():
        filled[missing] = interpolate.griddata(pts, vals, targets[missing], method="nearest")
    h[void] = filled
    return h


def _finish(
    heights: np.ndarray, lat0_deg, lon0_deg, dlat_deg, dlon_deg, name: str, source: str, fill: bool
) -> Dem:
    heights = np.asarray(heights, dtype=np.float64)
    if heights.ndim != 2 or heights.shape[0] < 2 or heights.shape[1] < 2:
        raise DemLoadError(
            f"{source}: elevation must be a 2-D grid of at least 2 x 2 posts, got {heights.shape}"
        )
    for key, value in (("lat0", lat0_deg), ("lon0", lon0_deg), ("dlat", dlat_deg), ("dlon", dlon_deg)):
        if not np.isfinite(value):
            raise DemLoadError(f"{source}: georeferencing {key} is not finite ({value})")
    if not (dlat_deg > 0.0 and dlon_deg > 0.0):
        raise DemLoadError(
            f"{source}: post spacing must be positive, got dlat={dlat_deg} deg, dlon={dlon_deg} deg"
        )
    lat_top = lat0_deg + (heights.shape[0] - 1) * dlat_deg
    if lat0_deg < -90.0 or lat_top > 90.0 or abs(lon0_deg) > 360.0:
        raise DemLoadError(
            f"{source}: georeferencing is not geographic degrees (lat {lat0_deg}..{lat_top}, lon0 {lon0_deg})"
        )
    if not np.isfinite(heights).any():
        raise DemLoadError(f"{source}: every post is a void (nodata); no terrain in this DEM")
    lon_east = lon0_deg + (heights.shape[1] - 1) * dlon_deg
    if lon0_deg >= 180.0 and lon_east <= 360.0:     # 0..360 longitudes, wholly east of 180: as -180..180
        lon0_deg -= 360.0
    if fill:
        heights = fill_voids(heights, source)
    return Dem(
        heights, np.radians(lat0_deg), np.radians(lon0_deg), np.radians(dlat_deg), np.radians(dlon_deg), name
    )


# --------------------------------------------------------------------------------------------- NPZ
def save_npz(dem: Dem, path) -> Path:
    """Write `dem` in our NPZ format (keys in the module docstring)."""
    path = Path(path)
    np.savez_compressed(
        path,
        heights_m=dem.heights_m,
        lat0_deg=np.degrees(dem.lat0_rad),
        lon0_deg=np.degrees(dem.lon0_rad),
        dlat_deg=np.degrees(dem.dlat_rad),
        dlon_deg=np.degrees(dem.dlon_rad),
        name=np.array(dem.name),
    )
    return path


def _matplotlib_npz(data, source: str, name: str, fill: bool) -> Dem:
    """matplotlib sample-data layout (jacksboro_fault_dem.npz).

    The file stores `elevation` (344 x 403 int16) with ymin = 36.7329 > ymax = 36.4462: the labels are
    swapped, and row 0 is the NORTH edge. Evidence: with row 0 drawn at the top (north up), the long straight
    Pine Mountain ridge runs from lower-left to upper-right (south-west to north-east, as it does on every map
    of the Jacksboro fault area) and the Jacksboro tear fault runs NNW-SSE; flipping the rows would turn
    Pine Mountain north-west/south-east. We therefore flip the rows so that row 0 is the south edge.
    (xmax - xmin) / dx = 403 = number of columns, so the x/y bounds are cell edges and posts sit at cell
    centres, half a spacing inside the bounds.
    """
    try:
        elev = np.asarray(data["elevation"], dtype=np.float64)
        dx = float(data["dx"])
        dy = float(data["dy"])
        xmin, xmax = float(data["xmin"]), float(data["xmax"])
        y_a, y_b = float(data["ymin"]), float(data["ymax"])
    except KeyError as exc:
        raise DemLoadError(f"{source}: matplotlib-style NPZ misses key {exc}") from None
    if elev.ndim != 2:
        raise DemLoadError(f"{source}: 'elevation' must be 2-D, got shape {elev.shape}")
    south, north = min(y_a, y_b), max(y_a, y_b)
    n_rows, n_cols = elev.shape
    if abs((xmax - xmin) / dx - n_cols) > 0.5 or abs((north - south) / dy - n_rows) > 0.5:
        raise DemLoadError(
            f"{source}: shape {elev.shape} does not match the extent/spacing "
            f"({(north - south) / dy:.1f} x {(xmax - xmin) / dx:.1f} cells)"
        )
    if y_a > y_b:  # row 0 is the north edge (see docstring): flip to row 0 = south
        elev = elev[::-1]
    return _finish(elev, south + 0.5 * dy, xmin + 0.5 * dx, dy, dx, name, source, fill)


def load_npz(path, fill_voids: bool = False, name: str | None = None) -> Dem:
    """Read an NPZ DEM (our keys, or matplotlib's sample-data keys)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"DEM file not found: {path}")
    try:
        data = np.load(path, allow_pickle=False)
    except Exception as exc:  # noqa: BLE001 - any read failure is reported with the file name
        raise DemLoadError(f"{path}: cannot read as NPZ ({exc})") from exc
    with data:
        return _npz_to_dem(data, str(path), name or path.stem, fill_voids)


def _npz_to_dem(data, source: str, name: str, fill: bool) -> Dem:
    keys = set(data.files)
    if "elevation" in keys and "heights_m" not in keys:
        return _matplotlib_npz(data, source, name, fill)
    required = ("heights_m", "lat0_deg", "lon0_deg", "dlat_deg", "dlon_deg")
    missing = [k for k in required if k not in keys]
    if missing:
        raise DemLoadError(f"{source}: NPZ misses keys {missing} (has {sorted(keys)})")
    heights = np.asarray(data["heights_m"], dtype=np.float64)
    if "name" in keys:
        name = str(data["name"])
    return _finish(
        heights,
        float(data["lat0_deg"]),
        float(data["lon0_deg"]),
        float(data["dlat_deg"]),
        float(data["dlon_deg"]),
        name,
        source,
        fill,
    )


def load_jacksboro(fill_voids: bool = False) -> Dem:
    """The bundled real DEM: USGS 3" Jacksboro fault area, Tennessee, from matplotlib's sample data."""
    from matplotlib import cbook

    data = cbook.get_sample_data("jacksboro_fault_dem.npz")
    if isinstance(data, np.lib.npyio.NpzFile):
        with data:
            return _npz_to_dem(
                data, "matplotlib sample data jacksboro_fault_dem.npz", "jacksboro", fill_voids
            )
    with np.load(data) as npz:  # older matplotlib returns a path or file object
        return _npz_to_dem(npz, "matplotlib sample data jacksboro_fault_dem.npz", "jacksboro", fill_voids)


# --------------------------------------------------------------------------------------------- rasters
def load_raster(path, fill_voids: bool = False, name: str | None = None) -> Dem:
    """Read a GeoTIFF, DTED or SRTM .hgt file through rasterio (band 1, north-up), heights in metres (the
    band's scale, offset and unit applied). A geographic CRS on WGS 84 is read as it is; a projected one
    (UTM, a national grid) or another datum's latitude and longitude is resampled onto a WGS 84
    latitude/longitude grid (_load_projected)."""
    import rasterio
    from rasterio.errors import RasterioIOError

    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"DEM file not found: {path}")
    try:
        ds = rasterio.open(path)
    except RasterioIOError as exc:
        raise DemLoadError(f"{path}: rasterio cannot open it as a raster ({exc})") from exc
    with ds:
        if ds.count < 1:
            raise DemLoadError(f"{path}: raster has no bands")
        crs = ds.crs
        if crs is None:
            raise DemLoadError(
                f"{path}: no coordinate reference system; need geographic lat/lon (e.g. EPSG:4326)"
            )
        scale_m, offset_m = _height_scale(ds, path)
        if not crs.is_geographic or not _on_wgs84(ds):
            return _load_projected(ds, path, fill_voids, name, scale_m, offset_m)
        _check_size(path, ds.height, ds.width, "posts")
        t = ds.transform
        if abs(t.b) > 0.0 or abs(t.d) > 0.0:
            raise DemLoadError(f"{path}: rotated/sheared geotransform {tuple(t)[:6]} is not supported")
        if t.a <= 0.0 or t.e == 0.0:
            raise DemLoadError(
                f"{path}: invalid pixel size (x {t.a}, y {t.e}); need positive x spacing and "
                "non-zero y spacing"
            )
        raw = ds.read(1)
        nodata = ds.nodata
        suffix = path.suffix.lower()
        heights = raw.astype(np.float64)
        void = ~np.isfinite(heights)
        if nodata is not None and np.isfinite(nodata):
            void |= raw == nodata
        if suffix in (".hgt", ".dt0", ".dt1", ".dt2") or raw.dtype == np.int16:
            void |= raw == SRTM_VOID
        del raw                                                       # in place from here: memory
        if scale_m != 1.0:
            heights *= scale_m
        if offset_m != 0.0:
            heights += offset_m
        heights[void] = np.nan
        # GDAL transforms address pixel corners; a post (pixel-is-point) sits at the pixel centre.
        lon0 = t.c + 0.5 * t.a
        if t.e < 0.0:  # north-up: row 0 is north -> flip so row 0 is south
            heights = heights[::-1]
            lat0 = t.f + (ds.height - 0.5) * t.e
        else:
            lat0 = t.f + 0.5 * t.e
        return _finish(heights, lat0, lon0, abs(t.e), t.a, name or path.stem, str(path), fill_voids)


# metres of latitude per degree on WGS 84, as the grid spacing of a reprojected raster is chosen (the posts
# only need to be about as far apart as the source's; the grid itself is exact in degrees)
_M_PER_DEG_LAT = 111_320.0


def _check_size(path: Path, n_rows: int, n_cols: int, what: str) -> None:
    if n_rows * n_cols > MAX_RASTER_POSTS:
        limit = f"MAX_RASTER_POSTS = {MAX_RASTER_POSTS / 1e6:.0f} M, ~20 bytes a post to read"
        raise DemLoadError(f"{path}: {n_rows} x {n_cols} {what} ({n_rows * n_cols / 1e6:.0f} M) is more "
                           f"than a DEM may have here ({limit}): crop it to the flight's area first (e.g. "
                           "gdal_translate -projwin, or rasterio's windowed reading)")


def _height_scale(ds, path: Path) -> tuple[float, float]:
    """(metres per stored unit, offset in metres) of band 1: its scale and offset (GDAL's, applied to the
    stored values) in its vertical unit."""
    unit = (ds.units[0] or "").strip().lower() if ds.units else ""
    if unit not in _VERTICAL_UNITS_M:
        raise DemLoadError(f"{path}: band 1's unit {ds.units[0]!r} is not a length this loader reads "
                           "(metres or feet); convert the heights to metres")
    scale = ds.scales[0] if ds.scales and ds.scales[0] is not None else 1.0
    offset = ds.offsets[0] if ds.offsets and ds.offsets[0] is not None else 0.0
    if not (np.isfinite(scale) and scale != 0.0 and np.isfinite(offset)):
        raise DemLoadError(f"{path}: band 1's scale {scale!r} / offset {offset!r} give no heights")
    m = _VERTICAL_UNITS_M[unit]
    return float(scale) * m, float(offset) * m


def _on_wgs84(ds) -> bool:
    """The raster's geographic CRS is WGS 84's latitude and longitude: EPSG:4326, or one PROJ transforms onto
    it with no shift (NAD83 without a grid, WGS 84 by another name). NAD27 or ED50 move the posts by tens to
    hundreds of metres, which a terrain match would take as navigation error."""
    from rasterio.crs import CRS
    from rasterio.warp import transform

    if ds.crs == CRS.from_epsg(4326):
        return True
    west, south, east, north = ds.bounds
    xs, ys = [west, east, 0.5 * (west + east)], [south, north, 0.5 * (south + north)]
    lon, lat = transform(ds.crs, CRS.from_epsg(4326), xs, ys)
    return bool(np.allclose(lon, xs, rtol=0.0, atol=1e-9) and np.allclose(lat, ys, rtol=0.0, atol=1e-9))


def _load_projected(ds, path: Path, fill_voids: bool, name: str | None, scale_m: float = 1.0,
                    offset_m: float = 0.0) -> Dem:
    """A raster in a projected CRS (UTM, a national grid), resampled bilinearly onto a WGS 84 (EPSG:4326)
    latitude/longitude grid through GDAL's warper (rasterio.vrt.WarpedVRT): posts as far apart in metres
    as the source's pixels (north-south; east-west at the grid's mid-latitude), covering the raster's
    footprint; posts outside the footprint, or from the source's nodata, are voids. Heights are scaled to
    metres (scale_m, offset_m: _height_scale), the vertical datum stays the source's."""
    from rasterio.crs import CRS
    from rasterio.enums import Resampling
    from rasterio.transform import Affine
    from rasterio.vrt import WarpedVRT
    from rasterio.warp import transform_bounds

    t = ds.transform
    if abs(t.b) > 0.0 or abs(t.d) > 0.0 or t.a <= 0.0 or t.e == 0.0:
        raise DemLoadError(f"{path}: rotated, sheared or empty geotransform {tuple(t)[:6]} is not supported")
    west, south, east, north = transform_bounds(ds.crs, CRS.from_epsg(4326), *ds.bounds, densify_pts=21)
    if not all(np.isfinite(v) for v in (west, south, east, north)) or not (west < east and south < north):
        raise DemLoadError(f"{path}: its footprint in {ds.crs.to_string()} has no latitude/longitude extent")
    if ds.crs.is_geographic:          # another datum's degrees: the source's spacing, in WGS 84 degrees
        dlat, dlon = abs(t.e), t.a
        res_m = dlat * _M_PER_DEG_LAT
    else:
        units = ds.crs.linear_units_factor[1] if ds.crs.linear_units_factor else 1.0
        res_m = min(abs(t.a), abs(t.e)) * units
        dlat = res_m / _M_PER_DEG_LAT
        dlon = dlat / np.cos(np.radians(0.5 * (south + north)))
    n_lat = max(2, int(np.ceil((north - south) / dlat)))
    n_lon = max(2, int(np.ceil((east - west) / dlon)))
    _check_size(path, n_lat, n_lon, "latitude/longitude posts to resample onto")
    src_nodata = ds.nodata if ds.nodata is not None and np.isfinite(ds.nodata) else None
    if src_nodata is None and ds.dtypes[0] == "int16":
        src_nodata = SRTM_VOID
    with WarpedVRT(ds, crs=CRS.from_epsg(4326), transform=Affine(dlon, 0.0, west, 0.0, -dlat, north),
                   width=n_lon, height=n_lat, resampling=Resampling.bilinear, src_nodata=src_nodata,
                   nodata=np.nan, dtype="float64") as vrt:
        heights = vrt.read(1)[::-1]             # north-up rows -> row 0 south
    if scale_m != 1.0:
        heights *= scale_m
    if offset_m != 0.0:
        heights += offset_m
    source = f"{path} (reprojected from {ds.crs.to_string()} to EPSG:4326, {res_m:g} m posts, bilinear)"
    # the southmost row's post: a pixel centre (the grid may overhang the footprint by part of a post)
    lat0 = north - (n_lat - 0.5) * dlat
    return _finish(heights, lat0, west + 0.5 * dlon, dlat, dlon, name or path.stem, source, fill_voids)


def load_path(path, fill_voids: bool = False) -> Dem:
    """Dispatch on the file suffix."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in NPZ_SUFFIXES:
        return load_npz(path, fill_voids)
    if suffix in RASTER_SUFFIXES:
        return load_raster(path, fill_voids)
    if not path.exists():
        raise FileNotFoundError(f"DEM file not found: {path}")
    raise DemLoadError(
        f"{path}: unsupported DEM format {suffix!r}; supported: {', '.join(NPZ_SUFFIXES + RASTER_SUFFIXES)}"
    )
