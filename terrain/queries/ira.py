"""IRA return (seed 000 sections 2.2, 3.2-3.3; seed 002 Fig. 1): the terrain point closest to the antenna on
the zero-Doppler line, i.e. on the plane through the antenna perpendicular to the velocity vector, whose look
angle theta = asin(y_b / R) satisfies |theta| <= half_window_rad and that lies below the antenna (z_b > 0).
(y_b, z_b): body-FRD components of the antenna->point vector, R its length; theta is the interferometric
angle from the plane perpendicular to the baseline (body y axis), positive toward the right wing (seed 000
eqs 18-19, 26-30).

Guarantee: the branch and bound drops only curve pieces whose lower bound is within 5 mm (tol of _ira_one) of
the best range found, so - unless its caps (20,000 evaluations, 4,096 stacked intervals) are reached - no
point of the DEM's bilinear surface (exact-curvature frame of terrain.queries.shared) on the zero-Doppler
curve and in the window is closer than the returned range minus 5 mm; the location is then polished by
three-point steps. Ranges agree with a dense brute-force search to a few mm (tests). No such point within
max_range_m, voids and off-grid antennas give valid = False. Each query is independent of the others in its
batch (same bits as single calls) unless ira_return's warm_start chains them (each search then starts from the
previous return; same returns to the 5 mm tolerance, not bit for bit).

Search: coarse intervals (a whole number of posts, about COARSE_STEP_M, long along the zero-Doppler curve)
are bounded below by range >= sqrt(horizontal^2 + (h_a - h_box)^2), h_box the highest terrain of the 2 x
2-cell blocks the curve piece can lie in; in order of that bound, while it can still beat the best, their
end samples are evaluated and they enter a branch and bound with Lipschitz / curvature bounds from per-cell
(or per-block) slopes, per-cell twists and the slope jumps at grid lines - for a piece between two adjacent
cells at its one crossing, weighted by where that crossing can lie (see _ira_one, _ira_interval_lb); each
curve point is a Newton solve in the bilinear cell (_zd_point). The per-DEM tables (block maxima and slopes,
height range: shared._ira_tables) are cached on the Dem and the scratch space is reused between calls, so a
call costs a few microseconds on top of its queries.

Kernel arguments: besides shared's map record and cv tuple, the per-query velocity terms travel as one tuple
vel = (v_hat north, east, down, u_h north, east, |v_hat_h|) (u_h: the horizontal unit velocity), and the
bounds' per-query constants in the scratch vector qc (see _ira_one).

The search's per-sample helpers (_zd_point, _ira_eval, _ira_interval_lb and what they call) are inlined
into _ira_one by LLVM (numba's forceinline=True: the LLVM alwaysinline attribute), not by numba
(inline="always"): a query makes ~25 evaluations and ~25 bound calls, and as calls they cost 8 % per query
(same-process A/B, issue 21). Numba's inlining re-types and re-lowers each call site's copy of the helper;
LLVM's copies the compiled helper, with the same bits and the same per-query speed, so the cold compile of
the IRA went from ~40 CPU s (numba inlining) to ~12. The branch and bound still bounds both halves of an
interval from one call site: each call site is one more copy.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..kernels import bilinear
from .ira_bounds import (  # noqa: F401
    _ira_box_max,
    _ira_cell_slope_twist,
    _ira_eval,
    _ira_interval_lb,
    _ira_lipschitz,
    _ira_push,
    _sort_candidates,
    _zd_point,
)
from .shared import (
    _INF,
    IRA_HEIGHT_BLOCK_CELLS,
    TerrainReturn,
    _check_positive,
    _consts,
    _insert_sorted,
    _ira_tables,
    _ira_workspace,
    _outputs,
    _positions,
    _stack,
)

COARSE_STEP_M = 45.0  # about the IRA's coarse sample spacing along the zero-Doppler curve (m)
_NO_WARM_START = np.zeros(0)  # _ira_batch's "no hints"


@njit(cache=True, fastmath=False, error_model="numpy")
def _ira_one(rec, tables, scratch, cell_m, lat, lon, ha, v, C, sin_w, max_range, hint_lat,
             hint_lon):
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
       Uses nothing from other queries, so a batch gives the same bits as single queries.

    Records: tables = (h_min, h_max, hmax_blocks, bslope, g_glob) of the DEM (shared._ira_tables);
    scratch = (buf_s, buf_f, buf_t, buf_r, buf_z, stack, out, qc, buf_h, buf_q) (_ira_batch's views of the
    workspace)."""
    h_min, h_max, hmax_blocks, bslope, g_glob = tables
    buf_s, buf_f, buf_t, buf_r, buf_z, stack, out, qc, buf_h, buf_q = scratch
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
    vel = (vx, vy, vz, uhx, uhy, vh)
    heights, lat0, lon0, dlat, dlon, _ = rec
    cv = _consts(lat)
    s, c, m, n, _ = cv
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
    f, t, r, z = _ira_eval(rec, lat, lon, ha, cv, vel, C, qc, sin_w, max_range, 0.0, t0, 1e-3)
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
                rec, lat, lon, ha, cv, vel, C, qc, sin_w, max_range, (q_seed - half) * step, t0,
                1e-3,
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
            rec, lat, lon, ha, cv, vel, C, qc, sin_w, max_range, s_hint,
            north_h * uhx + east_h * uhy, 1e-3,
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
        hb = _ira_box_max(hmax_blocks, np.int64(IRA_HEIGHT_BLOCK_CELLS), n_lat, n_lon, bi_lo + sa * qc[1],
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
            _insert_sorted(buf_h, buf_q, ci, buf_h[ci], buf_q[ci])
    else:  # no first best (nothing at s = 0 nor at the boresight): hundreds of candidates
        _sort_candidates(buf_h, buf_q, n_c)
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
                rec, lat, lon, ha, cv, vel, C, qc, sin_w, max_range, buf_s[e], tg, 1e-3,
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
            rec, lat, lon, ha, cv, vel, C, qc, sin_w, max_range, mid, tg, 1e-3,
        )
        n_eval += 1
        if fm < best:
            best = fm
            best_s = mid
            best_t = tm
        if n_st + 2 > cap:
            continue
        # the two halves' bounds from one call site: _ira_interval_lb is inlined, and each call site is one
        # more copy of it to compile (~10 s each on first use)
        lb_l = sp_l = lb_r = sp_r = 0.0
        for side in range(2):
            if side == 0:
                p0, f0, t0_, r0, z0, p1, f1, t1, r1, z1 = a, fa, ta, ra, za, mid, fm, tm, rm, zm
            else:
                p0, f0, t0_, r0, z0, p1, f1, t1, r1, z1 = mid, fm, tm, rm, zm, b, fb, tb, rb, zb
            lb_h, sp_h = _ira_interval_lb(
                heights, bslope, qc, best - tol, p0, f0, t0_, r0, z0, p1, f1, t1, r1, z1
            )
            if side == 0:
                lb_l, sp_l = lb_h, sp_h
            else:
                lb_r, sp_r = lb_h, sp_h
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
                rec, lat, lon, ha, cv, vel, C, qc, sin_w, max_range, sv_t, tc, 1e-4,
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
    t, x, y, z, dphi, dlam, hp = _zd_point(rec, lat, lon, ha, cv, vel, qc, centre, tc, 1e-6)
    if t != t:
        return
    out[0] = 1.0
    out[1] = np.sqrt(x * x + y * y + z * z)
    out[2] = lat + dphi
    out[3] = lon + dlam
    out[4] = hp


