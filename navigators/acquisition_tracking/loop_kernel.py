"""One tracking loop's epoch in one numba call: adaptivity block, stages, bias mitigation (seed 001 ch. 3).

`loop_epoch` runs one loop (speed or heading; tracking.py describes them) without leaving compiled code: the
SCF/HCF at 2K + 1 offsets around the prompt (spec section 2, `correlation_function`), the V-shape analysis
(bandwidth, minimum, side slopes; `analyse_v_kernel`), the spacing choice by bandwidth and symmetry ratio
(`choose_spacing_kernel`), the first early-late stage at that spacing, then the bias mitigation:

- "none": the first stage only (the plain early-late discriminator, eq 3.5);
- "ncs": narrow correlator spacing, a second stage at the fixed narrow spacing (thesis 3.5.2.2, eq 3.6);
- "els": NCS, then the early-late slope technique as a refinement (thesis 3.5.2.2, eq 3.7; the thesis:
  "ELS tends to be more useful as a refinement method ... can be applied in combination with NCS").

ELS with four correlators K1 < K2 < prompt < K3 < K4 (costs y1..y4, lower is better): the slope a1 through
K1, K2 (early side) and a2 through K3, K4 (late side); the two lines meet at

    x* = (y4 - y1 + a1 x1 - a2 x4) / (a1 - a2)

and the prompt's tracking error is T = x_P - x*; with x1 = x_P - s/2, x4 = x_P + s/2 this is the thesis'
eq (3.7), T = ((y1 - y4) + s (a1 + a2) / 2) / (a1 - a2). The prompt moves by -T until |T| is below the
narrow stage's threshold (or the 101-iteration break). Placement (thesis 3.5.2.2 "Implementation", its Sp2
option): the inner correlator of each side starts one narrow spacing S from the prompt; when its cost is
below the prompt's (the minimum lies beyond it) it steps outward by S while the cost keeps falling, and the
first position past the fall is the lower limit (thesis fig. 3.18b). The outer correlator sits at the
largest distance, half the V's bandwidth (at least S beyond the inner one). An epoch whose slopes do not
form a V (a1 >= 0 or a2 <= 0), whose intersection falls outside [x1, x4] (the thesis saw outliers), or
that does not converge keeps the NCS estimate.

MSD (correlation.py) is a parabola at its minimum; the loops correlate with its square root (the RMS
difference, V-shaped), since discriminator (3.5) on a parabola maps x -> -x and never locks.

The module is the one concept "the tracking loops' numba kernels": the speed / heading
loop and the start-point loop share the correlation functions, V analysis and ELS here, and track_loops
runs them all in one compiled call; its records are in loop_records.py.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .beam import replica_heights_at, replica_points
from .correlation import (
    COST_MSD,
    map_heights,
    replica_offsets,
    score,
)
from .loop_records import LoopOutputs, LoopSettings, TransectRecord  # noqa: F401
from .tracking import DISC_THESIS

MITIGATION_NONE = 0
MITIGATION_NCS = 1
MITIGATION_ELS = 2
MITIGATIONS = {"none": MITIGATION_NONE, "ncs": MITIGATION_NCS, "els": MITIGATION_ELS}


@njit(cache=True)
def replica_basis(dt, m_v, m_psi, basis):
    """Cumulative sums that make every replica of one transect a closed form in (b_v, b_psi).

    With step k's aiding speed vbar_k and heading base_k (correlation.replica_offsets' trapezoid) and
    ds_k = (vbar_k + b_v) dt_k: sum ds cos(base + b_psi) = cos b_psi Cn - sin b_psi Sn and
    sum ds sin(base + b_psi) = sin b_psi Cn + cos b_psi Sn, where Cn = P + b_v Q, Sn = R + b_v S and
    basis rows P, Q, R, S = cumsum(vbar dt cos base), cumsum(dt cos base), cumsum(vbar dt sin base),
    cumsum(dt sin base). So a replica costs one sine and one cosine instead of five per sample."""
    n = dt.shape[0]
    p = 0.0
    q = 0.0
    r = 0.0
    s = 0.0
    basis[0, 0] = basis[1, 0] = basis[2, 0] = basis[3, 0] = 0.0
    for i in range(1, n):
        v = 0.5 * (m_v[i - 1] + m_v[i])
        dpsi = m_psi[i] - m_psi[i - 1]
        base = m_psi[i - 1] + 0.5 * math.atan2(math.sin(dpsi), math.cos(dpsi))
        c = math.cos(base) * dt[i]
        sn = math.sin(base) * dt[i]
        p += v * c
        q += c
        r += v * sn
        s += sn
        basis[0, i] = p
        basis[1, i] = q
        basis[2, i] = r
        basis[3, i] = s


@njit(cache=True)
def basis_cost(rec, lat_s, lon_s, basis, b_v, b_psi, r_n, r_e_cos, prof, w):
    """Cost of the replica (b_v, b_psi) from a replica_basis on the map record rec against the profile prof
    (correlation.Profile); w: (3, N) work rows (lat, lon, map height)."""
    cb = math.cos(b_psi)
    sb = math.sin(b_psi)
    la, lo, h = w[0], w[1], w[2]
    for i in range(basis.shape[1]):
        cn = basis[0, i] + b_v * basis[1, i]
        sn = basis[2, i] + b_v * basis[3, i]
        la[i] = lat_s + (cb * cn - sb * sn) / r_n
        lo[i] = lon_s + (sb * cn + cb * sn) / r_e_cos
    map_heights(rec, la, lo, h)
    return score(prof, h)


@njit(cache=True)
def _cost_x(rec, rep, prof, which, x, w):
    """Tracking cost of the replica with the loop's quantity at x (b_v for which 0, b_psi for 1); rep: the
    replica record (lat_s, lon_s, basis, b_v, b_psi, r_n, r_e_cos)."""
    lat_s, lon_s, basis, b_v, b_psi, r_n, r_e_cos = rep
    bv = x if which == 0 else b_v
    bp = x if which == 1 else b_psi
    c = basis_cost(rec, lat_s, lon_s, basis, bv, bp, r_n, r_e_cos, prof, w)
    if prof[2] == COST_MSD:
        return math.sqrt(c)
    return c


@njit(cache=True)
def _scf(rec, rep, prof, which, x0, offsets, out, w):
    """out[k] = the loops' cost (_cost_x) with the loop's quantity at x0 + offsets[k]."""
    for k in range(offsets.shape[0]):
        out[k] = _cost_x(rec, rep, prof, which, x0 + offsets[k], w)


@njit(cache=True)
def correlation_function(rec, lat_s, lon_s, motion, b_v, b_psi, prof, which, offsets, out):
    """The SCF (which = 0: offsets added to b_v, m/s) or HCF (which = 1: offsets added to b_psi, rad) of
    the replica at (b_v, b_psi) from (lat_s, lon_s) with the transect's motion (correlation.Motion), as the
    loops see it: out[k] = the cost at offsets[k] (spec section 2; MSD as its square root, module
    docstring)."""
    dt, m_v, m_psi, r_n, r_e_cos = motion
    n = dt.shape[0]
    basis = np.empty((4, n))
    replica_basis(dt, m_v, m_psi, basis)
    x0 = b_v if which == 0 else b_psi
    rep = (lat_s, lon_s, basis, b_v, b_psi, r_n, r_e_cos)
    _scf(rec, rep, prof, which, x0, offsets, out, np.empty((3, n)))


@njit(cache=True)
def _eps(he, hl, hp, spacing, discriminator):
    """The early-late discriminator's step from the early, late and prompt costs (tracking.py)."""
    if discriminator == DISC_THESIS:  # eq (3.5)
        den = he + hl
        return spacing * (he - hl) / den if den > 0.0 else 0.0
    den = max(he, hl) - hp  # V-fit: the prompt removes the cost floor; at most one spacing
    eps = 0.5 * spacing * (he - hl) / den if den > 0.0 else 0.0
    if eps > spacing:
        return spacing
    if eps < -spacing:
        return -spacing
    return eps


