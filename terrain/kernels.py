"""Numba interpolation kernels on a geodetic grid (arrays only, no Python objects).

Grid convention (shared by every kernel): `heights[i, j]` is the elevation (m above MSL) of the post at
latitude `lat0 + i * dlat` and longitude `lon0 + j * dlon` (radians); row 0 is the southmost row. NaN marks
a void. Every lookup outside the grid (or touching a void) returns NaN - the hot path never raises; the
grid's bounds are its outermost posts (heights.shape from the origin).

The bilinear formula is written once, `bilinear_cell` (with `cell_index`, the cell and fractions of a point
in grid-index units): every bilinear lookup of the project (the kernels here, the terrain queries' in-cell
Newton steps, the fast tier's TERCOM) calls it, LLVM-inlined (forceinline).

`MapRecord(heights, lat0, lon0, dlat, dlon, cubic)` is that grid with its interpolation (bicubic when cubic,
else bilinear) as one kernel argument (numba passes it as a tuple; `Dem.record(cubic)` builds it);
`map_height(record, lat, lon)` reads it. The interpolation primitives below (bilinear, bicubic and their
batch forms) take the grid's five values: they are what a record dispatches to.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

# Points within 1e-9 post of the outermost posts count as inside (round-off in the index arithmetic).
_EDGE = 1e-9


@njit(cache=True, fastmath=False, error_model="numpy", forceinline=True)
def cell_index(n_lat, n_lon, fi, fj):
    """(i, j, u, v): the cell (i, j) of an n_lat x n_lon grid holding the point at fractional grid indices
    (fi along latitude, fj along longitude) and the point's fractions u, v in it; i = -1 outside the grid
    (beyond 1e-9 post of its outermost posts). A point on the last row or column belongs to the cell
    before it (u or v = 1)."""
    if not (fi >= -_EDGE and fj >= -_EDGE and fi <= n_lat - 1 + _EDGE and fj <= n_lon - 1 + _EDGE):
        return -1, -1, np.nan, np.nan
    i = min(max(int(fi), 0), n_lat - 2)
    j = min(max(int(fj), 0), n_lon - 2)
    return i, j, fi - i, fj - j


@njit(cache=True, fastmath=False, error_model="numpy", forceinline=True)
def bilinear_cell(heights, i, j, u, v):
    """The bilinear formula in cell (i, j) at fractions (u along latitude, v along longitude): (height m,
    a = row i's height at v, b = row i + 1's, ea = h[i, j + 1] - h[i, j], eb = h[i + 1, j + 1] - h[i + 1, j])
    - the terms the gradient needs too: dh/du = b - a, dh/dv = ea + u (eb - ea). NaN next to a void."""
    h00 = heights[i, j]
    h01 = heights[i, j + 1]
    h10 = heights[i + 1, j]
    h11 = heights[i + 1, j + 1]
    ea = h01 - h00
    eb = h11 - h10
    a = h00 + v * ea
    b = h10 + v * eb
    return a + u * (b - a), a, b, ea, eb


@njit(cache=True, fastmath=False, error_model="numpy")
def bilinear(heights, lat0, lon0, dlat, dlon, lat, lon) -> float:
    """Bilinear height (m) at (lat, lon) in radians; NaN outside the grid or next to a void."""
    return bilinear_at_index(heights, (lat - lat0) / dlat, (lon - lon0) / dlon)


@njit(cache=True, fastmath=False, error_model="numpy", forceinline=True)
def bilinear_at_index(heights, fi, fj) -> float:
    """Bilinear height (m) at fractional grid indices (fi along latitude, fj along longitude): the one
    bilinear lookup of the project (its formula: bilinear_cell); NaN outside the grid or next
    to a void (a point on a grid line next to a void is evaluated in the valid neighbour, _edge_retry)."""
    n_lat, n_lon = heights.shape
    i, j, u, v = cell_index(n_lat, n_lon, fi, fj)
    if i < 0:
        return np.nan
    r = bilinear_cell(heights, i, j, u, v)[0]
    if r != r:
        return _edge_retry(heights, i, j, u, v)
    return r


@njit(cache=True, fastmath=False, error_model="numpy")
def _edge_retry(heights, i, j, u, v):
    """A point on (within 1e-7 post of) a grid line between a void cell and a valid one belongs to both:
    evaluate it in the neighbouring cell. NaN when that cell is void too."""
    n_lat, n_lon = heights.shape
    tol = 1e-7
    for di in (0, -1, 1):
        for dj in (0, -1, 1):
            if di == 0 and dj == 0:
                continue
            if di == -1 and not (u < tol and i > 0):
                continue
            if di == 1 and not (u > 1.0 - tol and i < n_lat - 2):
                continue
            if dj == -1 and not (v < tol and j > 0):
                continue
            if dj == 1 and not (v > 1.0 - tol and j < n_lon - 2):
                continue
            ii = i + di
            jj = j + dj
            uu = u - di
            vv = v - dj
            a = heights[ii, jj] + vv * (heights[ii, jj + 1] - heights[ii, jj])
            b = heights[ii + 1, jj] + vv * (heights[ii + 1, jj + 1] - heights[ii + 1, jj])
            r = a + uu * (b - a)
            if r == r:
                return r
    return np.nan


@njit(cache=True, fastmath=False, error_model="numpy")
def bilinear_with_gradient(heights, lat0, lon0, dlat, dlon, lat, lon):
    """(h_m, dh/dlat, dh/dlon) of the bilinear surface, derivatives in m/rad; NaNs outside the grid."""
    n_lat, n_lon = heights.shape
    i, j, u, v = cell_index(n_lat, n_lon, (lat - lat0) / dlat, (lon - lon0) / dlon)
    if i < 0:
        return np.nan, np.nan, np.nan
    h, a, b, ea, eb = bilinear_cell(heights, i, j, u, v)
    return h, (b - a) / dlat, (ea + u * (eb - ea)) / dlon


@njit(cache=True, fastmath=False, error_model="numpy")
def _cubic_weights(t):
    # Keys cubic convolution, a = -0.5 (Catmull-Rom): interpolating, C1.
    t2 = t * t
    t3 = t2 * t
    w0 = -0.5 * t3 + t2 - 0.5 * t
    w1 = 1.5 * t3 - 2.5 * t2 + 1.0
    w2 = -1.5 * t3 + 2.0 * t2 + 0.5 * t
    w3 = 0.5 * t3 - 0.5 * t2
    return w0, w1, w2, w3


@njit(cache=True, fastmath=False, error_model="numpy")
def bicubic(heights, lat0, lon0, dlat, dlon, lat, lon) -> float:
    """Bicubic (Catmull-Rom) height (m); edge posts are replicated beyond the border; NaN outside."""
    n_lat, n_lon = heights.shape
    i, j, u, v = cell_index(n_lat, n_lon, (lat - lat0) / dlat, (lon - lon0) / dlon)
    if i < 0:
        return np.nan
    wu = _cubic_weights(u)
    wv = _cubic_weights(v)
    acc = 0.0
    for a in range(4):
        ii = min(max(i - 1 + a, 0), n_lat - 1)
        row = 0.0
        for b in range(4):
            jj = min(max(j - 1 + b, 0), n_lon - 1)
            row += wv[b] * heights[ii, jj]
        acc += wu[a] * row
    return acc


@njit(cache=True, fastmath=False, error_model="numpy")
def bilinear_batch(heights, lat0, lon0, dlat, dlon, lat, lon, out):
    """Bilinear heights for 1-D arrays lat, lon (rad) into out (m); NaN outside. Single thread. The
    divisions are hoisted (multiplication by the inverse spacings, so a point's result can differ from
    `bilinear`'s in the last bit)."""
    n_lat, n_lon = heights.shape
    inv_dlat = 1.0 / dlat
    inv_dlon = 1.0 / dlon
    for k in range(lat.shape[0]):
        i, j, u, v = cell_index(n_lat, n_lon, (lat[k] - lat0) * inv_dlat, (lon[k] - lon0) * inv_dlon)
        if i < 0:
            out[k] = np.nan
            continue
        r = bilinear_cell(heights, i, j, u, v)[0]
        if r != r:
            r = _edge_retry(heights, i, j, u, v)
        out[k] = r
    return out


@njit(cache=True, fastmath=False, error_model="numpy")
def bicubic_batch(heights, lat0, lon0, dlat, dlon, lat, lon, out):
    """Bicubic heights for 1-D arrays lat, lon (rad) into out (m); NaN outside."""
    for k in range(lat.shape[0]):
        out[k] = bicubic(heights, lat0, lon0, dlat, dlon, lat[k], lon[k])
    return out


@njit(cache=True, fastmath=False, error_model="numpy")
def gradient_batch(heights, lat0, lon0, dlat, dlon, lat, lon, dh_dlat, dh_dlon):
    """Bilinear-surface gradients (m/rad) for 1-D arrays lat, lon; NaN outside."""
    for k in range(lat.shape[0]):
        _, g_lat, g_lon = bilinear_with_gradient(heights, lat0, lon0, dlat, dlon, lat[k], lon[k])
        dh_dlat[k] = g_lat
        dh_dlon[k] = g_lon


@njit(cache=True, fastmath=False, error_model="numpy")
def bicubic_gradient_batch(heights, lat0, lon0, dlat, dlon, lat, lon, dh_dlat, dh_dlon):
    """Central-difference gradient (m/rad) of the bicubic surface (step 1e-3 post); NaN outside."""
    n_lat, n_lon = heights.shape
    for k in range(lat.shape[0]):
        hi = 1e-3 * dlat
        hj = 1e-3 * dlon
        la = lat[k]
        lo = lon[k]
        la_p = min(la + hi, lat0 + (n_lat - 1) * dlat)
        la_m = max(la - hi, lat0)
        lo_p = min(lo + hj, lon0 + (n_lon - 1) * dlon)
        lo_m = max(lo - hj, lon0)
        if la_p <= la_m or lo_p <= lo_m:
            dh_dlat[k] = np.nan
            dh_dlon[k] = np.nan
            continue
        dh_dlat[k] = (
            bicubic(heights, lat0, lon0, dlat, dlon, la_p, lo)
            - bicubic(heights, lat0, lon0, dlat, dlon, la_m, lo)
        ) / (la_p - la_m)
        dh_dlon[k] = (
            bicubic(heights, lat0, lon0, dlat, dlon, la, lo_p)
            - bicubic(heights, lat0, lon0, dlat, dlon, la, lo_m)
        ) / (lo_p - lo_m)


@njit(cache=True, fastmath=False, error_model="numpy")
def block_bounds(heights, block):
    """(max, min) height of each block of block x block cells; block (bi, bj) spans posts
    [bi*block, bi*block + block] x [bj*block, bj*block + block] (shared edges), so it bounds the bilinear
    surface of its cells. Voids are ignored; an all-void block has max = -inf, min = +inf."""
    n_lat, n_lon = heights.shape
    nbi = max((n_lat - 2) // block + 1, 1)
    nbj = max((n_lon - 2) // block + 1, 1)
    bmax = np.full((nbi, nbj), -np.inf)
    bmin = np.full((nbi, nbj), np.inf)
    for bi in range(nbi):
        i1 = min(bi * block + block, n_lat - 1)
        for bj in range(nbj):
            j1 = min(bj * block + block, n_lon - 1)
            hi = -np.inf
            lo = np.inf
            for i in range(bi * block, i1 + 1):
                for j in range(bj * block, j1 + 1):
                    v = heights[i, j]
                    if v == v:
                        if v > hi:
                            hi = v
                        if v < lo:
                            lo = v
            bmax[bi, bj] = hi
            bmin[bi, bj] = lo
    return bmax, bmin


@njit(cache=True, fastmath=False, error_model="numpy")
def block_slopes(heights, block, dn_m, de_m):
    """Upper bound of the bilinear surface's gradient magnitude (m/m) in each block (same block layout as
    block_bounds): sqrt(max|dh along rows|^2 / dn^2 + max|dh along columns|^2 / de^2) over the block's cell
    edges; within a bilinear cell each partial derivative is a convex combination of two edge differences.
    Edges touching a void are ignored (the surface is NaN there); an all-void block gets 0."""
    n_lat, n_lon = heights.shape
    nbi = max((n_lat - 2) // block + 1, 1)
    nbj = max((n_lon - 2) // block + 1, 1)
    out = np.zeros((nbi, nbj))
    for bi in range(nbi):
        i1 = min(bi * block + block, n_lat - 1)
        for bj in range(nbj):
            j1 = min(bj * block + block, n_lon - 1)
            gi = 0.0
            gj = 0.0
            for i in range(bi * block, i1 + 1):
                for j in range(bj * block, j1 + 1):
                    v = heights[i, j]
                    if i < i1:
                        d = abs(heights[i + 1, j] - v)
                        if d > gi:
                            gi = d
                    if j < j1:
                        d = abs(heights[i, j + 1] - v)
                        if d > gj:
                            gj = d
            out[bi, bj] = np.sqrt(gi * gi / (dn_m * dn_m) + gj * gj / (de_m * de_m))
    return out


class MapRecord(NamedTuple):
    """A map's grid and interpolation as one kernel argument (see the module docstring)."""

    heights: np.ndarray
    lat0: float
    lon0: float
    dlat: float
    dlon: float
    cubic: bool


@njit(cache=True, fastmath=False, error_model="numpy", forceinline=True)
def map_height(record, lat, lon):
    """Height (m) of the record's map at (lat, lon) rad by its interpolation; NaN off the map."""
    heights, lat0, lon0, dlat, dlon, cubic = record
    if cubic:
        return bicubic(heights, lat0, lon0, dlat, dlon, lat, lon)
    return bilinear(heights, lat0, lon0, dlat, dlon, lat, lon)