@njit(cache=True, fastmath=False, error_model="numpy")
def _ira_batch(rec, cell_m, queries, half_window, max_range, map_tables, workspace, outs, warm):
    """IRA queries k = 0..n-1 (see ira_return) on the map record rec (read bilinearly), records (numba
    tuples): queries = (lat, lon, h, v_ned, C_bn); map_tables = (hmax_blocks, bslope, h_min, h_max, g_glob):
    see _ira_tables; workspace = (work (8, >= n_max), stack (>= 64, 12)): scratch space, contents
    irrelevant; outs = (valid, rng, lat_out, lon_out, h_out). warm: (lat, lon) of the first query's hint,
    each later query's hint the previous valid return (warm_start of ira_return); an empty array: no
    hints."""
    lat, lon, h, v_ned, C_bn = queries
    hmax_blocks, bslope, h_min, h_max, g_glob = map_tables
    work, stack = workspace
    valid, rng, lat_out, lon_out, h_out = outs
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
    tables = (h_min, h_max, hmax_blocks, bslope, g_glob)
    scratch = (buf_s, buf_f, buf_t, buf_r, buf_z, stack, out, qc, buf_h, buf_q)
    chain = warm.shape[0] == 2
    hint_lat = warm[0] if chain else np.nan
    hint_lon = warm[1] if chain else np.nan
    for k in range(lat.shape[0]):
        if h[k] != h[k] or lat[k] != lat[k] or lon[k] != lon[k]:
            valid[k] = False
            rng[k] = lat_out[k] = lon_out[k] = h_out[k] = np.nan
            continue
        _ira_one(rec, tables, scratch, cell_m, lat[k], lon[k], h[k], v_ned[k], C_bn[k], sin_w,
                 max_range, hint_lat, hint_lon)
        valid[k] = out[0] > 0.5
        rng[k] = out[1]
        lat_out[k] = out[2]
        lon_out[k] = out[3]
        h_out[k] = out[4]
        if chain and valid[k]:
            hint_lat = out[2]
            hint_lon = out[3]


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
    return. Along a flight (samples metres apart) that saves part of the search
    (docs/validation/benchmarks.md); the results are the same to the search's tolerance (5 mm in range),
    not bit for bit. NaN: no point; an infinite one is refused."""
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
    *map_tables, cell_m = _ira_tables(dem)
    workspace = _ira_workspace(2 * int(np.ceil(float(max_range_m) / cell_m)) + 9)
    _ira_batch(dem.record(), cell_m, (lat, lon, h, v, C), float(half_window_rad), float(max_range_m),
               tuple(map_tables), workspace, (valid, rng, la, lo, hh), warm)
    return TerrainReturn(valid, rng, la, lo, hh)