@njit(cache=True, forceinline=True)
def _advance(x, he, hl, hp, spacing, threshold, discriminator):
    """One early-late iteration of a stage from finite early and late costs: (x moved by the
    discriminator's step, locked: the step was below threshold)."""
    eps = _eps(he, hl, hp, spacing, discriminator)
    x += eps
    return x, abs(eps) < threshold


@njit(cache=True)
def _stage(rec, rep, prof, which, x0, spacing, threshold, break_iteration, discriminator, w):
    """One early-late stage from x0 (discriminator eq 3.5, or v_fit; tracking.py): (x, iterations, locked).
    A replica off the map (inf cost early or late) ends the stage out of lock at the last finite x."""
    x = x0
    it = 1
    while it < break_iteration:
        he = _cost_x(rec, rep, prof, which, x - spacing, w)
        hl = _cost_x(rec, rep, prof, which, x + spacing, w)
        if not (np.isfinite(he) and np.isfinite(hl)):
            return x, it, False
        hp = 0.0 if discriminator == DISC_THESIS else _cost_x(rec, rep, prof, which, x, w)
        x, locked = _advance(x, he, hl, hp, spacing, threshold, discriminator)
        if locked:
            return x, it, True
        it += 1
    return x, it, False


@njit(cache=True)
def els_intersection(x1, y1, x2, y2, x3, y3, x4, y4):
    """(x*, a1, a2): where the line through (x1, y1), (x2, y2) meets the line through (x3, y3), (x4, y4)
    (thesis eq 3.7 in absolute coordinates; NaN when the lines are parallel)."""
    a1 = (y2 - y1) / (x2 - x1)
    a2 = (y4 - y3) / (x4 - x3)
    if a1 == a2:
        return np.nan, a1, a2
    return (y4 - y1 + a1 * x1 - a2 * x4) / (a1 - a2), a1, a2


