"""Per-sample helpers of the IRA return's branch and bound (terrain.queries.ira; seed 000 eqs 18-19, 26-30).

_zd_point solves the zero-Doppler plane's curve point in one bilinear cell by Newton steps; _ira_eval gives
its range and look angle; _ira_lipschitz, _ira_cell_slope_twist and _ira_interval_lb bound the range from
below over a curve piece (Lipschitz / curvature bounds from per-cell slopes and twists and the slope jumps
at grid lines); _ira_box_max reads the block-maxima table; _ira_push and _sort_candidates keep the search's
interval stack and candidate order. They are inlined into ira._ira_one by LLVM (forceinline=True; see
ira.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..kernels import bilinear, bilinear_cell, cell_index
from .shared import (
    _INF,
    IRA_BLOCK_POSTS,
    _ned,
)


@njit(cache=True, fastmath=False, error_model="numpy", forceinline=True)
def _zd_point(rec, lat, lon, ha, cv, vel, qc, sv, t_guess, tol):
    """Terrain point on the zero-Doppler plane at across-track nominal coordinate sv (m).

    Nominal horizontal coordinates (north, east) = sv * w_h + t * u_h, w_h = right-perpendicular of the
    horizontal velocity direction u_h; t solves P(t) = v_hat . NED(point) = 0 by Newton steps with the
    slope dP/dt = |v_h| - v_d dh/dt from the bilinear cell's gradient, kept inside the bracket of the root
    once one is known (bisection when a step leaves it). vel: (v_hat north, east, down, u_h north, east,
    |v_hat_h|) of _ira_one; qc: _ira_one's per-query constants.
    Returns (t, x, y, z, dphi, dlam, hp) or t = NaN."""
    heights = rec[0]
    n_lat, n_lon = heights.shape
    vx, vy, vz, uhx, uhy, vh = vel
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
        # bilinear height and its t-derivative (terrain.kernels: cell_index, bilinear_cell)
        fi = fi0 + tt * dfi
        fj = fj0 + tt * dfj
        i, j, u, v = cell_index(n_lat, n_lon, fi, fj)
        if i < 0:
            return np.nan, x, y, z, dphi, dlam, np.nan
        hp, ha_, hb_, ea, eb = bilinear_cell(heights, i, j, u, v)
        if hp != hp:
            hp = bilinear(rec[0], rec[1], rec[2], rec[3], rec[4], lat + dphi, lon + dlam)
            if hp != hp:
                return np.nan, x, y, z, dphi, dlam, hp
        x, y, z = _ned(dphi, dlam, hp, ha, cv)
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


@njit(cache=True, fastmath=False, error_model="numpy", forceinline=True)
def _ira_eval(rec, lat, lon, ha, cv, vel, C, qc, sin_w, max_range, sv, t_guess, tol):
    """(f, t, r, z) at across-track coordinate sv: f = range if the point is inside the look-angle window
    (else inf), t its along-track coordinate, r the raw range (inf: no point), z its NED down (m)."""
    t, x, y, z, dphi, dlam, hp = _zd_point(rec, lat, lon, ha, cv, vel, qc, sv, t_guess, tol)
    if t != t:
        return _INF, t_guess, _INF, np.nan
    r = np.sqrt(x * x + y * y + z * z)
    # body coordinates: b = C_bn^T x; look angle theta = asin(y_b / R) (seed 000 eqs 18-19), |theta| <= window
    by = C[0, 1] * x + C[1, 1] * y + C[2, 1] * z
    bz = C[0, 2] * x + C[1, 2] * y + C[2, 2] * z
    if r > max_range or bz <= 0.0 or abs(by) > sin_w * r:
        return _INF, t, r, z
    return r, t, r, z


@njit(cache=True, fastmath=False, error_model="numpy", forceinline=True)
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


@njit(cache=True, fastmath=False, error_model="numpy", forceinline=True)
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


@njit(cache=True, fastmath=False, error_model="numpy", forceinline=True)
def _ira_box_max(tab, block, n_lat, n_lon, fi_lo, fi_hi, fj_lo, fj_hi):
    """Largest value of tab (one value per block x block cells, layout of terrain.kernels.block_bounds) over
    the cells meeting the box [fi_lo, fi_hi] x [fj_lo, fj_hi] in post coordinates; -inf off the grid.
    Callers pass block as np.int64(CONSTANT): a bare integer constant is a literal type to numba, one more
    specialisation per value."""
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


@njit(cache=True, fastmath=False, error_model="numpy", forceinline=True)
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


@njit(cache=True, fastmath=False, error_model="numpy", forceinline=True)
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
                bslope, np.int64(IRA_BLOCK_POSTS), n_lat, n_lon, qc[0] + n_lo * qc[6], qc[0] + n_hi * qc[6],
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
def _sort_candidates(buf_h, buf_q, n):
    """Sort buf_h[:n] ascending, buf_q[:n] along, by the key (h, q), in place (Shell sort).

    buf_q holds distinct, increasing indices on entry, so this order is the one a stable sort by h gives
    (numpy's mergesort argsort, which it replaced: compiling that took a second of the first run)."""
    gap = 1
    while 3 * gap + 1 < n:
        gap = 3 * gap + 1  # Knuth's gaps 1, 4, 13, 40, ...
    while gap > 0:
        for i in range(gap, n):
            h = buf_h[i]
            q = buf_q[i]
            j = i
            while j >= gap and (buf_h[j - gap] > h or (buf_h[j - gap] == h and buf_q[j - gap] > q)):
                buf_h[j] = buf_h[j - gap]
                buf_q[j] = buf_q[j - gap]
                j -= gap
            buf_h[j] = h
            buf_q[j] = q
        gap //= 3
