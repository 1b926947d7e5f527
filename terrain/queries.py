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

Search: a coarse scan (posts in the beam footprint for the altimeter; samples one post apart along the
zero-Doppler curve for the IRA) pruned by the lower bound range >= sqrt(horizontal^2 + (h_a - h_max)^2).
Altimeter: pattern search in continuous grid-index coordinates (the bilinear surface's kinks lie on grid
lines, so axis moves follow ridges) from every post that is a local minimum within a slope-derived margin
of the best post, then a 1-D shrinking search along the cone boundary (in azimuth). IRA: branch and bound
over the intervals between coarse samples with Lipschitz / curvature bounds from per-block slopes and per-
cell twists (see _ira_one). Ranges agree with a dense brute-force search to a few cm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from terrain import geodesy, kernels
from terrain.geodesy import WGS84_A_M, WGS84_E2
from terrain.kernels import bilinear

_INF = np.inf
_OUT_OF_CONE = 1e300  # _ra_eval's value outside the beam (inf: no terrain / beyond max range)
_PRUNED = 1e301  # IRA coarse sample skipped by the block bound (it and its intervals cannot beat the best)
W_MIN_M = 0.1  # arc length (m) at which the cone-boundary search stops
COARSE_ARC_M = 20.0  # arc step (m) at which the boundary searches' coarse phase stops
FINE_SLOPE = 2.0  # bound on |d range / d arc| along the cone boundary used to skip fine phases
BLOCK_POSTS = 8  # block size of the height bounds used to prune the searches
_COS24 = np.cos(2.0 * np.pi * np.arange(24) / 24)  # azimuths sampling the beam-cone boundary
_SIN24 = np.sin(2.0 * np.pi * np.arange(24) / 24)


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
@njit(cache=True, fastmath=False, error_model="numpy")
def _consts(lat):
    s = np.sin(lat)
    c = np.cos(lat)
    w = 1.0 - WGS84_E2 * s * s
    m = WGS84_A_M * (1.0 - WGS84_E2) / (w * np.sqrt(w))
    n = WGS84_A_M / np.sqrt(w)
    dm = 3.0 * m * WGS84_E2 * s * c / w
    return s, c, m, n, dm


@njit(cache=True, fastmath=False, error_model="numpy")
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
def _ra_eval(
    heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, ax, ay, az, cosb, max_range, fi, fj
):
    """Range to the terrain point at grid coordinates (fi, fj) if inside the cone, else inf."""
    la = lat0 + fi * dlat
    lo = lon0 + fj * dlon
    hp = bilinear(heights, lat0, lon0, dlat, dlon, la, lo)
    if hp != hp:
        return _INF
    x, y, z = _ned(la - lat, lo - lon, hp, ha, s, c, m, n, dm)
    r = np.sqrt(x * x + y * y + z * z)
    if r > max_range:
        return _INF
    if x * ax + y * ay + z * az < cosb * r:
        return _OUT_OF_CONE
    return r


@njit(cache=True, fastmath=False, error_model="numpy")
def _pattern_search(
    heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, ax, ay, az, cosb, max_range, fi, fj, f0
):
    """Compass + diagonal pattern search in grid coordinates from (fi, fj); returns (f, fi, fj, touched)
    where touched says an out-of-cone neighbour was met at the finest steps."""
    step = 0.5
    f = f0
    touched = False
    it = 0
    while step > 1e-3 and it < 400:
        it += 1
        best_f = f
        best_i = fi
        best_j = fj
        # compass moves first; the diagonals only when no compass move improves
        for q in range(8):
            if q == 4 and best_f < f:
                break
            if q < 4:
                di = 1.0 if q == 0 else (-1.0 if q == 1 else 0.0)
                dj = 1.0 if q == 2 else (-1.0 if q == 3 else 0.0)
            else:
                di = 1.0 if q < 6 else -1.0
                dj = 1.0 if q % 2 == 0 else -1.0
            ci = fi + di * step
            cj = fj + dj * step
            fc = _ra_eval(
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
                ax,
                ay,
                az,
                cosb,
                max_range,
                ci,
                cj,
            )
            if fc == _OUT_OF_CONE and step < 0.05:
                touched = True
            if fc < best_f:
                best_f = fc
                best_i = ci
                best_j = cj
        if best_f < f:
            f = best_f
            fi = best_i
            fj = best_j
        else:
            step *= 0.5
        if touched and step < 0.02:
            break  # on the cone boundary: the 1-D boundary search takes over from here
    return f, fi, fj, touched


@njit(cache=True, fastmath=False, error_model="numpy")
def _boundary_eval(
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
    ax,
    ay,
    az,
    e1x,
    e1y,
    e1z,
    e2x,
    e2y,
    e2z,
    cosb,
    sinb,
    max_range,
    az_rad,
    t_guess,
    sl_guess,
):
    """Range of the first terrain hit along the cone-boundary ray at azimuth az_rad (inf if none)."""
    ca = np.cos(az_rad)
    sa = np.sin(az_rad)
    dx = cosb * ax + sinb * (ca * e1x + sa * e2x)
    dy = cosb * ay + sinb * (ca * e1y + sa * e2y)
    dz = cosb * az + sinb * (ca * e1z + sa * e2z)
    # secant from the previous range (any crossing on the boundary ray is a terrain point in the cone)
    t0 = t_guess
    g0 = _g_ray(heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, dx, dy, dz, t0)
    if g0 == g0 and abs(g0) < 1e-4 and t0 > 0.0 and t0 <= max_range:
        return t0, dx, dy, dz, sl_guess
    t1 = t_guess + 1.0
    if sl_guess < 0.0 and g0 == g0:
        # Newton step with the slope dg/dt of the neighbouring boundary ray (secant from then on)
        step_n = -g0 / sl_guess
        if abs(step_n) < 2.0 * cell_m and abs(step_n) > 1e-6:
            t1 = t_guess + step_n
    if g0 == g0:
        for _ in range(12):
            g1 = _g_ray(heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, dx, dy, dz, t1)
            if g1 != g1:
                break
            if abs(g1) < 1e-4:
                if t1 > 0.0 and t1 <= max_range:
                    sl = (g1 - g0) / (t1 - t0)
                    return t1, dx, dy, dz, sl
                break
            if g1 == g0:
                break
            t2 = t1 - g1 * (t1 - t0) / (g1 - g0)
            if abs(t2 - t1) > 4.0 * cell_m:
                break
            t0, g0, t1 = t1, g1, t2
    horiz = np.sqrt(dx * dx + dy * dy)
    back = 2.0 * cell_m / max(horiz, 1e-3)
    t_from = t_guess - back
    if t_from < 0.0:
        t_from = 0.0
    g0 = _g_ray(heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, dx, dy, dz, t_from)
    if not (g0 == g0 and g0 >= 0.0):
        t_from = 0.0
    t = _ray_hit(
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
        max_range,
    )
    if t != t:
        return _INF, dx, dy, dz, 0.0
    return t, dx, dy, dz, 0.0


