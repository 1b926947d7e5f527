"""Radar-altimeter return (seed 001 ch. 4; seed 000 section 2.1): the terrain point closest to the antenna
inside the cone of half-angle `half_beamwidth_rad` around the body down axis C_bn[:, 2].

Guarantee: the returned range is the minimum over the DEM's bilinear surface (in the exact-curvature frame
of terrain.queries.shared, each cell as its NED bilinear patch, < 1 mm from the exact map) of the in-cone
distance, up to the cell solver's tolerance; it agrees with a dense brute-force search to 0.5 m (tests).
No point in the cone within max_range_m, voids and off-grid antennas give valid = False. Queries are
independent: a batch gives the same bits as single calls.

Search (_ra_bnb): best-first branch and bound. Incumbent: the beam-axis ray hit (terrain.queries.raycast).
Lower bound of a block / cell: the distance to its box (horizontal rectangle x [-, max height]); blocks and
cells whose bounding sphere misses the cone are pruned. Each surviving cell, in order of bound, is solved
exactly (_cell_min): in the antenna's NED frame the cell is a bilinear patch A + u B + v C + u v D; each
row v is a segment whose in-cone part is one interval (the cone is convex), so min over u is a clamped
projection and the cell minimum is a 1-D minimisation over v (samples, edge points, golden section).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..kernels import bilinear
from .raycast import _ray_hit
from .shared import (
    _INF,
    TerrainReturn,
    _check_positive,
    _consts,
    _geo_of_ned,
    _insert_sorted,
    _ned,
    _outputs,
    _positions,
    _ra_tables,
    _ra_workspace,
    _stack,
)

N_SAMP = 6  # rows sampled per cell by the altimeter's exact cell solver (_cell_min), at most 16



@njit(cache=True, fastmath=False, error_model="numpy")
def _line_in_cone(p0x, p0y, p0z, qx, qy, qz, ax, ay, az, k):
    """Feasible interval [lo, hi] of u in [0, 1] where P0 + u Q lies in the cone (P.a >= sqrt(k) |P|);
    the cone is convex, so the set is one interval (lo > hi: empty). k = cos(half beam)^2."""
    w0 = p0x * ax + p0y * ay + p0z * az
    wq = qx * ax + qy * ay + qz * az
    pq = p0x * qx + p0y * qy + p0z * qz
    qq = qx * qx + qy * qy + qz * qz
    pp = p0x * p0x + p0y * p0y + p0z * p0z
    c2 = wq * wq - k * qq
    c1 = 2.0 * (w0 * wq - k * pq)
    c0 = w0 * w0 - k * pp
    # split [0, 1] at the roots t1 <= t2 of c2 u^2 + c1 u + c0 and keep the pieces whose midpoint is in the
    # cone (zero-length pieces are single points)
    t1 = 0.0
    t2 = 0.0
    scale = abs(c2) + abs(c1) + abs(c0)
    if abs(c2) > 1e-12 * scale:
        disc = c1 * c1 - 4.0 * c2 * c0
        if disc >= 0.0:
            sq = np.sqrt(disc)
            qv = -0.5 * (c1 + sq if c1 >= 0.0 else c1 - sq)
            r1 = qv / c2
            r2 = c0 / qv if qv != 0.0 else r1
            if r1 > r2:
                r1, r2 = r2, r1
            t1 = min(max(r1, 0.0), 1.0)
            t2 = min(max(r2, 0.0), 1.0)
    elif abs(c1) > 1e-12 * scale:
        t1 = min(max(-c0 / c1, 0.0), 1.0)
        t2 = t1
    lo = 2.0
    hi = -1.0
    for q in range(3):
        a = 0.0 if q == 0 else (t1 if q == 1 else t2)
        b = t1 if q == 0 else (t2 if q == 1 else 1.0)
        um = 0.5 * (a + b)
        if w0 + um * wq >= 0.0 and c2 * um * um + c1 * um + c0 >= 0.0:
            if a < lo:
                lo = a
            if b > hi:
                hi = b
    if lo > hi:
        # a single feasible point (tangency): test the cut points themselves
        for q in range(4):
            u = 0.0 if q == 0 else (t1 if q == 1 else (t2 if q == 2 else 1.0))
            if w0 + u * wq >= 0.0 and c2 * u * u + c1 * u + c0 >= -1e-9 * scale:
                return u, u
    return lo, hi


@njit(cache=True, fastmath=False, error_model="numpy")
def _line_min(p0x, p0y, p0z, qx, qy, qz, ax, ay, az, k):
    """(squared distance, u) of the closest in-cone point of P0 + u Q, u in [0, 1] (inf when none);
    k < 0: the segment is known to lie inside the cone."""
    if k < 0.0:
        lo, hi = 0.0, 1.0
    else:
        lo, hi = _line_in_cone(p0x, p0y, p0z, qx, qy, qz, ax, ay, az, k)
    if lo > hi:
        return _INF, 0.0
    qq = qx * qx + qy * qy + qz * qz
    u = lo
    if qq > 0.0:
        u = -(p0x * qx + p0y * qy + p0z * qz) / qq
        u = min(max(u, lo), hi)
    px = p0x + u * qx
    py = p0y + u * qy
    pz = p0z + u * qz
    return px * px + py * py + pz * pz, u


@njit(cache=True, fastmath=False, error_model="numpy")
def _patch_g(cell, v, ax, ay, az, k):
    """G(v) = min over u of the squared distance on the patch row v (cell: A, B, C, D NED vectors)."""
    p0x = cell[0] + v * cell[6]
    p0y = cell[1] + v * cell[7]
    p0z = cell[2] + v * cell[8]
    qx = cell[3] + v * cell[9]
    qy = cell[4] + v * cell[10]
    qz = cell[5] + v * cell[11]
    return _line_min(p0x, p0y, p0z, qx, qy, qz, ax, ay, az, k)


@njit(cache=True, fastmath=False, error_model="numpy")
def _golden_g(cell, ax, ay, az, k, a, b, bv, best, bu, best_v):
    """Golden-section minimum of G on [a, b] (bv: a feasible point inside, guiding the search while both
    probes are infeasible); returns the better of it and (best, bu, best_v)."""
    gr = 0.6180339887498949
    x1 = b - gr * (b - a)
    x2 = a + gr * (b - a)
    f1, u1 = _patch_g(cell, x1, ax, ay, az, k)
    f2, u2 = _patch_g(cell, x2, ax, ay, az, k)
    while b - a > 5e-5:
        if f1 == _INF and f2 == _INF:
            # both probes outside the feasible rows: keep the side of the best point (which is feasible)
            if bv >= x2:
                a = x1
                x1, f1, u1 = x2, f2, u2
                x2 = a + gr * (b - a)
                f2, u2 = _patch_g(cell, x2, ax, ay, az, k)
            else:
                b = x2
                x2, f2, u2 = x1, f1, u1
                x1 = b - gr * (b - a)
                f1, u1 = _patch_g(cell, x1, ax, ay, az, k)
        elif f1 <= f2:
            b = x2
            x2, f2, u2 = x1, f1, u1
            x1 = b - gr * (b - a)
            f1, u1 = _patch_g(cell, x1, ax, ay, az, k)
        else:
            a = x1
            x1, f1, u1 = x2, f2, u2
            x2 = a + gr * (b - a)
            f2, u2 = _patch_g(cell, x2, ax, ay, az, k)
    if f1 < best:
        best, bu, best_v = f1, u1, x1
    if f2 < best:
        best, bu, best_v = f2, u2, x2
    return best, bu, best_v


@njit(cache=True, fastmath=False, error_model="numpy")
def _cell_min(cell, ax, ay, az, k, n_samp):
    """Closest in-cone point of the bilinear patch P(u, v) = A + u B + v C + u v D, u, v in [0, 1]:
    (squared distance, u, v). For fixed v the patch row is a segment: its in-cone part is an interval
    (convex cone) and the closest point a clamped projection, so the 2-D problem reduces to the 1-D
    G(v) = min_u |P|^2, minimised by sampling n_samp + 1 rows (plus the closest in-cone points of the edges
    u = 0, 1 and the ends of the feasible rows) and golden-section searches around every local minimum.
    cell: float64[12 + n_samp + 1] (A, B, C, D, then scratch)."""
    best = _INF
    bu = 0.0
    bv = 0.0
    inv = 1.0 / n_samp
    g_prev = _INF
    for q in range(n_samp + 1):
        v = q * inv
        g, u = _patch_g(cell, v, ax, ay, az, k)
        cell[12 + q] = g
        if g < best:
            best, bu, bv = g, u, v
        if q > 0 and (g == _INF) != (g_prev == _INF):
            # the rows' in-cone part vanishes between the samples (a tangent row of the cone curve, where G
            # may drop steeply): bisect to that end of the feasible range and keep it as a candidate
            v_in = v if g < _INF else v - inv
            v_out = v - inv if g < _INF else v
            g_in = g if g < _INF else g_prev
            u_in = u
            if g == _INF:
                g_in, u_in = _patch_g(cell, v_in, ax, ay, az, k)
            for _ in range(18):
                vm = 0.5 * (v_in + v_out)
                gm, um = _patch_g(cell, vm, ax, ay, az, k)
                if gm < _INF:
                    v_in, g_in, u_in = vm, gm, um
                else:
                    v_out = vm
            if g_in < best:
                best, bu, bv = g_in, u_in, v_in
        g_prev = g
    # edges u = 0 and u = 1 as segments in v (catch in-cone slivers between samples)
    for e in range(2):
        fe = float(e)
        g, v = _line_min(
            cell[0] + fe * cell[3], cell[1] + fe * cell[4], cell[2] + fe * cell[5],
            cell[6] + fe * cell[9], cell[7] + fe * cell[10], cell[8] + fe * cell[11], ax, ay, az, k,
        )
        if g < best:
            g2, u2 = _patch_g(cell, v, ax, ay, az, k)
            if g2 < g:
                best, bu, bv = g2, u2, v
            else:
                best, bu, bv = g, fe, v
    if best == _INF:
        return _INF, 0.0, 0.0
    # golden-section search around every local minimum of the samples (G can have several basins) and
    # around the best point when it is not a sample (edge point / end of the feasible range)
    v_extra = bv if bv * n_samp != np.floor(bv * n_samp) else -1.0
    for q in range(n_samp + 1):
        g = cell[12 + q]
        if g == _INF:
            continue
        if q > 0 and cell[11 + q] < g:
            continue
        if q < n_samp and cell[13 + q] < g:
            continue
        v = q * inv
        best, bu, bv = _golden_g(cell, ax, ay, az, k, max(v - inv, 0.0), min(v + inv, 1.0), v, best, bu, bv)
    if v_extra >= 0.0:
        best, bu, bv = _golden_g(
            cell, ax, ay, az, k, max(v_extra - inv, 0.0), min(v_extra + inv, 1.0), v_extra, best, bu, bv
        )
    return best, bu, bv


@njit(cache=True, fastmath=False, error_model="numpy")
def _ra_patch(rec, lat, lon, ha, cv, i, j, cell):
    """Grid cell (i, j) (rows i, i + 1, columns j, j + 1) as the bilinear patch A + u B + v C + u v D in the
    antenna's NED frame (u east along the row, v north): cell[0:12] = A, B, C, D. The exact map of the
    bilinear surface differs from this patch by the curvature terms' variation inside a cell (< 1 mm)."""
    heights, lat0, lon0, dlat, dlon, _ = rec
    dphi0 = lat0 + i * dlat - lat
    dlam0 = lon0 + j * dlon - lon
    x00, y00, z00 = _ned(dphi0, dlam0, heights[i, j], ha, cv)
    x01, y01, z01 = _ned(dphi0, dlam0 + dlon, heights[i, j + 1], ha, cv)
    x10, y10, z10 = _ned(dphi0 + dlat, dlam0, heights[i + 1, j], ha, cv)
    x11, y11, z11 = _ned(dphi0 + dlat, dlam0 + dlon, heights[i + 1, j + 1], ha, cv)
    cell[0] = x00
    cell[1] = y00
    cell[2] = z00
    cell[3] = x01 - x00
    cell[4] = y01 - y00
    cell[5] = z01 - z00
    cell[6] = x10 - x00
    cell[7] = y10 - y00
    cell[8] = z10 - z00
    cell[9] = x11 - x10 - x01 + x00
    cell[10] = y11 - y10 - y01 + y00
    cell[11] = z11 - z10 - z01 + z00


