"""Ray cast: the first intersection of a ray with the terrain (the bilinear surface of the DEM's posts, in
the exact-curvature frame of terrain.queries.shared).

Guarantee: the returned point is the first sign change of the ray's height above the terrain found by
marching half a post horizontally per step from the depth of the DEM's highest post (a ray that grazes a
ridge for less than one step can pass it), refined by Illinois regula falsi to 1e-5 m in
ray parameter or 1e-6 m in height. Misses within max_range_m, voids and off-grid rays give valid = False.
The radar-altimeter search uses _ray_hit for its first incumbent (the beam-axis hit).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..kernels import bilinear
from .shared import (
    TerrainReturn,
    _cell_m,
    _check_positive,
    _consts,
    _geo_of_ned,
    _height_range,
    _outputs,
    _positions,
    _stack,
)


@njit(cache=True, fastmath=False, error_model="numpy")
def _g_ray(rec, lat, lon, ha, cv, dx, dy, dz, t):
    """Height of the ray point at parameter t above the terrain (m); NaN off-grid."""
    dphi, dlam, hp = _geo_of_ned(t * dx, t * dy, t * dz, ha, cv)
    ht = bilinear(rec[0], rec[1], rec[2], rec[3], rec[4], lat + dphi, lon + dlam)
    return hp - ht


@njit(cache=True, fastmath=False, error_model="numpy")
def _refine_root(rec, lat, lon, ha, cv, dx, dy, dz, ta, ga, tb, gb):
    """Illinois regula falsi on g(t) with g(ta) >= 0 > g(tb); returns t of the crossing."""
    side = 0
    for _ in range(60):
        tm = (ta * gb - tb * ga) / (gb - ga)
        if not (tm > ta and tm < tb):
            tm = 0.5 * (ta + tb)
        gm = _g_ray(rec, lat, lon, ha, cv, dx, dy, dz, tm)
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
def _ray_hit(rec, h_min, h_max, cell_m, lat, lon, ha, cv, dx, dy, dz, t_from, t_to):
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
    g_a = _g_ray(rec, lat, lon, ha, cv, dx, dy, dz, t_a)
    if g_a == g_a and g_a < 0.0:
        if t_a <= 1e-9:
            return 0.0  # the ray starts under the terrain
        # started below the surface (should not happen from the h_max depth): back off to the origin
        t_a = t_from
        g_a = _g_ray(rec, lat, lon, ha, cv, dx, dy, dz, t_a)
        if g_a == g_a and g_a < 0.0:
            return t_a
    while t_a < t_to:
        t_b = min(t_a + step, t_to)
        g_b = _g_ray(rec, lat, lon, ha, cv, dx, dy, dz, t_b)
        if g_a == g_a and g_b == g_b and g_b < 0.0:
            return _refine_root(
                rec, lat, lon, ha, cv, dx, dy, dz, t_a, g_a, t_b, g_b
            )
        if g_b == g_b and dz > 0.0:
            # ray point already below the lowest post and still descending: nothing further to hit
            dphi, dlam, hp = _geo_of_ned(t_b * dx, t_b * dy, t_b * dz, ha, cv)
            if hp < h_min - 1.0:
                return np.nan
        t_a, g_a = t_b, g_b
    return np.nan


@njit(cache=True, fastmath=False, error_model="numpy")
def _ray_cast_batch(rec, cell_m, queries, max_range, height_range, outs):
    """The ray cast of every origin (see ray_cast) on the map record rec (read bilinearly); records (numba
    tuples): queries = (lat, lon, h, dirs); height_range = (h_min, h_max): the DEM's finite height range;
    outs = (valid, rng, lat_out, lon_out, h_out)."""
    heights, lat0, lon0, dlat, dlon, _ = rec
    lat, lon, h, dirs = queries
    h_min, h_max = height_range
    valid, rng, lat_out, lon_out, h_out = outs
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
        cv = _consts(lat[k])
        t = _ray_hit(
            rec, h_min, h_max, cell_m, lat[k], lon[k], h[k], cv, dx, dy, dz, 0.0, max_range
        )
        if t == t:
            dphi, dlam, hp = _geo_of_ned(t * dx, t * dy, t * dz, h[k], cv)
            valid[k] = True
            rng[k] = t
            lat_out[k] = lat[k] + dphi
            lon_out[k] = lon[k] + dlam
            h_out[k] = bilinear(heights, lat0, lon0, dlat, dlon, lat[k] + dphi, lon[k] + dlam)


def ray_cast(dem, lat_rad, lon_rad, h_m, dir_ned, max_range_m: float = 20000.0) -> TerrainReturn:
    """First intersection of rays (origin lat/lon rad, h m MSL; direction dir_ned (n, 3), any length) with
    the terrain, up to max_range_m. Misses, voids and off-grid rays give valid = False."""
    _check_positive("max_range_m", max_range_m)
    lat, lon, h = _positions(lat_rad, lon_rad, h_m)
    dirs = _stack("dir_ned", dir_ned, lat.shape[0], (3,))
    valid, rng, la, lo, hh = _outputs(lat.shape[0])
    _ray_cast_batch(dem.record(), _cell_m(dem), (lat, lon, h, dirs), float(max_range_m),
                    tuple(_height_range(dem)), (valid, rng, la, lo, hh))
    return TerrainReturn(valid, rng, la, lo, hh)
