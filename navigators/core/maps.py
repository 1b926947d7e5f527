"""The navigator's map: where a navigator or monitor gets its terrain.Dem from its `dem` setting, and the
record the terrain kernels take it as.

`MapRecord(heights, lat0, lon0, dlat, dlon, cubic)` (terrain.kernels, re-exported here): the grid of
terrain.Dem.grid (heights[i, j] the post at lat0 + i dlat, lon0 + j dlon, rad; its bounds the outermost
posts) and the interpolation (bicubic when cubic, else bilinear), passed to numba kernels as one tuple;
`map_height(record, lat, lon)` is the height (m) there, NaN off the map. `map_record(dem_or_grid, cubic)`
builds one.
"""

from __future__ import annotations

from ...terrain.kernels import MapRecord, map_height  # noqa: F401 (the record and its reader, re-exported)


def map_record(dem_or_grid, cubic: bool) -> MapRecord:
    """The MapRecord of a terrain.Dem (or its grid tuple) with the interpolation."""
    grid = getattr(dem_or_grid, "grid", dem_or_grid)
    heights, lat0, lon0, dlat, dlon = grid
    return MapRecord(heights, float(lat0), float(lon0), float(dlat), float(dlon), bool(cubic))


def load_map(dem, who: str = "the navigator"):
    """The terrain.Dem a `dem` setting names: a Dem as given, a name or path loaded by terrain.load.

    Raises ValueError naming the setting when it is missing, cannot be loaded or is not a map.
    """
    if dem is None:
        raise ValueError(f"dem: the navigator's terrain map is required by {who}")
    if isinstance(dem, str):
        from ... import terrain

        try:
            dem = terrain.load(dem)
        except (OSError, ValueError) as exc:
            raise ValueError(f"dem: cannot load the navigator's map {dem!r}: {exc}") from exc
    if not hasattr(dem, "grid"):
        raise ValueError(f"dem must be a terrain.Dem or a map name, got {type(dem).__name__}")
    return dem


__all__ = ["MapRecord", "load_map", "map_height", "map_record"]
