"""Early-late tracking loops (seed 001 ch. 3-4; spec section 4).

Three replicas per loop: prompt at x, early at x - s, late at x + s (s: correlator spacing; x: the speed
reference b_v in m/s or the heading reference b_psi in rad). Discriminator (spec section 4):

    eps = s (H_E - H_L) / (H_E + H_L),    x <- x + eps

(H: the costs, lower is better; early worse than late means the minimum lies toward higher x, so x grows.)
Its gain is a s / (H_min + a s) for a V of slope a over a cost floor H_min (the noise), so over noisy
profiles it creeps and the threshold stops it short of the minimum. The optional "v_fit" discriminator
eps = (s / 2)(H_E - H_L) / (max(H_E, H_L) - H_P) subtracts the floor through the prompt and is exact on a
V within +-s (our addition, setting `discriminator`).
The loop iterates within one epoch; it is in lock when consecutive estimates differ by less than its
threshold (|eps| < threshold, in the loop's own unit - m/s or deg: our reading of the thesis' unitless
thresholds, spec section 8), and it breaks at the 101st iteration (at most 100 discriminator updates) out
of lock.

Adaptivity block (each epoch, first stage only): the SCF/HCF around the prompt -> the V's bandwidth (how far
the function rises monotonically on both sides of its minimum; no rise on a side: no V-shape, out of lock)
-> the widest spacing of the stage's set that is within the bandwidth and whose symmetry ratio (larger over
smaller absolute least-squares slope of the two sides, over +-s around the minimum) is at most
`symmetry_ratio_max` (our choice 2.0, spec section 8).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from navigators.acquisition_tracking.correlation import replica_cost

DISC_THESIS = 0  # eps = s (H_E - H_L) / (H_E + H_L)   (spec section 4)
DISC_V_FIT = 1  # eps = (s / 2) (H_E - H_L) / (max(H_E, H_L) - H_P)
DISCRIMINATORS = {"thesis": DISC_THESIS, "v_fit": DISC_V_FIT}


@njit(cache=True)
def early_late_loop(
    heights,
    lat0,
    lon0,
    dlat,
    dlon,
    lat_s,
    lon_s,
    dt,
    m_v,
    m_psi,
    b_v,
    b_psi,
    r_n,
    r_e_cos,
    d,
    valid,
    cost,
    remove_bias,
    interp,
    n_min,
    which,
    spacing,
    threshold,
    break_iteration,
    discriminator,
):
    """Run one loop stage. Returns (x, iterations, locked, H_prompt); x is b_v (which 0) or b_psi (1).

    A replica off the map (inf cost on early or late) ends the stage out of lock with x unchanged since
    the last finite step."""
    n = dt.shape[0]
    dlat_w = np.empty(n)
    dlon_w = np.empty(n)
    h_w = np.empty(n)
    x = b_v if which == 0 else b_psi
    it = 1
    while it < break_iteration:
        if which == 0:
            he = replica_cost(
                heights,
                lat0,
                lon0,
                dlat,
                dlon,
                lat_s,
                lon_s,
                dt,
                m_v,
                m_psi,
                x - spacing,
                b_psi,
                r_n,
                r_e_cos,
                d,
                valid,
                cost,
                remove_bias,
                interp,
                n_min,
                dlat_w,
                dlon_w,
                h_w,
            )
            hl = replica_cost(
                heights,
                lat0,
                lon0,
                dlat,
                dlon,
                lat_s,
                lon_s,
                dt,
                m_v,
                m_psi,
                x + spacing,
                b_psi,
                r_n,
                r_e_cos,
                d,
                valid,
                cost,
                remove_bias,
                interp,
                n_min,
                dlat_w,
                dlon_w,
                h_w,
            )
        else:
            he = replica_cost(
                heights,
                lat0,
                lon0,
                dlat,
                dlon,
                lat_s,
                lon_s,
                dt,
                m_v,
                m_psi,
                b_v,
                x - spacing,
                r_n,
                r_e_cos,
                d,
                valid,
                cost,
                remove_bias,
                interp,
                n_min,
                dlat_w,
                dlon_w,
                h_w,
            )
            hl = replica_cost(
                heights,
                lat0,
                lon0,
                dlat,
                dlon,
                lat_s,
                lon_s,
                dt,
                m_v,
                m_psi,
                b_v,
                x + spacing,
                r_n,
                r_e_cos,
                d,
                valid,
                cost,
                remove_bias,
                interp,
                n_min,
                dlat_w,
                dlon_w,
                h_w,
            )
        if not (np.isfinite(he) and np.isfinite(hl)):
            return x, it, False, np.inf
        if discriminator == DISC_THESIS:
            den = he + hl
            eps = spacing * (he - hl) / den if den > 0.0 else 0.0
        else:  # V-fit: the prompt removes the cost floor; exact on a V within +-spacing
            hp = replica_cost(
                heights,
                lat0,
                lon0,
                dlat,
                dlon,
                lat_s,
                lon_s,
                dt,
                m_v,
                m_psi,
                x if which == 0 else b_v,
                x if which == 1 else b_psi,
                r_n,
                r_e_cos,
                d,
                valid,
                cost,
                remove_bias,
                interp,
                n_min,
                dlat_w,
                dlon_w,
                h_w,
            )
            den = max(he, hl) - hp
            eps = 0.5 * spacing * (he - hl) / den if den > 0.0 else 0.0
            if eps > spacing:
                eps = spacing
            elif eps < -spacing:
                eps = -spacing
        x += eps
        if abs(eps) < threshold:
            bv = x if which == 0 else b_v
            bp = x if which == 1 else b_psi
            hp = replica_cost(
                heights,
                lat0,
                lon0,
                dlat,
                dlon,
                lat_s,
                lon_s,
                dt,
                m_v,
                m_psi,
                bv,
                bp,
                r_n,
                r_e_cos,
                d,
                valid,
                cost,
                remove_bias,
                interp,
                n_min,
                dlat_w,
                dlon_w,
                h_w,
            )
            return x, it, True, hp
        it += 1
    return x, it, False, np.nan


def early_late_reference(cost_fn, x: float, spacing: float, threshold: float, break_iteration: int = 101):
    """Plain-Python twin of early_late_loop on any cost function of x: (x, iterations, locked)."""
    it = 1
    while it < break_iteration:
        he, hl = cost_fn(x - spacing), cost_fn(x + spacing)
        den = he + hl
        eps = spacing * (he - hl) / den if den > 0 else 0.0
        x += eps
        if abs(eps) < threshold:
            return x, it, True
        it += 1
    return x, it, False


@dataclass
class VShape:
    """The correlation function's shape around its minimum (the adaptivity block's analysis).

    v_shape: it rises on both sides of an interior minimum; bandwidth: the narrower side's monotone rise
    (same unit as the offsets); min_offset: where the minimum lies; slopes: least-squares slopes (cost per
    unit) left (negative when V-shaped) and right, over the whole V."""

    v_shape: bool
    bandwidth: float
    min_offset: float
    min_cost: float
    slope_left: float
    slope_right: float


def analyse_v(
    offsets: np.ndarray, values: np.ndarray, min_points: int = 2, tolerance: float = 0.05
) -> VShape:
    """V-shape analysis of a correlation function sampled at increasing offsets: each side extends while
    the function stays above the minimum and drops by no more than `tolerance` x its range from one point
    to the next outward (noise wiggles); a V needs min_points on both sides."""
    ok = np.isfinite(values)
    if ok.sum() < 3:
        return VShape(False, 0.0, 0.0, np.inf, 0.0, 0.0)
    vals = np.where(ok, values, np.inf)
    k = int(np.argmin(vals))
    n = vals.size
    fin = vals[np.isfinite(vals)]
    tol = tolerance * float(fin.max() - fin.min())  # a wiggle this small does not end the V's side
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
    step = float(offsets[1] - offsets[0])
    wl, wr = k - left, right - k
    v = wl >= min_points and wr >= min_points
    sl = _slope(offsets[left : k + 1], vals[left : k + 1]) if wl >= 1 else 0.0
    sr = _slope(offsets[k : right + 1], vals[k : right + 1]) if wr >= 1 else 0.0
    return VShape(bool(v), float(min(wl, wr) * step), float(offsets[k]), float(vals[k]), sl, sr)


def _slope(x: np.ndarray, y: np.ndarray) -> float:
    if x.size < 2:
        return 0.0
    xm = x - x.mean()
    den = float((xm * xm).sum())
    return float((xm * (y - y.mean())).sum() / den) if den > 0 else 0.0


def symmetry_ratio(offsets: np.ndarray, values: np.ndarray, centre: float, spacing: float) -> float:
    """Larger over smaller absolute least-squares slope of the two sides within +-spacing of `centre`
    (1 = symmetric; inf when a side is flat or has fewer than two points)."""
    ok = np.isfinite(values)
    lm = ok & (offsets >= centre - spacing - 1e-12) & (offsets <= centre + 1e-12)
    rm = ok & (offsets <= centre + spacing + 1e-12) & (offsets >= centre - 1e-12)
    if lm.sum() < 2 or rm.sum() < 2:
        return np.inf
    a1 = abs(_slope(offsets[lm], values[lm]))
    a2 = abs(_slope(offsets[rm], values[rm]))
    lo, hi = min(a1, a2), max(a1, a2)
    return hi / lo if lo > 0 else np.inf


def choose_spacing(
    offsets: np.ndarray, values: np.ndarray, shape: VShape, spacings: np.ndarray, symmetry_max: float
) -> tuple[float, float]:
    """(spacing, symmetry ratio at it): the widest of `spacings` within the V's bandwidth whose symmetry
    ratio is at most symmetry_max; the narrowest within the bandwidth when none passes; the narrowest of
    all when none is within it."""
    cand = np.sort(np.asarray(spacings, float))[::-1]
    inside = cand[cand <= shape.bandwidth + 1e-12]
    if inside.size == 0:
        return float(cand[-1]), np.inf
    ratio = np.inf
    for s in inside:
        ratio = symmetry_ratio(offsets, values, shape.min_offset, float(s))
        if ratio <= symmetry_max:
            return float(s), float(ratio)
    return float(inside[-1]), float(ratio)


# ------------------------------------------------------------------------------ start-point (position) loops
# Our addition (the thesis dead-reckons the transect start; spec section 0), the GPS receiver's code loop
# beside its carrier loop: the speed and heading loops stretch and turn the replica about its start point,
# so they cannot move it as a whole. Two more early-late loops shift the whole replica along and across
# the track (x in metres along the unit vector (u_n, u_e)) with the same discriminator; that shift is the
# correlation's position fix (navigator.py fuses it).


@njit(cache=True)
def _shift_cost(
    heights, lat0, lon0, dlat, dlon, lat_s, lon_s, dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, d, valid,
    cost, remove_bias, interp, n_min, u_n, u_e, x, dlat_w, dlon_w, h_w,
):
    return replica_cost(
        heights, lat0, lon0, dlat, dlon, lat_s + x * u_n / r_n, lon_s + x * u_e / r_e_cos, dt, m_v, m_psi,
        b_v, b_psi, r_n, r_e_cos, d, valid, cost, remove_bias, interp, n_min, dlat_w, dlon_w, h_w,
    )


@njit(cache=True)
def shift_correlation_function(
    heights, lat0, lon0, dlat, dlon, lat_s, lon_s, dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, d, valid,
    cost, remove_bias, interp, n_min, u_n, u_e, offsets, out,
):
    """out[k] = cost of the replica with its start moved offsets[k] metres along (u_n, u_e)."""
    n = dt.shape[0]
    dlat_w = np.empty(n)
    dlon_w = np.empty(n)
    h_w = np.empty(n)
    for k in range(offsets.shape[0]):
        out[k] = _shift_cost(
            heights, lat0, lon0, dlat, dlon, lat_s, lon_s, dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, d,
            valid, cost, remove_bias, interp, n_min, u_n, u_e, offsets[k], dlat_w, dlon_w, h_w,
        )


@njit(cache=True)
def early_late_shift_loop(
    heights, lat0, lon0, dlat, dlon, lat_s, lon_s, dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, d, valid,
    cost, remove_bias, interp, n_min, u_n, u_e, x0, spacing, threshold, break_iteration, discriminator,
):
    """One stage of a start-point loop from shift x0 (m): (x, iterations, locked, H_prompt), as
    early_late_loop (same discriminators, lock on |eps| < threshold, break at break_iteration)."""
    n = dt.shape[0]
    dlat_w = np.empty(n)
    dlon_w = np.empty(n)
    h_w = np.empty(n)
    x = x0
    it = 1
    while it < break_iteration:
        he = _shift_cost(
            heights, lat0, lon0, dlat, dlon, lat_s, lon_s, dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, d,
            valid, cost, remove_bias, interp, n_min, u_n, u_e, x - spacing, dlat_w, dlon_w, h_w,
        )
        hl = _shift_cost(
            heights, lat0, lon0, dlat, dlon, lat_s, lon_s, dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, d,
            valid, cost, remove_bias, interp, n_min, u_n, u_e, x + spacing, dlat_w, dlon_w, h_w,
        )
        if not (np.isfinite(he) and np.isfinite(hl)):
            return x, it, False, np.inf
        if discriminator == DISC_THESIS:
            den = he + hl
            eps = spacing * (he - hl) / den if den > 0.0 else 0.0
        else:
            hp = _shift_cost(
                heights, lat0, lon0, dlat, dlon, lat_s, lon_s, dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, d,
                valid, cost, remove_bias, interp, n_min, u_n, u_e, x, dlat_w, dlon_w, h_w,
            )
            den = max(he, hl) - hp
            eps = 0.5 * spacing * (he - hl) / den if den > 0.0 else 0.0
            if eps > spacing:
                eps = spacing
            elif eps < -spacing:
                eps = -spacing
        x += eps
        if abs(eps) < threshold:
            hp = _shift_cost(
                heights, lat0, lon0, dlat, dlon, lat_s, lon_s, dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, d,
                valid, cost, remove_bias, interp, n_min, u_n, u_e, x, dlat_w, dlon_w, h_w,
            )
            return x, it, True, hp
        it += 1
    return x, it, False, np.nan
