"""Radar altimeter measurement model (seed 000 eq 1; seed 001 ch. 4): the terrain clearance under hypotheses.

The altimeter measures the range to the nearest terrain inside its beam, a cone of half-angle beta around
the body down axis; the measured terrain height is h_antenna - range (seed 000 eq 1). Over many hypotheses
(grid cells, particles: offsets dn_k, de_k of the aircraft from a reference, a height offset dh_k and a
heading offset dpsi_k, map lookups through the radii at the reference, seed 000 eq 2):

- `predict(rec, ...)`: the predicted range of every hypothesis on the map record (navigators.core.maps.
  MapRecord): the shortest distance inside the cone. The cone is sampled by lines of sight on rings
  (n_rings = 0: the axis and the vertical only), each traced to the map by a fixed-point iteration, and
  refined around the shortest; with the aircraft banked past the half beamwidth the nadir leaves the cone
  and the shortest return is a slant one - the case where the hypothesis' attitude matters. It is checked
  against the exact branch-and-bound search terrain.queries.radar_altimeter_return in the tests.
- `variance(sigma_m, map_sigma_m, terrain_model_sigma_m)`: the measured height's variance: the sensor's,
  the map's error class and the terrain the map does not resolve.
- `likelihood`: the heavy-tailed terrain likelihood every terrain sensor shares
  (navigators.measurements.terrain_models.robust_log_likelihood) of the residuals (measured minus
  predicted terrain height).

The kernels write into arrays the caller allocates (numba, cache=True).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..core.maps import map_height
from .terrain_models import robust_log_likelihood as likelihood


def variance(sigma_m: float, map_sigma_m: float, terrain_model_sigma_m: float) -> float:
    """Variance (m^2) of the terrain height an altimeter sample measures: sensor, map, unresolved terrain."""
    return sigma_m ** 2 + map_sigma_m ** 2 + terrain_model_sigma_m ** 2


@njit(cache=True, fastmath=False, error_model="numpy")
def _cone_ray(rec, ant, cone, ang, ph):
    """Distance (m) to the map along the cone direction at angle ang from the axis, azimuth ph (inf if the
    line of sight misses the map or leaves the cone). Records (numba tuples): ant = (lat, lon rad, r_lat_m,
    r_lon_m the radii of the map lookups, h_a m, agl m above the map at nadir) the antenna; cone = (ax, ay,
    az the unit axis, ux, uy, uz and wx, wy, wz the orthonormal pair perpendicular to it (NED), cos of the
    half beam)."""
    lat_k, lon_k, r_lat_m, r_lon_m, ha, agl = ant
    ax, ay, az, ux, uy, uz, wx, wy, wz, cosb = cone
    ca, sa = math.cos(ang), math.sin(ang)
    cph, sph = math.cos(ph), math.sin(ph)
    dx = ca * ax + sa * (cph * ux + sph * wx)
    dy = ca * ay + sa * (cph * uy + sph * wy)
    dz = ca * az + sa * (cph * uz + sph * wz)
    if dz <= 1e-3:
        return np.inf
    t = agl / dz
    for _ in range(4):   # fixed point: where this line of sight meets the terrain
        hp = map_height(rec, lat_k + t * dx / r_lat_m, lon_k + t * dy / r_lon_m)
        if hp != hp:
            return np.inf
        t = (ha - hp) / dz
    if not (t > 0.0):
        return np.inf
    hp = map_height(rec, lat_k + t * dx / r_lat_m, lon_k + t * dy / r_lon_m)
    if hp != hp:
        return np.inf
    px, py, pz = t * dx, t * dy, ha - hp
    d = math.sqrt(px * px + py * py + pz * pz)
    if d > 0.0 and (px * ax + py * ay + pz * az) >= cosb * d - 1e-9:
        return d
    return np.inf


@njit(cache=True, fastmath=False, error_model="numpy")
def predict(rec, lat_ref, lon_ref, r_lat_m, r_lon_m, h_ant_m, dn_m, de_m, dh_m, C_bn, dpsi, half_beam_rad,
            n_rings, n_az, out):
    """Predicted radar-altimeter range (m) for every hypothesis k: the shortest distance from the antenna
    at the reference + (dn_m[k], de_m[k]) and height h_ant_m - dh_m[k] (dh_m length m or 1) to the map
    inside the cone of half-angle half_beam_rad around the body down axis Rz(dpsi[k]) C_bn[:, 2] (dpsi
    length m or 1), on the map record `rec` (navigators.core.maps.MapRecord) by its interpolation.

    The cone is sampled by lines of sight on n_rings rings of n_az directions (plus its axis and, when it
    lies inside the cone, the vertical), each traced to the map by a fixed-point iteration; around the
    shortest, three rounds of a 3 x 3 pattern of half the previous steps refine it (the minimum of a
    banked beam sits on the cone's edge, between samples). n_rings = 0: the axis and the vertical only.
    NaN where no line of sight finds the map. Returns the NaN count."""
    m = dn_m.shape[0]
    cosb = math.cos(half_beam_rad)
    n_nan = 0
    for k in range(m):
        ps = dpsi[k] if dpsi.shape[0] > 1 else dpsi[0]
        ha = h_ant_m - (dh_m[k] if dh_m.shape[0] > 1 else dh_m[0])
        cp, sp = math.cos(ps), math.sin(ps)
        ax = cp * C_bn[0, 2] - sp * C_bn[1, 2]
        ay = sp * C_bn[0, 2] + cp * C_bn[1, 2]
        az = C_bn[2, 2]
        lat_k = lat_ref + dn_m[k] / r_lat_m
        lon_k = lon_ref + de_m[k] / r_lon_m
        best = np.inf
        h_nadir = map_height(rec, lat_k, lon_k)
        agl = ha - h_nadir
        if not (agl > 0.0) or not (az > 0.05):
            out[k] = np.nan
            n_nan += 1
            continue
        if az >= cosb:  # the vertical ray lies inside the cone
            best = agl
        # orthonormal pair perpendicular to the axis
        if abs(az) < 0.9:
            ux, uy, uz = -ay, ax, 0.0  # perpendicular to the axis and to the vertical
        else:
            ux, uy, uz = 0.0, az, -ay  # perpendicular to the axis and to north
        nu = math.sqrt(ux * ux + uy * uy + uz * uz)
        ux, uy, uz = ux / nu, uy / nu, uz / nu
        wx = ay * uz - az * uy
        wy = az * ux - ax * uz
        wz = ax * uy - ay * ux
        ant = (lat_k, lon_k, r_lat_m, r_lon_m, ha, agl)
        cone = (ax, ay, az, ux, uy, uz, wx, wy, wz, cosb)
        step_a = half_beam_rad / max(n_rings, 1)
        step_p = 2.0 * math.pi / n_az
        best_a, best_p = 0.0, 0.0
        for r in range(n_rings + 1):
            ang = step_a * r
            n_a = 1 if r == 0 else n_az
            for q in range(n_a):
                ph = step_p * q
                d = _cone_ray(rec, ant, cone, ang, ph)
                if d < best:
                    best, best_a, best_p = d, ang, ph
        if n_rings > 0 and best < np.inf:
            for _ in range(3):
                step_a *= 0.5
                step_p *= 0.5
                a0, p0 = best_a, best_p
                for ia in range(-1, 2):
                    ang = min(max(a0 + ia * step_a, 0.0), half_beam_rad)
                    for ip in range(-1, 2):
                        if ia == 0 and ip == 0:
                            continue
                        ph = p0 + ip * step_p
                        d = _cone_ray(rec, ant, cone, ang, ph)
                        if d < best:
                            best, best_a, best_p = d, ang, ph
        if best < np.inf:
            out[k] = best
        else:
            out[k] = np.nan
            n_nan += 1
    return n_nan


__all__ = ["likelihood", "predict", "variance"]
