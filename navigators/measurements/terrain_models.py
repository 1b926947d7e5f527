"""Terrain measurement models over many position hypotheses (grid cells, particles) of one epoch.

Shared by the point-mass filter and the particle filter (navigators.filters.pmf / pf). Every hypothesis k is
an offset of the aircraft from a reference (the INS position): north/east dn_k, de_k (m) and, where the
filter carries them, a horizontal velocity offset dv_k (m/s) and a heading offset dpsi_k (rad). Map lookups
go through the meridian and prime-vertical radii at the reference (seed 000 eq 2: offsets of a few km).

- IRA (seed 000 sections 3.2-3.3): one (R, theta) sample and each hypothesis' attitude and velocity give
  the closest point's position relative to the antenna, p_k (NED), by the proposed formula (seed 000 eqs
  14-36) or the conventional one (eqs 9-13); `ira_points_batch` is navigators.measurements.
  closest_point_ned over hypotheses. The measured terrain height is h_antenna - p_d (eq 2) and the
  prediction the map height at the hypothesis' position + p_ne: one map lookup per hypothesis.
- Radar altimeter (seed 000 eq 1; seed 001 ch. 4): terrain clearance h_antenna - range against the map
  under the hypothesis, where the range is the shortest return inside the beam cone around the body down
  axis. `ra_cone_ranges` samples the cone's footprint on rings (n_rings = 0: the nadir ray only) and keeps
  the shortest in-cone distance; with the aircraft banked past the half beamwidth the nadir leaves the
  cone and the shortest return is a slant one - the case where the hypothesis' attitude matters. It is
  checked against the exact branch-and-bound search terrain.queries.radar_altimeter_return in the tests.
- `robust_log_likelihood`: a heavy-tailed mixture (1 - eps) N(r; 0, S) + eps / width, so one bad return
  (an outlier, a multipath, a map void) cannot zero a hypothesis; a NaN residual (a lookup off the map) gets
  the outlier density only.

Every kernel writes into arrays the caller allocates, and has a plain numpy `*_reference` twin in the tests.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ...terrain.geodesy import meridian_radius_m, prime_vertical_radius_m
from ...terrain.kernels import bilinear

IRA_FORMULA_CODES = {"conventional": 0, "proposed": 1}
LOG_2PI = math.log(2.0 * math.pi)


def radii_m(lat_rad: float, h_m: float) -> tuple[float, float]:
    """(R_N + h, (R_E + h) cos lat): metres per radian of latitude and of longitude (seed 000 eq 2)."""
    return (float(meridian_radius_m(lat_rad)) + h_m,
            (float(prime_vertical_radius_m(lat_rad)) + h_m) * math.cos(lat_rad))


@njit(cache=True, fastmath=False, error_model="numpy")
def ira_points_batch(range_m, theta_rad, C_bn, v_ned, dpsi, dv_ne, code, out):
    """Closest-point vectors p (m, NED) of one IRA sample (range_m, theta_rad) for every hypothesis k.

    C_bn (3, 3), v_ned (3,): the reference (INS) attitude and velocity; hypothesis k has heading C_bn turned
    by dpsi[k] about the down axis and velocity v_ned + (dv_ne[k, 0], dv_ne[k, 1], 0). dpsi has length m
    or 1 (shared), dv_ne shape (m, 2) or (1, 2). code 1: proposed (seed 000 eqs 14-36, branch nearest the
    conventional angle as in navigators.measurements.ira_closest_point); 0: conventional (eqs 9-13, angle
    theta - roll). out (m, 3); a hypothesis without a solution (|sin theta| > |t|) gets NaN. Returns the
    number of NaN rows."""
    m = out.shape[0]
    sth = math.sin(theta_rad)
    roll = math.atan2(C_bn[2, 1], C_bn[2, 2])  # a turn about the down axis leaves the roll unchanged
    ref = theta_rad - roll
    cr, sr = math.cos(ref), math.sin(ref)
    n_bad = 0
    for k in range(m):
        ps = dpsi[k] if dpsi.shape[0] > 1 else dpsi[0]
        kv = k if dv_ne.shape[0] > 1 else 0
        vn = v_ned[0] + dv_ne[kv, 0]
        ve = v_ned[1] + dv_ne[kv, 1]
        vd = v_ned[2]
        vh = math.sqrt(vn * vn + ve * ve)
        vv = math.sqrt(vh * vh + vd * vd)
        if not (vh > 0.0):
            out[k, 0] = out[k, 1] = out[k, 2] = np.nan
            n_bad += 1
            continue
        # eqs 9, 10, 12 without the angles: sin/cos of alpha (up positive) and beta (track)
        sa, ca, sb, cb = -vd / vv, vh / vv, ve / vh, vn / vh
        s1n, s1e, s1d = sa * cb, sa * sb, ca  # eq 12 in NED
        s2n, s2e = -sb, cb
        if code == 0:
            c, s = cr, sr  # eq 13 with the project's sign (theta - roll)
        else:
            cp, sp = math.cos(ps), math.sin(ps)
            # body right axis of the hypothesis: Rz(dpsi) C_bn[:, 1]
            yn = cp * C_bn[0, 1] - sp * C_bn[1, 1]
            ye = sp * C_bn[0, 1] + cp * C_bn[1, 1]
            yd = C_bn[2, 1]
            t1 = yn * s1n + ye * s1e + yd * s1d  # eq 31
            t2 = yn * s2n + ye * s2e
            rho = math.sqrt(t1 * t1 + t2 * t2)
            if not (rho > 0.0) or abs(sth) > rho:
                out[k, 0] = out[k, 1] = out[k, 2] = np.nan
                n_bad += 1
                continue
            # eqs 32-35: sin(eta + xi) = sin(theta) / rho with sin eta = t1 / rho, cos eta = t2 / rho; the two
            # solutions xi_a = asin(.) - eta and xi_b = pi - asin(.) - eta by their sines and cosines
            u = sth / rho
            cu = math.sqrt(max(1.0 - u * u, 0.0))
            se, ce = t1 / rho, t2 / rho
            ca_ = cu * ce + u * se
            sa_ = u * ce - cu * se
            cb_ = -(cu * ce - u * se)
            sb_ = u * ce + cu * se
            # the branch nearest the conventional angle: the larger cos(xi - ref)
            if ca_ * cr + sa_ * sr >= cb_ * cr + sb_ * sr:
                c, s = ca_, sa_
            else:
                c, s = cb_, sb_
        out[k, 0] = range_m * (c * s1n + s * s2n)  # eq 36 (eq 13 for the conventional angle)
        out[k, 1] = range_m * (c * s1e + s * s2e)
        out[k, 2] = range_m * (c * s1d)
    return n_bad


@njit(cache=True, fastmath=False, error_model="numpy")
def map_heights_at_offsets(heights, lat0, lon0, dlat, dlon, lat_ref, lon_ref, r_lat_m, r_lon_m,
                           dn_m, de_m, shift_n_m, shift_e_m, out):
    """Map height (bilinear, m) at the reference + (dn_m[k] + shift_n_m[k], de_m[k] + shift_e_m[k]) for
    every hypothesis k (shift arrays of length m, or 1 for a shift shared by all). r_lat_m, r_lon_m: metres
    per radian of latitude / longitude at the reference (radii_m). NaN off the map. Returns the NaN count."""
    n_nan = 0
    m = dn_m.shape[0]
    shared = shift_n_m.shape[0] == 1
    for k in range(m):
        sn = shift_n_m[0] if shared else shift_n_m[k]
        se = shift_e_m[0] if shared else shift_e_m[k]
        h = bilinear(heights, lat0, lon0, dlat, dlon, lat_ref + (dn_m[k] + sn) / r_lat_m,
                     lon_ref + (de_m[k] + se) / r_lon_m)
        out[k] = h
        if h != h:
            n_nan += 1
    return n_nan


@njit(cache=True, fastmath=False, error_model="numpy")
def _cone_ray(heights, lat0, lon0, dlat, dlon, lat_k, lon_k, r_lat_m, r_lon_m, ha, agl, ax, ay, az, ux, uy,
              uz,
              wx, wy, wz, ang, ph, cosb):
    """Distance (m) to the map along the cone direction at angle ang from the axis, azimuth ph (inf if the
    line of sight misses the map or leaves the cone)."""
    ca, sa = math.cos(ang), math.sin(ang)
    cph, sph = math.cos(ph), math.sin(ph)
    dx = ca * ax + sa * (cph * ux + sph * wx)
    dy = ca * ay + sa * (cph * uy + sph * wy)
    dz = ca * az + sa * (cph * uz + sph * wz)
    if dz <= 1e-3:
        return np.inf
    t = agl / dz
    for _ in range(4):   # fixed point: where this line of sight meets the terrain
        hp = bilinear(heights, lat0, lon0, dlat, dlon, lat_k + t * dx / r_lat_m, lon_k + t * dy / r_lon_m)
        if hp != hp:
            return np.inf
        t = (ha - hp) / dz
    if not (t > 0.0):
        return np.inf
    hp = bilinear(heights, lat0, lon0, dlat, dlon, lat_k + t * dx / r_lat_m, lon_k + t * dy / r_lon_m)
    if hp != hp:
        return np.inf
    px, py, pz = t * dx, t * dy, ha - hp
    d = math.sqrt(px * px + py * py + pz * pz)
    if d > 0.0 and (px * ax + py * ay + pz * az) >= cosb * d - 1e-9:
        return d
    return np.inf


@njit(cache=True, fastmath=False, error_model="numpy")
def ra_cone_ranges(heights, lat0, lon0, dlat, dlon, lat_ref, lon_ref, r_lat_m, r_lon_m, h_ant_m,
                   dn_m, de_m, dh_m, C_bn, dpsi, half_beam_rad, n_rings, n_az, out):
    """Predicted radar-altimeter range (m) for every hypothesis k: the shortest distance from the antenna
    at the reference + (dn_m[k], de_m[k]) and height h_ant_m - dh_m[k] (dh_m length m or 1) to the map
    inside the cone of half-angle half_beam_rad around the body down axis Rz(dpsi[k]) C_bn[:, 2] (dpsi
    length m or 1).

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
        h_nadir = bilinear(heights, lat0, lon0, dlat, dlon, lat_k, lon_k)
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
        step_a = half_beam_rad / max(n_rings, 1)
        step_p = 2.0 * math.pi / n_az
        best_a, best_p = 0.0, 0.0
        for r in range(n_rings + 1):
            ang = step_a * r
            n_a = 1 if r == 0 else n_az
            for q in range(n_a):
                ph = step_p * q
                d = _cone_ray(heights, lat0, lon0, dlat, dlon, lat_k, lon_k, r_lat_m, r_lon_m, ha, agl, ax,
                              ay,
                              az, ux, uy, uz, wx, wy, wz, ang, ph, cosb)
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
                        d = _cone_ray(heights, lat0, lon0, dlat, dlon, lat_k, lon_k, r_lat_m, r_lon_m, ha,
                                      agl,
                                      ax, ay, az, ux, uy, uz, wx, wy, wz, ang, ph, cosb)
                        if d < best:
                            best, best_a, best_p = d, ang, ph
        if best < np.inf:
            out[k] = best
        else:
            out[k] = np.nan
            n_nan += 1
    return n_nan