@njit(cache=True, fastmath=False, error_model="numpy")
def _sphere_curved(cx, cy, cz_flat, rad, mh):
    """Bounding sphere of a box given in the flat-Earth frame (centre cx, cy, cz_flat, radius rad) moved down
    by the curvature drop (module docstring) at its centre, with a radius margin of 4e-4 of the horizontal
    distance for the second-order horizontal terms and the drop's variation across the box."""
    d2 = cx * cx + cy * cy
    return cz_flat + 0.5 * d2 / mh, rad + 4e-4 * np.sqrt(d2)


@njit(cache=True, fastmath=False, error_model="numpy", forceinline=True)
def _sphere_seen(cx, cy, cz, rad):
    """(dc, q) of the sphere (centre c NED from the apex, radius rad): its centre's distance dc and
    q = rad / dc, the sine of its angular radius; q = NaN when the sphere holds the apex (rad >= dc)."""
    dc = np.sqrt(cx * cx + cy * cy + cz * cz)
    if rad >= dc:
        return dc, np.nan
    return dc, rad / dc


@njit(cache=True, fastmath=False, error_model="numpy")
def _outside_cone(cx, cy, cz, rad, ax, ay, az, cosb, sinb):
    """True when the sphere (centre c NED, radius rad) lies entirely outside the cone around a."""
    dc, q = _sphere_seen(cx, cy, cz, rad)
    if q != q:
        return False
    # angle(c, a) > half beam + asin(q)  <=>  cos(angle) < cos(half beam + asin(q))
    return cx * ax + cy * ay + cz * az < dc * (cosb * np.sqrt(1.0 - q * q) - sinb * q)


