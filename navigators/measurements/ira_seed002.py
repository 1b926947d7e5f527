"""Seed 002's IRA measurement model for many position hypotheses of one epoch (eqs 23-26), batched in numba.

For hypothesis i (antenna at lat_i, lon_i, h_i) and the epoch's INS velocity v and attitude C_bn (shared by
all hypotheses: in the RBPF velocity and attitude are the Kalman part, entering through eqs 24-25):

- eq 23, range: R_i = min over the zero-Doppler line (ZDL: terrain points P with v . (P - A_i) = 0) of
  |P - A_i|, restricted to the sensor's look window |theta| <= half_window and to points below the antenna
  (z_b > 0), as trn_env.sensors.ira / terrain.queries.ira_return define the return. Distances use the
  second-order expansion of the WGS84 position about the antenna (terrain.queries' local frame), which
  equals the ECEF distance of eq 23 to < 1 cm within 10 km.
- eq 26, look angle: theta_i = atan(y_b / sqrt(x_b^2 + z_b^2)) (= asin(y_b / R)) of the closest point in
  body axes.
- eq 24, range sensitivity to velocity (step-wise): [dR/dtheta_zdl, dR/dpsi_zdl] (the range gradient when
  the ZDL is tilted in elevation theta_zdl or turned in azimuth psi_zdl, the new closest point searched near
  the old one: its first-order limit by the envelope theorem, see zdl_batch) times the ZDL angles'
  sensitivity to velocity. Departure:
  eq 24 prints that second factor as [[0, 0, -|v_h|], [-1/v_e, 1/v_n, 0]], which is not the Jacobian of any
  angle of v (its units differ); we use the Jacobian of theta_zdl = atan2(-v_d, |v_h|),
  psi_zdl = atan2(v_e, v_n) (tests/test_ira_seed002.py checks the product against finite differences of
  the exact search).
- eq 25, look-angle sensitivity to attitude: [z_b, 0, -x_b] / sqrt(x_b^2 + z_b^2) in body axes (the
  attitude error as a body-axis rotation); rotated to NED by C_bn for the NED attitude error of eq 17.

Search per hypothesis: a coarse scan of the ZDL in across-track steps ds_m (search_step_for: from the map's
post spacing) from the nadir outwards, each side
stopped once the lower bound sqrt(s^2 + (h_a - h_max)^2) exceeds the best range (h_max: the highest terrain
near the cloud), samples skipped whose across-track strip bin (strip_bounds: the highest post near it, one
table per epoch shared by the cloud) cannot beat the best, then golden-section refinement around the best
sample (and a runner-up basin nearly as low). Each ZDL point is a Newton solve of
the plane condition along track in the bilinear cell. Checked against the exact branch-and-bound search
terrain.queries.ira_return.

Measurement Jacobian rows for the RBPF's linear state (dv, eps, ...), with errors computed minus true:
the true range is R(v_ins - dv), so H_R,v = -dR/dv; C_true = (I + [eps x]) C_ins, so H_theta,eps =
+C_bn (eq 25's body vector).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...terrain.kernels import bilinear_with_gradient
from ...terrain.queries.shared import _consts, _ned
from .ira_map_noise import (
    calibration_height_m,
    interpolation_sigma_m,
    map_noise_calibration,
    map_noise_variances,
    search_step_for,
)

_GOLD = 0.6180339887498949


(OUT_R, OUT_THETA, OUT_XB, OUT_YB, OUT_ZB, OUT_DR_DTH, OUT_DR_DPSI, OUT_S, OUT_VALID, OUT_R2,
 OUT_THETA2) = range(11)
N_OUT = 11


# forceinline: LLVM inlines it into the scan and refinement loops (zdl_batch ~10 % faster, the same bits)
@njit(cache=True, forceinline=True)
def _zd_eval(rec, ant, zdl, look, sv, t_guess):
    """Terrain point on the plane v . p = 0 at across-track coordinate sv (m): returns (f, t, x, y, z) with f
    the range if it lies in the look window (else inf; no point: t NaN). Records (tuples): ant = (lat, lon
    rad, h_a m, cv, 1 / (M + h_a), 1 / ((N + h_a) cos lat)) the antenna and its curvature constants (cv:
    terrain.queries.shared._consts); zdl = (vx, vy, vz, un, ue) the ZDL plane's unit normal (NED) and the
    horizontal along-track unit vector (_direction); look = (C_bn, sin of the half window, max range m)."""
    heights, lat0, lon0, dlat, dlon, _ = rec   # the map record's grid (read bilinearly)
    lat, lon, ha, cv, imh, inhc = ant
    vx, vy, vz, un, ue = zdl
    C, sin_w, max_range = look
    wn = -ue
    we = un
    vh = np.sqrt(vx * vx + vy * vy)
    t = t_guess
    x = y = z = np.nan
    for _ in range(12):
        north = t * un + sv * wn
        east = t * ue + sv * we
        dphi = north * imh
        dlam = east * inhc
        hp, gl, go = bilinear_with_gradient(heights, lat0, lon0, dlat, dlon, lat + dphi, lon + dlam)
        if hp != hp:
            return np.inf, np.nan, x, y, z
        x, y, z = _ned(dphi, dlam, hp, ha, cv)
        g = vx * x + vy * y + vz * z
        if abs(g) < 1e-4:
            break
        dh_dt = gl * un * imh + go * ue * inhc
        slope = vh - vz * dh_dt
        if slope < 0.1 * vh:
            slope = vh
        step = g / slope
        if step > 200.0:
            step = 200.0
        elif step < -200.0:
            step = -200.0
        t -= step
    r = np.sqrt(x * x + y * y + z * z)
    by = C[0, 1] * x + C[1, 1] * y + C[2, 1] * z
    bz = C[0, 2] * x + C[1, 2] * y + C[2, 2] * z
    if r > max_range or bz <= 0.0 or abs(by) > sin_w * r:
        return np.inf, t, x, y, z
    return r, t, x, y, z


@njit(cache=True)
def _golden(rec, ant, zdl, look, a, b, t_guess, iters):
    """Golden-section minimum of the in-window range over s in [a, b]: (f, s, t, x, y, z) of the lowest
    point evaluated (a minimum on the look window's edge is approached from inside). Each step drops the
    bracket's side beyond the higher inner point and probes one new point on the kept side, its Newton
    solve started from the along-track coordinate last found on that side (records: _zd_eval)."""
    c1 = b - _GOLD * (b - a)
    c2 = a + _GOLD * (b - a)
    f1, t1, x1, y1, z1 = _zd_eval(rec, ant, zdl, look, c1, t_guess)
    f2, t2, x2, y2, z2 = _zd_eval(rec, ant, zdl, look, c2, t_guess)
    if f1 <= f2:
        fb, sb, tb, xb, yb, zb = f1, c1, t1, x1, y1, z1
    else:
        fb, sb, tb, xb, yb, zb = f2, c2, t2, x2, y2, z2
    tg = t_guess
    for _ in range(iters):
        lower = f1 <= f2   # the minimum lies in [a, c2]: probe a new lower inner point
        if lower:
            b, c2, f2 = c2, c1, f1
            c1 = c = b - _GOLD * (b - a)
            t_side = t1
        else:
            a, c1, f1 = c1, c2, f2
            c2 = c = a + _GOLD * (b - a)
            t_side = t2
        if t_side == t_side:
            tg = t_side
        f, t, x, y, z = _zd_eval(rec, ant, zdl, look, c, tg)
        if lower:
            f1, t1 = f, t
        else:
            f2, t2 = f, t
        if f < fb:
            fb, sb, tb, xb, yb, zb = f, c, t, x, y, z
    return fb, sb, tb, xb, yb, zb


@njit(cache=True)
def _direction(elev, azim):
    ce = np.cos(elev)
    return ce * np.cos(azim), ce * np.sin(azim), -np.sin(elev), np.cos(azim), np.sin(azim)


RUNNER_UP_SEPARATION_M = 67.5   # 1.5 scan steps of 45 m: another basin, or a flat minimum's far side


@njit(cache=True)
def zdl_batch(rec, lat, lon, h, v_ned, look, scan, strip, out):
    """Seed 002 eqs 23-26 for hypotheses k (antenna lat[k], lon[k] rad, h[k] m) and the epoch's v_ned (3,).
    Records (tuples): look = (C_bn (3, 3), sin of the half window, max range m); scan = (h_max m the highest
    terrain near the cloud, ds_m the coarse step, d_ang rad (<= 0 skips the eq 24 differences), n_golden
    refinement steps, sep_m the runner-up's separation); strip = (lat_c, lon_c rad, s_lo m, bin_hmax m) the
    strip bins of strip_bounds (empty: none). out (n, N_OUT): R, theta, x_b, y_b, z_b, dR/dtheta_zdl,
    dR/dpsi_zdl (m/rad), s* (m across track), valid (1/0), and the range and look angle of the coarse scan's
    best sample farther than sep_m across track from the minimum (another basin or a flat minimum's far
    side; NaN: none in the window)."""
    heights, lat0, lon0, dlat, dlon, _ = rec   # the map record's grid (read bilinearly)
    C, sin_w, max_range = look
    h_max, ds_m, d_ang, n_golden, sep_m = scan
    lat_c, lon_c, s_lo, bin_hmax = strip
    vhs = np.sqrt(v_ned[0] ** 2 + v_ned[1] ** 2)
    elev = np.arctan2(-v_ned[2], vhs)
    azim = np.arctan2(v_ned[1], v_ned[0])
    zdl = _direction(elev, azim)
    vx, vy, vz, un, ue = zdl
    nb = bin_hmax.shape[0]
    sc, cc, mc, nc, _ = _consts(lat_c)
    for k in range(lat.shape[0]):
        for j in range(N_OUT):
            out[k, j] = np.nan
        out[k, OUT_VALID] = 0.0
        la = lat[k]
        lo = lon[k]
        ha = h[k]
        if not (la == la and lo == lo and ha == ha):
            continue
        cv = _consts(la)
        s_, c_, m, n, dm = cv
        imh = 1.0 / (m + ha)
        inhc = 1.0 / ((n + ha) * c_)
        ant = (la, lo, ha, cv, imh, inhc)
        dz_min = ha - h_max
        if dz_min < 0.0:
            dz_min = 0.0
        best = np.inf
        s_best = 0.0
        t_best = 0.0
        best2 = np.inf
        s_best2 = 0.0
        t_best2 = 0.0
        r2 = np.inf        # the runner-up as reported: the best sample farther than sep_m from the best
        s_r2 = 0.0
        t_r2 = 0.0
        # across-track offset of this antenna from the cloud centre (the strip bins' origin)
        sig = (la - lat_c) * (mc + ha) * (-ue) + (lo - lon_c) * (nc + ha) * cc * un
        for side in range(2):
            sgn = 1.0 if side == 0 else -1.0
            tg = 0.0
            i = 0 if side == 0 else 1
            while True:
                sv = sgn * i * ds_m
                if sv * sv + dz_min * dz_min > best * best or abs(sv) > max_range:
                    break
                if nb > 0 and best < np.inf:  # the strip's terrain bound: skip samples that cannot win
                    ib = int(np.floor((sv + sig - s_lo) / ds_m))
                    if 0 <= ib < nb:
                        dzb = ha - bin_hmax[ib]
                        if dzb > 0.0 and sv * sv + dzb * dzb > best * best:
                            i += 1
                            continue
                f, t, _, _, _ = _zd_eval(rec, ant, zdl, look, sv, tg)
                if t == t:
                    tg = t
                if f < best:
                    if abs(sv - s_best) > 1.5 * ds_m:  # the old best becomes the runner-up basin
                        best2 = best
                        s_best2 = s_best
                        t_best2 = t_best
                    if abs(sv - s_best) > sep_m:
                        r2 = best
                        s_r2 = s_best
                        t_r2 = t_best
                    best = f
                    s_best = sv
                    t_best = t
                else:
                    if f < best2 and abs(sv - s_best) > 1.5 * ds_m:
                        best2 = f
                        s_best2 = sv
                        t_best2 = t
                    if f < r2 and abs(sv - s_best) > sep_m:
                        r2 = f
                        s_r2 = sv
                        t_r2 = t
                i += 1
        if not best < np.inf:
            continue
        f, sm, t, x, y, z = _golden(rec, ant, zdl, look, s_best - ds_m, s_best + ds_m, t_best, n_golden)
        if best2 < best + 0.3 * ds_m:  # a second basin nearly as low: refine it too, keep the lower
            f2, sm2, t2, x2, y2, z2 = _golden(rec, ant, zdl, look, s_best2 - ds_m, s_best2 + ds_m, t_best2,
                                              n_golden)
            if f2 < f:
                f, sm, t, x, y, z = f2, sm2, t2, x2, y2, z2
                best, s_best, t_best = best2, s_best2, t_best2
        if not f < best:  # refinement left the window (a window-edge minimum): keep the coarse sample
            f, t, x, y, z = _zd_eval(rec, ant, zdl, look, s_best, t_best)
            sm = s_best
        # the coarse scan's best sample farther than sep_m across track from the minimum (range, look
        # angle): another basin, or the far side of a flat one - how near the closest point is to jumping
        if abs(sm - s_r2) < sep_m and r2 < np.inf:
            so, to = s_best, t_best
        else:
            so, to = s_r2, t_r2
        if r2 < np.inf:
            fo, _, xo, yo, zo = _zd_eval(rec, ant, zdl, look, so, to)
            if fo < np.inf:
                byo = C[0, 1] * xo + C[1, 1] * yo + C[2, 1] * zo
                out[k, OUT_R2] = fo
                out[k, OUT_THETA2] = np.arcsin(min(max(byo / fo, -1.0), 1.0))
        bx = C[0, 0] * x + C[1, 0] * y + C[2, 0] * z
        by = C[0, 1] * x + C[1, 1] * y + C[2, 1] * z
        bz = C[0, 2] * x + C[1, 2] * y + C[2, 2] * z
        out[k, OUT_R] = f
        out[k, OUT_THETA] = np.arctan(by / np.sqrt(bx * bx + bz * bz))   # eq 26
        out[k, OUT_XB] = bx
        out[k, OUT_YB] = by
        out[k, OUT_ZB] = bz
        out[k, OUT_S] = sm
        out[k, OUT_VALID] = 1.0
        if d_ang > 0.0:
            # eq 24's first factor, dR/d(theta_zdl, psi_zdl) with the new closest point near the old one: the
            # envelope theorem on min |P| s.t. v.P = 0 over the terrain surface, dR/da = -mu (dv/da . P*),
            # mu the Lagrange multiplier from the gradients of |P| and v.P along the terrain's tangent plane
            # (the limit of re-searching a tilted / turned ZDL near P*; tests check it against that)
            _, gl, go = bilinear_with_gradient(heights, lat0, lon0, dlat, dlon, la + x * imh, lo + y * inhc)
            hn = gl * imh
            he = go * inhc
            # tangent vectors of the surface (n, e, ha - h(n, e)) in NED: T1 = (1, 0, -hn), T2 = (0, 1, -he)
            a1 = (x - z * hn) / f
            a2 = (y - z * he) / f
            b1 = vx - vz * hn
            b2 = vy - vz * he
            bb = b1 * b1 + b2 * b2
            if bb > 0.0 and hn == hn and he == he:
                mu = (a1 * b1 + a2 * b2) / bb
                se = np.sin(elev)
                ce = np.cos(elev)
                sa = np.sin(azim)
                ca = np.cos(azim)
                dg_de = -se * ca * x - se * sa * y - ce * z
                dg_da = -ce * sa * x + ce * ca * y
                out[k, OUT_DR_DTH] = -mu * dg_de
                out[k, OUT_DR_DPSI] = -mu * dg_da


@njit(cache=True)
def strip_bounds(rec, lat_c, lon_c, h_c, un, ue, s_lo, ds, nb, s_half, t_half):
    """Highest terrain post near each across-track bin [s_lo + b ds, s_lo + (b + 1) ds) of the strip
    |along-track| <= t_half around the cloud centre's ZDL direction (u = (un, ue) along, w = (-ue, un)
    across). Every bilinear height in a cell is at most its highest corner post, so dilating each post by the
    cell diagonal makes the bins upper bounds of the terrain (-inf: no post)."""
    heights, lat0, lon0, dlat, dlon, _ = rec   # the map record's grid (read bilinearly)
    out = np.full(nb, -np.inf)
    s_, c_, m, n, _ = _consts(lat_c)
    dn = (m + h_c) * dlat
    de = (n + h_c) * c_ * dlon
    diag = np.sqrt(dn * dn + de * de)
    ext = s_half + t_half + diag
    n_lat, n_lon = heights.shape
    i0 = max(int(np.floor((lat_c - ext / (m + h_c) - lat0) / dlat)), 0)
    i1 = min(int(np.ceil((lat_c + ext / (m + h_c) - lat0) / dlat)) + 1, n_lat)
    j0 = max(int(np.floor((lon_c - ext / ((n + h_c) * c_) - lon0) / dlon)), 0)
    j1 = min(int(np.ceil((lon_c + ext / ((n + h_c) * c_) - lon0) / dlon)) + 1, n_lon)
    for i in range(i0, i1):
        north = (lat0 + i * dlat - lat_c) * (m + h_c)
        for j in range(j0, j1):
            hp = heights[i, j]
            if hp != hp:
                continue
            east = (lon0 + j * dlon - lon_c) * (n + h_c) * c_
            t = north * un + east * ue
            if abs(t) > t_half + diag:
                continue
            sv = -north * ue + east * un
            b0 = int(np.floor((sv - diag - s_lo) / ds))
            b1 = int(np.floor((sv + diag - s_lo) / ds))
            for b in range(max(b0, 0), min(b1, nb - 1) + 1):
                if hp > out[b]:
                    out[b] = hp
    return out


@njit(cache=True)
def zdl_angle_jacobian(v_ned):
    """d(theta_zdl, psi_zdl) / d(v_n, v_e, v_d) (2 x 3, rad per m/s): theta_zdl = atan2(-v_d, |v_h|) (the
    ZDL plane's tilt), psi_zdl = atan2(v_e, v_n) (its azimuth). Eq 24's second factor (see the module
    docstring for the departure from the printed matrix)."""
    vn, ve, vd = v_ned[0], v_ned[1], v_ned[2]
    vh2 = vn * vn + ve * ve
    vh = np.sqrt(vh2)
    v2 = vh2 + vd * vd
    J = np.zeros((2, 3))
    J[0, 0] = vd * vn / (vh * v2)
    J[0, 1] = vd * ve / (vh * v2)
    J[0, 2] = -vh / v2
    J[1, 0] = -ve / vh2
    J[1, 1] = vn / vh2
    return J


@njit(cache=True)
def measurement_rows(out, v_ned, C, H):
    """H (n, 2, 6): the rows of eqs 24-25 for each hypothesis over [dv_n, dv_e, dv_d, eps_n, eps_e, eps_d]
    (errors computed minus true; see the module docstring). Invalid hypotheses get zeros."""
    J = zdl_angle_jacobian(v_ned)
    for k in range(out.shape[0]):
        for a in range(2):
            for b in range(6):
                H[k, a, b] = 0.0
        if out[k, OUT_VALID] < 0.5:
            continue
        d1 = out[k, OUT_DR_DTH]
        d2 = out[k, OUT_DR_DPSI]
        if d1 == d1 and d2 == d2:
            for b in range(3):
                H[k, 0, b] = -(d1 * J[0, b] + d2 * J[1, b])          # eq 24, with dv = v_ins - v_true
        bx = out[k, OUT_XB]
        bz = out[k, OUT_ZB]
        rho = np.sqrt(bx * bx + bz * bz)
        gb0 = bz / rho                                                # eq 25 (body axes)
        gb2 = -bx / rho
        for a in range(3):
            H[k, 1, 3 + a] = C[a, 0] * gb0 + C[a, 2] * gb2            # to NED: C_bn g_b


def cloud_height_max(dem, lat_rad: np.ndarray, lon_rad: np.ndarray, margin_m: float) -> float:
    """Highest post of the DEM within margin_m of the hypotheses' bounding box (the search's bound)."""
    heights, lat0, lon0, dlat, dlon = dem.grid
    r = 6.371e6
    dla = margin_m / r
    dlo = margin_m / (r * np.cos(float(np.nanmean(lat_rad))))
    i0 = max(int(np.floor((np.nanmin(lat_rad) - dla - lat0) / dlat)), 0)
    i1 = min(int(np.ceil((np.nanmax(lat_rad) + dla - lat0) / dlat)) + 1, heights.shape[0])
    j0 = max(int(np.floor((np.nanmin(lon_rad) - dlo - lon0) / dlon)), 0)
    j1 = min(int(np.ceil((np.nanmax(lon_rad) + dlo - lon0) / dlon)) + 1, heights.shape[1])
    if i1 <= i0 or j1 <= j0:
        return float(np.nanmax(heights))
    block = heights[i0:i1, j0:j1]
    return float(np.nanmax(block)) if np.isfinite(block).any() else float(np.nanmax(heights))


def predict_ira(dem, lat_rad, lon_rad, h_m, v_ned, C_bn, half_window_rad: float = np.radians(45.0),
                max_range_m: float = 10000.0, ds_m: float = 45.0, d_ang_rad: float = 1e-3,
                n_golden: int = 13, runner_up_separation_m: float = RUNNER_UP_SEPARATION_M) -> np.ndarray:
    """eqs 23-26 for hypotheses (arrays lat, lon rad, h m) sharing v_ned (3,) and C_bn (3, 3); returns
    zdl_batch's (n, N_OUT) array (see OUT_*). ds_m: the coarse scan's step (search_step_for);
    runner_up_separation_m: how far across track the runner-up (OUT_R2, OUT_THETA2) lies from the minimum,
    independent of the step (the ambiguity tests' thresholds were set at 1.5 x 45 m)."""
    lat = np.ascontiguousarray(lat_rad, float).ravel()
    lon = np.ascontiguousarray(lon_rad, float).ravel()
    h = np.ascontiguousarray(h_m, float).ravel()
    rec = dem.record()          # the map record (terrain.kernels.MapRecord), read bilinearly by the search
    out = np.empty((lat.shape[0], N_OUT))
    # every closest point lies within its range of the antenna, and the range is at most the range to the ZDL
    # point under the antenna (~AGL / cos(gamma)): bound the terrain over that margin (with 50 % spare)
    h_nadir = dem.height(lat, lon)
    agl = np.nanmax(h - h_nadir) if np.isfinite(h_nadir).any() else np.nan
    margin = float(max_range_m)
    if np.isfinite(agl) and agl > 0:
        margin = float(min(max_range_m, 1.5 * agl + 200.0))
    h_max = cloud_height_max(dem, lat, lon, margin)
    v = np.ascontiguousarray(v_ned, float)
    ok = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(h)
    bins = np.zeros(0)
    lat_c = lon_c = s_lo = 0.0
    vh = float(np.hypot(v[0], v[1]))
    if ok.any() and vh > 0 and np.isfinite(margin):
        lat_c, lon_c, h_c = float(np.mean(lat[ok])), float(np.mean(lon[ok])), float(np.mean(h[ok]))
        un, ue = v[0] / vh, v[1] / vh
        r_e = 6.371e6
        north = (lat[ok] - lat_c) * r_e
        east = (lon[ok] - lon_c) * r_e * np.cos(lat_c)
        spread_t = float(np.max(np.abs(north * un + east * ue)))
        spread_s = float(np.max(np.abs(-north * ue + east * un)))
        s_half = margin + spread_s + ds_m
        t_half = spread_t + margin * abs(v[2]) / vh + 50.0
        s_lo = -s_half
        nb = int(np.ceil(2.0 * s_half / ds_m)) + 1
        bins = strip_bounds(rec, lat_c, lon_c, h_c, un, ue, s_lo, float(ds_m), nb, s_half, t_half)
    look = (np.ascontiguousarray(C_bn, float), float(np.sin(half_window_rad)), float(max_range_m))
    scan = (h_max, float(ds_m), float(d_ang_rad), int(n_golden), float(runner_up_separation_m))
    zdl_batch(rec, lat, lon, h, v, look, scan, (lat_c, lon_c, s_lo, bins), out)
    return out


__all__ = ["N_OUT", "OUT_DR_DPSI", "OUT_DR_DTH", "OUT_R", "OUT_R2", "OUT_S", "OUT_THETA", "OUT_THETA2",
           "OUT_VALID", "OUT_XB", "RUNNER_UP_SEPARATION_M",
           "OUT_YB", "OUT_ZB", "calibration_height_m", "cloud_height_max", "interpolation_sigma_m",
           "map_noise_calibration",
           "map_noise_variances",
           "search_step_for",
           "measurement_rows", "predict_ira", "zdl_angle_jacobian", "zdl_batch"]
