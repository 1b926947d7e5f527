"""Terrain queries (numba, batched over antenna positions): ray cast, radar-altimeter and IRA returns.

Geometry. Every query works in the local NED frame at the antenna. A terrain point at geodetic offset
(dphi, dlam) and height h_p maps to NED through the second-order expansion of the WGS84 position about the
antenna (meridian radius M, prime-vertical radius N, antenna height h_a, latitude phi):

    n = (M + h_p) dphi + 1/2 (N + h_a) sin(phi) cos(phi) dlam^2 + 1/2 dM/dphi dphi^2
    e = (N + h_p) cos(phi) dlam - (M + h_a) sin(phi) dphi dlam
    d = (h_a - h_p) + 1/2 (M + h_a) dphi^2 + 1/2 (N + h_a) cos(phi)^2 dlam^2       (curvature drop)

The first-order terms are seed 000 eq 2; the second-order terms carry the Earth's curvature (about 2 m of
drop and 1-3 m of horizontal bending at 5 km). The neglected third-order terms are below 1 cm within 10 km.

Radar altimeter (seed 001 ch. 4; seed 000 section 2.1): the terrain point closest to the antenna inside
the cone of half-angle `half_beamwidth_rad` around the body down axis C_bn[:, 2].

IRA (seed 000 sections 2.2, 3.2-3.3; seed 002 Fig. 1): the terrain point closest to the antenna on the
zero-Doppler line, i.e. on the plane through the antenna perpendicular to the velocity vector, whose look
angle theta = asin(y_b / R) satisfies |theta| <= half_window_rad and that lies below the antenna (z_b > 0).
(y_b, z_b): body-FRD components of the antenna->point vector, R its length; theta is the interferometric
angle from the plane perpendicular to the baseline (body y axis), positive toward the right wing (seed 000
eqs 18-19, 26-30).

Altimeter search (_ra_bnb): best-first branch and bound. Incumbent: the beam-axis ray hit. Lower bound of
a block / cell: the distance to its box (horizontal rectangle x [-, max height]); blocks and cells whose
bounding sphere misses the cone are pruned. Each surviving cell, in order of bound, is solved exactly
(_cell_min): in the antenna's NED frame the cell is a bilinear patch A + u B + v C + u v D; each row v is a
segment whose in-cone part is one interval (the cone is convex), so min over u is a clamped projection and
the cell minimum is a 1-D minimisation over v (samples, edge points, golden section).
IRA search: coarse intervals (a whole number of posts, about COARSE_STEP_M, long along the zero-Doppler
curve) are bounded below by range >= sqrt(horizontal^2 + (h_a - h_box)^2), h_box the highest terrain of the
2 x 2-cell blocks the curve piece can lie in; in order of that bound, while it can still beat the best,
their end samples are evaluated and they enter a branch and bound with Lipschitz / curvature bounds from
per-cell (or per-block) slopes, per-cell twists and the slope jumps at grid lines - for a piece between
two adjacent cells at its one crossing, weighted by where that crossing can lie (see _ira_one,
_ira_interval_lb); each curve point is a Newton solve in the bilinear cell (_zd_point). Per-DEM tables
(block maxima and slopes, height range) are cached on the Dem and the scratch space is reused between
calls, so a call costs a few microseconds on top of its queries. Ranges agree with a dense brute-force
search to a few mm; each query is independent of the others in its batch unless ira_return's
warm_start chains them (each search then starts from the previous return).
The IRA search's per-sample helpers (_zd_point, _ira_eval, _ira_interval_lb and what they call) carry numba's
inline="always": a query makes ~25 evaluations and ~25 bound calls, and inlining them into _ira_one cut a
query by a quarter (same bits), for ~20 s more compilation on first use (cached).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from terrain import geodesy, kernels
from terrain.geodesy import WGS84_A_M, WGS84_E2
from terrain.kernels import bilinear

_INF = np.inf
BLOCK_POSTS = 8  # block size of the height bounds used to prune the searches
IRA_BLOCK_POSTS = 8  # block size of the IRA's slope bounds for large curve pieces
IRA_HEIGHT_BLOCK_CELLS = 2  # cells per block side of the IRA's height bound (2: fastest of 1-4)
COARSE_STEP_M = 45.0  # about the IRA's coarse sample spacing along the zero-Doppler curve (m)
N_SAMP = 6  # rows sampled per cell by the altimeter's exact cell solver (_cell_min), at most 16


@dataclass
class TerrainReturn:
    """Closest-point query results, (n,) arrays; invalid entries hold NaN. Range in m, angles in rad,
    h_m in metres above MSL (the DEM's datum)."""

    valid: np.ndarray
    range_m: np.ndarray
    lat_rad: np.ndarray
    lon_rad: np.ndarray
    h_m: np.ndarray


# ----------------------------------------------------------------------------------------- local frame
@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _consts(lat):
    s = np.sin(lat)
    c = np.cos(lat)
    w = 1.0 - WGS84_E2 * s * s
    m = WGS84_A_M * (1.0 - WGS84_E2) / (w * np.sqrt(w))
    n = WGS84_A_M / np.sqrt(w)
    dm = 3.0 * m * WGS84_E2 * s * c / w
    return s, c, m, n, dm


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _ned(dphi, dlam, hp, ha, s, c, m, n, dm):
    """NED (m) of the point (lat_a + dphi, lon_a + dlam, hp) from the antenna at height ha."""
    mh = m + ha
    nh = n + ha
    x = (m + hp) * dphi + 0.5 * nh * s * c * dlam * dlam + 0.5 * dm * dphi * dphi
    y = (n + hp) * c * dlam - mh * s * dphi * dlam
    z = (ha - hp) + 0.5 * mh * dphi * dphi + 0.5 * nh * c * c * dlam * dlam
    return x, y, z


@njit(cache=True, fastmath=False, error_model="numpy")
def _geo_of_ned(x, y, z, ha, s, c, m, n, dm):
    """Inverse of _ned: (dphi, dlam, h_p) of the NED point (x, y, z) by fixed-point iteration."""
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
    lo = np.inf
    hi = -np.inf
    for v in heights.ravel():
        if v == v:
            if v < lo:
                lo = v
            if v > hi:
                hi = v
    return lo, hi


# ----------------------------------------------------------------------------------------- ray cast
@njit(cache=True, fastmath=False, error_model="numpy")
def _g_ray(heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, dx, dy, dz, t):
    """Height of the ray point at parameter t above the terrain (m); NaN off-grid."""
    dphi, dlam, hp = _geo_of_ned(t * dx, t * dy, t * dz, ha, s, c, m, n, dm)
    ht = bilinear(heights, lat0, lon0, dlat, dlon, lat + dphi, lon + dlam)
    return hp - ht


@njit(cache=True, fastmath=False, error_model="numpy")
def _refine_root(heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, dx, dy, dz, ta, ga, tb, gb):
    """Illinois regula falsi on g(t) with g(ta) >= 0 > g(tb); returns t of the crossing."""
    side = 0
    for _ in range(60):
        tm = (ta * gb - tb * ga) / (gb - ga)
        if not (tm > ta and tm < tb):
            tm = 0.5 * (ta + tb)
        gm = _g_ray(heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, dx, dy, dz, tm)
        if gm != gm:
            return 0.5 * (ta + tb)
        if gm >= 0.0:
            ta, ga = tm, gm
            if side == 1:
                gb *= 0.5
            side = 1
        else:
            tb, gb = tm, gm
            if side == -1:
                ga *= 0.5
            side = -1
        if tb - ta < 1e-5 or abs(gm) < 1e-6:
            return tm
    return 0.5 * (ta + tb)


@njit(cache=True, fastmath=False, error_model="numpy")
def _ray_hit(
    heights,
    lat0,
    lon0,
    dlat,
    dlon,
    h_min,
    h_max,
    cell_m,
    lat,
    lon,
    ha,
    s,
    c,
    m,
    n,
    dm,
    dx,
    dy,
    dz,
    t_from,
    t_to,
):
    """First crossing of the ray (unit NED direction dx, dy, dz) into the terrain for t in [t_from, t_to].

    Marches half a post horizontally per step, starting no earlier than the depth of the highest post.
    Returns t (NaN when there is no hit)."""
    t0 = t_from
    if dz > 1e-12:
        t_top = (ha - h_max) / dz - 1.0
        if t_top > t0:
            t0 = t_top
    if t0 > t_to:
        return np.nan
    horiz = np.sqrt(dx * dx + dy * dy)
    step = 0.5 * cell_m / max(horiz, 1e-9)
    if dz > 1e-12:
        slab = (h_max - h_min + 2.0) / dz
        if step > 0.25 * slab:
            step = max(0.25 * slab, 0.01)
    t_a = t0
    g_a = _g_ray(heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, dx, dy, dz, t_a)
    if g_a == g_a and g_a < 0.0:
        if t_a <= 1e-9:
            return 0.0  # the ray starts under the terrain
        # started below the surface (should not happen from the h_max depth): back off to the origin
        t_a = t_from
        g_a = _g_ray(heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, dx, dy, dz, t_a)
        if g_a == g_a and g_a < 0.0:
            return t_a
    while t_a < t_to:
        t_b = min(t_a + step, t_to)
        g_b = _g_ray(heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, dx, dy, dz, t_b)
        if g_a == g_a and g_b == g_b and g_b < 0.0:
            return _refine_root(
                heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, dx, dy, dz, t_a, g_a, t_b, g_b
            )
        if g_b == g_b and dz > 0.0:
            # ray point already below the lowest post and still descending: nothing further to hit
            dphi, dlam, hp = _geo_of_ned(t_b * dx, t_b * dy, t_b * dz, ha, s, c, m, n, dm)
            if hp < h_min - 1.0:
                return np.nan
        t_a, g_a = t_b, g_b
    return np.nan


@njit(cache=True, fastmath=False, error_model="numpy")
def _ray_cast_batch(
    heights,
    lat0,
    lon0,
    dlat,
    dlon,
    cell_m,
    lat,
    lon,
    h,
    dirs,
    max_range,
    h_min,
    h_max,
    valid,
    rng,
    lat_out,
    lon_out,
    h_out,
):
    for k in range(lat.shape[0]):
        valid[k] = False
        rng[k] = np.nan
        lat_out[k] = np.nan
        lon_out[k] = np.nan
        h_out[k] = np.nan
        dx, dy, dz = dirs[k, 0], dirs[k, 1], dirs[k, 2]
        norm = np.sqrt(dx * dx + dy * dy + dz * dz)
        if not (norm > 0.0) or not (h[k] == h[k]):
            continue
        dx /= norm
        dy /= norm
        dz /= norm
        s, c, m, n, dm = _consts(lat[k])
        t = _ray_hit(
            heights,
            lat0,
            lon0,
            dlat,
            dlon,
            h_min,
            h_max,
            cell_m,
            lat[k],
            lon[k],
            h[k],
            s,
            c,
            m,
            n,
            dm,
            dx,
            dy,
            dz,
            0.0,
            max_range,
        )
        if t == t:
            dphi, dlam, hp = _geo_of_ned(t * dx, t * dy, t * dz, h[k], s, c, m, n, dm)
            valid[k] = True
            rng[k] = t
            lat_out[k] = lat[k] + dphi
            lon_out[k] = lon[k] + dlam
            h_out[k] = bilinear(heights, lat0, lon0, dlat, dlon, lat[k] + dphi, lon[k] + dlam)


# ----------------------------------------------------------------------------------------- radar altimeter
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
def _ra_patch(heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, i, j, cell):
    """Grid cell (i, j) (rows i, i + 1, columns j, j + 1) as the bilinear patch A + u B + v C + u v D in the
    antenna's NED frame (u east along the row, v north): cell[0:12] = A, B, C, D. The exact map of the
    bilinear surface differs from this patch by the curvature terms' variation inside a cell (< 1 mm)."""
    dphi0 = lat0 + i * dlat - lat
    dlam0 = lon0 + j * dlon - lon
    x00, y00, z00 = _ned(dphi0, dlam0, heights[i, j], ha, s, c, m, n, dm)
    x01, y01, z01 = _ned(dphi0, dlam0 + dlon, heights[i, j + 1], ha, s, c, m, n, dm)
    x10, y10, z10 = _ned(dphi0 + dlat, dlam0, heights[i + 1, j], ha, s, c, m, n, dm)
    x11, y11, z11 = _ned(dphi0 + dlat, dlam0 + dlon, heights[i + 1, j + 1], ha, s, c, m, n, dm)
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


@njit(cache=True, fastmath=False, error_model="numpy")
def _outside_cone(cx, cy, cz, rad, ax, ay, az, cosb, sinb):
    """True when the sphere (centre c NED, radius rad) lies entirely outside the cone around a."""
    dc = np.sqrt(cx * cx + cy * cy + cz * cz)
    if rad >= dc:
        return False
    q = rad / dc
    # angle(c, a) > half beam + asin(q)  <=>  cos(angle) < cos(half beam + asin(q))
    return cx * ax + cy * ay + cz * az < dc * (cosb * np.sqrt(1.0 - q * q) - sinb * q)


@njit(cache=True, fastmath=False, error_model="numpy")
def _inside_cone(cx, cy, cz, rad, ax, ay, az, cosb, sinb):
    """True when the sphere (centre c NED, radius rad) lies entirely inside the cone around a."""
    dc = np.sqrt(cx * cx + cy * cy + cz * cz)
    if rad >= dc:
        return False
    q = rad / dc
    if q >= sinb:
        return False
    # angle(c, a) < half beam - asin(q)
    return cx * ax + cy * ay + cz * az > dc * (cosb * np.sqrt(1.0 - q * q) + sinb * q)


@njit(cache=True, fastmath=False, error_model="numpy")
def _ra_bnb(
    heights, lat0, lon0, dlat, dlon, h_min, h_max, cell_m, lat, lon, ha, ax, ay, az, cosb, sinb, max_range,
    bs, bmax, bmin, blk_lb, blk_id, cell, out,
):
    """Closest terrain point in the beam cone by best-first branch and bound over DEM blocks; writes
    (valid, range, lat, lon, h) into out[0:5]. blk_lb, blk_id, cell: scratch arrays.

    Incumbent: the beam-axis ray hit. Block lower bound: distance to its box (horizontal rectangle x
    [-, block max height]); blocks whose bounding sphere misses the cone are pruned. Surviving cells (own
    box bound < incumbent, sphere touching the cone) are solved exactly by _cell_min."""
    out[0] = 0.0
    for q in range(1, 5):
        out[q] = np.nan
    n_lat, n_lon = heights.shape
    s, c, m, n, dm = _consts(lat)
    k = cosb * cosb
    best2 = max_range * max_range
    best_i = np.nan
    best_j = np.nan
    t_ax = _ray_hit(
        heights, lat0, lon0, dlat, dlon, h_min, h_max, cell_m, lat, lon, ha, s, c, m, n, dm, ax, ay, az, 0.0,
        max_range,
    )
    if t_ax == t_ax:
        best2 = t_ax * t_ax
        dphi, dlam, _ = _geo_of_ned(t_ax * ax, t_ax * ay, t_ax * az, ha, s, c, m, n, dm)
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
            # insertion into the list sorted by lower bound
            q = nb
            while q > 0 and blk_lb[q - 1] > lb2:
                blk_lb[q] = blk_lb[q - 1]
                blk_id[q] = blk_id[q - 1]
                q -= 1
            blk_lb[q] = lb2
            blk_id[q] = bi * nbj + bj
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
                _ra_patch(heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, i, j, cell)
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
def _ra_batch(
    heights,
    lat0,
    lon0,
    dlat,
    dlon,
    cell_m,
    lat,
    lon,
    h,
    C_bn,
    half_beam,
    max_range,
    bs,
    bmax,
    bmin,
    h_min,
    h_max,
    blk_lb,
    blk_id,
    valid,
    rng,
    lat_out,
    lon_out,
    h_out,
):
    """The radar-altimeter query of every antenna state; h_min/h_max: the DEM's finite height range,
    blk_lb (bmax.size,) and blk_id (bmax.size,) int64: scratch space (overwritten before it is read)."""
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
        _ra_bnb(
            heights, lat0, lon0, dlat, dlon, h_min, h_max, cell_m, lat[k], lon[k], h[k], ax / nrm, ay / nrm,
            az / nrm, cosb, sinb, max_range, bs, bmax, bmin, blk_lb, blk_id, cell, out,
        )
        valid[k] = out[0] > 0.5
        rng[k] = out[1]
        lat_out[k] = out[2]
        lon_out[k] = out[3]
        h_out[k] = out[4]


# ----------------------------------------------------------------------------------------- IRA
@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _zd_point(
    heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, vx, vy, vz, uhx, uhy, vh, qc, sv, t_guess,
    tol,
):
    """Terrain point on the zero-Doppler plane at across-track nominal coordinate sv (m).

    Nominal horizontal coordinates (north, east) = sv * w_h + t * u_h, w_h = right-perpendicular of the
    horizontal velocity direction u_h; t solves P(t) = v_hat . NED(point) = 0 by Newton steps with the
    slope dP/dt = |v_h| - v_d dh/dt from the bilinear cell's gradient, kept inside the bracket of the root
    once one is known (bisection when a step leaves it). qc: _ira_one's per-query constants.
    Returns (t, x, y, z, dphi, dlam, hp) or t = NaN."""
    n_lat, n_lon = heights.shape
    wx = -uhy
    wy = uhx
    imh = qc[8]
    inhc = qc[9]
    # grid coordinates are affine in t: fi = fi0 + t dfi, fj = fj0 + t dfj
    fi0 = qc[0] + sv * qc[1]
    fj0 = qc[3] + sv * qc[4]
    dfi = qc[2]
    dfj = qc[5]
    t_lo = -np.inf
    t_hi = np.inf
    tt = t_guess
    x = y = z = dphi = dlam = hp = np.nan
    for _it in range(40):
        north = sv * wx + tt * uhx
        east = sv * wy + tt * uhy
        dphi = north * imh
        dlam = east * inhc
        # bilinear height and its t-derivative (terrain.kernels.bilinear's cell choice and formula)
        fi = fi0 + tt * dfi
        fj = fj0 + tt * dfj
        if not (fi >= -1e-9 and fj >= -1e-9 and fi <= n_lat - 1 + 1e-9 and fj <= n_lon - 1 + 1e-9):
            return np.nan, x, y, z, dphi, dlam, np.nan
        i = min(max(int(fi), 0), n_lat - 2)
        j = min(max(int(fj), 0), n_lon - 2)
        u = fi - i
        v = fj - j
        h00 = heights[i, j]
        h01 = heights[i, j + 1]
        h10 = heights[i + 1, j]
        h11 = heights[i + 1, j + 1]
        ea = h01 - h00
        eb = h11 - h10
        ha_ = h00 + v * ea
        hb_ = h10 + v * eb
        hp = ha_ + u * (hb_ - ha_)
        if hp != hp:
            hp = bilinear(heights, lat0, lon0, dlat, dlon, lat + dphi, lon + dlam)
            if hp != hp:
                return np.nan, x, y, z, dphi, dlam, hp
        x, y, z = _ned(dphi, dlam, hp, ha, s, c, m, n, dm)
        p = vx * x + vy * y + vz * z
        if abs(p) < tol:
            return tt, x, y, z, dphi, dlam, hp
        if p > 0.0:
            t_hi = min(t_hi, tt)
        else:
            t_lo = max(t_lo, tt)
        dh_dt = (hb_ - ha_) * dfi + (ea + u * (eb - ea)) * dfj
        slope = vh - vz * dh_dt
        if not (slope > 0.1 * vh):
            slope = vh
        t_new = tt - p / slope
        lim = 200.0
        if abs(t_new - tt) > lim:
            t_new = tt + lim * np.sign(t_new - tt)
        if not (t_new > t_lo and t_new < t_hi):
            if t_lo > -np.inf and t_hi < np.inf:
                t_new = 0.5 * (t_lo + t_hi)
                if t_hi - t_lo < 1e-9:
                    return tt, x, y, z, dphi, dlam, hp
        tt = t_new
    return np.nan, x, y, z, dphi, dlam, hp


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _ira_eval(
    heights,
    lat0,
    lon0,
    dlat,
    dlon,
    lat,
    lon,
    ha,
    s,
    c,
    m,
    n,
    dm,
    vx,
    vy,
    vz,
    uhx,
    uhy,
    vh,
    C,
    qc,
    sin_w,
    max_range,
    sv,
    t_guess,
    tol,
):
    """(f, t, r, z) at across-track coordinate sv: f = range if the point is inside the look-angle window
    (else inf), t its along-track coordinate, r the raw range (inf: no point), z its NED down (m)."""
    t, x, y, z, dphi, dlam, hp = _zd_point(
        heights,
        lat0,
        lon0,
        dlat,
        dlon,
        lat,
        lon,
        ha,
        s,
        c,
        m,
        n,
        dm,
        vx,
        vy,
        vz,
        uhx,
        uhy,
        vh,
        qc,
        sv,
        t_guess,
        tol,
    )
    if t != t:
        return _INF, t_guess, _INF, np.nan
    r = np.sqrt(x * x + y * y + z * z)
    # body coordinates: b = C_bn^T x; look angle theta = asin(y_b / R) (seed 000 eqs 18-19), |theta| <= window
    by = C[0, 1] * x + C[1, 1] * y + C[2, 1] * z
    bz = C[0, 2] * x + C[1, 2] * y + C[2, 2] * z
    if r > max_range or bz <= 0.0 or abs(by) > sin_w * r:
        return _INF, t, r, z
    return r, t, r, z


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _ira_lipschitz(a, b, ta, tb, za, zb, ra, rb, tp, zp, g_pad):
    """Upper bound of |dr/ds| on the zero-Doppler curve for s in [a, b] (r = range, s = across-track m).

    r' = (P . P') / r with P_h . P_h' = s + t t' and z z' (P = antenna->point NED): |r'| <= (max|s| +
    max|t| tp + max|z| zp) / min r, tp and zp bounding |t'| and |z'|. Falls back to |P'| when the range
    can come near zero."""
    w = b - a
    if ta != ta:
        ta = tb
    if tb != tb:
        tb = ta
    t_max = max(abs(ta), abs(tb)) + tp * w
    z_max = max(abs(za), abs(zb)) + zp * w
    s_max = max(abs(a), abs(b))
    l_crude = np.sqrt(1.0 + tp * tp + zp * zp)  # |P'|: P_h' = w + t' u_h (w, u_h orthonormal), z'
    r_min = min(ra, rb) - l_crude * w
    if not (r_min > 0.05 * min(ra, rb)):
        return l_crude * g_pad
    return min((s_max + t_max * tp + z_max * zp) / r_min, l_crude) * g_pad


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _ira_push(stack, row, a, fa, ta, ra, za, b, fb, tb, rb, zb, lb, split):
    stack[row, 0] = a
    stack[row, 1] = fa
    stack[row, 2] = ta
    stack[row, 3] = ra
    stack[row, 4] = za
    stack[row, 5] = b
    stack[row, 6] = fb
    stack[row, 7] = tb
    stack[row, 8] = rb
    stack[row, 9] = zb
    stack[row, 10] = lb
    stack[row, 11] = split


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _ira_box_max(tab, block, n_lat, n_lon, fi_lo, fi_hi, fj_lo, fj_hi):
    """Largest value of tab (one value per block x block cells, layout of terrain.kernels.block_bounds) over
    the cells meeting the box [fi_lo, fi_hi] x [fj_lo, fj_hi] in post coordinates; -inf off the grid."""
    c_ia = max(int(np.floor(fi_lo)), 0)
    c_ib = min(int(np.ceil(fi_hi)) - 1, n_lat - 2)
    c_ja = max(int(np.floor(fj_lo)), 0)
    c_jb = min(int(np.ceil(fj_hi)) - 1, n_lon - 2)
    hi = -_INF
    if c_ia > c_ib or c_ja > c_jb:
        return hi
    for bi in range(c_ia // block, c_ib // block + 1):
        for bj in range(c_ja // block, c_jb // block + 1):
            if tab[bi, bj] > hi:
                hi = tab[bi, bj]
    return hi


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _ira_cell_slope_twist(heights, ci, cj, qc):
    """(bound of the squared gradient (m/m)^2, |twist| h00 - h01 - h10 + h11 (m)) of the bilinear cell
    (ci, cj); qc6, qc7: posts per metre north / east. NaN next to a void."""
    h00 = heights[ci, cj]
    h01 = heights[ci, cj + 1]
    h10 = heights[ci + 1, cj]
    h11 = heights[ci + 1, cj + 1]
    gu = max(abs(h10 - h00), abs(h11 - h01)) * qc[6]
    gv = max(abs(h01 - h00), abs(h11 - h10)) * qc[7]
    return gu * gu + gv * gv, abs(h00 - h01 - h10 + h11)


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _ira_interval_lb(heights, bslope, qc, best_tol, a, fa, ta, ra, za, b, fb, tb, rb, zb):
    """(lower bound of the in-window range f over the curve piece s in [a, b], split point) from the end
    samples (f, t, r, z at a and b; see _ira_eval); qc: _ira_one's per-query constants. Intervals with
    w < 1e-4 m (or < 5 cm next to a point without terrain) get +inf: they are not searched further. A bound
    already >= best_tol from the global slope (cheap test) is returned as is.

    One-cell pieces (both ends in one bilinear cell: the surface is smooth between them) use the cell's own
    slope and twist: f >= the chord minus K (s - a)(b - s) / 2 with K >= |r''|, minimised over [a, b].
    Other pieces get the Lipschitz bound (f_a + f_b - L w) / 2 with L from the slopes of the cells (or
    blocks) they can cross; when that region is small (<= 16 cells) also the curvature bound with the
    cells' largest slope and twist, lowered by w / 4 times the largest upward jumps of r' at the grid lines
    inside it (f is piecewise smooth: f - bound is concave with zero ends). Pieces whose ends lie in two
    adjacent cells use those two cells only, and when the curve's grid coordinate across their shared line
    is monotone (so it crosses it once, at a distance from a known from that coordinate's rate) the jump's
    weight is Green's function there, G(s_k, s_k) = (s_k - a)(b - s_k) / w, instead of w / 4: a split next
    to a grid line leaves a sliver that costs almost nothing. They split where the straight chord first
    crosses a grid line, so that the pieces become smooth."""
    n_lat = heights.shape[0]
    n_lon = heights.shape[1]
    w = b - a
    split = 0.5 * (a + b)
    if w < 1e-4:
        return _INF, split
    gam = qc[13]
    g_glob = qc[14]
    if ra == _INF or rb == _INF:
        # an end without terrain/point: unknown geometry there, bisect until the interval is tiny
        if w < 0.05:
            return _INF, split
        return min(fa, fb) - (1.0 + g_glob) * 2.0 * w, split
    if fa < _INF and fb < _INF:
        # cheap test first: |r'| <= |P'| <= qc[15] (global slope) everywhere
        lb0 = 0.5 * (fa + fb - qc[15] * w)
        if lb0 >= best_tol:
            return lb0, split
    uhx = qc[11]
    uhy = qc[12]
    # grid coordinates of the two ends (exact: _zd_point's north/east -> lat/lon map)
    fia = qc[0] + a * qc[1] + ta * qc[2]
    fja = qc[3] + a * qc[4] + ta * qc[5]
    fib = qc[0] + b * qc[1] + tb * qc[2]
    fjb = qc[3] + b * qc[4] + tb * qc[5]
    cia = min(max(int(np.floor(fia)), 0), n_lat - 2)
    cja = min(max(int(np.floor(fja)), 0), n_lon - 2)
    cib = min(max(int(np.floor(fib)), 0), n_lat - 2)
    cjb = min(max(int(np.floor(fjb)), 0), n_lon - 2)
    one_cell = cia == cib and cja == cjb
    # one grid line between the ends (adjacent cells): two smooth pieces meeting at one kink
    one_line = (cia == cib and abs(cja - cjb) == 1) or (cja == cjb and abs(cia - cib) == 1)
    h_ne = 0.0
    kinks = False  # multi-cell piece with cell-level bounds: curvature plus kink bound available
    line_kink = False  # two-cell piece: one kink, line_d posts from end a across the shared line
    line_d = line_rate = line_rate_t = 0.0  # posts; posts per metre of s and of t across that line
    jump_n = 0.0  # sums over the grid lines the piece can cross of the largest jump in dh/dn, dh/de
    jump_e = 0.0
    if one_cell:
        # smooth piece inside one bilinear cell: the cell's own slope and twist bound r' and r''
        g2, tw = _ira_cell_slope_twist(heights, cia, cja, qc)
        g = np.sqrt(g2)
        h_ne = tw * (qc[6] * qc[7])
    elif one_line:
        # the two cells' slopes and twists, and the ridge jump of the slope across their shared grid line
        # (posts l - 1..l + 1 exist: 1 <= l <= n - 2 for the line l between two cells)
        g = 0.0
        for ci in range(min(cia, cib), max(cia, cib) + 1):
            for cj in range(min(cja, cjb), max(cja, cjb) + 1):
                gc, tw = _ira_cell_slope_twist(heights, ci, cj, qc)
                if not (gc <= g):
                    g = gc
                if not (tw <= h_ne):
                    h_ne = tw
        h_ne *= qc[6] * qc[7]
        if cia != cib:
            l_row = max(cia, cib)
            r0 = 2.0 * heights[l_row, cja] - heights[l_row + 1, cja] - heights[l_row - 1, cja]
            r1 = 2.0 * heights[l_row, cja + 1] - heights[l_row + 1, cja + 1] - heights[l_row - 1, cja + 1]
            jump_n = max(max(r0, r1), 0.0) * qc[6]
            line_d = abs(l_row - fia)
            line_rate = abs(qc[1])
            line_rate_t = abs(qc[2])
        else:
            l_col = max(cja, cjb)
            r0 = 2.0 * heights[cia, l_col] - heights[cia, l_col + 1] - heights[cia, l_col - 1]
            r1 = 2.0 * heights[cia + 1, l_col] - heights[cia + 1, l_col + 1] - heights[cia + 1, l_col - 1]
            jump_e = max(max(r0, r1), 0.0) * qc[7]
            line_d = abs(l_col - fja)
            line_rate = abs(qc[4])
            line_rate_t = abs(qc[5])
        line_kink = g == g and h_ne == h_ne and jump_n == jump_n and jump_e == jump_e
        g = np.sqrt(g)
    else:
        # slope bound over the region the curve segment can cross
        tt = ta if ta == ta else tb
        t_lo = min(ta, tb) if (ta == ta and tb == tb) else tt
        t_hi = max(ta, tb) if (ta == ta and tb == tb) else tt
        t_lo -= 0.2 * w + 1.0
        t_hi += 0.2 * w + 1.0
        na = -a * uhy
        nb = -b * uhy
        ea = a * uhx
        eb = b * uhx
        n_lo = min(na, nb) + min(t_lo * uhx, t_hi * uhx) - 1.0
        n_hi = max(na, nb) + max(t_lo * uhx, t_hi * uhx) + 1.0
        e_lo = min(ea, eb) + min(t_lo * uhy, t_hi * uhy) - 1.0
        e_hi = max(ea, eb) + max(t_lo * uhy, t_hi * uhy) + 1.0
        # the cells' own slopes when the region is small (tighter than the block slopes), else the blocks'
        i_a = int(np.floor(qc[0] + n_lo * qc[6]))
        i_b = int(np.ceil(qc[0] + n_hi * qc[6]))
        j_a = int(np.floor(qc[3] + e_lo * qc[7]))
        j_b = int(np.ceil(qc[3] + e_hi * qc[7]))
        inside = i_a >= 0 and j_a >= 0 and i_b <= n_lat - 1 and j_b <= n_lon - 1
        if inside and (i_b - i_a) * (j_b - j_a) <= 16:
            g = 0.0
            for ci in range(i_a, i_b):
                for cj in range(j_a, j_b):
                    gc, tw = _ira_cell_slope_twist(heights, ci, cj, qc)
                    if tw > h_ne:
                        h_ne = tw
                    if gc > g:
                        g = gc
                    elif not (gc == gc):
                        g = np.nan
                        break
                if not (g == g):
                    break
            h_ne *= qc[6] * qc[7]
            # kinks: across a row (column) grid line only dh/dn (dh/de) jumps, by the second difference d2
            # of the heights across the line interpolated between two posts; lines strictly inside the
            # region. Only ridge creases (d2 < 0) count: with t = -(v_d / |v_h|) z on the plane, crossing
            # the line changes z' by -d2 |dfi/ds| / (1 + gamma dh/du) (dfi/ds: posts per metre of s), and
            # r' by (z / r)(1 + gamma^2) times that, so a valley crease (d2 > 0) only bends r' down, which
            # keeps f - bound concave.
            for li in range(i_a + 1, i_b):
                mx = 0.0
                for lj in range(j_a, j_b + 1):
                    ridge = 2.0 * heights[li, lj] - heights[li + 1, lj] - heights[li - 1, lj]
                    if ridge > mx:
                        mx = ridge
                jump_n += mx
            for lj in range(j_a + 1, j_b):
                mx = 0.0
                for li in range(i_a, i_b + 1):
                    ridge = 2.0 * heights[li, lj] - heights[li, lj + 1] - heights[li, lj - 1]
                    if ridge > mx:
                        mx = ridge
                jump_e += mx
            jump_n *= qc[6]
            jump_e *= qc[7]
            kinks = g == g
            g = np.sqrt(g)
        else:
            g = _ira_box_max(
                bslope, IRA_BLOCK_POSTS, n_lat, n_lon, qc[0] + n_lo * qc[6], qc[0] + n_hi * qc[6],
                qc[3] + e_lo * qc[7], qc[3] + e_hi * qc[7],
            )
    if not one_cell:
        # split where the straight chord first crosses a grid line: the pieces are smooth
        lam = 2.0
        if cia != cib:
            li = cia + 1.0 if fib > fia else float(cia)
            lam = min(lam, (li - fia) / (fib - fia))
        if cja != cjb:
            lj = cja + 1.0 if fjb > fja else float(cja)
            lam = min(lam, (lj - fja) / (fjb - fja))
        if lam * w > 1e-3 and (1.0 - lam) * w > 1e-3:
            split = a + lam * w
    if not (g >= 0.0):
        g = g_glob
    den = 1.0 - gam * g
    if den < 0.1:
        den = 0.1
    zp = g / den + max(abs(a), abs(b)) / 6.3e6
    tp = gam * zp
    lip = _ira_lipschitz(a, b, ta, tb, za, zb, ra, rb, tp, zp, 1.02)
    if not (fa < _INF and fb < _INF):
        return min(fa, fb) - lip * w, split
    lb = 0.5 * (fa + fb - lip * w)
    kink_w = 0.25 * w
    if line_kink:
        # the curve crosses the line once when its grid coordinate across the line is monotone in s; the
        # kink then lies d / rate from end a, rate within |d fi/ds| +- tp |d fi/dt|: Green weight there
        r_lo_ = line_rate - 1.05 * tp * line_rate_t
        if r_lo_ > 0.0:
            x_lo = min(line_d / (line_rate + 1.05 * tp * line_rate_t), w)
            x_hi = min(line_d / r_lo_, w)
            xg = min(max(0.5 * w, x_lo), x_hi)
            kink_w = xg * (w - xg) / w
            kinks = True
    if one_cell or kinks:
        # |r''| <= |P'|^2 / r + |P''| with |z''| <= (|h_ss| + 1/R) / (1 - gamma g)
        p1sq = 1.0 + tp * tp + zp * zp
        r_lo = max(min(ra, rb) - np.sqrt(p1sq) * w, 0.05 * min(ra, rb))
        # h_ss = 2 h_ne x'_n x'_e on the bilinear cell, x' = w_h + t' u_h
        xnxe = (abs(uhy) + tp * abs(uhx)) * (abs(uhx) + tp * abs(uhy))
        zpp = (2.0 * h_ne * xnxe + 1.0 / 6.3e6) / den
        kk = 1.05 * (p1sq / r_lo + (1.0 + gam) * zpp)
        # f(a + u) >= fa + (fb - fa) u / w - kk u (w - u) / 2, minimised over u in [0, w]
        u = 0.5 * w - (fb - fa) / (kk * w) if kk > 0.0 else (0.0 if fa <= fb else w)
        u = min(max(u, 0.0), w)
        q2 = fa + (fb - fa) * u / w - 0.5 * kk * u * (w - u)
        if kinks:
            # a kink where r' jumps up by J lowers the bound by at most J G(s, kink) <= J w / 4 (G: Green's
            # function of d^2/ds^2 on [a, b]); |jump of r'| <= |jump of P'| = sqrt(1 + gamma^2) |jump of z'|
            # with |jump of z'| <= (|jump of h_w| + gamma |z'| |jump of h_u|) / (1 - gamma g); kinks where r'
            # jumps down (valley creases, see above) cannot lower it
            jz = (jump_n * (abs(uhy) + tp * abs(uhx)) + jump_e * (abs(uhx) + tp * abs(uhy))) / den
            q2 -= kink_w * 1.05 * np.sqrt(1.0 + gam * gam) * jz
        lb = max(lb, q2)
    return lb, split


@njit(cache=True, fastmath=False, error_model="numpy")
def _ira_one(
    heights,
    lat0,
    lon0,
    dlat,
    dlon,
    h_min,
    h_max,
    cell_m,
    lat,
    lon,
    ha,
    v,
    C,
    sin_w,
    max_range,
    buf_s,
    buf_f,
    buf_t,
    buf_r,
    buf_z,
    stack,
    hmax_blocks,
    bslope,
    g_glob,
    out,
    qc,
    buf_h,
    buf_q,
    hint_lat,
    hint_lon,
):
    """Closest in-window zero-Doppler terrain point; writes (valid, range, lat, lon, h) into out[0:5].

    (hint_lat, hint_lon): a terrain point near the expected return (rad; NaN: none), e.g. the previous
    sample's return along a flight: the curve point at its across-track coordinate is evaluated after the
    one at s = 0, so the search starts from a nearly final best. It changes only which intervals must be
    searched, not what the search guarantees.

    1) coarse intervals [s_q, s_q + step] along the curve (step: a whole number of posts; s: across-track
       coordinate), out to where the horizontal distance alone loses to the point at s = 0, each bounded
       below by its horizontal distance and the highest terrain of the 2 x 2-cell blocks its curve piece
       can lie in; in order of that bound, while it can beat the best, an interval's end samples are
       evaluated and its own bound (_ira_interval_lb) decides whether it joins 2) the branch and bound: an
       interval whose lower bound is >= best - tol cannot hold a closer point and is dropped, the others are
       bisected (split where the chord crosses a grid line, so that the pieces are smooth or meet at one
       kink, and the bound from the cells' slope and twist on r'' applies); 3) polish of the location by
       three-point steps. qc (>= 16): scratch for the per-query constants; buf_*: per-sample scratch.
       Uses nothing from other queries, so a batch gives the same bits as single queries."""
    out[0] = 0.0
    for q in range(1, 5):
        out[q] = np.nan
    speed = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if not (speed > 0.0):
        return
    vx = v[0] / speed
    vy = v[1] / speed
    vz = v[2] / speed
    vh = np.sqrt(vx * vx + vy * vy)
    if vh < 1e-3:
        return
    uhx = vx / vh
    uhy = vy / vh
    s, c, m, n, dm = _consts(lat)
    mh = m + ha
    nhc = (n + ha) * c
    n_lat = heights.shape[0]
    n_lon = heights.shape[1]
    d_top = ha - h_max
    # coarse step: a whole number of posts near COARSE_STEP_M (measured fastest on 23 m and 75 m grids)
    step = cell_m * max(1.0, np.floor(COARSE_STEP_M / cell_m + 0.5))
    gam = abs(vz) / vh
    # per-query constants of the bounds: grid coordinates fi = qc0 + s qc1 + t qc2, fj = qc3 + s qc4 + t qc5
    # of the nominal point (s, t); qc6, qc7: posts per metre north / east; qc11, qc12: u_h; qc13: gamma;
    # qc14: largest block slope; qc15: |P'| bound from it
    qc[0] = (lat - lat0) / dlat
    qc[1] = -uhy / (mh * dlat)
    qc[2] = uhx / (mh * dlat)
    qc[3] = (lon - lon0) / dlon
    qc[4] = uhx / (nhc * dlon)
    qc[5] = uhy / (nhc * dlon)
    qc[6] = 1.0 / (mh * dlat)
    qc[7] = 1.0 / (nhc * dlon)
    qc[8] = 1.0 / mh
    qc[9] = 1.0 / nhc
    qc[11] = uhx
    qc[12] = uhy
    qc[13] = gam
    qc[14] = g_glob
    den_g = max(1.0 - gam * g_glob, 0.1)
    zp_g = g_glob / den_g + max_range / 6.3e6
    qc[15] = np.sqrt(1.0 + (gam * zp_g) ** 2 + zp_g * zp_g) * 1.02
    n_max = buf_s.shape[0]
    half = n_max // 2
    t0 = 0.0
    hp0 = bilinear(heights, lat0, lon0, dlat, dlon, lat, lon)
    if hp0 == hp0:
        t0 = -(vz / vh) * (ha - hp0)
    # 1) coarse samples s_q = (q - half) step (buffer index q), evaluated when an interval needs them
    #    (buf_f NaN until then); the sample at s = 0 first, for a first best
    tol = 5e-3  # m: an interval must promise at least this much improvement to be searched
    tz = -(vz / vh)
    buf_s[half] = 0.0
    f, t, r, z = _ira_eval(
        heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, vx, vy, vz, uhx, uhy, vh, C,
        qc, sin_w, max_range, 0.0, t0, 1e-3,
    )
    buf_f[half] = f
    buf_t[half] = t
    buf_r[half] = r
    buf_z[half] = z
    best = f
    best_s = 0.0
    best_t = t
    # nadir outside the look-angle window (steep bank): a second first sample, where the window's edge
    # nearest the vertical (or, if that is the vertical, the boresight: body down axis) meets the nadir
    # terrain height; only the speed depends on it
    q_seed = -1
    f_seed = t_seed = r_seed = z_seed = np.nan
    if best == _INF:
        phi_b = np.arctan2(C[0, 2] * (-uhy) + C[1, 2] * uhx, C[2, 2])  # boresight from the vertical, across
        phi_w = 0.95 * np.arcsin(sin_w)
        phi = min(max(0.0, phi_b - phi_w), phi_b + phi_w)
        if phi == 0.0:
            phi = phi_b
        if abs(phi) < 1.4:
            drop = ha - (hp0 if hp0 == hp0 else 0.5 * (h_min + h_max))
            s_seed = max(drop, 0.0) * np.tan(phi)
            q_seed = min(max(half + int(np.floor(s_seed / step + 0.5)), 1), n_max - 2)
            f_seed, t_seed, r_seed, z_seed = _ira_eval(
                heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, vx, vy, vz, uhx, uhy, vh, C,
                qc, sin_w, max_range, (q_seed - half) * step, t0, 1e-3,
            )
            if f_seed < best:
                best = f_seed
                best_s = (q_seed - half) * step
                best_t = t_seed
    if hint_lat == hint_lat and hint_lon == hint_lon:
        # the hint's nominal coordinates: (north, east) = s w_h + t u_h, w_h = (-u_h,y, u_h,x)
        north_h = (hint_lat - lat) * mh
        east_h = (hint_lon - lon) * nhc
        s_hint = east_h * uhx - north_h * uhy
        f_h, t_h, _, _ = _ira_eval(
            heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, vx, vy, vz, uhx, uhy, vh, C,
            qc, sin_w, max_range, s_hint, north_h * uhx + east_h * uhy, 1e-3,
        )
        if f_h < best:
            best = f_h
            best_s = s_hint
            best_t = t_h
    # intervals q_a..q_b - 1: beyond them the horizontal distance alone, with the DEM's highest post, loses
    q_a = half
    q_b = half
    for side in range(2):
        for k in range(n_max):
            q = half + k if side == 0 else half - k - 1
            if q < 1 or q >= n_max - 2:
                break
            horiz_lb = k * step * 0.998 - 2.0
            if horiz_lb > max_range:
                break
            if best < _INF and d_top > 0.0 and horiz_lb > 0.0 and (
                horiz_lb * horiz_lb + d_top * d_top > best * best
            ):
                break
            if side == 0:
                q_b = q + 1
            else:
                q_a = q
    for q in range(q_a, q_b + 1):
        buf_s[q] = (q - half) * step
        if q != half:
            buf_f[q] = np.nan
            buf_t[q] = np.nan
    if q_a <= q_seed <= q_b and q_seed != half:
        buf_f[q_seed] = f_seed
        buf_t[q_seed] = t_seed
        buf_r[q_seed] = r_seed
        buf_z[q_seed] = z_seed
    # height bound of each interval: its curve piece lies in the grid box of s in [s_q, s_q+1] x the t band
    # below (+- 1 m), t band taken at the extent's largest |s| (one box shape, shifted by s); the range is
    # >= sqrt(horizontal^2 + (h_a - box max)^2). Candidates (buf_q) are then sorted by bound (buf_h).
    # The t band: on the curve v_hat . P = 0, i.e. u_h . P_h = t_z z with t_z = -v_d / |v_h|, and by the
    # expansion of the module doc u_h . P_h = kappa t + e, kappa = 1 - (h_a - h_p) / (M + h_a), with
    # |e| <= |tan(lat)| d^2 / (N + h_a) + 2e-9 d^2 + 1.1e-9 |h_a - h_p| d (second-order terms; the north and
    # east scale factors differ by (h_a - h_p)(N - M) / ((M + h_a)(N + h_a))), d^2 = s^2 + t^2; z lies
    # between the drops to h_max and to h_min, plus the curvature drop < d^2 / 2R. So t = (t_z z - e) / kappa
    # lies within t_err of t_z z (each term of t_err with a margin of 1.5x or more).
    n_c = 0
    s_ext = max(abs(buf_s[q_a]), abs(buf_s[q_b]))
    z_lo = ha - h_max - 1.0
    z_hi = ha - h_min + 1.0
    t_abs = abs(tz) * max(abs(z_lo), abs(z_hi))
    z_hi += (s_ext * s_ext + t_abs * t_abs) / 6.3e6
    t_a = tz * z_lo
    t_b = tz * z_hi
    t_abs = max(abs(t_a), abs(t_b))
    kap = 1.5 * (max(abs(z_lo), abs(z_hi)) + 1.0) / 6.3e6
    d2 = s_ext * s_ext + t_abs * t_abs
    t_err = 0.5 + kap * t_abs + (2.0 + 2.5 * abs(s / c)) * d2 / 6.3e6 + 5e-9 * (z_hi + 1.0) * np.sqrt(d2)
    t_lo = min(t_a, t_b) - t_err
    t_hi = max(t_a, t_b) + t_err
    bi_lo = qc[0] + min(0.0, step * qc[1]) + min(t_lo * qc[2], t_hi * qc[2]) - abs(qc[6])
    bi_hi = qc[0] + max(0.0, step * qc[1]) + max(t_lo * qc[2], t_hi * qc[2]) + abs(qc[6])
    bj_lo = qc[3] + min(0.0, step * qc[4]) + min(t_lo * qc[5], t_hi * qc[5]) - abs(qc[7])
    bj_hi = qc[3] + max(0.0, step * qc[4]) + max(t_lo * qc[5], t_hi * qc[5]) + abs(qc[7])
    cut = best - tol
    cut2 = cut * cut if cut > 0.0 else -1.0
    for q in range(q_a, q_b):
        sa = buf_s[q]
        sb = buf_s[q + 1]
        s_near = 0.0 if (sa < 0.0 and sb > 0.0) else min(abs(sa), abs(sb))
        horiz = max(s_near * 0.998 - 2.0, 0.0)
        if horiz > max_range:
            continue
        hb = _ira_box_max(hmax_blocks, IRA_HEIGHT_BLOCK_CELLS, n_lat, n_lon, bi_lo + sa * qc[1],
                          bi_hi + sa * qc[1], bj_lo + sa * qc[4], bj_hi + sa * qc[4])
        if hb == -_INF:
            continue
        dv = max(ha - hb, 0.0)
        lb2 = horiz * horiz + dv * dv
        if best < _INF and lb2 >= cut2:
            continue
        buf_h[n_c] = np.sqrt(lb2)
        buf_q[n_c] = q
        n_c += 1
    if n_c <= 64:
        for ci in range(1, n_c):  # insertion sort: the usual few tens of candidates
            lbh = buf_h[ci]
            q = buf_q[ci]
            row = ci
            while row > 0 and buf_h[row - 1] > lbh:
                buf_h[row] = buf_h[row - 1]
                buf_q[row] = buf_q[row - 1]
                row -= 1
            buf_h[row] = lbh
            buf_q[row] = q
    else:  # no first best (nothing at s = 0 nor at the boresight): hundreds of candidates
        order = np.argsort(buf_h[:n_c], kind="mergesort")
        sorted_h = buf_h[:n_c][order]
        sorted_q = buf_q[:n_c][order]
        buf_h[:n_c] = sorted_h
        buf_q[:n_c] = sorted_q
    n_st = 0
    cap = stack.shape[0]
    for ci in range(n_c):
        if buf_h[ci] >= best - tol:
            break
        q = int(buf_q[ci])
        for e in range(q, q + 2):
            if buf_f[e] == buf_f[e]:
                continue
            tg = t0
            if e > q_a and buf_f[e - 1] == buf_f[e - 1] and buf_t[e - 1] == buf_t[e - 1]:
                tg = buf_t[e - 1]
            elif e < q_b and buf_f[e + 1] == buf_f[e + 1] and buf_t[e + 1] == buf_t[e + 1]:
                tg = buf_t[e + 1]
            f, t, r, z = _ira_eval(
                heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, vx, vy, vz, uhx, uhy, vh, C,
                qc, sin_w, max_range, buf_s[e], tg, 1e-3,
            )
            buf_f[e] = f
            buf_t[e] = t
            buf_r[e] = r
            buf_z[e] = z
            if f < best:
                best = f
                best_s = buf_s[e]
                best_t = t
        fa = buf_f[q]
        fb = buf_f[q + 1]
        if fa == _INF and fb == _INF:
            continue
        if buf_r[q] == _INF and buf_r[q + 1] == _INF:
            continue
        lb, split = _ira_interval_lb(
            heights, bslope, qc, best - tol, buf_s[q], fa, buf_t[q], buf_r[q], buf_z[q], buf_s[q + 1], fb,
            buf_t[q + 1], buf_r[q + 1], buf_z[q + 1],
        )
        if lb >= best - tol or n_st >= cap:
            continue
        # insertion by lower bound, descending, so the most promising interval is popped first
        row = n_st
        while row > 0 and stack[row - 1, 10] < lb:
            for col in range(12):
                stack[row, col] = stack[row - 1, col]
            row -= 1
        _ira_push(stack, row, buf_s[q], fa, buf_t[q], buf_r[q], buf_z[q], buf_s[q + 1], fb, buf_t[q + 1],
                  buf_r[q + 1], buf_z[q + 1], lb, split)
        n_st += 1
    if best == _INF:
        return
    n_eval = 0
    while n_st > 0 and n_eval < 20000:
        n_st -= 1
        if stack[n_st, 10] >= best - tol:
            continue
        a = stack[n_st, 0]
        fa = stack[n_st, 1]
        ta = stack[n_st, 2]
        ra = stack[n_st, 3]
        za = stack[n_st, 4]
        b = stack[n_st, 5]
        fb = stack[n_st, 6]
        tb = stack[n_st, 7]
        rb = stack[n_st, 8]
        zb = stack[n_st, 9]
        mid = stack[n_st, 11]
        if ta == ta and tb == tb:
            tg = ta + (tb - ta) * (mid - a) / (b - a)  # linear interpolation: Newton starts close
        else:
            tg = ta if ta == ta else tb
        if tg != tg:
            tg = best_t if best_t == best_t else t0
        fm, tm, rm, zm = _ira_eval(
            heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, vx, vy, vz, uhx, uhy, vh, C,
            qc, sin_w, max_range, mid, tg, 1e-3,
        )
        n_eval += 1
        if fm < best:
            best = fm
            best_s = mid
            best_t = tm
        if n_st + 2 > cap:
            continue
        lb_l, sp_l = _ira_interval_lb(heights, bslope, qc, best - tol, a, fa, ta, ra, za, mid, fm, tm, rm, zm)
        lb_r, sp_r = _ira_interval_lb(heights, bslope, qc, best - tol, mid, fm, tm, rm, zm, b, fb, tb, rb, zb)
        # push the less promising half first so the more promising one is searched first
        left_first = lb_l >= lb_r
        for side in range(2):
            left = (side == 0) == left_first
            if left and lb_l < best - tol:
                _ira_push(stack, n_st, a, fa, ta, ra, za, mid, fm, tm, rm, zm, lb_l, sp_l)
                n_st += 1
            elif not left and lb_r < best - tol:
                _ira_push(stack, n_st, mid, fm, tm, rm, zm, b, fb, tb, rb, zb, lb_r, sp_r)
                n_st += 1
    # 3) polish the location (the bound stops at tol in range, which on a flat minimum leaves metres of
    #    slack in position): three-point steps with a parabolic jump, h = 0.5 m then 0.05 m (the jump
    #    from the 0.05 m stencil puts a smooth minimum within millimetres)
    centre = best_s
    tc = best_t
    fc = best
    h_p = 0.5
    for _it in range(12):
        if h_p < 4e-2:
            break
        # trials: 0 = centre - h_p, 1 = centre + h_p, 2 = the parabola's vertex (one _ira_eval call site)
        fm = tm = fp = tp_ = 0.0
        moved = False
        for trial in range(3):
            if trial == 0:
                sv_t = centre - h_p
            elif trial == 1:
                sv_t = centre + h_p
            else:
                if fm < fc and fm <= fp:
                    centre, fc, tc = centre - h_p, fm, tm
                    moved = True
                    break
                if fp < fc:
                    centre, fc, tc = centre + h_p, fp, tp_
                    moved = True
                    break
                den = fm - 2.0 * fc + fp
                if not (den > 0.0 and den < _INF):
                    break
                sv_t = centre + 0.5 * h_p * (fm - fp) / den
            f_t, t_t, _, _ = _ira_eval(
                heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, vx, vy, vz, uhx, uhy, vh, C,
                qc, sin_w, max_range, sv_t, tc, 1e-4,
            )
            if trial == 0:
                fm, tm = f_t, t_t
            elif trial == 1:
                fp, tp_ = f_t, t_t
            elif f_t < fc:
                centre, fc, tc = sv_t, f_t, t_t
        if moved:
            continue
        h_p *= 0.1
    t, x, y, z, dphi, dlam, hp = _zd_point(
        heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, vx, vy, vz, uhx, uhy, vh, qc, centre,
        tc, 1e-6,
    )
    if t != t:
        return
    out[0] = 1.0
    out[1] = np.sqrt(x * x + y * y + z * z)
    out[2] = lat + dphi
    out[3] = lon + dlam
    out[4] = hp


@njit(cache=True, fastmath=False, error_model="numpy")
def _ira_batch(
    heights,
    lat0,
    lon0,
    dlat,
    dlon,
    cell_m,
    lat,
    lon,
    h,
    v_ned,
    C_bn,
    half_window,
    max_range,
    hmax_blocks,
    bslope,
    h_min,
    h_max,
    g_glob,
    work,
    stack,
    valid,
    rng,
    lat_out,
    lon_out,
    h_out,
    warm,
):
    """IRA queries k = 0..n-1 (see ira_return); hmax_blocks, bslope, h_min, h_max, g_glob: see _ira_tables;
    work (8, >= n_max) and stack (>= 64, 12): scratch space, contents irrelevant. warm: (lat, lon) of the
    first query's hint, each later query's hint the previous valid return (warm_start of ira_return); an
    empty array: no hints."""
    sin_w = np.sin(half_window)
    n_max = 2 * int(np.ceil(max_range / cell_m)) + 9
    buf_s = work[0, :n_max]
    buf_f = work[1, :n_max]
    buf_t = work[2, :n_max]
    buf_r = work[3, :n_max]
    buf_z = work[4, :n_max]
    out = work[5, :5]
    qc = work[5, 8:24]
    buf_h = work[6, :n_max]
    buf_q = work[7, :n_max]
    chain = warm.shape[0] == 2
    hint_lat = warm[0] if chain else np.nan
    hint_lon = warm[1] if chain else np.nan
    for k in range(lat.shape[0]):
        if h[k] != h[k] or lat[k] != lat[k] or lon[k] != lon[k]:
            valid[k] = False
            rng[k] = lat_out[k] = lon_out[k] = h_out[k] = np.nan
            continue
        _ira_one(
            heights,
            lat0,
            lon0,
            dlat,
            dlon,
            h_min,
            h_max,
            cell_m,
            lat[k],
            lon[k],
            h[k],
            v_ned[k],
            C_bn[k],
            sin_w,
            max_range,
            buf_s,
            buf_f,
            buf_t,
            buf_r,
            buf_z,
            stack,
            hmax_blocks,
            bslope,
            g_glob,
            out,
            qc,
            buf_h,
            buf_q,
            hint_lat,
            hint_lon,
        )
        valid[k] = out[0] > 0.5
        rng[k] = out[1]
        lat_out[k] = out[2]
        lon_out[k] = out[3]
        h_out[k] = out[4]
        if chain and valid[k]:
            hint_lat = out[2]
            hint_lon = out[3]


# ----------------------------------------------------------------------------------------- public API
def _is_f8_vector(a, n=None) -> bool:
    return (
        type(a) is np.ndarray
        and a.dtype == np.float64
        and a.ndim == 1
        and a.flags.c_contiguous
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
    return np.ascontiguousarray(lat), np.ascontiguousarray(lon), np.ascontiguousarray(h)


def _stack(name, arr, n, shape):
    if (
        type(arr) is np.ndarray
        and arr.dtype == np.float64
        and arr.shape == (n,) + shape
        and arr.flags.c_contiguous
    ):
        return arr  # fast path: what the general path below would return
    a = np.asarray(arr, dtype=np.float64)
    if a.shape == shape:
        a = np.broadcast_to(a, (n,) + shape)
    if a.shape != (n,) + shape:
        raise ValueError(
            f"{name} must have shape {shape} or ({n}, {', '.join(map(str, shape))}), got {a.shape}"
        )
    return np.ascontiguousarray(a)


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


_IRA_WORK: dict = {}
_NO_WARM_START = np.zeros(0)  # _ira_batch's "no hints"


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


_RA_WORK: dict = {}


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


def ray_cast(dem, lat_rad, lon_rad, h_m, dir_ned, max_range_m: float = 20000.0) -> TerrainReturn:
    """First intersection of rays (origin lat/lon rad, h m MSL; direction dir_ned (n, 3), any length) with
    the terrain, up to max_range_m. Misses, voids and off-grid rays give valid = False."""
    _check_positive("max_range_m", max_range_m)
    lat, lon, h = _positions(lat_rad, lon_rad, h_m)
    dirs = _stack("dir_ned", dir_ned, lat.shape[0], (3,))
    valid, rng, la, lo, hh = _outputs(lat.shape[0])
    heights, lat0, lon0, dlat, dlon = dem.grid
    _ray_cast_batch(
        heights,
        lat0,
        lon0,
        dlat,
        dlon,
        _cell_m(dem),
        lat,
        lon,
        h,
        dirs,
        float(max_range_m),
        *_height_range(dem),
        valid,
        rng,
        la,
        lo,
        hh,
    )
    return TerrainReturn(valid, rng, la, lo, hh)


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
    heights, lat0, lon0, dlat, dlon = dem.grid
    bs, bmax, bmin, h_min, h_max, cell_m = _ra_tables(dem)
    _ra_batch(
        heights,
        lat0,
        lon0,
        dlat,
        dlon,
        cell_m,
        lat,
        lon,
        h,
        C,
        float(half_beamwidth_rad),
        float(max_range_m),
        bs,
        bmax,
        bmin,
        h_min,
        h_max,
        *_ra_workspace(bmax.size),
        valid,
        rng,
        la,
        lo,
        hh,
    )
    return TerrainReturn(valid, rng, la, lo, hh)


def ira_return(
    dem,
    lat_rad,
    lon_rad,
    h_m,
    v_ned,
    C_bn,
    half_window_rad: float,
    max_range_m: float = 12000.0,
    warm_start: tuple[float, float] | None = None,
) -> TerrainReturn:
    """Closest terrain point on the zero-Doppler plane (through the antenna, perpendicular to v_ned (n, 3))
    whose look angle |theta| = |asin(y_b / R)| <= half_window_rad and z_b > 0 (body FRD via C_bn (n, 3,
    3)); theta per seed 000 eqs 18-19.

    warm_start: None (default) searches every query on its own, so a batch gives the same bits as single
    calls. A (lat_rad, lon_rad) pair, a terrain point near the first query's return ((nan, nan) if none is
    known), makes the queries a sequence: each search starts from that point, then from the previous valid
    return. Along a flight (samples metres apart) that saves ~2 % of the search; the results are the same
    to the search's tolerance (5 mm in range), not bit for bit. NaN: no point; an infinite one is refused."""
    if not (0.0 < half_window_rad < np.pi / 2):
        raise ValueError(f"half_window_rad must be in (0, pi/2), got {half_window_rad}")
    _check_positive("max_range_m", max_range_m)
    if warm_start is None:
        warm = _NO_WARM_START
    else:
        bad = f"warm_start must be None or a (lat_rad, lon_rad) pair, got {warm_start!r}"
        try:
            warm = np.array([float(warm_start[0]), float(warm_start[1])])
        except (TypeError, IndexError, ValueError) as exc:
            raise ValueError(bad) from exc
        if len(warm_start) != 2 or np.isinf(warm).any():
            raise ValueError(bad)
    lat, lon, h = _positions(lat_rad, lon_rad, h_m)
    n = lat.shape[0]
    v = _stack("v_ned", v_ned, n, (3,))
    C = _stack("C_bn", C_bn, n, (3, 3))
    valid, rng, la, lo, hh = _outputs(n)
    heights, lat0, lon0, dlat, dlon = dem.grid
    hmax_blocks, bslope, h_min, h_max, g_glob, cell_m = _ira_tables(dem)
    work, stack = _ira_workspace(2 * int(np.ceil(float(max_range_m) / cell_m)) + 9)
    _ira_batch(
        heights,
        lat0,
        lon0,
        dlat,
        dlon,
        cell_m,
        lat,
        lon,
        h,
        v,
        C,
        float(half_window_rad),
        float(max_range_m),
        hmax_blocks,
        bslope,
        h_min,
        h_max,
        g_glob,
        work,
        stack,
        valid,
        rng,
        la,
        lo,
        hh,
        warm,
    )
    return TerrainReturn(valid, rng, la, lo, hh)


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
        s, c, m, n, dm = _consts(lat[k])
        x, y, z = _ned(lat_p[k] - lat[k], lon_p[k] - lon[k], h_p[k], h[k], s, c, m, n, dm)
        out[k, 0] = x
        out[k, 1] = y
        out[k, 2] = z
