"""Kernels of the batch TERCOM / MAD correlation (seed 000 section 2; the MAD surface of tercom.mad).

mad_surface(...)[a, b] = (1/M) sum_k | h_meas,k - h_DB(lat_k + a dlat_cell, lon_k + b dlon_cell) | over the
(2 half + 1)^2 shifts, bilinear map look-ups, inf where any look-up is off the map or in a void. Three
implementations with the same values: mad_surface_reference (the definition, one look-up per sample and
shift, the tests' yardstick); _mad_surface_separable (the bilinear weights split per axis, any voids);
_mad_surface_void_free (per-chunk tables of the shifted rows and columns, when no look-up of the block can
touch a void, optionally split in bands over TERCOM_THREADS threads: the kernels release the GIL).
mad_surface picks among them.
"""

from __future__ import annotations

import os
import threading

import numpy as np
from numba import njit

from ...terrain.kernels import _EDGE, bilinear

_CHUNK = 8  # samples whose tables _mad_surface_void_free builds at once (their rows stay in L1)
# Threads of one MAD surface: a fix is a burst of work (~10 ms for the default scenario's), and in the
# pipelined closed loop the other core waits for it (trn_env/sim/nav_stage.py), so it is split in two.
TERCOM_THREADS = min(2, os.cpu_count() or 1)
PARALLEL_MIN_LOOKUPS = 2_000_000   # below this a thread's start-up (~0.1 ms) is not worth it



@njit(cache=True, error_model="numpy")
def mad_surface_reference(
    rec, lat_k, lon_k, h_meas_k, dlat_cell, dlon_cell, half, remove_bias
):
    """mad_surface by one terrain.kernels.bilinear lookup per (cell, sample): the plain definition, kept as
    the reference the fast kernel is tested against."""
    heights, lat0, lon0, dlat, dlon, _ = rec   # the map record's grid (terrain.kernels.MapRecord)
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
def _block_void_free(rec, lat_k, lon_k, span_lat, span_lon):
    """True if the DEM posts around every sample +- the shift spans hold no NaN (no lookup can be void)."""
    heights, lat0, lon0, dlat, dlon, _ = rec   # the map record's grid (terrain.kernels.MapRecord)
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


@njit(cache=True, forceinline=True)
def _rows_of(g, ri, ru, a, i_lo):
    """The two interpolated map rows (ga, gb) bracketing replica row a and its weight u between them."""
    return g[ri[a] - i_lo], g[ri[a] + 1 - i_lo], ru[a]