@njit(cache=True)
def _els_step(rec, rep, prof, which, x, step, outer, max_steps, w):
    """The prompt's tracking error T = x - x* from four correlators placed around x (module docstring);
    (T, ok)."""
    hp = _cost_x(rec, rep, prof, which, x, w)
    inner = np.empty(2)
    for side in range(2):  # 0: early (x - ...), 1: late (x + ...)
        sgn = -1.0 if side == 0 else 1.0
        xi = x + sgn * step
        e = _cost_x(rec, rep, prof, which, xi, w)
        j = 1
        if e < hp:  # the minimum lies beyond this correlator: step outward while the cost falls
            while j < max_steps:
                e2 = _cost_x(rec, rep, prof, which, x + sgn * (j + 1) * step, w)
                j += 1
                if not (e2 < e):
                    break
                e = e2
        inner[side] = j * step
    x2 = x - inner[0]
    x3 = x + inner[1]
    x1 = x - max(outer, inner[0] + step)
    x4 = x + max(outer, inner[1] + step)
    y1 = _cost_x(rec, rep, prof, which, x1, w)
    y2 = _cost_x(rec, rep, prof, which, x2, w)
    y3 = _cost_x(rec, rep, prof, which, x3, w)
    y4 = _cost_x(rec, rep, prof, which, x4, w)
    if not (np.isfinite(y1) and np.isfinite(y2) and np.isfinite(y3) and np.isfinite(y4)):
        return 0.0, False
    xs, a1, a2 = els_intersection(x1, y1, x2, y2, x3, y3, x4, y4)
    if not (a1 < 0.0 and a2 > 0.0 and xs >= x1 and xs <= x4):
        return 0.0, False
    return x - xs, True


@njit(cache=True)
def _slope(x, y, lo, hi):
    """Least-squares slope of y[lo:hi] over x[lo:hi]."""
    m = hi - lo
    if m < 2:
        return 0.0
    xm = 0.0
    ym = 0.0
    for i in range(lo, hi):
        xm += x[i]
        ym += y[i]
    xm /= m
    ym /= m
    sxx = 0.0
    sxy = 0.0
    for i in range(lo, hi):
        a = x[i] - xm
        sxx += a * a
        sxy += a * (y[i] - ym)
    return sxy / sxx if sxx > 0.0 else 0.0