@njit(cache=True, fastmath=False, error_model="numpy")
def robust_ll_one(r, s, lg, le):
    """log((1 - eps) N(r; 0, s) + eps u) of one residual r (m) with variance s (m^2); lg = log(1 - eps),
    le = log(eps u) (-inf: no outlier term). NaN r: le. The scalar behind robust_log_likelihood, for kernels
    that fuse it with their lookups (the point-mass filter's)."""
    if r != r:
        return le
    a = lg - 0.5 * (r * r / s + math.log(s) + LOG_2PI)
    if le == -np.inf:
        return a
    if a > le:
        return a + math.log1p(math.exp(le - a))
    return le + math.log1p(math.exp(a - le))


@njit(cache=True, fastmath=False, error_model="numpy")
def robust_log_likelihood(residual_m, var_m2, outlier_prob, log_outlier_density, out):
    """log((1 - eps) N(r; 0, S) + eps * u) per hypothesis (eps = outlier_prob, log u = log_outlier_density);
    var_m2 has length m or 1. A NaN residual gets log(eps u) (no information but not impossible; -inf when
    eps = 0). Returns the number of NaN residuals."""
    m = residual_m.shape[0]
    le = math.log(outlier_prob) + log_outlier_density if outlier_prob > 0.0 else -np.inf
    lg = math.log1p(-outlier_prob) if outlier_prob < 1.0 else -np.inf
    n_nan = 0
    for k in range(m):
        s = var_m2[0] if var_m2.shape[0] == 1 else var_m2[k]
        r = residual_m[k]
        if r != r:
            n_nan += 1
        out[k] = robust_ll_one(r, s, lg, le)
    return n_nan