@njit(cache=True, fastmath=False, error_model="numpy")
def _boundary_search(
    heights, lat0, lon0, dlat, dlon, h_min, h_max, cell_m, lat, lon, ha, s, c, m, n, dm, ax, ay, az, e1x, e1y,
    e1z, e2x, e2y, e2z, cosb, sinb, max_range, st, w_stop,
):
    """Shrinking local 1-D search in azimuth along the cone boundary for the closest boundary terrain hit.

    st (float64[9]): resumable state (best range fb, centre azimuth, its ray dx, dy, dz, range guess t_ref,
    slope dg/dt, current step w rad, unused); halves w until w <= w_stop. The reach from the start azimuth is
    +-(initial w)."""
    fb = st[0]
    centre = st[1]
    t_ref = st[5]
    sl = st[6]
    w = st[7]
    while w > w_stop:
        for sgn in (-0.5, 0.5):
            a = centre + sgn * w
            fa, ddx, ddy, ddz, sla = _boundary_eval(
                heights, lat0, lon0, dlat, dlon, h_min, h_max, cell_m, lat, lon, ha, s, c, m, n, dm,
                ax, ay, az,
                e1x, e1y, e1z, e2x, e2y, e2z, cosb, sinb, max_range, a, t_ref, sl,
            )
            if sla < 0.0:
                sl = sla
            if fa < fb:
                fb = fa
                centre = a
                st[2] = ddx
                st[3] = ddy
                st[4] = ddz
                break
        if fb < _INF:
            t_ref = fb
        w *= 0.5
    st[0] = fb
    st[1] = centre
    st[5] = t_ref
    st[6] = sl
    st[7] = w


