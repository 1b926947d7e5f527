"""Batch TERCOM / MAD correlation (seed 000 section 2).

Measured terrain heights along the INS track are compared with the map shifted over a reference matrix
(default 101 x 101 cells of 5 m, seed 000 Table 2):

    MAD_ij = (1/M) sum_k | h_meas,k - h_DB(lat_k + p_k,lat + j dlat, lon_k + p_k,lon + i dlon) |

- plain radar altimeter (eq 1): h_meas,k = h_baro,k - RA range, p_k = 0 (terrain assumed straight below);
- IRA (eq 2): h_meas,k = h_baro,k - |p_k,alt|, (p_k,lat, p_k,lon) = (p_n / R_ns, p_e / R_ew) from the
  closest-point relative position (navigators.ira_geometry).

The cell with the smallest MAD is the fix: the INS position plus (j dn, i de) metres is the matched
position. The surface and a quality figure come with each fix. Cells for which any sample falls off the
map (NaN lookups) are invalid (MAD = inf).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from terrain.geodesy import meridian_radius_m, prime_vertical_radius_m
from terrain.kernels import _EDGE, bilinear


@njit(cache=True, error_model="numpy")
def mad_surface_reference(
    heights, lat0, lon0, dlat, dlon, lat_k, lon_k, h_meas_k, dlat_cell, dlon_cell, half, remove_bias
):
    """mad_surface by one terrain.kernels.bilinear lookup per (cell, sample): the plain definition, kept as
    the reference the fast kernel is tested against."""
    n = 2 * half + 1
    m = lat_k.shape[0]
    out = np.empty((n, n))
    d = np.empty(m)
    for a in range(n):
        dla = (a - half) * dlat_cell
        for b in range(n):
            dlo = (b - half) * dlon_cell
            s = 0.0
            bad = False
            for k in range(m):
                hdb = bilinear(heights, lat0, lon0, dlat, dlon, lat_k[k] + dla, lon_k[k] + dlo)
                if not np.isfinite(hdb):
                    bad = True
                    break
                d[k] = h_meas_k[k] - hdb
                s += d[k]
            if bad:
                out[a, b] = np.inf
                continue
            mean = s / m if remove_bias else 0.0
            acc = 0.0
            for k in range(m):
                acc += abs(d[k] - mean)
            out[a, b] = acc / m
    return out


@njit(cache=True, error_model="numpy")
def _axis_cells(x0, step, n, origin, spacing, n_posts, idx, frac, ok):
    """Grid cell index and fraction of x0 + (c - half) step for c in 0..n-1 along one DEM axis, as
    terrain.kernels.bilinear computes them (ok False: outside the grid on this axis)."""
    half = (n - 1) // 2
    for c in range(n):
        f = ((x0 + (c - half) * step) - origin) / spacing
        ok[c] = f >= -_EDGE and f <= n_posts - 1 + _EDGE
        i = min(max(int(f), 0), n_posts - 2) if ok[c] else 0
        idx[c] = i
        frac[c] = f - i


@njit(cache=True, error_model="numpy")
def _block_void_free(heights, lat0, lon0, dlat, dlon, lat_k, lon_k, span_lat, span_lon):
    """True if the DEM posts around every sample +- the shift spans hold no NaN (no lookup can be void)."""
    n_lat, n_lon = heights.shape
    lat_lo = lat_hi = lat_k[0]
    lon_lo = lon_hi = lon_k[0]
    for k in range(lat_k.shape[0]):
        lat_lo = min(lat_lo, lat_k[k])
        lat_hi = max(lat_hi, lat_k[k])
        lon_lo = min(lon_lo, lon_k[k])
        lon_hi = max(lon_hi, lon_k[k])
    r0 = max(int(np.floor((lat_lo - span_lat - lat0) / dlat)) - 1, 0)
    r1 = min(int(np.floor((lat_hi + span_lat - lat0) / dlat)) + 2, n_lat - 1)
    c0 = max(int(np.floor((lon_lo - span_lon - lon0) / dlon)) - 1, 0)
    c1 = min(int(np.floor((lon_hi + span_lon - lon0) / dlon)) + 2, n_lon - 1)
    for r in range(r0, r1 + 1):
        for c in range(c0, c1 + 1):
            if heights[r, c] != heights[r, c]:
                return False
    return True


@njit(cache=True, error_model="numpy")
def mad_surface(
    heights, lat0, lon0, dlat, dlon, lat_k, lon_k, h_meas_k, dlat_cell, dlon_cell, half, remove_bias
):
    """MAD surface (2 half + 1, 2 half + 1), rows = north shifts j, columns = east shifts i (seed 000 eq 1/2).
    lat_k/lon_k already include the closest-point offsets; shifts are j*dlat_cell, i*dlon_cell (rad).
    remove_bias: subtract each cell's mean difference first (bias-insensitive variant, not eq 1/2).

    Same numbers as mad_surface_reference (one bilinear lookup per cell and sample), computed separably:
    for each sample the bilinear's along-longitude interpolation (its `a`/`b` terms) is done once per DEM
    row and east shift, then each cell needs one interpolation along latitude - the same operations in the
    same order, so the surface is bit-identical. Points that the bilinear would retry at a void edge go
    through terrain.kernels.bilinear itself."""
    n = 2 * half + 1
    m = lat_k.shape[0]
    n_lat, n_lon = heights.shape
    acc = np.zeros((n, n))
    ssum = np.zeros((n, n))
    ri = np.empty(n, np.int64)
    ru = np.empty(n)
    rok = np.empty(n, np.bool_)
    cj = np.empty(n, np.int64)
    cv = np.empty(n)
    cok = np.empty(n, np.bool_)
    row_ok = np.ones(n, np.bool_)
    tmp = np.empty(n)
    col_ok = np.ones(n, np.bool_)
    n_pass = 2 if remove_bias else 1
    void_free = _block_void_free(heights, lat0, lon0, dlat, dlon, lat_k, lon_k, half * abs(dlat_cell),
                                 half * abs(dlon_cell))
    for pss in range(n_pass):
        for k in range(m):
            _axis_cells(lat_k[k], dlat_cell, n, lat0, dlat, n_lat, ri, ru, rok)
            _axis_cells(lon_k[k], dlon_cell, n, lon0, dlon, n_lon, cj, cv, cok)
            i_lo = n_lat
            i_hi = -1
            for a in range(n):
                if rok[a]:
                    i_lo = min(i_lo, ri[a])
                    i_hi = max(i_hi, ri[a] + 1)
                else:
                    row_ok[a] = False
            for b in range(n):
                if not cok[b]:
                    col_ok[b] = False
            if i_hi < 0:
                continue
            # along-longitude interpolation on each DEM row the shifts touch (bilinear's a / b terms)
            g = np.empty((i_hi - i_lo + 1, n))
            for r in range(i_lo, i_hi + 1):
                for b in range(n):
                    j = cj[b]
                    h0 = heights[r, j]
                    g[r - i_lo, b] = h0 + cv[b] * (heights[r, j + 1] - h0)
            hk = h_meas_k[k]
            if void_free:  # the common case in one fused loop per row (per pass with remove_bias)
                for a in range(n):
                    if not rok[a]:
                        continue
                    ga = g[ri[a] - i_lo]
                    gb = g[ri[a] + 1 - i_lo]
                    u = ru[a]
                    acc_a = acc[a]
                    s_a = ssum[a]
                    if not remove_bias:
                        for b in range(n):
                            x = ga[b]
                            acc_a[b] += abs(hk - (x + u * (gb[b] - x)))
                    elif pss == 0:
                        for b in range(n):
                            x = ga[b]
                            s_a[b] += hk - (x + u * (gb[b] - x))
                    else:
                        for b in range(n):
                            x = ga[b]
                            acc_a[b] += abs((hk - (x + u * (gb[b] - x))) - s_a[b] / m)
                continue
            for a in range(n):
                if not rok[a]:
                    continue
                ga = g[ri[a] - i_lo]
                gb = g[ri[a] + 1 - i_lo]
                u = ru[a]
                chk = 0.0
                for b in range(n):  # bilinear's r = a + u (b - a)
                    x = ga[b]
                    hdb = x + u * (gb[b] - x)
                    tmp[b] = hdb
                    chk += hdb
                if chk != chk:  # a NaN (void): the points bilinear retries at a void's edge
                    dla = (a - half) * dlat_cell
                    for b in range(n):
                        if tmp[b] != tmp[b] and cok[b]:
                            tmp[b] = bilinear(heights, lat0, lon0, dlat, dlon, lat_k[k] + dla,
                                              lon_k[k] + (b - half) * dlon_cell)
                acc_a = acc[a]
                if pss == 1:
                    s_a = ssum[a]
                    for b in range(n):
                        acc_a[b] += abs((hk - tmp[b]) - s_a[b] / m)
                elif remove_bias:
                    s_a = ssum[a]
                    for b in range(n):
                        s_a[b] += hk - tmp[b]
                else:
                    for b in range(n):
                        acc_a[b] += abs(hk - tmp[b])
    out = np.empty((n, n))
    for a in range(n):
        for b in range(n):
            v = acc[a, b] / m
            out[a, b] = v if (row_ok[a] and col_ok[b] and np.isfinite(v)) else np.inf
    return out


@dataclass
class TercomFix:
    """One batch fix. Correction (dn_m, de_m): matched position = INS position + correction, i.e. the INS
    position error (INS - true) is estimated as -(dn_m, de_m)."""

    t_s: float
    valid: bool
    reason: str  # "ok" or why the fix is unusable (no_samples, off_map, ...)
    dn_m: float
    de_m: float
    dlat_rad: float
    dlon_rad: float
    mad_min_m: float
    quality: float  # second-best separated local minimum / best (>= 1; larger = more distinct)
    on_edge: bool  # minimum on the border of the reference matrix (true offset may lie outside)
    n_samples: int
    surface_m: np.ndarray  # (2 half + 1, 2 half + 1), rows north shift, columns east shift
    cell_m: float


def _second_minimum(surface: np.ndarray, ia: int, ib: int, exclusion: int) -> float:
    """Smallest local minimum of the surface farther than `exclusion` cells (Chebyshev) from (ia, ib)."""
    s = surface
    n = s.shape[0]
    pad = np.pad(s, 1, constant_values=np.inf)
    core = pad[1:-1, 1:-1]
    is_min = np.isfinite(core)
    for da in (-1, 0, 1):
        for db in (-1, 0, 1):
            if da or db:
                is_min &= core <= pad[1 + da : n + 1 + da, 1 + db : n + 1 + db]
    a, b = np.nonzero(is_min)
    far = np.maximum(np.abs(a - ia), np.abs(b - ib)) > exclusion
    return float(s[a[far], b[far]].min()) if far.any() else np.inf


def correlate(
    grid,
    t_s: float,
    lat_rad,
    lon_rad,
    h_meas_m,
    dn_rel_m=None,
    de_rel_m=None,
    half: int = 50,
    cell_m: float = 5.0,
    exclusion_cells: int = 4,
    remove_bias: bool = False,
) -> TercomFix:
    """Batch MAD fix from M samples (seed 000 eqs 1-2).

    grid: Dem.grid tuple (heights_m, lat0, lon0, dlat, dlon) or an object with `.grid`.
    lat_rad, lon_rad: INS positions (M,); h_meas_m: measured terrain heights (M,) (baro - RA range, or baro -
    |p_alt| for the IRA); dn_rel_m, de_rel_m: horizontal closest-point offsets (M,) for the IRA (None: 0).
    Non-finite samples are dropped. half: reference matrix is (2 half + 1)^2 cells of cell_m metres.
    remove_bias: correlate after removing each cell's mean height difference (insensitive to a baro bias;
    seed 000 uses plain MAD, the default).
    """
    if hasattr(grid, "grid"):
        grid = grid.grid
    heights, lat0, lon0, dlat, dlon = grid
    lat = np.asarray(lat_rad, float)
    lon = np.asarray(lon_rad, float)
    hm = np.asarray(h_meas_m, float)
    dn = np.zeros_like(lat) if dn_rel_m is None else np.asarray(dn_rel_m, float)
    de = np.zeros_like(lat) if de_rel_m is None else np.asarray(de_rel_m, float)
    ok = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(hm) & np.isfinite(dn) & np.isfinite(de)
    n = 2 * half + 1
    empty = np.full((n, n), np.inf)
    if ok.sum() < 2:
        return TercomFix(
            t_s,
            False,
            "no_samples",
            np.nan,
            np.nan,
            np.nan,
            np.nan,
            np.nan,
            np.nan,
            False,
            int(ok.sum()),
            empty,
            cell_m,
        )
    lat, lon, hm, dn, de = lat[ok], lon[ok], hm[ok], dn[ok], de[ok]
    lat_c = float(np.mean(lat))
    r_ns = meridian_radius_m(lat_c)
    r_ew = prime_vertical_radius_m(lat_c) * np.cos(lat_c)
    lat_k = lat + dn / r_ns  # seed 000 eq 2: p_lat = p_n / R_ns
    lon_k = lon + de / r_ew  #                p_lon = p_e / R_ew
    d_lat_cell = cell_m / r_ns
    d_lon_cell = cell_m / r_ew
    surf = mad_surface(
        heights,
        float(lat0),
        float(lon0),
        float(dlat),
        float(dlon),
        np.ascontiguousarray(lat_k),
        np.ascontiguousarray(lon_k),
        np.ascontiguousarray(hm),
        d_lat_cell,
        d_lon_cell,
        half,
        bool(remove_bias),
    )
    if not np.isfinite(surf).any():
        return TercomFix(
            t_s,
            False,
            "off_map",
            np.nan,
            np.nan,
            np.nan,
            np.nan,
            np.nan,
            np.nan,
            False,
            int(lat.size),
            surf,
            cell_m,
        )
    ia, ib = np.unravel_index(int(np.argmin(surf)), surf.shape)
    best = float(surf[ia, ib])
    second = _second_minimum(surf, ia, ib, exclusion_cells)
    quality = second / max(best, 1e-9) if np.isfinite(second) else np.inf
    on_edge = bool(ia in (0, n - 1) or ib in (0, n - 1))
    partly_off = not np.isfinite(surf).all()
    dn_fix = (ia - half) * cell_m
    de_fix = (ib - half) * cell_m
    near = surf[
        max(ia - exclusion_cells, 0) : ia + exclusion_cells + 1,
        max(ib - exclusion_cells, 0) : ib + exclusion_cells + 1,
    ]
    valid = not on_edge and bool(np.isfinite(near).all())
    if on_edge:
        reason = "edge"
    elif not valid:
        reason = "minimum_next_to_map_edge"
    else:
        reason = "ok_partial_map" if partly_off else "ok"
    return TercomFix(
        t_s,
        valid,
        reason,
        dn_fix,
        de_fix,
        dn_fix / r_ns,
        de_fix / r_ew,
        best,
        quality,
        on_edge,
        int(lat.size),
        surf,
        cell_m,
    )


class TercomBatch:
    """Accumulates (t, INS lat/lon, measured terrain height, closest-point offsets) between fixes."""

    def __init__(self):
        self.clear()

    def clear(self) -> None:
        self._parts: list[np.ndarray] = []

    def add(self, t_s, lat_rad, lon_rad, h_meas_m, dn_rel_m=None, de_rel_m=None) -> None:
        t = np.atleast_1d(np.asarray(t_s, float))
        z = np.zeros_like(t)
        cols = [
            t,
            lat_rad,
            lon_rad,
            h_meas_m,
            z if dn_rel_m is None else dn_rel_m,
            z if de_rel_m is None else de_rel_m,
        ]
        self._parts.append(np.stack([np.broadcast_to(np.asarray(c, float), t.shape) for c in cols], 1))

    def add_rows(self, rows: np.ndarray) -> None:
        """Append an (n, 6) float array of rows (t, lat, lon, h_meas, dn_rel, de_rel), taken as is."""
        rows = np.asarray(rows, float)
        if rows.ndim != 2 or rows.shape[1] != 6:
            raise ValueError(f"rows must be an (n, 6) array, got shape {rows.shape}")
        self._parts.append(rows)

    @property
    def samples(self) -> np.ndarray:
        """(M, 6): t, lat, lon, h_meas, dn_rel, de_rel."""
        return np.concatenate(self._parts) if self._parts else np.zeros((0, 6))

    def __len__(self) -> int:
        return int(sum(p.shape[0] for p in self._parts))

    def shift(self, dlat_rad: float, dlon_rad: float) -> None:
        """Move every stored INS position (after the INS was corrected by a filter update)."""
        for p in self._parts:
            p[:, 1] += dlat_rad
            p[:, 2] += dlon_rad