@njit(cache=True, fastmath=False, error_model="numpy")
def _inside_cone(cx, cy, cz, rad, ax, ay, az, cosb, sinb):
    """True when the sphere (centre c NED, radius rad) lies entirely inside the cone around a."""
    dc, q = _sphere_seen(cx, cy, cz, rad)
    if not (q < sinb):  # the sphere holds the apex (q NaN) or is wider than the half beam
        return False
    # angle(c, a) < half beam - asin(q)
    return cx * ax + cy * ay + cz * az > dc * (cosb * np.sqrt(1.0 - q * q) + sinb * q)


@njit(cache=True, fastmath=False, error_model="numpy")
def _ra_bnb(rec, map_tables, cell_m, ant, beam, workspace, cell, out):
    """Closest terrain point in the beam cone by best-first branch and bound over DEM blocks; writes
    (valid, range, lat, lon, h) into out[0:5]. Records (numba tuples): map_tables as in _ra_batch; ant =
    (lat, lon rad, h m) the antenna; beam = (ax, ay, az) the unit beam axis (NED), cos and sin of the half
    beam, max range m; workspace = (blk_lb, blk_id) and cell: scratch arrays.

    Incumbent: the beam-axis ray hit. Block lower bound: distance to its box (horizontal rectangle x
    [-, block max height]); blocks whose bounding sphere misses the cone are pruned. Surviving cells (own
    box bound < incumbent, sphere touching the cone) are solved exactly by _cell_min."""
    out[0] = 0.0
    for q in range(1, 5):
        out[q] = np.nan
    heights, lat0, lon0, dlat, dlon, _ = rec
    bs, bmax, bmin, h_min, h_max = map_tables
    lat, lon, ha = ant
    ax, ay, az, cosb, sinb, max_range = beam
    blk_lb, blk_id = workspace
    n_lat, n_lon = heights.shape
    cv = _consts(lat)
    _, c, m, n, _ = cv
    k = cosb * cosb
    best2 = max_range * max_range
    best_i = np.nan
    best_j = np.nan
    t_ax = _ray_hit(rec, h_min, h_max, cell_m, lat, lon, ha, cv, ax, ay, az, 0.0, max_range)
    if t_ax == t_ax:
        best2 = t_ax * t_ax
        dphi, dlam, _ = _geo_of_ned(t_ax * ax, t_ax * ay, t_ax * az, ha, cv)
        best_i = (lat + dphi - lat0) / dlat
        best_j = (lon + dlam - lon0) / dlon
    reach = np.sqrt(best2) * 1.003 + 2.0  # margin for the second-order horizontal terms (module docstring)
    # metres per grid step (horizontal)
    mn = (m + h_min) * dlat
    me = (n + h_min) * c * dlon
    fi = (lat - lat0) / dlat
    fj = (lon - lon0) / dlon
    i_lo = max(int(np.floor(fi - reach / mn)) - 1, 0)
    i_hi = min(int(np.ceil(fi + reach / mn)) + 1, n_lat - 2)
    j_lo = max(int(np.floor(fj - reach / me)) - 1, 0)
    j_hi = min(int(np.ceil(fj + reach / me)) + 1, n_lon - 2)
    if i_lo > i_hi or j_lo > j_hi:
        return
    nbi, nbj = bmax.shape
    bi0 = i_lo // bs
    bi1 = min(i_hi // bs, nbi - 1)
    bj0 = j_lo // bs
    bj1 = min(j_hi // bs, nbj - 1)
    nb = 0
    for bi in range(bi0, bi1 + 1):
        ia = bi * bs
        ib = min(ia + bs, n_lat - 1)
        n_a = (ia - fi) * mn
        n_b = (ib - fi) * mn
        dn_ = n_a if n_a > 0.0 else (-n_b if n_b < 0.0 else 0.0)
        for bj in range(bj0, bj1 + 1):
            hx = bmax[bi, bj]
            if hx == -np.inf:
                continue
            ja = bj * bs
            jb = min(ja + bs, n_lon - 1)
            e_a = (ja - fj) * me
            e_b = (jb - fj) * me
            de_ = e_a if e_a > 0.0 else (-e_b if e_b < 0.0 else 0.0)
            dh = max(np.sqrt(dn_ * dn_ + de_ * de_) * 0.998 - 2.0, 0.0)
            dv = max(ha - hx, 0.0)
            lb2 = dh * dh + dv * dv
            if lb2 > best2:
                continue
            hmn = bmin[bi, bj]
            cx = 0.5 * (n_a + n_b)
            cy = 0.5 * (e_a + e_b)
            hz = 0.5 * (hx - hmn)
            rad = np.sqrt(0.25 * (n_b - n_a) ** 2 + 0.25 * (e_b - e_a) ** 2 + hz * hz) * 1.002 + 5.0
            cz, rad = _sphere_curved(cx, cy, ha - 0.5 * (hx + hmn), rad, m + ha)
            if _outside_cone(cx, cy, cz, rad, ax, ay, az, cosb, sinb):
                continue
            _insert_sorted(blk_lb, blk_id, nb, lb2, bi * nbj + bj)  # the list sorted by lower bound
            nb += 1
    # cells of the surviving blocks, blocks best first: box bound, cone test, then the projection bound
    # |P| >= P.g >= min over the corners of P_corner.g (g: unit vector to the cell centre; P.g is bilinear
    # in (u, v), so its minimum is at a corner), which is within (half diagonal)^2 / (2 range) of exact
    for q_blk in range(nb):
        if blk_lb[q_blk] > best2:
            break
        bi = blk_id[q_blk] // nbj
        bj = blk_id[q_blk] % nbj
        ia = bi * bs
        ib = min(ia + bs, n_lat - 1)
        ja = bj * bs
        jb = min(ja + bs, n_lon - 1)
        for i in range(ia, ib):
            n_a = (i - fi) * mn
            n_b = n_a + mn
            dn_ = n_a if n_a > 0.0 else (-n_b if n_b < 0.0 else 0.0)
            for j in range(ja, jb):
                h00 = heights[i, j]
                h01 = heights[i, j + 1]
                h10 = heights[i + 1, j]
                h11 = heights[i + 1, j + 1]
                hx = max(max(h00, h01), max(h10, h11))
                if hx != hx:
                    continue  # a void corner: no terrain in this cell
                e_a = (j - fj) * me
                e_b = e_a + me
                de_ = e_a if e_a > 0.0 else (-e_b if e_b < 0.0 else 0.0)
                dh = max(np.sqrt(dn_ * dn_ + de_ * de_) * 0.998 - 2.0, 0.0)
                dv = max(ha - hx, 0.0)
                if dh * dh + dv * dv > best2:
                    continue
                hmn = min(min(h00, h01), min(h10, h11))
                hz = 0.5 * (hx - hmn)
                rad = np.sqrt(0.25 * mn * mn + 0.25 * me * me + hz * hz) * 1.002 + 2.0
                cx = 0.5 * (n_a + n_b)
                cy = 0.5 * (e_a + e_b)
                cz, rad = _sphere_curved(cx, cy, ha - 0.5 * (hx + hmn), rad, m + ha)
                if _outside_cone(cx, cy, cz, rad, ax, ay, az, cosb, sinb):
                    continue
                inside = _inside_cone(cx, cy, cz, rad, ax, ay, az, cosb, sinb)
                _ra_patch(rec, lat, lon, ha, cv, i, j, cell)
                gx = cell[0] + 0.5 * cell[3] + 0.5 * cell[6] + 0.25 * cell[9]
                gy = cell[1] + 0.5 * cell[4] + 0.5 * cell[7] + 0.25 * cell[10]
                gz = cell[2] + 0.5 * cell[5] + 0.5 * cell[8] + 0.25 * cell[11]
                gn = np.sqrt(gx * gx + gy * gy + gz * gz)
                if gn > 0.0:
                    p00 = cell[0] * gx + cell[1] * gy + cell[2] * gz
                    pb = cell[3] * gx + cell[4] * gy + cell[5] * gz
                    pc = cell[6] * gx + cell[7] * gy + cell[8] * gz
                    pd = cell[9] * gx + cell[10] * gy + cell[11] * gz
                    lbp = min(min(p00, p00 + pb), min(p00 + pc, p00 + pb + pc + pd)) / gn
                    if lbp > 0.0 and lbp * lbp > best2:
                        continue
                d2, u, v = _cell_min(cell, ax, ay, az, -1.0 if inside else k, N_SAMP)
                if d2 < best2:
                    best2 = d2
                    best_i = i + v
                    best_j = j + u
    if best_i != best_i:
        return
    la = lat0 + best_i * dlat
    lo = lon0 + best_j * dlon
    out[0] = 1.0
    out[1] = np.sqrt(best2)
    out[2] = la
    out[3] = lo
    out[4] = bilinear(heights, lat0, lon0, dlat, dlon, la, lo)


@njit(cache=True, fastmath=False, error_model="numpy")
def _ra_batch(rec, cell_m, queries, half_beam, max_range, map_tables, workspace, outs):
    """The radar-altimeter query of every antenna state on the map record rec (read bilinearly); records
    (numba tuples): queries = (lat, lon, h, C_bn); map_tables = (bs, bmax, bmin, h_min, h_max) of
    _ra_tables (h_min/h_max: the DEM's finite height range); workspace = (blk_lb (bmax.size,), blk_id
    (bmax.size,) int64): scratch space (overwritten before it is read); outs = (valid, rng, lat_out,
    lon_out, h_out)."""
    lat, lon, h, C_bn = queries
    valid, rng, lat_out, lon_out, h_out = outs
    cosb = np.cos(half_beam)
    sinb = np.sin(half_beam)
    out = np.empty(5)
    cell = np.empty(12 + 17)
    for k in range(lat.shape[0]):
        ax, ay, az = C_bn[k, 0, 2], C_bn[k, 1, 2], C_bn[k, 2, 2]
        nrm = np.sqrt(ax * ax + ay * ay + az * az)
        if not (nrm > 0.0) or h[k] != h[k] or lat[k] != lat[k] or lon[k] != lon[k]:
            valid[k] = False
            rng[k] = lat_out[k] = lon_out[k] = h_out[k] = np.nan
            continue
        _ra_bnb(rec, map_tables, cell_m, (lat[k], lon[k], h[k]),
                (ax / nrm, ay / nrm, az / nrm, cosb, sinb, max_range), workspace, cell, out)
        valid[k] = out[0] > 0.5
        rng[k] = out[1]
        lat_out[k] = out[2]
        lon_out[k] = out[3]
        h_out[k] = out[4]


def radar_altimeter_return(
    dem, lat_rad, lon_rad, h_m, C_bn, half_beamwidth_rad: float, max_range_m: float = 8000.0
) -> TerrainReturn:
    """Closest terrain point inside the cone of half-angle half_beamwidth_rad around the body down axis
    (C_bn[:, :, 2] in NED), for antennas at (lat, lon rad, h m MSL); C_bn is (n, 3, 3) or (3, 3)."""
    if not (0.0 < half_beamwidth_rad < np.pi / 2):
        raise ValueError(f"half_beamwidth_rad must be in (0, pi/2), got {half_beamwidth_rad}")
    _check_positive("max_range_m", max_range_m)
    lat, lon, h = _positions(lat_rad, lon_rad, h_m)
    C = _stack("C_bn", C_bn, lat.shape[0], (3, 3))
    valid, rng, la, lo, hh = _outputs(lat.shape[0])
    *map_tables, cell_m = _ra_tables(dem)
    _ra_batch(dem.record(), cell_m, (lat, lon, h, C), float(half_beamwidth_rad), float(max_range_m),
              tuple(map_tables), _ra_workspace(map_tables[1].size), (valid, rng, la, lo, hh))
    return TerrainReturn(valid, rng, la, lo, hh)