@njit(cache=True, fastmath=False, error_model="numpy")
def _ra_one(
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
    ax,
    ay,
    az,
    cosb,
    sinb,
    max_range,
    bs,
    bmax,
    bmin,
    g_max,
    out,
):
    """Closest terrain point in the beam cone; writes (valid, range, lat, lon, h) into out[0:5].

    bs, bmax, bmin: block size and per-block height bounds (terrain.kernels.block_bounds) used to skip
    blocks that cannot hold a point closer than the best so far or that lie outside the cone."""
    out[0] = 0.0
    for q in range(1, 5):
        out[q] = np.nan
    n_lat, n_lon = heights.shape
    s, c, m, n, dm = _consts(lat)
    # cone frame: e1, e2 perpendicular to the axis
    if abs(az) < 0.9:
        px, py, pz = 0.0, 0.0, 1.0
    else:
        px, py, pz = 1.0, 0.0, 0.0
    e1x = ay * pz - az * py
    e1y = az * px - ax * pz
    e1z = ax * py - ay * px
    nrm = np.sqrt(e1x * e1x + e1y * e1y + e1z * e1z)
    e1x /= nrm
    e1y /= nrm
    e1z /= nrm
    e2x = ay * e1z - az * e1y
    e2y = az * e1x - ax * e1z
    e2z = ax * e1y - ay * e1x

    # a point within 0.71 post of a post is at most 0.71 post * |dP/dx| <= 0.71 post * sqrt(1 + g^2) closer
    margin = 0.75 * cell_m * np.sqrt(1.0 + g_max * g_max)
    best = _INF
    best_i = np.nan
    best_j = np.nan
    # 1) the axis ray: an upper bound and a start point
    t_ax = _ray_hit(
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
        ax,
        ay,
        az,
        0.0,
        max_range,
    )
    if t_ax == t_ax:
        dphi, dlam, hp = _geo_of_ned(t_ax * ax, t_ax * ay, t_ax * az, ha, s, c, m, n, dm)
        fi = (lat + dphi - lat0) / dlat
        fj = (lon + dlam - lon0) / dlon
        f = _ra_eval(
            heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, ax, ay, az, cosb, max_range, fi, fj
        )
        if f < best and f < _OUT_OF_CONE:
            best, best_i, best_j = f, fi, fj
    # 2) footprint bounding box (NED north/east) of the cone between the highest and lowest terrain depths
    d_top = ha - h_max
    d_bot = ha - h_min + 0.5 * max_range * max_range / 6.3e6 + 1.0
    n_lo = _INF
    n_hi = -_INF
    e_lo = _INF
    e_hi = -_INF
    if d_top <= 0.0:
        n_lo = min(n_lo, 0.0)
        n_hi = max(n_hi, 0.0)
        e_lo = min(e_lo, 0.0)
        e_hi = max(e_hi, 0.0)
    n_az = 24
    for k in range(n_az + 1):
        if k < n_az:
            ca = _COS24[k]
            sa = _SIN24[k]
            dx = cosb * ax + sinb * (ca * e1x + sa * e2x)
            dy = cosb * ay + sinb * (ca * e1y + sa * e2y)
            dz = cosb * az + sinb * (ca * e1z + sa * e2z)
        else:
            dx, dy, dz = ax, ay, az
        for dd in (d_top, d_bot):
            if dz > 1e-9:
                t = dd / dz
                if t < 0.0:
                    t = 0.0
                if t > max_range:
                    t = max_range
            else:
                t = max_range
            n_lo = min(n_lo, t * dx)
            n_hi = max(n_hi, t * dx)
            e_lo = min(e_lo, t * dy)
            e_hi = max(e_hi, t * dy)
    pad_n = 0.03 * (n_hi - n_lo) + 2.0 * cell_m
    pad_e = 0.03 * (e_hi - e_lo) + 2.0 * cell_m
    n_lo -= pad_n
    n_hi += pad_n
    e_lo -= pad_e
    e_hi += pad_e
    if best < _INF and d_top > 0.0:
        rho = np.sqrt(max(best * best - d_top * d_top, 0.0)) * 1.002 + 2.0 * cell_m
        n_lo = max(n_lo, -rho)
        n_hi = min(n_hi, rho)
        e_lo = max(e_lo, -rho)
        e_hi = min(e_hi, rho)
    # 3) scan the posts inside the box; start points = in-cone posts that are local minima of the range
    #    among their 8 neighbours (out-of-cone neighbours count as +inf), the K lowest
    kk = 12
    kb = 16
    tilt = np.arccos(min(max(az, -1.0), 1.0))  # axis angle from the local down
    dz_max = 1.0 if np.arccos(cosb) >= tilt else np.cos(tilt - np.arccos(cosb))  # steepest boundary ray
    bnd_key = np.full(kb, _INF)
    bnd_f = np.full(kb, _INF)
    bnd_i = np.zeros(kb)
    bnd_j = np.zeros(kb)
    cand_f = np.full(kk, _INF)
    cand_i = np.zeros(kk)
    cand_j = np.zeros(kk)
    if n_lo <= n_hi and e_lo <= e_hi:
        mh = m + ha
        nh = (n + ha) * c
        i_lo = max(int(np.floor((lat + n_lo / mh - lat0) / dlat)) - 1, 0)
        i_hi = min(int(np.ceil((lat + n_hi / mh - lat0) / dlat)) + 1, n_lat - 1)
        j_lo = max(int(np.floor((lon + e_lo / nh - lon0) / dlon)) - 1, 0)
        j_hi = min(int(np.ceil((lon + e_hi / nh - lon0) / dlon)) + 1, n_lon - 1)
        ni = i_hi - i_lo + 1
        nj = j_hi - j_lo + 1
        if ni > 0 and nj > 0:
            rbuf = np.full((ni + 2, nj + 2), _INF)
            nbi, nbj = bmax.shape
            half_beam = np.arccos(cosb)
            post_best = best
            bi0 = i_lo // bs
            bi1 = min(i_hi // bs, nbi - 1)
            bj0 = j_lo // bs
            bj1 = min(j_hi // bs, nbj - 1)
            nbw = bj1 - bj0 + 1
            scanned = np.zeros((bi1 - bi0 + 1, nbw), dtype=np.bool_)
            # blocks in the box that may hold a point in the cone, with the lower bound of their range
            blk_lb2 = np.empty((bi1 - bi0 + 1) * nbw)
            blk_id = np.empty((bi1 - bi0 + 1) * nbw, dtype=np.int64)
            n_blk = 0
            for bi in range(bi0, bi1 + 1):
                pi0 = max(bi * bs, i_lo)
                pi1 = min(bi * bs + bs - 1 if bi < nbi - 1 else n_lat - 1, i_hi)
                if pi0 > pi1:
                    continue
                n0 = (lat0 + bi * bs * dlat - lat) * mh
                n1 = (lat0 + min(bi * bs + bs, n_lat - 1) * dlat - lat) * mh
                dn_ = n0 if n0 > 0.0 else (-n1 if n1 < 0.0 else 0.0)
                for bj in range(bj0, bj1 + 1):
                    pj0 = max(bj * bs, j_lo)
                    pj1 = min(bj * bs + bs - 1 if bj < nbj - 1 else n_lon - 1, j_hi)
                    hmx = bmax[bi, bj]
                    if pj0 > pj1 or hmx == -_INF:
                        continue
                    hmn = bmin[bi, bj]
                    e0 = (lon0 + bj * bs * dlon - lon) * nh
                    e1 = (lon0 + min(bj * bs + bs, n_lon - 1) * dlon - lon) * nh
                    de_ = e0 if e0 > 0.0 else (-e1 if e1 < 0.0 else 0.0)
                    # lower bound of the range to any point of the block (curvature only adds depth)
                    dh = max(np.sqrt(dn_ * dn_ + de_ * de_) * 0.998 - 2.0, 0.0)
                    dv = max(ha - hmx, 0.0)
                    lb2 = dh * dh + dv * dv
                    bound = post_best + 0.5 * cell_m
                    if lb2 > bound * bound:
                        continue
                    # the block's bounding sphere must reach into the cone
                    cx = 0.5 * (n0 + n1)
                    cy = 0.5 * (e0 + e1)
                    cz = ha - 0.5 * (hmx + hmn)
                    rad = 0.5 * np.sqrt((n1 - n0) ** 2 + (e1 - e0) ** 2 + (hmx - hmn) ** 2)
                    cn = np.sqrt(cx * cx + cy * cy + cz * cz)
                    rad += 0.5 * (cn + rad) ** 2 / 6.3e6 + 0.002 * cn + 2.0
                    if cn > rad:
                        cos_c = (cx * ax + cy * ay + cz * az) / cn
                        cos_c = min(max(cos_c, -1.0), 1.0)
                        if np.arccos(cos_c) - np.arcsin(rad / cn) > half_beam:
                            continue
                    blk_lb2[n_blk] = lb2
                    blk_id[n_blk] = (bi - bi0) * nbw + (bj - bj0)
                    n_blk += 1
            # best first: the closest posts found early prune the remaining blocks
            order = np.argsort(blk_lb2[:n_blk])
            for q_blk in range(n_blk):
                bound = post_best + 0.5 * cell_m
                if blk_lb2[order[q_blk]] > bound * bound:
                    break
                bid = blk_id[order[q_blk]]
                bi = bi0 + bid // nbw
                bj = bj0 + bid % nbw
                pi0 = max(bi * bs, i_lo)
                pi1 = min(bi * bs + bs - 1 if bi < nbi - 1 else n_lat - 1, i_hi)
                pj0 = max(bj * bs, j_lo)
                pj1 = min(bj * bs + bs - 1 if bj < nbj - 1 else n_lon - 1, j_hi)
                scanned[bi - bi0, bj - bj0] = True
                for i in range(pi0, pi1 + 1):
                    dphi = lat0 + i * dlat - lat
                    for j in range(pj0, pj1 + 1):
                        hp = heights[i, j]
                        if hp != hp:
                            continue
                        dlam = lon0 + j * dlon - lon
                        x, y, z = _ned(dphi, dlam, hp, ha, s, c, m, n, dm)
                        r = np.sqrt(x * x + y * y + z * z)
                        if r > max_range:
                            continue
                        if x * ax + y * ay + z * az < cosb * r:
                            rbuf[i - i_lo + 1, j - j_lo + 1] = -r  # out of the cone: raw range, negated
                            continue
                        rbuf[i - i_lo + 1, j - j_lo + 1] = r
                        if r < post_best:
                            post_best = r
            for bi in range(bi0, bi1 + 1):
                for bj in range(bj0, bj1 + 1):
                    if not scanned[bi - bi0, bj - bj0]:
                        continue
                    pi0 = max(bi * bs, i_lo)
                    pi1 = min(bi * bs + bs - 1 if bi < nbi - 1 else n_lat - 1, i_hi)
                    pj0 = max(bj * bs, j_lo)
                    pj1 = min(bj * bs + bs - 1 if bj < nbj - 1 else n_lon - 1, j_hi)
                    for a_i in range(pi0 - i_lo + 1, pi1 - i_lo + 2):
                        for a_j in range(pj0 - j_lo + 1, pj1 - j_lo + 2):
                            r = rbuf[a_i, a_j]
                            if r == _INF or r < 0.0:
                                continue
                            is_min = True
                            edge_key = _INF
                            for di in range(-1, 2):
                                for dj in range(-1, 2):
                                    rn = rbuf[a_i + di, a_j + dj]
                                    if rn < 0.0:
                                        edge_key = min(edge_key, -rn)
                                    elif (di != 0 or dj != 0) and rn < r:
                                        is_min = False
                            if edge_key < _INF:
                                # a post next to the cone boundary: a seed for the boundary search
                                edge_key = min(edge_key, r)
                                if edge_key < bnd_key[kb - 1]:
                                    q = kb - 1
                                    while q > 0 and bnd_key[q - 1] > edge_key:
                                        bnd_key[q] = bnd_key[q - 1]
                                        bnd_f[q] = bnd_f[q - 1]
                                        bnd_i[q] = bnd_i[q - 1]
                                        bnd_j[q] = bnd_j[q - 1]
                                        q -= 1
                                    bnd_key[q] = edge_key
                                    bnd_f[q] = r
                                    bnd_i[q] = i_lo + a_i - 1
                                    bnd_j[q] = j_lo + a_j - 1
                            if not is_min or r >= cand_f[kk - 1]:
                                continue
                            q = kk - 1
                            while q > 0 and cand_f[q - 1] > r:
                                cand_f[q] = cand_f[q - 1]
                                cand_i[q] = cand_i[q - 1]
                                cand_j[q] = cand_j[q - 1]
                                q -= 1
                            cand_f[q] = r
                            cand_i[q] = i_lo + a_i - 1
                            cand_j[q] = j_lo + a_j - 1
    # 4) local refinement from distinct start points
    done_i = np.empty(kk + 1 + kb)
    done_j = np.empty(kk + 1 + kb)
    n_done = 0
    res_f = np.empty(kk + 1 + kb)
    res_key = np.empty(kk + 1 + kb)
    res_t = np.zeros(kk + 1 + kb, dtype=np.bool_)
    for q in range(-1, kk):
        if q < 0:
            if t_ax != t_ax or best == _INF or cand_f[0] < _INF:
                continue  # the axis hit is a start point only when no post lies in the beam
            fi0, fj0, f0 = best_i, best_j, best
        else:
            if cand_f[q] == _INF:
                break
            if cand_f[q] > best + margin:
                break
            fi0, fj0, f0 = cand_i[q], cand_j[q], cand_f[q]
            if n_done > 0:
                # skip a start whose surroundings (+-2 posts) cannot beat the best refined point
                ci = int(fi0)
                cj = int(fj0)
                i_a = max(ci - 2, 0)
                i_b = min(ci + 2, n_lat - 1)
                j_a = max(cj - 2, 0)
                j_b = min(cj + 2, n_lon - 1)
                hmx = -_INF
                for i in range(i_a, i_b + 1):
                    for j in range(j_a, j_b + 1):
                        if heights[i, j] > hmx:
                            hmx = heights[i, j]
                n_a = (lat0 + i_a * dlat - lat) * (m + ha)
                n_b = (lat0 + i_b * dlat - lat) * (m + ha)
                e_a = (lon0 + j_a * dlon - lon) * (n + ha) * c
                e_b = (lon0 + j_b * dlon - lon) * (n + ha) * c
                dn_ = n_a if n_a > 0.0 else (-n_b if n_b < 0.0 else 0.0)
                de_ = e_a if e_a > 0.0 else (-e_b if e_b < 0.0 else 0.0)
                dh = max(np.sqrt(dn_ * dn_ + de_ * de_) * 0.998 - 2.0, 0.0)
                dv = max(ha - hmx, 0.0)
                if dh * dh + dv * dv > best * best:
                    continue
        near = False
        for p in range(n_done):
            if abs(done_i[p] - fi0) <= 0.25 and abs(done_j[p] - fj0) <= 0.25:
                near = True
        if near or n_done >= 4:
            continue
        f, fi, fj, touched = _pattern_search(
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
            ax,
            ay,
            az,
            cosb,
            max_range,
            fi0,
            fj0,
            f0,
        )
        done_i[n_done] = fi
        done_j[n_done] = fj
        res_f[n_done] = f
        res_key[n_done] = f
        res_t[n_done] = touched
        n_done += 1
        if f < best:
            best, best_i, best_j = f, fi, fj
    if n_done == 0 and best < _INF:
        done_i[0] = best_i
        done_j[0] = best_j
        res_f[0] = best
        res_key[0] = best
        res_t[0] = False
        n_done = 1
    # boundary seeds (posts next to the cone edge whose neighbourhood may hold a closer boundary point),
    # at least 1.5 posts apart: the boundary search from each covers +-1.5 posts of arc
    n_ref = n_done
    for q in range(kb):
        if bnd_key[q] == _INF or bnd_key[q] > best + margin:
            break
        # height bound: a boundary point in the 4 cells around the seed sits at depth >= ha - (their max
        # height), and a cone-boundary ray descends at most cos(half_beam - axis tilt) per metre of range
        ci = int(bnd_i[q])
        cj = int(bnd_j[q])
        hmx = -_INF
        for i in range(max(ci - 1, 0), min(ci + 1, n_lat - 1) + 1):
            for j in range(max(cj - 1, 0), min(cj + 1, n_lon - 1) + 1):
                if heights[i, j] > hmx:
                    hmx = heights[i, j]
        # steepest descent rate (down component of the unit direction) of the boundary rays within the
        # arc of those cells (+-1.5 posts) around the seed's azimuth
        la_q = lat0 + bnd_i[q] * dlat
        lo_q = lon0 + bnd_j[q] * dlon
        x, y, z = _ned(la_q - lat, lo_q - lon, heights[ci, cj], ha, s, c, m, n, dm)
        ua = x * ax + y * ay + z * az
        px = x - ua * ax
        py = y - ua * ay
        pz = z - ua * az
        pn = np.sqrt(px * px + py * py + pz * pz)
        dz_b = dz_max
        if pn > 1e-9:
            # d(dz)/d(azimuth) <= sin(half beam) sin(tilt); the arc spans <= 2 posts (diagonal) / |perp| rad
            dz_b = cosb * az + sinb * pz / pn + sinb * np.sin(tilt) * min(2.0 * cell_m / pn, np.pi)
            dz_b = min(dz_b, dz_max)
        if dz_b > 0.0 and (ha - hmx) > best * dz_b:
            continue
        near = False
        for p in range(n_done):
            sep = 2.5 if p >= n_ref else (1.5 if res_t[p] else -1.0)
            if abs(done_i[p] - bnd_i[q]) <= sep and abs(done_j[p] - bnd_j[q]) <= sep:
                near = True
        if near:
            continue
        done_i[n_done] = bnd_i[q]
        done_j[n_done] = bnd_j[q]
        res_f[n_done] = bnd_f[q]
        res_key[n_done] = bnd_key[q]
        res_t[n_done] = True
        n_done += 1
    if best == _INF:
        return
    # 5) on the cone boundary the pattern search can stall: 1-D search in azimuth along the boundary from
    #    every refined point near the best (the closest point may lie on another stretch of the boundary)
    #    Two phases: every boundary search first shrinks to a coarse step; only those whose coarse best
    #    lies within the fine phase's possible gain of the overall best are finished.
    final = _INF
    fin_lat = fin_lon = fin_h = np.nan
    n_b = 0
    bst = np.empty((2 * n_done, 9))
    for p_res in range(n_done):
        if res_key[p_res] > final + margin or res_f[p_res] == _INF:
            continue
        best = res_f[p_res]
        best_i = done_i[p_res]
        best_j = done_j[p_res]
        la = lat0 + best_i * dlat
        lo = lon0 + best_j * dlon
        hp = bilinear(heights, lat0, lon0, dlat, dlon, la, lo)
        x, y, z = _ned(la - lat, lo - lon, hp, ha, s, c, m, n, dm)
        cos_off = (x * ax + y * ay + z * az) / best
        if best < final:
            final = best
            fin_lat, fin_lon, fin_h = la, lo, hp
        if res_t[p_res] or cos_off < cosb + 1e-6:
            az0 = np.arctan2(x * e2x + y * e2y + z * e2z, x * e1x + y * e1y + z * e1z)
            r_arc = max(best * sinb, 1e-6)
            fb0, dx0, dy0, dz0, sl0 = _boundary_eval(
                heights, lat0, lon0, dlat, dlon, h_min, h_max, cell_m, lat, lon, ha, s, c, m, n, dm,
                ax, ay, az, e1x, e1y, e1z, e2x, e2y, e2z, cosb, sinb, max_range, az0, best, 0.0,
            )
            # two reaches (+-3 and +-1.5 posts of arc): the wide search can step over a nearby minimum
            for width_posts in (3.0, 1.5):
                if width_posts < 2.0 and abs(bst[n_b - 1, 1] - az0) * r_arc < 0.75 * cell_m:
                    break  # the wide search stayed near its start: the narrow one finds the same minimum
                st = bst[n_b]
                st[0] = fb0
                st[1] = az0
                st[2] = dx0
                st[3] = dy0
                st[4] = dz0
                st[5] = fb0 if fb0 < _INF else best
                st[6] = sl0
                st[7] = min(np.pi, width_posts * cell_m / r_arc)
                st[8] = r_arc
                _boundary_search(
                    heights, lat0, lon0, dlat, dlon, h_min, h_max, cell_m, lat, lon, ha, s, c, m, n, dm,
                    ax, ay, az, e1x, e1y, e1z, e2x, e2y, e2z, cosb, sinb, max_range, st, COARSE_ARC_M / r_arc,
                )
                n_b += 1
                if st[0] < final:
                    final = st[0]
                    fin_lat = np.nan  # position filled in below
    # fine phase, most promising first; gain bound = fine reach (arc) x range slope along the boundary
    for _rep in range(n_b):
        q_best = -1
        for q in range(n_b):
            if bst[q, 0] < _INF and (q_best < 0 or bst[q, 0] < bst[q_best, 0]):
                q_best = q
        if q_best < 0:
            break
        st = bst[q_best]
        gain = FINE_SLOPE * st[7] * st[8] + 0.05
        if st[0] - gain > final:
            break
        _boundary_search(
            heights, lat0, lon0, dlat, dlon, h_min, h_max, cell_m, lat, lon, ha, s, c, m, n, dm, ax, ay, az,
            e1x, e1y, e1z, e2x, e2y, e2z, cosb, sinb, max_range, st, W_MIN_M / st[8],
        )
        fb = st[0]
        if fb <= final:
            final = fb
            dphi, dlam, _ = _geo_of_ned(fb * st[2], fb * st[3], fb * st[4], ha, s, c, m, n, dm)
            fin_lat = lat + dphi
            fin_lon = lon + dlam
            fin_h = bilinear(heights, lat0, lon0, dlat, dlon, fin_lat, fin_lon)
        st[0] = _INF  # done
    best = final
    out_lat, out_lon, out_h = fin_lat, fin_lon, fin_h
    out[0] = 1.0
    out[1] = best
    out[2] = out_lat
    out[3] = out_lon
    out[4] = out_h


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
    bslope,
    valid,
    rng,
    lat_out,
    lon_out,
    h_out,
):
    h_min = _finite_range(bmin)[0]
    h_max = _finite_range(bmax)[1]
    g_max = _finite_range(bslope)[1]
    cosb = np.cos(half_beam)
    sinb = np.sin(half_beam)
    out = np.empty(5)
    for k in range(lat.shape[0]):
        ax, ay, az = C_bn[k, 0, 2], C_bn[k, 1, 2], C_bn[k, 2, 2]
        nrm = np.sqrt(ax * ax + ay * ay + az * az)
        if not (nrm > 0.0) or h[k] != h[k] or lat[k] != lat[k] or lon[k] != lon[k]:
            valid[k] = False
            rng[k] = lat_out[k] = lon_out[k] = h_out[k] = np.nan
            continue
        _ra_one(
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
            ax / nrm,
            ay / nrm,
            az / nrm,
            cosb,
            sinb,
            max_range,
            bs,
            bmax,
            bmin,
            g_max,
            out,
        )
        valid[k] = out[0] > 0.5
        rng[k] = out[1]
        lat_out[k] = out[2]
        lon_out[k] = out[3]
        h_out[k] = out[4]


# ----------------------------------------------------------------------------------------- IRA
@njit(cache=True, fastmath=False, error_model="numpy")
def _zd_point(
    heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, vx, vy, vz, uhx, uhy, vh, sv, t_guess, tol
):
    """Terrain point on the zero-Doppler plane at across-track nominal coordinate sv (m).

    Nominal horizontal coordinates (north, east) = sv * w_h + t * u_h, w_h = right-perpendicular of the
    horizontal velocity direction u_h; t solves v_hat . NED(point) = 0 by the secant method.
    Returns (t, x, y, z, dphi, dlam, hp) or t = NaN."""
    mh = m + ha
    nhc = (n + ha) * c
    wx = -uhy
    wy = uhx
    t0 = t_guess
    t1 = t_guess + 1.0
    p0 = 0.0
    x = y = z = dphi = dlam = hp = np.nan
    for it in range(30):
        tt = t0 if it == 0 else t1
        north = sv * wx + tt * uhx
        east = sv * wy + tt * uhy
        dphi = north / mh
        dlam = east / nhc
        hp = bilinear(heights, lat0, lon0, dlat, dlon, lat + dphi, lon + dlam)
        if hp != hp:
            return np.nan, x, y, z, dphi, dlam, hp
        x, y, z = _ned(dphi, dlam, hp, ha, s, c, m, n, dm)
        p = vx * x + vy * y + vz * z
        if abs(p) < tol:
            return tt, x, y, z, dphi, dlam, hp
        if it == 0:
            p0 = p
            # Newton-like first step: dP/dt ~ |v_h|
            t1 = t0 - p / vh
            continue
        denom = p - p0
        if denom == 0.0:
            t_new = t1 - p / vh
        else:
            t_new = t1 - p * (t1 - t0) / denom
        # safeguard: limit the step
        lim = 4.0 * (abs(t1 - t0) + 1.0)
        if abs(t_new - t1) > lim:
            t_new = t1 + lim * np.sign(t_new - t1)
        t0, p0 = t1, p
        t1 = t_new
    return np.nan, x, y, z, dphi, dlam, hp


@njit(cache=True, fastmath=False, error_model="numpy")
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


@njit(cache=True, fastmath=False, error_model="numpy")
def _region_max(bs, bmax, n_lat, n_lon, lat0, lon0, dlat, dlon, lat, lon, mh, nhc, n_a, n_b, e_a, e_b):
    """Upper bound of the terrain height over the NED rectangle [n_a, n_b] x [e_a, e_b] (-inf: no terrain)."""
    i_a = int(np.floor((lat + n_a / mh - lat0) / dlat))
    i_b = int(np.ceil((lat + n_b / mh - lat0) / dlat))
    j_a = int(np.floor((lon + e_a / nhc - lon0) / dlon))
    j_b = int(np.ceil((lon + e_b / nhc - lon0) / dlon))
    if i_b < 0 or j_b < 0 or i_a > n_lat - 1 or j_a > n_lon - 1:
        return -_INF
    nbi, nbj = bmax.shape
    bi_a = min(max(i_a, 0) // bs, nbi - 1)
    bi_b = min(min(i_b, n_lat - 1) // bs, nbi - 1)
    bj_a = min(max(j_a, 0) // bs, nbj - 1)
    bj_b = min(min(j_b, n_lon - 1) // bs, nbj - 1)
    hi = -_INF
    for bi in range(bi_a, bi_b + 1):
        for bj in range(bj_a, bj_b + 1):
            if bmax[bi, bj] > hi:
                hi = bmax[bi, bj]
    return hi


@njit(cache=True, fastmath=False, error_model="numpy")
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
    bs,
    bmax,
    bslope,
    g_glob,
    out,
):
    """Closest in-window zero-Doppler terrain point; writes (valid, range, lat, lon, h) into out[0:5].

    1) coarse march along the curve one post apart, outward from the across-track coordinate s = 0, stopping
       where no farther point can beat the best and skipping samples whose neighbourhood (+-1 post) lies in
       blocks too low to beat it; 2) branch and bound over the intervals between samples: the range is
       Lipschitz in s with a constant from the blocks' maximum slopes (_ira_lipschitz), so an interval with
       (f_a + f_b - L w) / 2 >= best - tol cannot hold a closer point and is dropped, the others are
       bisected (split where the chord crosses a grid line, so that the pieces are smooth and the bound
       from the cell's slope and twist on r'' applies: min(f_a, f_b) - K w^2 / 8)."""
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
    step = cell_m
    gam = abs(vz) / vh
    n_max = buf_s.shape[0]
    half = n_max // 2
    best = _INF
    # the buffers are written for every visited sample, and the visited samples are contiguous: lo_q..hi_q
    t0 = 0.0
    hp0 = bilinear(heights, lat0, lon0, dlat, dlon, lat, lon)
    if hp0 == hp0:
        t0 = -(vz / vh) * (ha - hp0)
    lo_q = half
    hi_q = half
    # 1) coarse march outward from s = 0 in both directions (buffer index half + k <-> s = k * step)
    for direction in (1, -1):
        t_prev = t0
        misses = 0
        k = 0 if direction == 1 else 1
        while True:
            q = half + direction * k
            if q < 1 or q >= n_max - 1:
                break
            sv = (q - half) * step
            horiz_lb = (abs(sv) - step) * 0.998 - 2.0  # covers the neighbouring intervals too
            if horiz_lb > max_range:
                break
            if (
                best < _INF
                and d_top > 0.0
                and horiz_lb > 0.0
                and horiz_lb * horiz_lb + d_top * d_top > best * best
            ):
                break
            if q < lo_q:
                lo_q = q
            if q > hi_q:
                hi_q = q
            if best < _INF and horiz_lb > 0.0:
                # skip the sample when the blocks its terrain point (and the intervals on either side) can
                # lie in are too low to beat the best
                tz = -(vz / vh)
                t_a = tz * (ha - h_max - 5.0)
                t_b = tz * (ha - h_min + 5.0 + sv * sv / 6.3e6)
                t_lo = min(t_a, t_b) - 5.0 - 0.01 * abs(sv)
                t_hi = max(t_a, t_b) + 5.0 + 0.01 * abs(sv)
                na = -sv * uhy + t_lo * uhx
                nb = -sv * uhy + t_hi * uhx
                ea = sv * uhx + t_lo * uhy
                eb = sv * uhx + t_hi * uhy
                hb = _region_max(
                    bs,
                    bmax,
                    n_lat,
                    n_lon,
                    lat0,
                    lon0,
                    dlat,
                    dlon,
                    lat,
                    lon,
                    mh,
                    nhc,
                    min(na, nb) - step,
                    max(na, nb) + step,
                    min(ea, eb) - step,
                    max(ea, eb) + step,
                )
                dv = ha - hb
                if dv > 0.0 and horiz_lb * horiz_lb + dv * dv > best * best:
                    buf_s[q] = sv
                    buf_f[q] = _PRUNED
                    buf_t[q] = np.nan
                    buf_r[q] = _INF
                    buf_z[q] = np.nan
                    k += 1
                    continue
            f, t, r, z = _ira_eval(
                heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, vx, vy, vz, uhx, uhy, vh, C,
                sin_w, max_range, sv, t_prev, 1e-3,
            )
            buf_s[q] = sv
            buf_f[q] = f
            buf_t[q] = t
            buf_r[q] = r
            buf_z[q] = z
            if t == t and r < _INF:
                t_prev = t
                misses = 0
            else:
                misses += 1
                if misses > 3:
                    break
            if f < best:
                best = f
            k += 1
    if best == _INF:
        return
    best_s = np.nan
    best_t = np.nan
    for q in range(lo_q, hi_q + 1):
        if buf_f[q] == best:
            best_s = buf_s[q]
            best_t = buf_t[q]
            break
    # 2) branch and bound over the intervals between coarse samples
    tol = 5e-3  # m: an interval must promise at least this much improvement to be searched
    n_st = 0
    cap = stack.shape[0]
    for q in range(lo_q, hi_q):
        fa = buf_f[q]
        fb = buf_f[q + 1]
        if fa == _PRUNED or fb == _PRUNED or (fa == _INF and fb == _INF):
            continue
        if buf_r[q] == _INF and buf_r[q + 1] == _INF:
            continue
        if n_st < cap:
            # insertion by key min(f_a, f_b), descending, so the most promising interval is popped first
            key = min(fa, fb)
            row = n_st
            while row > 0 and min(stack[row - 1, 1], stack[row - 1, 6]) < key:
                stack[row, :] = stack[row - 1, :]
                row -= 1
            stack[row, 0] = buf_s[q]
            stack[row, 1] = fa
            stack[row, 2] = buf_t[q]
            stack[row, 3] = buf_r[q]
            stack[row, 4] = buf_z[q]
            stack[row, 5] = buf_s[q + 1]
            stack[row, 6] = fb
            stack[row, 7] = buf_t[q + 1]
            stack[row, 8] = buf_r[q + 1]
            stack[row, 9] = buf_z[q + 1]
            n_st += 1
    n_eval = 0
    while n_st > 0 and n_eval < 20000:
        n_st -= 1
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
        w = b - a
        split = 0.5 * (a + b)
        if ra == _INF or rb == _INF:
            # an end without terrain/point: unknown geometry there, bisect until the interval is tiny
            if w < 0.05:
                continue
            lb = min(fa, fb) - (1.0 + g_glob) * 2.0 * w
        else:
            # grid coordinates of the two ends (exact: _zd_point's north/east -> lat/lon map)
            fia = (lat + (-a * uhy + ta * uhx) / mh - lat0) / dlat
            fja = (lon + (a * uhx + ta * uhy) / nhc - lon0) / dlon
            fib = (lat + (-b * uhy + tb * uhx) / mh - lat0) / dlat
            fjb = (lon + (b * uhx + tb * uhy) / nhc - lon0) / dlon
            cia = min(max(int(np.floor(fia)), 0), n_lat - 2)
            cja = min(max(int(np.floor(fja)), 0), n_lon - 2)
            cib = min(max(int(np.floor(fib)), 0), n_lat - 2)
            cjb = min(max(int(np.floor(fjb)), 0), n_lon - 2)
            one_cell = cia == cib and cja == cjb
            if one_cell:
                # smooth piece inside one bilinear cell: the cell's own slope and twist bound r' and r''
                h00 = heights[cia, cja]
                h01 = heights[cia, cja + 1]
                h10 = heights[cia + 1, cja]
                h11 = heights[cia + 1, cja + 1]
                dn_c = dlat * mh
                de_c = dlon * nhc
                gu = max(abs(h10 - h00), abs(h11 - h01)) / dn_c
                gv = max(abs(h01 - h00), abs(h11 - h10)) / de_c
                g = np.sqrt(gu * gu + gv * gv)
                h_ne = abs(h00 - h01 - h10 + h11) / (dn_c * de_c)
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
                g = _region_max(
                    bs, bslope, n_lat, n_lon, lat0, lon0, dlat, dlon, lat, lon, mh, nhc, n_lo, n_hi, e_lo,
                    e_hi,
                )
                h_ne = 0.0
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
            if fa < _INF and fb < _INF:
                lb = 0.5 * (fa + fb - lip * w)
                if one_cell:
                    # |r''| <= |P'|^2 / r + |P''| with |z''| <= (|h_ss| + 1/R) / (1 - gamma g)
                    p1sq = 1.0 + tp * tp + zp * zp
                    r_lo = max(min(ra, rb) - np.sqrt(p1sq) * w, 0.05 * min(ra, rb))
                    # h_ss = 2 h_ne x'_n x'_e on the bilinear cell, x' = w_h + t' u_h
                    xnxe = (abs(uhy) + tp * abs(uhx)) * (abs(uhx) + tp * abs(uhy))
                    zpp = (2.0 * h_ne * xnxe + 1.0 / 6.3e6) / den
                    kk = 1.05 * (p1sq / r_lo + (1.0 + gam) * zpp)
                    lb = max(lb, min(fa, fb) - 0.125 * kk * w * w)
            else:
                lb = min(fa, fb) - lip * w
        if lb >= best - tol or w < 1e-4:
            continue
        mid = split
        tg = ta if ta == ta else tb
        if tg != tg:
            tg = best_t if best_t == best_t else t0
        fm, tm, rm, zm = _ira_eval(
            heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, vx, vy, vz, uhx, uhy, vh, C,
            sin_w, max_range, mid, tg, 1e-3,
        )
        n_eval += 1
        if fm < best:
            best = fm
            best_s = mid
            best_t = tm
        if n_st + 2 > cap:
            continue
        # push the less promising half first so the more promising one is searched first
        first_left = fa <= fb
        for side in range(2):
            left = (side == 1) == first_left
            row = n_st
            if left:
                stack[row, 0] = a
                stack[row, 1] = fa
                stack[row, 2] = ta
                stack[row, 3] = ra
                stack[row, 4] = za
                stack[row, 5] = mid
                stack[row, 6] = fm
                stack[row, 7] = tm
                stack[row, 8] = rm
                stack[row, 9] = zm
            else:
                stack[row, 0] = mid
                stack[row, 1] = fm
                stack[row, 2] = tm
                stack[row, 3] = rm
                stack[row, 4] = zm
                stack[row, 5] = b
                stack[row, 6] = fb
                stack[row, 7] = tb
                stack[row, 8] = rb
                stack[row, 9] = zb
            n_st += 1
    # 3) polish the location (the bound stops at tol in range, which on a flat minimum leaves metres of
    #    slack in position): three-point steps with a parabolic jump, h = 1 m, 0.1 m, 0.01 m
    centre = best_s
    tc = best_t
    fc = best
    h_p = 0.5
    for _it in range(12):
        if h_p < 5e-3:
            break
        fm, tm, _, _ = _ira_eval(
            heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, vx, vy, vz, uhx, uhy, vh, C,
            sin_w, max_range, centre - h_p, tc, 1e-4,
        )
        fp, tp_, _, _ = _ira_eval(
            heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, vx, vy, vz, uhx, uhy, vh, C,
            sin_w, max_range, centre + h_p, tc, 1e-4,
        )
        if fm < fc and fm <= fp:
            centre, fc, tc = centre - h_p, fm, tm
            continue
        if fp < fc:
            centre, fc, tc = centre + h_p, fp, tp_
            continue
        den = fm - 2.0 * fc + fp
        if den > 0.0 and den < _INF:
            x_v = centre + 0.5 * h_p * (fm - fp) / den
            fx, tx, _, _ = _ira_eval(
                heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, vx, vy, vz, uhx, uhy, vh, C,
                sin_w, max_range, x_v, tc, 1e-4,
            )
            if fx < fc:
                centre, fc, tc = x_v, fx, tx
        h_p *= 0.1
    t, x, y, z, dphi, dlam, hp = _zd_point(
        heights, lat0, lon0, dlat, dlon, lat, lon, ha, s, c, m, n, dm, vx, vy, vz, uhx, uhy, vh, centre, tc,
        1e-6,
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
    bs,
    bmax,
    bmin,
    bslope,
    valid,
    rng,
    lat_out,
    lon_out,
    h_out,
):
    h_min = _finite_range(bmin)[0]
    h_max = _finite_range(bmax)[1]
    sin_w = np.sin(half_window)
    g_glob = _finite_range(bslope)[1]
    n_max = 2 * int(np.ceil(max_range / cell_m)) + 9
    buf_s = np.empty(n_max)
    buf_f = np.empty(n_max)
    buf_t = np.empty(n_max)
    buf_r = np.empty(n_max)
    buf_z = np.empty(n_max)
    stack = np.empty((4096, 10))
    out = np.empty(5)
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
            bs,
            bmax,
            bslope,
            g_glob,
            out,
        )
        valid[k] = out[0] > 0.5
        rng[k] = out[1]
        lat_out[k] = out[2]
        lon_out[k] = out[3]
        h_out[k] = out[4]


# ----------------------------------------------------------------------------------------- public API
def _positions(lat_rad, lon_rad, h_m):
    lat = np.atleast_1d(np.asarray(lat_rad, dtype=np.float64))
    lon = np.atleast_1d(np.asarray(lon_rad, dtype=np.float64))
    h = np.atleast_1d(np.asarray(h_m, dtype=np.float64))
    lat, lon, h = np.broadcast_arrays(lat, lon, h)
    if lat.ndim != 1:
        raise ValueError(f"antenna positions must be scalars or (n,) arrays, got shape {lat.shape}")
    return np.ascontiguousarray(lat), np.ascontiguousarray(lon), np.ascontiguousarray(h)


def _stack(name, arr, n, shape):
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


def _block_slopes(dem) -> np.ndarray:
    """Per-block maximum slope (terrain.kernels.block_slopes, BLOCK_POSTS blocks), cached on the Dem next
    to its height bounds (keyed by the heights array, which is read-only once queries have run)."""
    cached = getattr(dem, "_query_block_slopes", None)
    if cached is not None and cached[0] is dem.heights_m:
        return cached[1]
    b = dem.bounds
    lat_far = max(abs(b[0]), abs(b[1]))
    lat_near = 0.0 if b[0] <= 0.0 <= b[1] else min(abs(b[0]), abs(b[1]))
    dn = dem.dlat_rad * geodesy.meridian_radius_m(lat_near)  # shortest rows
    de = dem.dlon_rad * geodesy.prime_vertical_radius_m(lat_far) * np.cos(lat_far)  # narrowest columns
    slopes = kernels.block_slopes(dem.heights_m, BLOCK_POSTS, float(dn), float(de))
    dem._query_block_slopes = (dem.heights_m, slopes)
    return slopes


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
    _ra_batch(
        heights,
        lat0,
        lon0,
        dlat,
        dlon,
        _cell_m(dem),
        lat,
        lon,
        h,
        C,
        float(half_beamwidth_rad),
        float(max_range_m),
        *dem.block_bounds(BLOCK_POSTS),
        _block_slopes(dem),
        valid,
        rng,
        la,
        lo,
        hh,
    )
    return TerrainReturn(valid, rng, la, lo, hh)


def ira_return(
    dem, lat_rad, lon_rad, h_m, v_ned, C_bn, half_window_rad: float, max_range_m: float = 12000.0
) -> TerrainReturn:
    """Closest terrain point on the zero-Doppler plane (through the antenna, perpendicular to v_ned (n, 3))
    whose look angle |theta| = |asin(y_b / R)| <= half_window_rad and z_b > 0 (body FRD via C_bn (n, 3,
    3)); theta per seed 000 eqs 18-19."""
    if not (0.0 < half_window_rad < np.pi / 2):
        raise ValueError(f"half_window_rad must be in (0, pi/2), got {half_window_rad}")
    _check_positive("max_range_m", max_range_m)
    lat, lon, h = _positions(lat_rad, lon_rad, h_m)
    n = lat.shape[0]
    v = _stack("v_ned", v_ned, n, (3,))
    C = _stack("C_bn", C_bn, n, (3, 3))
    valid, rng, la, lo, hh = _outputs(n)
    heights, lat0, lon0, dlat, dlon = dem.grid
    _ira_batch(
        heights,
        lat0,
        lon0,
        dlat,
        dlon,
        _cell_m(dem),
        lat,
        lon,
        h,
        v,
        C,
        float(half_window_rad),
        float(max_range_m),
        *dem.block_bounds(BLOCK_POSTS),
        _block_slopes(dem),
        valid,
        rng,
        la,
        lo,
        hh,
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