def ira_points_reference(range_m: float, theta_rad: float, C_bn: np.ndarray, v_ned: np.ndarray,
                         dpsi: np.ndarray, dv_ne: np.ndarray, formula: str) -> np.ndarray:
    """ira_points_batch through the single-query formulas (navigators.measurements.closest_point_ned)."""
    from .ira_closest_point import closest_point_ned
    m = max(len(dpsi), len(dv_ne))
    dpsi = np.broadcast_to(dpsi, (m,))
    dv = np.broadcast_to(dv_ne, (m, 2))
    c, s = np.cos(dpsi), np.sin(dpsi)
    Rz = np.zeros((m, 3, 3))
    Rz[:, 0, 0] = c
    Rz[:, 0, 1] = -s
    Rz[:, 1, 0] = s
    Rz[:, 1, 1] = c
    Rz[:, 2, 2] = 1.0
    C = Rz @ C_bn
    v = np.tile(np.asarray(v_ned, float), (m, 1))
    v[:, :2] += dv
    return closest_point_ned(np.full(m, range_m), np.full(m, theta_rad), None, None, None, v,
                             formula=formula, C_bn=C)


def robust_log_likelihood_reference(residual_m, var_m2, outlier_prob, log_outlier_density):
    """robust_log_likelihood in numpy (logaddexp of the two mixture terms)."""
    r = np.asarray(residual_m, float)
    s = np.broadcast_to(np.asarray(var_m2, float), r.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.log1p(-outlier_prob) - 0.5 * (r * r / s + np.log(s) + LOG_2PI)
        le = np.log(outlier_prob) + log_outlier_density
        return np.where(np.isnan(r), le, np.logaddexp(a, le))