@njit(cache=True)
def analyse_v_kernel(offsets, values, min_points, tolerance):
    """V-shape analysis of a correlation function sampled at increasing offsets (tracking.VShape's fields:
    (v_shape, bandwidth, min_offset, min_cost, slope_left, slope_right)): each side extends while the
    function stays above the minimum and drops by no more than `tolerance` x its range from one point to
    the next outward (noise wiggles); a V needs min_points on both sides."""
    n = values.shape[0]
    vals = np.empty(n)
    n_ok = 0
    vmin = np.inf
    vmax = -np.inf
    k = 0
    for i in range(n):
        if np.isfinite(values[i]):
            vals[i] = values[i]
            n_ok += 1
            vmax = max(vmax, values[i])
            if values[i] < vmin:
                vmin = values[i]
                k = i
        else:
            vals[i] = np.inf
    if n_ok < 3:
        return False, 0.0, 0.0, np.inf, 0.0, 0.0
    tol = tolerance * (vmax - vmin)
    left = k
    while (
        left > 0
        and np.isfinite(vals[left - 1])
        and vals[left - 1] > vals[left] - tol
        and vals[left - 1] > vals[k]
    ):
        left -= 1
    right = k
    while (
        right < n - 1
        and np.isfinite(vals[right + 1])
        and vals[right + 1] > vals[right] - tol
        and vals[right + 1] > vals[k]
    ):
        right += 1
    step = offsets[1] - offsets[0]
    wl = k - left
    wr = right - k
    sl = _slope(offsets, vals, left, k + 1) if wl >= 1 else 0.0
    sr = _slope(offsets, vals, k, right + 1) if wr >= 1 else 0.0
    return wl >= min_points and wr >= min_points, min(wl, wr) * step, offsets[k], vals[k], sl, sr


@njit(cache=True)
def _side_slope(offsets, values, lo_x, hi_x):
    """(|least-squares slope|, points) of the finite values with lo_x <= offset <= hi_x."""
    m = 0
    xm = 0.0
    ym = 0.0
    for i in range(offsets.shape[0]):
        if np.isfinite(values[i]) and offsets[i] >= lo_x and offsets[i] <= hi_x:
            m += 1
            xm += offsets[i]
            ym += values[i]
    if m < 2:
        return 0.0, m
    xm /= m
    ym /= m
    sxx = 0.0
    sxy = 0.0
    for i in range(offsets.shape[0]):
        if np.isfinite(values[i]) and offsets[i] >= lo_x and offsets[i] <= hi_x:
            a = offsets[i] - xm
            sxx += a * a
            sxy += a * (values[i] - ym)
    return (abs(sxy / sxx) if sxx > 0.0 else 0.0), m


@njit(cache=True)
def symmetry_ratio_kernel(offsets, values, centre, spacing):
    """Larger over smaller absolute least-squares slope of the two sides within +-spacing of `centre`
    (1 = symmetric; inf when a side is flat or has fewer than two points)."""
    a1, m1 = _side_slope(offsets, values, centre - spacing - 1e-12, centre + 1e-12)
    a2, m2 = _side_slope(offsets, values, centre - 1e-12, centre + spacing + 1e-12)
    if m1 < 2 or m2 < 2:
        return np.inf
    lo = min(a1, a2)
    hi = max(a1, a2)
    return hi / lo if lo > 0.0 else np.inf


@njit(cache=True)
def choose_spacing_kernel(offsets, values, bandwidth, min_offset, spacings_desc, symmetry_max):
    """(spacing, symmetry ratio at it): the widest of spacings_desc (sorted widest first) within the V's
    bandwidth whose symmetry ratio is at most symmetry_max; the narrowest within the bandwidth when none
    passes; the narrowest of all when none is within it."""
    last = -1.0
    ratio = np.inf
    for s in spacings_desc:
        if s <= bandwidth + 1e-12:
            last = s
            ratio = symmetry_ratio_kernel(offsets, values, min_offset, s)
            if ratio <= symmetry_max:
                return s, ratio
    if last < 0.0:
        return spacings_desc[spacings_desc.shape[0] - 1], np.inf
    return last, ratio


