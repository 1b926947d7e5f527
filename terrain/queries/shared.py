"""What the three terrain queries share: the exact-curvature local frame, per-DEM tables, scratch space and
the argument checks of the public calls.

Geometry. Every query works in the local NED frame at the antenna. A terrain point at geodetic offset
(dphi, dlam) and height h_p maps to NED through the second-order expansion of the WGS84 position about the
antenna (meridian radius M, prime-vertical radius N, antenna height h_a, latitude phi):

    n = (M + h_p) dphi + 1/2 (N + h_a) sin(phi) cos(phi) dlam^2 + 1/2 dM/dphi dphi^2
    e = (N + h_p) cos(phi) dlam - (M + h_a) sin(phi) dphi dlam
    d = (h_a - h_p) + 1/2 (M + h_a) dphi^2 + 1/2 (N + h_a) cos(phi)^2 dlam^2       (curvature drop)

The first-order terms are seed 000 eq 2; the second-order terms carry the Earth's curvature (about 2 m of
drop and 1-3 m of horizontal bending at 5 km). The neglected third-order terms are below 1 cm within 10 km.
_ned is this map, _geo_of_ned its inverse (three fixed-point steps), ned_of_points / look_angle_rad its
public face.

Kernel arguments. Every kernel, the _*_batch ones Python calls and those inside a search, takes the map
as one record rec (terrain.kernels.MapRecord: heights, lat0, lon0, dlat, dlon rad, cubic; the queries
read it bilinearly whatever its flag) and the curvature constants at the antenna as cv = (sin phi, cos phi,
M, N, dM/dphi) (_consts): tuples unpacked where used, the same bits as the explicit arguments they
replace.

Per-DEM tables (block maxima and slopes, the finite height range; _ra_tables, _ira_tables) are built on
the first query and cached on the Dem, keyed by its heights array (do not change heights_m afterwards), and
the scratch space (_ra_workspace, _ira_workspace) is reused between calls: the kernels write every entry
before they read it, so a call costs a few microseconds on top of its queries and its results never depend
on earlier calls.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .. import geodesy, kernels
from ..geodesy import WGS84_A_M, WGS84_E2

_INF = np.inf
BLOCK_POSTS = 8  # block size of the height bounds used to prune the searches
IRA_BLOCK_POSTS = 8  # block size of the IRA's slope bounds for large curve pieces
IRA_HEIGHT_BLOCK_CELLS = 2  # cells per block side of the IRA's height bound (2: fastest of 1-4)

_IRA_WORK: dict = {}
_RA_WORK: dict = {}


@dataclass
class TerrainReturn:
    """Closest-point query results, (n,) arrays; invalid entries hold NaN. Range in m, angles in rad,
    h_m in metres above MSL (the DEM's datum)."""

    valid: np.ndarray
    range_m: np.ndarray
    lat_rad: np.ndarray
    lon_rad: np.ndarray
    h_m: np.ndarray


@njit(cache=True, fastmath=False, error_model="numpy", forceinline=True)
def _consts(lat):
    """Curvature constants cv = (sin, cos of the latitude, meridian radius M, prime-vertical radius N,
    dM/dphi) (m) of the expansion in the module docstring, at the antenna latitude lat (rad)."""
    s = np.sin(lat)
    c = np.cos(lat)
    w = 1.0 - WGS84_E2 * s * s
    m = WGS84_A_M * (1.0 - WGS84_E2) / (w * np.sqrt(w))
    n = WGS84_A_M / np.sqrt(w)
    dm = 3.0 * m * WGS84_E2 * s * c / w
    return s, c, m, n, dm


@njit(cache=True, fastmath=False, error_model="numpy", forceinline=True)
def _ned(dphi, dlam, hp, ha, cv):
    """NED (m) of the point (lat_a + dphi, lon_a + dlam, hp) from the antenna at height ha; cv: _consts."""
    s, c, m, n, dm = cv
    mh = m + ha
    nh = n + ha
    x = (m + hp) * dphi + 0.5 * nh * s * c * dlam * dlam + 0.5 * dm * dphi * dphi
    y = (n + hp) * c * dlam - mh * s * dphi * dlam
    z = (ha - hp) + 0.5 * mh * dphi * dphi + 0.5 * nh * c * c * dlam * dlam
    return x, y, z


@njit(cache=True, fastmath=False, error_model="numpy", forceinline=True)
def _insert_sorted(keys, ids, n, key, ident):
    """Insert (key, ident) into keys[:n], ids[:n] kept ascending by key (after the equal keys): the
    searches' candidate lists; keys[:n + 1], ids[:n + 1] hold the list afterwards."""
    q = n
    while q > 0 and keys[q - 1] > key:
        keys[q] = keys[q - 1]
        ids[q] = ids[q - 1]
        q -= 1
    keys[q] = key
    ids[q] = ident


@njit(cache=True, fastmath=False, error_model="numpy")
def _geo_of_ned(x, y, z, ha, cv):
    """Inverse of _ned: (dphi, dlam, h_p) of the NED point (x, y, z) by fixed-point iteration."""
    s, c, m, n, dm = cv
    mh = m + ha
    nh = n + ha
    hp0 = ha - z
    # 1 / (m + hp) = im0 (1 - (hp - hp0) im0) to (8 m / 6.4e6 m)^2 relative: two divisions per call
    im0 = 1.0 / (m + hp0)
    in0 = 1.0 / (n + hp0)
    ic = 1.0 / c
    dphi = x * im0
    dlam = y * in0 * ic
    hp = hp0
    for _ in range(3):
        hp = hp0 + 0.5 * mh * dphi * dphi + 0.5 * nh * c * c * dlam * dlam
        d = hp - hp0
        dphi = (x - 0.5 * nh * s * c * dlam * dlam - 0.5 * dm * dphi * dphi) * (im0 * (1.0 - d * im0))
        dlam = (y + mh * s * dphi * dlam) * (in0 * (1.0 - d * in0)) * ic
    return dphi, dlam, hp


@njit(cache=True, fastmath=False, error_model="numpy")
def _finite_range(heights):
    """(lowest, highest) finite value of the 2-D array heights ((inf, -inf) when none is finite)."""
    lo = np.inf
    hi = -np.inf
    for i in range(heights.shape[0]):  # 2-D loops: ravel() alone took most of this kernel's compile
        for j in range(heights.shape[1]):
            v = heights[i, j]
            if v == v:
                if v < lo:
                    lo = v
                if v > hi:
                    hi = v
    return lo, hi



def _is_f8_vector(a, n=None) -> bool:
    return (
        type(a) is np.ndarray
        and a.dtype == np.float64
        and a.ndim == 1
        and a.flags.c_contiguous
        and a.flags.writeable
        and (n is None or a.shape[0] == n)
    )


def _positions(lat_rad, lon_rad, h_m):
    if _is_f8_vector(lat_rad) and _is_f8_vector(lon_rad, lat_rad.shape[0]) and _is_f8_vector(
        h_m, lat_rad.shape[0]
    ):
        return lat_rad, lon_rad, h_m  # fast path: what the general path below would return
    lat = np.atleast_1d(np.asarray(lat_rad, dtype=np.float64))
    lon = np.atleast_1d(np.asarray(lon_rad, dtype=np.float64))
    h = np.atleast_1d(np.asarray(h_m, dtype=np.float64))
    lat, lon, h = np.broadcast_arrays(lat, lon, h)
    if lat.ndim != 1:
        raise ValueError(f"antenna positions must be scalars or (n,) arrays, got shape {lat.shape}")
    return _kernel_array(lat), _kernel_array(lon), _kernel_array(h)


def _kernel_array(a: np.ndarray) -> np.ndarray:
    """a as a C-contiguous, writable array (a copy only where needed): numba compiles a kernel again for
    each new array type, and read-only arrays (broadcast_to's views, a caller's read-only data) are one."""
    return np.require(a, requirements=["C", "W"])


def _stack(name, arr, n, shape):
    if (
        type(arr) is np.ndarray
        and arr.dtype == np.float64
        and arr.shape == (n,) + shape
        and arr.flags.c_contiguous
        and arr.flags.writeable
    ):
        return arr  # fast path: what the general path below would return
    a = np.asarray(arr, dtype=np.float64)
    if a.shape == shape:
        a = np.broadcast_to(a, (n,) + shape)
    if a.shape != (n,) + shape:
        raise ValueError(
            f"{name} must have shape {shape} or ({n}, {', '.join(map(str, shape))}), got {a.shape}"
        )
    return _kernel_array(a)


def _outputs(n):
    return (np.zeros(n, dtype=np.bool_), np.empty(n), np.empty(n), np.empty(n), np.empty(n))


def _height_range(dem) -> tuple[float, float]:
    _, bmax, bmin = dem.block_bounds(BLOCK_POSTS)
    return float(bmin.min()), float(bmax.max())


def _block_slopes(dem, block: int = BLOCK_POSTS) -> np.ndarray:
    """Per-block maximum slope (terrain.kernels.block_slopes) of `block`-post blocks."""
    b = dem.bounds
    lat_far = max(abs(b[0]), abs(b[1]))
    lat_near = 0.0 if b[0] <= 0.0 <= b[1] else min(abs(b[0]), abs(b[1]))
    dn = dem.dlat_rad * geodesy.meridian_radius_m(lat_near)  # shortest rows
    de = dem.dlon_rad * geodesy.prime_vertical_radius_m(lat_far) * np.cos(lat_far)  # narrowest columns
    return kernels.block_slopes(dem.heights_m, block, float(dn), float(de))


def _ira_tables(dem):
    """(max heights of IRA_HEIGHT_BLOCK_CELLS-cell blocks, slopes of IRA_BLOCK_POSTS-post blocks, finite
    h_min, finite h_max, largest block slope, cell_m) for the IRA search, cached on the Dem (keyed by the
    heights array, read-only once queries have run)."""
    cached = getattr(dem, "_query_ira_tables", None)
    if cached is not None and cached[0] is dem.heights_m:
        return cached[1]
    hmax_blocks, hmin_blocks = kernels.block_bounds(dem.heights_m, IRA_HEIGHT_BLOCK_CELLS)
    bslope = _block_slopes(dem, IRA_BLOCK_POSTS)
    h_min = _finite_range(hmin_blocks)[0]
    h_max = _finite_range(hmax_blocks)[1]
    g_glob = _finite_range(bslope)[1]
    tables = (hmax_blocks, bslope, float(h_min), float(h_max), float(g_glob), _cell_m(dem))
    dem._query_ira_tables = (dem.heights_m, tables)
    return tables


def _ra_tables(dem):
    """(block size, block max heights, block min heights, finite h_min, finite h_max, cell_m) for the
    radar-altimeter search, cached on the Dem like _ira_tables."""
    cached = getattr(dem, "_query_ra_tables", None)
    if cached is not None and cached[0] is dem.heights_m:
        return cached[1]
    bs, bmax, bmin = dem.block_bounds(BLOCK_POSTS)
    tables = (bs, bmax, bmin, float(_finite_range(bmin)[0]), float(_finite_range(bmax)[1]), _cell_m(dem))
    dem._query_ra_tables = (dem.heights_m, tables)
    return tables


def _ra_workspace(n_blocks: int):
    """Scratch arrays of the radar-altimeter search (reused between calls: _ra_bnb writes before it reads)."""
    if _RA_WORK.get("n", -1) < n_blocks:
        _RA_WORK["n"] = n_blocks
        _RA_WORK["lb"] = np.empty(n_blocks)
        _RA_WORK["id"] = np.empty(n_blocks, dtype=np.int64)
    return _RA_WORK["lb"], _RA_WORK["id"]


def _ira_workspace(n_max: int):
    """Scratch arrays of the IRA search (reused between calls: _ira_batch overwrites what it reads)."""
    work = _IRA_WORK.get("work")
    if work is None or work.shape[1] < n_max:
        work = np.empty((8, max(n_max, 64)))
        _IRA_WORK["work"] = work
        _IRA_WORK["stack"] = np.empty((4096, 12))
    return work, _IRA_WORK["stack"]


def _cell_m(dem) -> float:
    dn, de = dem.spacing_m
    return float(min(dn, de))


def _check_positive(name, value):
    if not (np.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be a positive finite number, got {value}")



def look_angle_rad(C_bn, lat_rad, lon_rad, h_m, ret: TerrainReturn) -> np.ndarray:
    """Interferometric look angle theta = asin(y_b / R) (rad, + toward the right wing; seed 000 eqs
    18-19) of returned points from antennas; y_b: body-FRD y of the antenna->point vector, R its length."""
    lat, lon, h = _positions(lat_rad, lon_rad, h_m)
    C = _stack("C_bn", C_bn, lat.shape[0], (3, 3))
    ned = ned_of_points(lat, lon, h, ret.lat_rad, ret.lon_rad, ret.h_m)
    b = np.einsum("kji,kj->ki", C, ned)
    return np.arcsin(np.clip(b[:, 1] / np.linalg.norm(b, axis=1), -1.0, 1.0))


def ned_of_points(lat_rad, lon_rad, h_m, lat_p_rad, lon_p_rad, h_p_m) -> np.ndarray:
    """(n, 3) NED vectors (m) from antennas to points, via the second-order expansion of the module doc."""
    lat, lon, h = _positions(lat_rad, lon_rad, h_m)
    out = np.empty((lat.shape[0], 3))
    _ned_batch(
        lat, lon, h, np.asarray(lat_p_rad, float), np.asarray(lon_p_rad, float), np.asarray(h_p_m, float), out
    )
    return out


@njit(cache=True, fastmath=False, error_model="numpy")
def _ned_batch(lat, lon, h, lat_p, lon_p, h_p, out):
    for k in range(lat.shape[0]):
        cv = _consts(lat[k])
        x, y, z = _ned(lat_p[k] - lat[k], lon_p[k] - lon[k], h_p[k], h[k], cv)
        out[k, 0] = x
        out[k, 1] = y
        out[k, 2] = z
