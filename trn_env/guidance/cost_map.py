"""The route planner's cost map: terrain information of the navigator's MAP on a coarse planning grid.

    grid = information_grid(map_dem, cell_m=500.0)
    grid.crlb_m[i, j]          horizontal position CRLB (m) a TRN could reach over cell (i, j)
    grid.featureless[i, j]     0 (informative) .. 1 (featureless): the planner's per-metre penalty factor

The CRLB is `terrain.metrics.terrain_information` (Fisher information of altimeter heights with noise
`sigma_m` over a `window_m` square, the terrain-information form of seed 001's terrain SNR: a TRN fixes
where the height gradient is large against the sensor noise), evaluated on the map's posts and summarised
per planning cell by its median. Featureless-ness is a log ramp between two CRLB levels:

    u = clip(log(crlb / informative_crlb_m) / log(featureless_crlb_m / informative_crlb_m), 0, 1)

so cells whose CRLB is at most `informative_crlb_m` cost nothing extra, cells at `featureless_crlb_m` or
worse (and map voids) cost the full weight. Only the map DEM is read, never the world.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trn_env.terrain import geodesy, metrics
from trn_env.terrain.dem import Dem


def _positive(name: str, v) -> float:
    if (
        isinstance(v, bool)
        or not isinstance(v, (int, float, np.floating, np.integer))
        or not math.isfinite(v)
        or v <= 0
    ):
        raise ValueError(f"{name} must be a finite number > 0, got {v!r}")
    return float(v)


@dataclass(frozen=True)
class InformationGrid:
    """A coarse planning grid over the map: cell (i, j) has its centre at lat0 + i dlat, lon0 + j dlon (rad).

    crlb_m: median CRLB of the map posts in the cell (m; inf where the information matrix is singular or
    the cell holds a void); featureless: the 0..1 penalty factor of the module docstring; height_m: mean
    map height of the cell (m MSL, NaN over voids); cell_n_m, cell_e_m: cell size north and east (m)."""

    lat0_rad: float
    lon0_rad: float
    dlat_rad: float
    dlon_rad: float
    crlb_m: np.ndarray
    featureless: np.ndarray
    height_m: np.ndarray
    cell_n_m: float
    cell_e_m: float
    informative_crlb_m: float
    featureless_crlb_m: float

    @property
    def shape(self) -> tuple[int, int]:
        return self.crlb_m.shape

    def cell_of(self, lat_rad: float, lon_rad: float) -> tuple[int, int]:
        """(i, j) of the cell holding the position (may lie outside the grid: check `contains_cell`)."""
        return (
            int(math.floor((lat_rad - self.lat0_rad) / self.dlat_rad + 0.5)),
            int(math.floor((lon_rad - self.lon0_rad) / self.dlon_rad + 0.5)),
        )

    def contains_cell(self, i: int, j: int) -> bool:
        return 0 <= i < self.shape[0] and 0 <= j < self.shape[1]

    def latlon_of(self, i, j):
        """Centre (lat, lon) in rad of cell(s) (i, j)."""
        return self.lat0_rad + np.asarray(i) * self.dlat_rad, self.lon0_rad + np.asarray(j) * self.dlon_rad

    def featureless_at(self, lat_rad: np.ndarray, lon_rad: np.ndarray) -> np.ndarray:
        """Penalty factor of the cells holding the positions (1 outside the grid)."""
        i = np.floor((np.asarray(lat_rad) - self.lat0_rad) / self.dlat_rad + 0.5).astype(np.int64)
        j = np.floor((np.asarray(lon_rad) - self.lon0_rad) / self.dlon_rad + 0.5).astype(np.int64)
        ok = (i >= 0) & (i < self.shape[0]) & (j >= 0) & (j < self.shape[1])
        out = np.ones(np.shape(i))
        out[ok] = self.featureless[i[ok], j[ok]]
        return out

    def crlb_at(self, lat_rad: np.ndarray, lon_rad: np.ndarray) -> np.ndarray:
        """CRLB (m) of the cells holding the positions (inf outside the grid)."""
        i = np.floor((np.asarray(lat_rad) - self.lat0_rad) / self.dlat_rad + 0.5).astype(np.int64)
        j = np.floor((np.asarray(lon_rad) - self.lon0_rad) / self.dlon_rad + 0.5).astype(np.int64)
        ok = (i >= 0) & (i < self.shape[0]) & (j >= 0) & (j < self.shape[1])
        out = np.full(np.shape(i), np.inf)
        out[ok] = self.crlb_m[i[ok], j[ok]]
        return out


def featureless_factor(
    crlb_m: np.ndarray, informative_crlb_m: float, featureless_crlb_m: float
) -> np.ndarray:
    """The log ramp of the module docstring (NaN/inf -> 1)."""
    c = np.where(np.isfinite(crlb_m), crlb_m, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.log(np.maximum(c, 1e-12) / informative_crlb_m) / math.log(
            featureless_crlb_m / informative_crlb_m
        )
    return np.clip(np.where(np.isfinite(u), u, 1.0), 0.0, 1.0)


def information_grid(
    map_dem: Dem,
    cell_m: float = 500.0,
    sigma_m: float = 5.0,
    window_m: float = 2000.0,
    informative_crlb_m: float = 5.0,
    featureless_crlb_m: float = 50.0,
) -> InformationGrid:
    """The cost map of the module docstring over whole blocks of map posts (about cell_m on a side)."""
    if not isinstance(map_dem, Dem):
        raise ValueError(f"map_dem must be a terrain.Dem, got {type(map_dem).__name__}")
    cell_m = _positive("cell_m", cell_m)
    _positive("sigma_m", sigma_m)
    _positive("window_m", window_m)
    informative_crlb_m = _positive("informative_crlb_m", informative_crlb_m)
    featureless_crlb_m = _positive("featureless_crlb_m", featureless_crlb_m)
    if featureless_crlb_m <= informative_crlb_m:
        raise ValueError(
            f"featureless_crlb_m ({featureless_crlb_m}) must exceed informative_crlb_m ({informative_crlb_m})"
        )
    sp_n, sp_e = map_dem.spacing_m
    bn = max(1, int(round(cell_m / sp_n)))
    be = max(1, int(round(cell_m / sp_e)))
    n_i, n_j = map_dem.n_lat // bn, map_dem.n_lon // be
    if n_i < 2 or n_j < 2:
        raise ValueError(
            f"cell_m = {cell_m:g} m leaves fewer than 2 x 2 planning cells on the map "
            f"({map_dem.n_lat} x {map_dem.n_lon} posts of {sp_n:.0f} x {sp_e:.0f} m)"
        )
    info = metrics.terrain_information(map_dem, sigma_m, window_m)
    crlb = np.where(np.isnan(info.crlb_sigma_h_m), np.inf, info.crlb_sigma_h_m)
    blocks = (
        crlb[: n_i * bn, : n_j * be].reshape(n_i, bn, n_j, be).transpose(0, 2, 1, 3).reshape(n_i, n_j, -1)
    )
    crlb_cell = np.median(blocks, axis=2)
    h = map_dem.heights_m[: n_i * bn, : n_j * be].reshape(n_i, bn, n_j, be)
    h_cell = h.mean(axis=(1, 3))
    # cell centre = the mean of its posts' positions
    lat0 = map_dem.lat0_rad + 0.5 * (bn - 1) * map_dem.dlat_rad
    lon0 = map_dem.lon0_rad + 0.5 * (be - 1) * map_dem.dlon_rad
    lat_c = lat0 + 0.5 * (n_i - 1) * bn * map_dem.dlat_rad
    cell_n = bn * map_dem.dlat_rad * geodesy.meridian_radius_m(lat_c)
    cell_e = be * map_dem.dlon_rad * geodesy.prime_vertical_radius_m(lat_c) * math.cos(lat_c)
    return InformationGrid(
        lat0,
        lon0,
        bn * map_dem.dlat_rad,
        be * map_dem.dlon_rad,
        crlb_cell,
        featureless_factor(crlb_cell, informative_crlb_m, featureless_crlb_m),
        h_cell,
        float(cell_n),
        float(cell_e),
        informative_crlb_m,
        featureless_crlb_m,
    )