@njit(cache=True)
def loop_epoch(rec, lat_s, lon_s, motion, b_v, b_psi, prof, which, loop, vset, o_n, o_e):
    """One loop's epoch (module docstring) on the map record rec, from (lat_s, lon_s) with the transect's
    motion (correlation.Motion) and references (b_v, b_psi), against the profile prof
    (correlation.Profile). loop = (reach, spacings_desc, threshold_1, spacing_2, threshold_2): the loop's
    reach, first-stage spacings (widest first) and threshold, second-stage spacing and threshold; vset =
    (n_side, symmetry_max, break_iteration, discriminator, mitigation): the V analysis and stages. Returns
    (x, it_1, it_2, it_els, locked, v_shape, bandwidth, min_offset, min_cost, slope_left, slope_right,
    spacing_1, els_applied). o_n, o_e: the beam offsets of the samples' map points (m, replica frame;
    beam.py), added to the basis' P and R rows so that they turn with b_psi."""
    dt, m_v, m_psi, r_n, r_e_cos = motion
    reach, spacings_desc, threshold_1, spacing_2, threshold_2 = loop
    n_side, symmetry_max, break_iteration, discriminator, mitigation = vset
    n = dt.shape[0]
    w = np.empty((3, n))
    basis = np.empty((4, n))
    replica_basis(dt, m_v, m_psi, basis)
    for i in range(n):
        basis[0, i] += o_n[i]
        basis[2, i] += o_e[i]
    rep = (lat_s, lon_s, basis, b_v, b_psi, r_n, r_e_cos)
    x0 = b_v if which == 0 else b_psi
    offs = np.linspace(-reach, reach, 2 * n_side + 1)
    vals = np.empty(offs.shape[0])
    _scf(rec, rep, prof, which, x0, offs, vals, w)
    v_shape, bw, m_off, m_cost, sl, sr = analyse_v_kernel(offs, vals, 2, 0.05)
    spacing, _ = choose_spacing_kernel(offs, vals, bw, m_off, spacings_desc, symmetry_max)
    x, it1, locked = _stage(rec, rep, prof, which, x0, spacing, threshold_1, break_iteration, discriminator,
                            w)
    it2 = 0
    it_els = 0
    els_applied = False
    if mitigation != MITIGATION_NONE:
        x2, it2, lock2 = _stage(rec, rep, prof, which, x, spacing_2, threshold_2, break_iteration,
                                discriminator, w)
        if np.isfinite(x2):
            x = x2
        locked = locked and lock2
    if mitigation == MITIGATION_ELS:
        xe = x
        outer = 0.5 * bw
        max_steps = max(int(math.ceil(reach / spacing_2)), 2)
        it = 1
        while it < break_iteration:
            t_err, ok = _els_step(rec, rep, prof, which, xe, spacing_2, outer, max_steps, w)
            if not ok:
                break
            xe -= t_err
            if abs(t_err) < threshold_2:
                els_applied = True
                break
            it += 1
        it_els = it
        if els_applied:
            x = xe
    if not np.isfinite(x):
        x = x0
        locked = False
    return x, it1, it2, it_els, locked, v_shape, bw, m_off, m_cost, sl, sr, spacing, els_applied


@njit(cache=True)
def _shift_cost_pre(rec, srep, prof, x, w):
    """Cost of the replica with its start moved x metres along (u_n, u_e), from the replica's offsets
    dla, dlo (rad) computed once: the shift moves the start only, so the offsets (references fixed) are the
    same for every x. srep: the shifted replica's record (lat_s, lon_s, dla, dlo, u_n, u_e, r_n, r_e_cos)."""
    lat_s, lon_s, dla, dlo, u_n, u_e, r_n, r_e_cos = srep
    ls = lat_s + x * u_n / r_n
    lo_s = lon_s + x * u_e / r_e_cos
    la, lo, h = w[0], w[1], w[2]
    for i in range(dla.shape[0]):
        la[i] = ls + dla[i]
        lo[i] = lo_s + dlo[i]
    map_heights(rec, la, lo, h)
    return score(prof, h)


@njit(cache=True)
def _shift_function(rec, srep, prof, offsets, out, w):
    for k in range(offsets.shape[0]):
        out[k] = _shift_cost_pre(rec, srep, prof, offsets[k], w)


@njit(cache=True)
def shift_correlation_function(rec, lat_s, lon_s, motion, b_v, b_psi, prof, u_n, u_e, offsets, out):
    """out[k] = cost of the replica (b_v, b_psi) with its start moved offsets[k] metres along (u_n, u_e)
    (the start-point loops' correlation function; records as loop_epoch's)."""
    dt, m_v, m_psi, r_n, r_e_cos = motion
    n = dt.shape[0]
    dla = np.empty(n)
    dlo = np.empty(n)
    replica_offsets(dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, dla, dlo)
    srep = (lat_s, lon_s, dla, dlo, u_n, u_e, r_n, r_e_cos)
    _shift_function(rec, srep, prof, offsets, out, np.empty((3, n)))


