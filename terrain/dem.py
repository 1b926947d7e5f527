"""`Dem`: a digital elevation model on a regular geodetic (latitude/longitude) grid.

Heights are metres above MSL in a float64 array (n_lat, n_lon); row 0 is the southmost row, column 0 the
westmost; NaN marks a void. Post (i, j) sits at latitude lat0_rad + i * dlat_rad and longitude
lon0_rad + j * dlon_rad. Lookups outside the grid or over voids return NaN and never raise.
heights_m is read-only (a read-only view when the array given is writable): queries cache tables derived
from it (block height bounds), so a changed map is a new Dem (with_heights()). Read-only also gives the
numba kernels one array type wherever a Dem comes from: Ray's object store hands its workers read-only
arrays, and numba compiles a kernel again for each array type.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import geodesy, kernels

_METHODS = ("bilinear", "bicubic")


def _coords(name: str, value) -> np.ndarray:
    """float64 array of a coordinate argument; ValueError naming it if it is not numeric (None, text)."""
    raw = np.asarray(value)
    if raw.dtype.kind not in "biuf":      # None, text, objects (np.asarray(None, float) would be NaN)
        raise ValueError(f"Dem: {name} must be a number or an array of numbers (radians), got {value!r}")
    return raw.astype(np.float64, copy=False)


def _query_points(what: str, method: str, lat_rad, lon_rad) -> tuple[tuple, np.ndarray, np.ndarray]:
    """(broadcast shape, flat contiguous lat, lon) of a lookup's coordinates; ValueError naming the bad
    argument of Dem.<what>."""
    if method not in _METHODS:
        raise ValueError(f"Dem.{what}: method must be one of {_METHODS}, got {method!r}")
    lat, lon = np.broadcast_arrays(_coords("lat_rad", lat_rad), _coords("lon_rad", lon_rad))
    return lat.shape, np.ascontiguousarray(lat).ravel(), np.ascontiguousarray(lon).ravel()


def _radii(lat_rad: np.ndarray, h_m=0.0) -> tuple[np.ndarray, np.ndarray]:
    """(meridian, prime-vertical) radii of curvature (m) at lat_rad, each plus h_m (numpy; the scalar
    kernel is terrain.geodesy.radii_m)."""
    s = np.sin(lat_rad)
    w = 1.0 - geodesy.WGS84_E2 * s * s
    return (geodesy.WGS84_A_M * (1.0 - geodesy.WGS84_E2) / (w * np.sqrt(w)) + h_m,
            geodesy.WGS84_A_M / np.sqrt(w) + h_m)


def read_only_heights(h: np.ndarray) -> np.ndarray:
    """h, read-only: a read-only view of a writable array (the caller's array keeps its own flags)."""
    if h.flags.writeable:
        h = h.view()
        h.flags.writeable = False
    return h


@dataclass
class Dem:
    """Geodetic elevation grid (the module docstring gives the layout).

    Parameters
    ----------
    heights_m : ndarray
        Heights above MSL, m, shape (n_lat, n_lon) with at least 2 x 2 posts, south row first, west column
        first; NaN marks a void.
    lat0_rad, lon0_rad : float
        Latitude and longitude of post (0, 0), rad.
    dlat_rad, dlon_rad : float
        Post spacing, rad (positive).
    name : str
        A label for messages.

    Raises
    ------
    ValueError
        Naming the field that is malformed (shape, spacing, a grid beyond the poles, no valid height).
    """

    heights_m: np.ndarray
    lat0_rad: float
    lon0_rad: float
    dlat_rad: float
    dlon_rad: float
    name: str = "dem"

    def __post_init__(self):
        h = np.ascontiguousarray(np.asarray(self.heights_m, dtype=np.float64))
        if h.ndim != 2 or h.shape[0] < 2 or h.shape[1] < 2:
            raise ValueError(
                f"Dem {self.name!r}: heights_m must be 2-D with at least 2 x 2 posts, got {h.shape}"
            )
        for field_name in ("lat0_rad", "lon0_rad", "dlat_rad", "dlon_rad"):
            value = float(getattr(self, field_name))
            if not np.isfinite(value):
                raise ValueError(f"Dem {self.name!r}: {field_name} is not finite ({value})")
            setattr(self, field_name, value)
        if self.dlat_rad <= 0.0 or self.dlon_rad <= 0.0:
            raise ValueError(
                f"Dem {self.name!r}: post spacing must be positive, got dlat_rad={self.dlat_rad}, "
                f"dlon_rad={self.dlon_rad}"
            )
        lat_max = self.lat0_rad + (h.shape[0] - 1) * self.dlat_rad
        if self.lat0_rad < -np.pi / 2 or lat_max > np.pi / 2:
            raise ValueError(
                f"Dem {self.name!r}: latitude range [{self.lat0_rad}, {lat_max}] rad is beyond the poles"
            )
        if not np.isfinite(h).any():
            raise ValueError(f"Dem {self.name!r}: every post is a void (NaN)")
        if np.isinf(h).any():
            raise ValueError(f"Dem {self.name!r}: heights_m holds {int(np.isinf(h).sum())} infinite posts "
                             "(a void is NaN; a height must be finite)")
        self.heights_m = read_only_heights(h)
        self._pyramid = None

    def __setstate__(self, state: dict) -> None:
        # unpickled in-band (a spawned worker) the heights come back writable: a fresh array, ours to freeze
        self.__dict__.update(state)
        if self.heights_m.flags.writeable:
            self.heights_m.flags.writeable = False

    # ----------------------------------------------------------------- geometry
    @property
    def n_lat(self) -> int:
        return int(self.heights_m.shape[0])

    @property
    def n_lon(self) -> int:
        return int(self.heights_m.shape[1])

    def block_bounds(self, block: int = 8):
        """(block, max, min): per-block height bounds (terrain.kernels.block_bounds), cached."""
        if self._pyramid is None or self._pyramid[0] != block:
            bmax, bmin = kernels.block_bounds(self.heights_m, block)
            self._pyramid = (block, bmax, bmin)
        return self._pyramid

    @property
    def grid(self):
        """(heights_m, lat0_rad, lon0_rad, dlat_rad, dlon_rad) for numba kernels."""
        return self.heights_m, self.lat0_rad, self.lon0_rad, self.dlat_rad, self.dlon_rad

    def record(self, cubic: bool = False) -> kernels.MapRecord:
        """The grid and its interpolation (bicubic when cubic, else bilinear) as one kernel argument."""
        return kernels.MapRecord(self.heights_m, float(self.lat0_rad), float(self.lon0_rad),
                                 float(self.dlat_rad), float(self.dlon_rad), bool(cubic))

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(lat_min, lat_max, lon_min, lon_max) of the outermost posts, radians."""
        return (
            self.lat0_rad,
            self.lat0_rad + (self.n_lat - 1) * self.dlat_rad,
            self.lon0_rad,
            self.lon0_rad + (self.n_lon - 1) * self.dlon_rad,
        )

    @property
    def lat_rad(self) -> np.ndarray:
        """Latitudes of the rows (south to north), radians."""
        return self.lat0_rad + np.arange(self.n_lat) * self.dlat_rad

    @property
    def lon_rad(self) -> np.ndarray:
        """Longitudes of the columns (west to east), radians."""
        return self.lon0_rad + np.arange(self.n_lon) * self.dlon_rad

    @property
    def center_rad(self) -> tuple[float, float]:
        """(lat, lon) of the grid centre, radians."""
        b = self.bounds
        return 0.5 * (b[0] + b[1]), 0.5 * (b[2] + b[3])

    @property
    def spacing_m(self) -> tuple[float, float]:
        """(north, east) post spacing in metres at the grid centre (seed 000 eq 2 radii)."""
        lat_c, _ = self.center_rad
        return (
            self.dlat_rad * geodesy.meridian_radius_m(lat_c),
            self.dlon_rad * geodesy.prime_vertical_radius_m(lat_c) * np.cos(lat_c),
        )

    @property
    def extent_m(self) -> tuple[float, float]:
        """(north, east) size of the grid in metres at the grid centre."""
        dn, de = self.spacing_m
        return dn * (self.n_lat - 1), de * (self.n_lon - 1)

    @property
    def void_fraction(self) -> float:
        return float(np.isnan(self.heights_m).mean())

    def contains(self, lat_rad, lon_rad):
        """True where (lat, lon) lies inside the grid's outermost posts (scalar or array)."""
        lat = np.asarray(lat_rad, dtype=np.float64)
        lon = np.asarray(lon_rad, dtype=np.float64)
        b = self.bounds
        inside = (lat >= b[0]) & (lat <= b[1]) & (lon >= b[2]) & (lon <= b[3])
        return bool(inside) if inside.ndim == 0 else inside

    # ----------------------------------------------------------------- lookups
    def height(self, lat_rad, lon_rad, method: str = "bilinear"):
        """Height (m above MSL) at (lat, lon) radians; scalars or arrays; NaN off-grid or over voids."""
        shape, flat_lat, flat_lon = _query_points("height", method, lat_rad, lon_rad)
        out = np.empty(flat_lat.shape[0])
        kernel = kernels.bilinear_batch if method == "bilinear" else kernels.bicubic_batch
        kernel(*self.grid, flat_lat, flat_lon, out)
        if len(shape) == 0:
            return float(out[0])
        return out.reshape(shape)

    def gradient(self, lat_rad, lon_rad, method: str = "bilinear"):
        """(dh_dn, dh_de): terrain slope along north and east (m/m) at (lat, lon); NaN outside."""
        shape, flat_lat, flat_lon = _query_points("gradient", method, lat_rad, lon_rad)
        g_lat = np.empty(flat_lat.shape[0])
        g_lon = np.empty(flat_lat.shape[0])
        kernel = kernels.gradient_batch if method == "bilinear" else kernels.bicubic_gradient_batch
        kernel(*self.grid, flat_lat, flat_lon, g_lat, g_lon)
        r_n, r_e = _radii(flat_lat)
        dh_dn = g_lat / r_n
        dh_de = g_lon / (r_e * np.cos(flat_lat))
        if len(shape) == 0:
            return float(dh_dn[0]), float(dh_de[0])
        return dh_dn.reshape(shape), dh_de.reshape(shape)

    # ----------------------------------------------------------------- displacements
    def offset_to_latlon(self, lat_rad, lon_rad, dn_m, de_m, h_m=0.0):
        """Add north/east displacements (m) to positions (seed 000 eq 2); returns (lat, lon) radians."""
        lat = np.asarray(lat_rad, dtype=np.float64)
        r_n, r_e = _radii(lat, h_m)
        return lat + np.asarray(dn_m) / r_n, np.asarray(lon_rad) + np.asarray(de_m) / (r_e * np.cos(lat))

    def latlon_to_offset(self, lat0_rad, lon0_rad, lat_rad, lon_rad, h_m=0.0):
        """North/east displacement (m) from (lat0, lon0) to (lat, lon) (small-offset seed 000 eq 2)."""
        lat0 = np.asarray(lat0_rad, dtype=np.float64)
        r_n, r_e = _radii(lat0, h_m)
        return (np.asarray(lat_rad) - lat0) * r_n, (np.asarray(lon_rad) - lon0_rad) * r_e * np.cos(lat0)

    def latlon_of_offset_from_center(self, dn_m, de_m):
        """(lat, lon) of a north/east offset (m) from the grid centre."""
        lat_c, lon_c = self.center_rad
        return self.offset_to_latlon(lat_c, lon_c, dn_m, de_m)

    # ----------------------------------------------------------------- sub-grids
    def subset(
        self,
        lat_min_rad: float,
        lat_max_rad: float,
        lon_min_rad: float,
        lon_max_rad: float,
        name: str | None = None,
    ) -> Dem:
        """The posts inside [lat_min, lat_max] x [lon_min, lon_max] (plus one post of margin) as a new Dem."""
        i0 = max(int(np.floor((lat_min_rad - self.lat0_rad) / self.dlat_rad)) - 1, 0)
        i1 = min(int(np.ceil((lat_max_rad - self.lat0_rad) / self.dlat_rad)) + 1, self.n_lat - 1)
        j0 = max(int(np.floor((lon_min_rad - self.lon0_rad) / self.dlon_rad)) - 1, 0)
        j1 = min(int(np.ceil((lon_max_rad - self.lon0_rad) / self.dlon_rad)) + 1, self.n_lon - 1)
        if i1 - i0 < 1 or j1 - j0 < 1:
            raise ValueError(f"Dem {self.name!r}: subset region does not overlap the grid")
        return Dem(
            self.heights_m[i0 : i1 + 1, j0 : j1 + 1].copy(),
            self.lat0_rad + i0 * self.dlat_rad,
            self.lon0_rad + j0 * self.dlon_rad,
            self.dlat_rad,
            self.dlon_rad,
            name or f"{self.name}[subset]",
        )

    def with_heights(self, heights_m: np.ndarray, name: str | None = None) -> Dem:
        """A Dem on the same grid with other heights."""
        return Dem(heights_m, self.lat0_rad, self.lon0_rad, self.dlat_rad, self.dlon_rad, name or self.name)

    def __repr__(self) -> str:
        b = np.degrees(self.bounds)
        return (
            f"Dem({self.name!r}, {self.n_lat} x {self.n_lon} posts, lat {b[0]:.4f}..{b[1]:.4f} deg, "
            f"lon {b[2]:.4f}..{b[3]:.4f} deg, spacing {self.spacing_m[0]:.1f} x {self.spacing_m[1]:.1f} m)"
        )