@njit(cache=True, error_model="numpy")
def _mad_surface_separable(
    rec, lat_k, lon_k, h_meas_k, dlat_cell, dlon_cell, half, remove_bias
):
    """mad_surface's general path (any voids): same numbers as mad_surface_reference (one bilinear lookup
    per cell and sample), computed separably:
    for each sample the bilinear's along-longitude interpolation (its `a`/`b` terms) is done once per DEM
    row and east shift, then each cell needs one interpolation along latitude - the same operations in the
    same order, so the surface is bit-identical. Points that the bilinear would retry at a void edge go
    through terrain.kernels.bilinear itself."""
    heights, lat0, lon0, dlat, dlon, _ = rec   # the map record's grid (terrain.kernels.MapRecord)
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
    void_free = _block_void_free(rec, lat_k, lon_k, half * abs(dlat_cell),
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
                    ga, gb, u = _rows_of(g, ri, ru, a, i_lo)
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
                ga, gb, u = _rows_of(g, ri, ru, a, i_lo)
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


@njit(cache=True, error_model="numpy")
def _axis_fractions(x0, offsets, n, origin, spacing, n_posts, idx, frac, ok):
    """_axis_cells without branches (so LLVM vectorises it): grid cell index (uint32) and fraction of
    x0 + offsets[c], c < n, as terrain.kernels.bilinear computes them. floor = int() wherever the index is
    not clamped (f >= 0), and both clamp to 0 on [-_EDGE, 0): same index and same fraction bits."""
    hi = n_posts - 1 + _EDGE
    top = np.float64(n_posts - 2)
    for c in range(n):
        f = ((x0 + offsets[c]) - origin) / spacing
        o = (f >= -_EDGE) & (f <= hi)
        fi = min(max(np.floor(f), 0.0), top) if o else 0.0
        ok[c] = o
        frac[c] = f - fi
        idx[c] = np.uint32(np.int32(fi))  # via int32: packed double->int32 conversion vectorises


@njit(cache=True, error_model="numpy")
def _chunk_tables(rec, lat_k, lon_k, k0, kc, lat_off, lon_off, n, n_b, nb, span,
                  ri, row_off, row_u, row_in, g, dg, cj, cv, cok, row_ok, col_ok):
    """Per sample k0 + kk (kk < kc): the along-longitude interpolation of every DEM row the north shifts
    touch, g[kk, rr, b] = bilinear's a/b term for east shift b (flat, row stride nb), its row-to-row
    difference dg (bilinear's b - a), and per north shift a the flat offset of its row (row_off), fraction
    u (row_u) and validity (row_in); n north shifts (lat_off), n_b east shifts padded to nb (lon_off).
    row_ok / col_ok are and-ed with this sample's validity."""
    heights, lat0, lon0, dlat, dlon, _ = rec   # the map record's grid (terrain.kernels.MapRecord)
    n_lat, n_lon = heights.shape
    unb = np.uint64(nb)
    one = np.uint32(1)
    for kk in range(kc):
        k = k0 + kk
        rin = row_in[kk]
        _axis_fractions(lat_k[k], lat_off, n, lat0, dlat, n_lat, ri, row_u[kk], rin)
        _axis_fractions(lon_k[k], lon_off, nb, lon0, dlon, n_lon, cj, cv, cok)
        i_lo = np.uint32(n_lat)
        i_hi = np.uint32(0)
        any_in = False
        for a in range(n):
            o = rin[a]
            i_lo = min(i_lo, ri[a] if o else np.uint32(n_lat))
            i_hi = max(i_hi, ri[a] if o else np.uint32(0))
            any_in |= o
            row_ok[a] &= o
        for b in range(n_b):
            col_ok[b] &= cok[b]
        if not any_in:
            i_lo = np.uint32(0)
            i_hi = np.uint32(0)
        nr = np.uint64(i_hi - i_lo) + np.uint64(2)  # rows i_lo .. i_hi + 1
        if nr > np.uint64(span):
            raise ValueError("mad_surface: north shifts span more DEM rows than the table holds")
        g0 = np.uint64(kk * span)
        base = g0 - np.uint64(i_lo)  # wraps for rows outside the map; row_in is False there
        for a in range(n):
            row_off[kk, a] = (base + np.uint64(ri[a])) * unb
        for rr in range(nr):
            hr = heights[np.uint64(i_lo) + rr]
            go = (g0 + rr) * unb
            for b in range(nb):
                j = cj[b]
                h0 = hr[j]
                g[go + np.uint64(b)] = h0 + cv[b] * (hr[j + one] - h0)  # bilinear's a = h00 + v (h01 - h00)
        for rr in range(nr - np.uint64(1)):
            go = (g0 + rr) * unb
            g1 = go + unb
            for b in range(nb):
                ub = np.uint64(b)
                dg[go + ub] = g[g1 + ub] - g[go + ub]  # bilinear's (b - a)


@njit(cache=True, error_model="numpy", nogil=True)
def _mad_rows_pass(rec, lat_k, lon_k, h_meas_k, k_begin, k_end, lat_off, lon_off,
                   n_b, mode, mean_in, acc_io, row_ok, col_ok):
    """One pass of the MAD surface's rows over samples k_begin <= k < k_end, added to acc (flat, row stride
    len(lon_off)): mode 0 adds |d|, mode 1 adds d, mode 2 adds |d - mean| (d = h_meas - map height at the
    sample shifted by (lat_off[a], lon_off[b]), b < n_b; lon_off padded to a multiple of 8). row_ok / col_ok
    are and-ed with the samples' validity. Samples in chunks of _CHUNK: the chunk's tables (_chunk_tables),
    then per north shift a, four samples at a time in one branch-free loop over the (padded) east shifts, so
    each cell's sum stays in a register across the four and LLVM vectorises across cells. Per cell the
    operations and their order over k are those of mad_surface_reference, so any split of the rows or of
    the samples (in order) gives the same bits. Releases the GIL."""
    heights, lat0, lon0, dlat, dlon, _ = rec   # the map record's grid (terrain.kernels.MapRecord)
    K = _CHUNK
    n = lat_off.shape[0]
    nb = lon_off.shape[0]
    span = int(np.ceil(abs(lat_off[n - 1] - lat_off[0]) / dlat)) + 5
    ri = np.empty(n, np.uint32)
    row_off = np.empty((K, n), np.uint64)
    row_u = np.empty((K, n))
    row_in = np.empty((K, n), np.bool_)
    g = np.empty(K * span * nb)
    dg = np.empty(K * span * nb)
    cj = np.empty(nb, np.uint32)
    cv = np.empty(nb)
    cok = np.empty(nb, np.bool_)
    # the sums in arrays of this function's own, so LLVM knows they alias nothing else and vectorises
    acc = np.zeros(n * nb)
    mean = np.zeros(n * nb)
    for q in range(n * nb):
        acc[q] = acc_io[q]
        mean[q] = mean_in[q]
    unb = np.uint64(nb)
    for k0 in range(k_begin, k_end, K):
        kc = min(K, k_end - k0)
        _chunk_tables(rec, lat_k, lon_k, k0, kc, lat_off, lon_off, n, n_b,
                      nb, span, ri, row_off, row_u, row_in, g, dg, cj, cv, cok, row_ok, col_ok)
        for a in range(n):
            ao = np.uint64(a) * unb
            kk = 0
            while (kk + 4 <= kc and row_in[kk, a] and row_in[kk + 1, a] and row_in[kk + 2, a]
                   and row_in[kk + 3, a]):
                o0 = row_off[kk, a]
                o1 = row_off[kk + 1, a]
                o2 = row_off[kk + 2, a]
                o3 = row_off[kk + 3, a]
                u0 = row_u[kk, a]
                u1 = row_u[kk + 1, a]
                u2 = row_u[kk + 2, a]
                u3 = row_u[kk + 3, a]
                h0 = h_meas_k[k0 + kk]
                h1 = h_meas_k[k0 + kk + 1]
                h2 = h_meas_k[k0 + kk + 2]
                h3 = h_meas_k[k0 + kk + 3]
                # hdb = x + u (y - x): bilinear's r = a + u (b - a); d = h_meas - hdb
                if mode == 0:
                    for b in range(nb):
                        ub = np.uint64(b)
                        s = acc[ao + ub]
                        s += abs(h0 - (g[o0 + ub] + u0 * dg[o0 + ub]))
                        s += abs(h1 - (g[o1 + ub] + u1 * dg[o1 + ub]))
                        s += abs(h2 - (g[o2 + ub] + u2 * dg[o2 + ub]))
                        s += abs(h3 - (g[o3 + ub] + u3 * dg[o3 + ub]))
                        acc[ao + ub] = s
                elif mode == 1:
                    for b in range(nb):
                        ub = np.uint64(b)
                        s = acc[ao + ub]
                        s += h0 - (g[o0 + ub] + u0 * dg[o0 + ub])
                        s += h1 - (g[o1 + ub] + u1 * dg[o1 + ub])
                        s += h2 - (g[o2 + ub] + u2 * dg[o2 + ub])
                        s += h3 - (g[o3 + ub] + u3 * dg[o3 + ub])
                        acc[ao + ub] = s
                else:
                    for b in range(nb):
                        ub = np.uint64(b)
                        s = acc[ao + ub]
                        mu = mean[ao + ub]
                        s += abs((h0 - (g[o0 + ub] + u0 * dg[o0 + ub])) - mu)
                        s += abs((h1 - (g[o1 + ub] + u1 * dg[o1 + ub])) - mu)
                        s += abs((h2 - (g[o2 + ub] + u2 * dg[o2 + ub])) - mu)
                        s += abs((h3 - (g[o3 + ub] + u3 * dg[o3 + ub])) - mu)
                        acc[ao + ub] = s
                kk += 4
            while kk < kc:  # the chunk's tail, or a sample whose shift a is off the map
                if row_in[kk, a]:
                    o0 = row_off[kk, a]
                    u0 = row_u[kk, a]
                    h0 = h_meas_k[k0 + kk]
                    if mode == 0:
                        for b in range(nb):
                            ub = np.uint64(b)
                            acc[ao + ub] += abs(h0 - (g[o0 + ub] + u0 * dg[o0 + ub]))
                    elif mode == 1:
                        for b in range(nb):
                            ub = np.uint64(b)
                            acc[ao + ub] += h0 - (g[o0 + ub] + u0 * dg[o0 + ub])
                    else:
                        for b in range(nb):
                            ub = np.uint64(b)
                            acc[ao + ub] += abs((h0 - (g[o0 + ub] + u0 * dg[o0 + ub])) - mean[ao + ub])
                kk += 1
    for q in range(n * nb):
        acc_io[q] = acc[q]


@njit(cache=True, error_model="numpy", nogil=True)
def _mad_rows_finish(acc, m, n_b, row_ok, col_ok, out):
    """out[a, b] = acc / m, or inf where a sample fell off the map at that shift."""
    nb = acc.shape[0] // out.shape[0]
    for a in range(out.shape[0]):
        for b in range(n_b):
            v = acc[a * nb + b] / m
            out[a, b] = v if (row_ok[a] and col_ok[b] and np.isfinite(v)) else np.inf


@njit(cache=True, error_model="numpy", nogil=True)
def _mad_rows_void_free(rec, lat_k, lon_k, h_meas_k, lat_off, lon_off, n_b,
                        remove_bias, out):
    """Rows of the MAD surface when no lookup can touch a void: out[a, b] for the north shifts lat_off[a]
    (rad) and east shifts lon_off[b], b < n_b: the passes of _mad_rows_pass over every sample (with
    remove_bias: the sum of d, each cell's mean = sum / m, then the sum of |d - mean|). Releases the GIL."""
    n = lat_off.shape[0]
    nb = lon_off.shape[0]
    m = lat_k.shape[0]
    acc = np.zeros(n * nb)
    mean = np.zeros(n * nb)
    row_ok = np.ones(n, np.bool_)
    col_ok = np.ones(n_b, np.bool_)
    if remove_bias:
        _mad_rows_pass(rec, lat_k, lon_k, h_meas_k, 0, m, lat_off, lon_off, n_b,
                       1, mean, acc, row_ok, col_ok)
        for q in range(n * nb):
            mean[q] = acc[q] / m  # the reference's mean = s / m
            acc[q] = 0.0
        _mad_rows_pass(rec, lat_k, lon_k, h_meas_k, 0, m, lat_off, lon_off, n_b,
                       2, mean, acc, row_ok, col_ok)
    else:
        _mad_rows_pass(rec, lat_k, lon_k, h_meas_k, 0, m, lat_off, lon_off, n_b,
                       0, mean, acc, row_ok, col_ok)
    _mad_rows_finish(acc, m, n_b, row_ok, col_ok, out)


def _shift_offsets(half: int, dlat_cell: float, dlon_cell: float) -> tuple[np.ndarray, np.ndarray]:
    """North shifts (c - half) dlat_cell, c < 2 half + 1, and east shifts padded to whole vectors of 8 (the
    padding is computed and dropped), as mad_surface_reference forms them (its dla, dlo)."""
    n = 2 * half + 1
    nb = (n + 7) // 8 * 8
    lat_off = np.array([(c - half) * dlat_cell for c in range(n)])
    lon_off = np.array([(c - half) * dlon_cell for c in range(nb)])
    return lat_off, lon_off


def _in_bands(n_rows: int, threads: int, band) -> None:
    """band(a0, a1, i) over `threads` bands of rows [a0, a1) (at least 8 rows each), all at the same time:
    band i > 0 on threads made for this call (not a pool: a pool's threads would not survive the closed
    loop's fork), band 0 on this one. The bands' kernels release the GIL."""
    bands = np.linspace(0, n_rows, max(1, min(int(threads), n_rows // 8)) + 1).astype(int)
    workers = [threading.Thread(target=band, args=(int(bands[i]), int(bands[i + 1]), i))
               for i in range(1, len(bands) - 1)]
    for w in workers:
        w.start()
    band(int(bands[0]), int(bands[1]), 0)
    for w in workers:
        w.join()


def _mad_surface_void_free(rec, lat_k, lon_k, h_meas_k, dlat_cell, dlon_cell,
                           half, remove_bias, threads: int = 1):
    """mad_surface when no lookup can touch a void: _mad_rows_void_free over all north shifts, split into
    `threads` bands of rows computed at the same time (the kernel releases the GIL; same bits either way)."""
    n = 2 * half + 1
    lat_off, lon_off = _shift_offsets(half, dlat_cell, dlon_cell)
    out = np.empty((n, n))
    args = (rec, lat_k, lon_k, h_meas_k)

    def band(a0: int, a1: int, _i: int) -> None:
        _mad_rows_void_free(*args, lat_off[a0:a1], lon_off, n, remove_bias, out[a0:a1])

    _in_bands(n, threads, band)
    return out


def mad_surface(
    rec, lat_k, lon_k, h_meas_k, dlat_cell, dlon_cell, half, remove_bias,
    threads: int | None = None,
):
    """MAD surface (2 half + 1, 2 half + 1), rows = north shifts j, columns = east shifts i (seed 000 eq 1/2).
    lat_k/lon_k already include the closest-point offsets; shifts are j*dlat_cell, i*dlon_cell (rad).
    remove_bias: subtract each cell's mean difference first (bias-insensitive variant, not eq 1/2).

    Bit-identical to mad_surface_reference. When the DEM posts around the track +- the shifts hold no
    void (the common case) it runs _mad_surface_void_free, on `threads` threads (default: TERCOM_THREADS
    for a surface of more than PARALLEL_MIN_LOOKUPS lookups, else 1), else the separable
    _mad_surface_separable."""
    if lat_k.shape[0] == 0:
        return _mad_surface_separable(rec, lat_k, lon_k, h_meas_k, dlat_cell,
                                      dlon_cell, half, remove_bias)
    void_free = _block_void_free(rec, lat_k, lon_k, half * abs(dlat_cell),
                                 half * abs(dlon_cell))
    if void_free:
        if threads is None:
            lookups = lat_k.shape[0] * (2 * half + 1) ** 2
            threads = TERCOM_THREADS if lookups > PARALLEL_MIN_LOOKUPS else 1
        return _mad_surface_void_free(rec, lat_k, lon_k, h_meas_k, dlat_cell,
                                      dlon_cell, half, remove_bias, threads)
    return _mad_surface_separable(rec, lat_k, lon_k, h_meas_k, dlat_cell,
                                  dlon_cell, half, remove_bias)