@njit(cache=True)
def _shift_stage(rec, srep, prof, x0, spacing, threshold, break_iteration, discriminator, w):
    """One stage of a start-point loop from shift x0 (m), as _stage: (x, iterations, locked)."""
    x = x0
    it = 1
    locked = False
    while it < break_iteration:
        he = _shift_cost_pre(rec, srep, prof, x - spacing, w)
        hl = _shift_cost_pre(rec, srep, prof, x + spacing, w)
        if not (np.isfinite(he) and np.isfinite(hl)):
            return x, it, False
        hp = 0.0 if discriminator == DISC_THESIS else _shift_cost_pre(rec, srep, prof, x, w)
        x, locked = _advance(x, he, hl, hp, spacing, threshold, discriminator)
        if locked:
            break
        it += 1
    return x, it, locked


@njit(cache=True)
def shift_loop_epoch(rec, lat_s, lon_s, motion, b_v, b_psi, prof, u_n, u_e, loop, vset, o_n, o_e):
    """One start-point loop's epoch along (u_n, u_e) in one call (records as loop_epoch's, loop's quantities
    in m): the shift correlation function at 2 n_side + 1 offsets in [-reach, reach] m, its V-shape, the
    spacing choice, the first stage from 0 and (mitigation "ncs" only) the second stage at spacing_2.
    Returns (x m, locked, v_shape, bandwidth, min_offset, min_cost, slope_left, slope_right); x = 0,
    unlocked when the loop ran off the map or beyond the function's reach. o_n, o_e: the samples' beam
    offsets (m, replica frame; beam.py)."""
    dt, m_v, m_psi, r_n, r_e_cos = motion
    reach, spacings_desc, threshold_1, spacing_2, threshold_2 = loop
    n_side, symmetry_max, break_iteration, discriminator, mitigation = vset
    narrow = mitigation == MITIGATION_NCS
    n = dt.shape[0]
    dla = np.empty(n)
    dlo = np.empty(n)
    w = np.empty((3, n))
    replica_points(dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, o_n, o_e, dla, dlo)
    srep = (lat_s, lon_s, dla, dlo, u_n, u_e, r_n, r_e_cos)
    offs = np.linspace(-reach, reach, 2 * n_side + 1)
    vals = np.empty(offs.shape[0])
    _shift_function(rec, srep, prof, offs, vals, w)
    v_shape, bw, m_off, m_cost, sl, sr = analyse_v_kernel(offs, vals, 2, 0.05)
    spacing, _ = choose_spacing_kernel(offs, vals, bw, m_off, spacings_desc, symmetry_max)
    x, _, locked = _shift_stage(rec, srep, prof, 0.0, spacing, threshold_1, break_iteration, discriminator, w)
    if narrow:
        x2, _, lock2 = _shift_stage(rec, srep, prof, x, spacing_2, threshold_2, break_iteration,
                                    discriminator, w)
        if np.isfinite(x2):
            x = x2
        locked = locked and lock2
    if not np.isfinite(x) or abs(x) > reach:
        x = 0.0
        locked = False
    return x, locked, v_shape, bw, m_off, m_cost, sl, sr


@njit(cache=True)
def _put_shape(out, k, v_shape, bw, m_off, m_cost, sl, sr):
    out[k, 0] = 1.0 if v_shape else 0.0
    out[k, 1] = bw
    out[k, 2] = m_off
    out[k, 3] = m_cost
    out[k, 4] = sl
    out[k, 5] = sr


