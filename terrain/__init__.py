"""Terrain: DEMs, map error models, terrain queries and metrics. Imports neither trn_env nor navigators.

`terrain.load(name_or_path, fill_voids=False) -> Dem`:
    "jacksboro"            the bundled real USGS 3" DEM (matplotlib sample data)
    "synthetic:<preset>"   a seeded synthetic terrain (presets in terrain.synthetic.PRESETS)
    a path                 .tif/.tiff, .hgt, .dt0/.dt1/.dt2 (rasterio) or .npz (terrain.loaders)

Modules: dem (Dem), kernels (numba interpolation), loaders, queries (package: queries.raycast,
queries.radar_altimeter, queries.ira - the ray cast and the radar-altimeter and IRA closest points, one search
per module - and queries.shared, their curvature frame, per-DEM tables and scratch space), synthetic
(spectral terrain), refine (world finer than the map), map_error (the navigator's map), spectrum (PSD),
metrics (roughness, slope, ACF, terrain information), bench (throughput).
"""

from __future__ import annotations

from pathlib import Path

from .dem import Dem
from .loaders import DemLoadError

BUNDLED = ("jacksboro",)

__all__ = ["Dem", "DemLoadError", "load", "BUNDLED"]


def load(name_or_path, fill_voids: bool = False) -> Dem:
    """Load a DEM by bundled name, ``"synthetic:<preset>"`` or file path (see the module docstring).

    Parameters
    ----------
    name_or_path : str or path-like
        ``"jacksboro"`` (the bundled real USGS 3" DEM), ``"synthetic:<preset>"``, or a GeoTIFF, DTED, SRTM
        ``.hgt`` or NPZ file read with rasterio / numpy.
    fill_voids : bool
        Fill voids by interpolation instead of leaving them NaN.

    Returns
    -------
    Dem
        The geodetic grid; ``Dem.height(lat_rad, lon_rad)`` gives metres above MSL (NaN off the grid).

    Raises
    ------
    ValueError
        For an unknown name, a file that does not load, or a DEM without valid heights.
    """
    from . import loaders

    if not isinstance(name_or_path, (str, Path)) and not hasattr(name_or_path, "__fspath__"):
        raise ValueError(f"terrain.load: give a DEM name (e.g. 'jacksboro', 'synthetic:rolling') or a file "
                         f"path, got {name_or_path!r}")
    if isinstance(name_or_path, str):
        key = name_or_path.strip()
        if key.lower() in ("jacksboro", "jacksboro_fault", "default"):
            return loaders.load_jacksboro(fill_voids)
        if key.lower().startswith("synthetic:"):
            from . import synthetic

            return synthetic.from_preset(key.split(":", 1)[1])
    path = Path(name_or_path).expanduser()
    if not path.exists() and not path.suffix and len(path.parts) == 1:
        from .synthetic import PRESETS

        raise FileNotFoundError(
            f"{str(name_or_path)!r} is neither a bundled terrain ('jacksboro', or 'synthetic:' with one of "
            f"{', '.join(sorted(PRESETS))}) nor a DEM file here"
        )
    return loaders.load_path(path, fill_voids)