@njit(cache=True)
def track_loops(rec, transect, settings, out):
    """All of one tracking epoch's loops in one call (navigator.py's order): aided, the start-point loops
    along and across the track at the references, then the speed and heading loops (loop_epoch; speed first
    unless speed_first is False); unaided the loops first and the start-point loops after them. Then the
    prompt replica's map heights into out_h_prompt. o_n, o_e: the samples' beam offsets (m, replica frame;
    beam.py), in every replica and the prompt.

    mean_m_v, mean_m_psi: the transect's mean aiding speed (m/s) and heading (rad); f_r: the correlation
    functions' reach at the far end (m). Loop k (0 speed, 1 heading, 2 along, 3 across): out_its[2k: 2k + 2]
    the two stages' iterations (speed and heading), out_locked[k], out_ran[k], out_shapes[k] = (v_shape,
    bandwidth, min_offset, min_cost, slope_left, slope_right). Returns (b_v, b_psi, lat_p, lon_p, speed
    spacing, heading spacing): the references and start point the loops found.

    Records (numba tuples): rec = the map and its interpolation (terrain.kernels.MapRecord);
    transect = TransectRecord; settings = LoopSettings (fixed by the navigator's config); out = LoopOutputs
    (arrays the caller allocates)."""
    (lat_s, lon_s, dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, d, valid, mean_m_v, mean_m_psi, o_n,
     o_e) = transect
    (cost, remove_bias, n_min, aided, position_loops, speed_first, n_side, symmetry_max,
     break_iteration, discriminator, mitigation, f_r, sample_period_s, speed_reach, speed_desc,
     speed_threshold_1, speed_spacing_2, speed_threshold_2, heading_desc, heading_threshold_1,
     heading_spacing_2, heading_threshold_2, position_reach, position_desc, position_threshold_1,
     position_spacing_2, position_threshold_2) = settings
    out_its, out_locked, out_ran, out_shapes, out_h_prompt = out
    n = dt.shape[0]
    prof = (d, valid, cost, remove_bias, n_min)
    motion = (dt, m_v, m_psi, r_n, r_e_cos)
    vset = (n_side, symmetry_max, break_iteration, discriminator, mitigation)
    for k in range(4):
        out_ran[k] = False
        out_locked[k] = False
        out_its[k] = 0
    lat_p = lat_s
    lon_p = lon_s
    sp_v = 0.0
    sp_psi = 0.0
    for phase in range(3):  # 0: start-point loops (aided), 1: speed and heading, 2: start-point (unaided)
        if phase == 1:
            for j in range(2):
                which = 0 if (j == 0) == speed_first else 1
                if which == 0:
                    reach = speed_reach
                    loop = (reach, speed_desc, speed_threshold_1, speed_spacing_2, speed_threshold_2)
                    # np.int64: a bare 0 / 1 is a numba literal, which compiled loop_epoch once per loop
                    r = loop_epoch(rec, lat_p, lon_p, motion, b_v, b_psi, prof, np.int64(0), loop, vset, o_n,
                                   o_e)
                    b_v = r[0]
                    sp_v = r[11]
                else:  # spec section 2: 2 sin(eps / 2) v t N = f R_db
                    v = max(mean_m_v + b_v, 1.0)
                    reach = 2.0 * math.asin(min(1.0, f_r / (2.0 * v * sample_period_s * n)))
                    reach = max(reach, heading_desc[0])
                    loop = (reach, heading_desc, heading_threshold_1, heading_spacing_2, heading_threshold_2)
                    r = loop_epoch(rec, lat_p, lon_p, motion, b_v, b_psi, prof, np.int64(1), loop, vset, o_n,
                                   o_e)
                    b_psi = r[0] if aided else math.atan2(math.sin(r[0]), math.cos(r[0]))
                    sp_psi = r[11]
                _x, it1, it2, _it_els, locked, v_shape, bw, m_off, m_cost, sl, sr, _sp, _els = r
                out_its[2 * which] = it1
                out_its[2 * which + 1] = it2
                out_locked[which] = locked
                out_ran[which] = True
                _put_shape(out_shapes, which, v_shape, bw, m_off, m_cost, sl, sr)
            continue
        if not position_loops or (phase == 0) != aided:
            continue
        psi_c = mean_m_psi + b_psi if aided else b_psi
        c = math.cos(psi_c)
        sn = math.sin(psi_c)
        loop = (position_reach, position_desc, position_threshold_1, position_spacing_2, position_threshold_2)
        for j in range(2):
            u_n = c if j == 0 else -sn
            u_e = sn if j == 0 else c
            r2 = shift_loop_epoch(rec, lat_p, lon_p, motion, b_v, b_psi, prof, u_n, u_e, loop, vset, o_n, o_e)
            x, locked, v_shape, bw, m_off, m_cost, sl, sr = r2
            lat_p = lat_p + x * u_n / r_n
            lon_p = lon_p + x * u_e / r_e_cos
            out_locked[2 + j] = locked
            out_ran[2 + j] = True
            _put_shape(out_shapes, 2 + j, v_shape, bw, m_off, m_cost, sl, sr)
    replica_heights_at(rec, lat_p, lon_p, motion, b_v, b_psi, o_n, o_e, out_h_prompt)
    return b_v, b_psi, lat_p, lon_p, sp_v, sp_psi
