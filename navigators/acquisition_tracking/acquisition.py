"""Acquisition: serial search over start position x speed x heading (seed 001 ch. 3; spec section 3).

For each speed hypothesis and each heading hypothesis the replica's offsets from its start are computed once
(correlation.replica_offsets), then every start position of the square search area around the estimate is
correlated with the measured profile (one numba kernel over the whole hypothesis grid). The number of
combinations is (U_v / bin_v + 1)(U_psi / bin_psi + 1)(positions), as in the thesis. The best cell starts
tracking. The kernel (bounded_search_kernel) abandons a cell as soon as a lower bound of its cost shows it
can matter neither as the best cell nor against the distinctness test, so the outcome is the exhaustive
search's (search_kernel, kept as its reference) at a fraction of the map lookups.

Distinct minimum (the thesis gives no test; our choice, spec section 8): for each start position the best
cost over speed and heading forms a position surface; the acquisition is accepted when its minimum is below
`distinct_ratio` times the best cost found farther than `exclusion_m` from it. Otherwise it reports no
distinct minimum and the navigator retries with the next transect.

Kernel records (numba tuples): the map (terrain.kernels.MapRecord), the transect's motion
(correlation.Motion), the measured profile with its cost (correlation.Profile) and the hypothesis grids
(dn_grid, de_grid m, bv_grid m/s, bpsi_grid rad).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ...terrain.kernels import bilinear_at_index, map_height
from .correlation import (
    COST_MAD,
    COST_PEARSON,
    Motion,
    Profile,
    replica_offsets,
    score,
)


@njit(cache=True, forceinline=True)
def _work_arrays(n):
    """The search kernels' per-sample scratch: offsets (rad), offsets in grid-index units, heights (m)."""
    return np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)


@njit(cache=True, forceinline=True)
def _replica_height(rec, lat_s, lon_s, fi, fj, dlat_k, dlon_k):
    """Map height (m) of a replica sample on the map record rec: at grid index (fi, fj) when bilinear, else
    at (lat_s + dlat_k, lon_s + dlon_k) by its interpolation."""
    if not rec[5]:
        return bilinear_at_index(rec[0], fi, fj)
    return map_height(rec, lat_s + dlat_k, lon_s + dlon_k)


@njit(cache=True)
def search_kernel(rec, lat_c, lon_c, hyp, motion, prof, out):
    """out[i, j, a, b] = cost of the replica starting dn_grid[i] north, de_grid[j] east of (lat_c, lon_c)
    with references bv_grid[a] (m/s) and bpsi_grid[b] (rad); hyp = (dn_grid, de_grid, bv_grid, bpsi_grid),
    motion a correlation.Motion, prof a correlation.Profile, rec the map (MapRecord)."""
    heights, lat0, lon0, dlat, dlon, _ = rec
    dn_grid, de_grid, bv_grid, bpsi_grid = hyp
    dt, m_v, m_psi, r_n, r_e_cos = motion
    n = dt.shape[0]
    dlat_w, dlon_w, fi_w, fj_w, h_w = _work_arrays(n)
    for a in range(bv_grid.shape[0]):
        for b in range(bpsi_grid.shape[0]):
            replica_offsets(dt, m_v, m_psi, bv_grid[a], bpsi_grid[b], r_n, r_e_cos, dlat_w, dlon_w)
            for k in range(n):  # offsets in grid-index units, once per (speed, heading)
                fi_w[k] = dlat_w[k] / dlat
                fj_w[k] = dlon_w[k] / dlon
            for i in range(dn_grid.shape[0]):
                lat_s = lat_c + dn_grid[i] / r_n
                fi_s = (lat_s - lat0) / dlat
                for j in range(de_grid.shape[0]):
                    lon_s = lon_c + de_grid[j] / r_e_cos
                    fj_s = (lon_s - lon0) / dlon
                    for k in range(n):
                        h_w[k] = _replica_height(rec, lat_s, lon_s, fi_s + fi_w[k], fj_s + fj_w[k], dlat_w[k],
                                                 dlon_w[k])
                    out[i, j, a, b] = score(prof, h_w)


@njit(cache=True)
def bounded_search_kernel(rec, lat_c, lon_c, hyp, a_order, b_order, motion, prof, distinct_ratio, best0, out):
    """search_kernel with early abandonment; the search's outcome (best cell, its cost, distinct or not)
    is the exhaustive one.

    A cell is abandoned once a lower bound of its cost exceeds tau = best so far / min(distinct_ratio, 1);
    out then holds that bound (> tau) instead of the cost. Bounds over the valid samples met so far (nv
    valid samples in all, and the cost divides by at most nv): plain MAD / MSD - the partial sum; with the
    mean removed (remove_bias) - disjoint pairs, since |r_a - c| + |r_b - c| >= |r_a - r_b| and
    (r_a - c)^2 + (r_b - c)^2 >= (r_a - r_b)^2 / 2 for any offset c. Pearson has no bound (no abandonment).
    Why exact: the best cell's cost never exceeds tau, and a far cell that could make the minimum not
    distinct (cost <= best / distinct_ratio) has its bound below tau too, so both are computed exactly;
    every abandoned cell costs more than the final tau, which is all the decision needs of it.
    a_order / b_order: the order the speed / heading hypotheses are visited (centre first, so tau falls
    early). out is indexed [speed, heading, north, east] (written in the loops' order; serial_search
    hands _decide its transpose)."""
    heights, lat0, lon0, dlat, dlon, cubic = rec
    dn_grid, de_grid, bv_grid, bpsi_grid = hyp
    dt, m_v, m_psi, r_n, r_e_cos = motion
    d, valid, cost, remove_bias, n_min = prof
    n = dt.shape[0]
    n_lat, n_lon = heights.shape
    dlat_w, dlon_w, fi_w, fj_w, h_w = _work_arrays(n)
    row_w = np.empty(n, np.int64)
    u_w = np.empty(n)
    nv = 0
    for k in range(n):
        if valid[k]:
            nv += 1
    scale = min(distinct_ratio, 1.0)
    bounded = cost != COST_PEARSON and nv > 0
    # samples in the order 0, n2, 1, n2 + 1, ...: a pair spans half the transect, so a wrong replica's
    # slowly varying misfit still separates the pair and the bound grows fast
    n2 = (n + 1) // 2
    perm = np.empty(n, np.int64)
    for k in range(n):
        perm[k] = k // 2 if k % 2 == 0 else n2 + k // 2
    best = best0
    for ia in range(a_order.shape[0]):
        a = a_order[ia]
        for ib in range(b_order.shape[0]):
            b = b_order[ib]
            replica_offsets(dt, m_v, m_psi, bv_grid[a], bpsi_grid[b], r_n, r_e_cos, dlat_w, dlon_w)
            fi_lo = fj_lo = np.inf
            fi_hi = fj_hi = -np.inf
            for k in range(n):
                fi_w[k] = dlat_w[k] / dlat
                fj_w[k] = dlon_w[k] / dlon
                fi_lo = min(fi_lo, fi_w[k])
                fi_hi = max(fi_hi, fi_w[k])
                fj_lo = min(fj_lo, fj_w[k])
                fj_hi = max(fj_hi, fj_w[k])
            for i in range(dn_grid.shape[0]):
                lat_s = lat_c + dn_grid[i] / r_n
                fi_s = (lat_s - lat0) / dlat
                # the whole replica's rows inside the grid: row index and weight once per sample
                rows_in = not cubic and fi_s + fi_lo >= 0.0 and fi_s + fi_hi < n_lat - 1
                if rows_in:
                    for k in range(n):
                        f = fi_s + fi_w[k]
                        row_w[k] = int(f)
                        u_w[k] = f - row_w[k]
                for j in range(de_grid.shape[0]):
                    lon_s = lon_c + de_grid[j] / r_e_cos
                    fj_s = (lon_s - lon0) / dlon
                    inside = rows_in and fj_s + fj_lo >= 0.0 and fj_s + fj_hi < n_lon - 1
                    lim = best / scale * nv if bounded else np.inf
                    lb = 0.0
                    pend = 0.0
                    have = False
                    abandoned = False
                    for kk in range(n):
                        k = perm[kk]
                        if inside:  # bilinear_at_index's arithmetic without its range checks
                            f = fj_s + fj_w[k]
                            jj = int(f)
                            v = f - jj
                            ii = row_w[k]
                            h00 = heights[ii, jj]
                            h10 = heights[ii + 1, jj]
                            ha = h00 + v * (heights[ii, jj + 1] - h00)
                            hb = h10 + v * (heights[ii + 1, jj + 1] - h10)
                            h = ha + u_w[k] * (hb - ha)
                        elif not cubic:   # (not _replica_height: a call keeps the loop small)
                            h = bilinear_at_index(heights, fi_s + fi_w[k], fj_s + fj_w[k])
                        else:
                            h = map_height(rec, lat_s + dlat_w[k], lon_s + dlon_w[k])
                        h_w[k] = h
                        if bounded and valid[k] and h == h:
                            r = d[k] - h
                            if remove_bias:
                                if have:
                                    q = r - pend
                                    lb += abs(q) if cost == COST_MAD else 0.5 * q * q
                                    have = False
                                else:
                                    pend = r
                                    have = True
                            else:
                                lb += abs(r) if cost == COST_MAD else r * r
                            if lb > lim:
                                abandoned = True
                                break
                    if abandoned:
                        out[a, b, i, j] = lb / nv
                        continue
                    c = score(prof, h_w)
                    out[a, b, i, j] = c
                    if c < best:
                        best = c


def centre_out(m: int) -> np.ndarray:
    """Indices 0..m-1 ordered by distance from the centre index (the prior first)."""
    return np.argsort(np.abs(np.arange(m) - m // 2), kind="stable").astype(np.int64)


@dataclass
class AcquisitionResult:
    """Outcome of one serial search. dn_m/de_m: best start offset from the searched centre; b_v, b_psi_rad:
    the best references; cost: its correlation cost; second_cost: the best cost outside the exclusion
    radius (when distinct, possibly only a lower bound above cost / distinct_ratio: the search abandons
    cells that cannot matter, bounded_search_kernel); distinct: cost < distinct_ratio * second_cost;
    n_hypotheses: cells correlated."""

    distinct: bool
    dn_m: float
    de_m: float
    b_v: float
    b_psi_rad: float
    cost: float
    second_cost: float
    n_hypotheses: int
    reason: str = ""


def hypothesis_grid(half: float, bin_: float) -> np.ndarray:
    """Symmetric grid -half..half in steps of bin_ (the centre always included)."""
    k = int(math.floor(half / bin_ + 1e-9))
    return np.arange(-k, k + 1, dtype=float) * bin_


def _hypotheses(position_half_m, position_bin_m, speed_half_mps, speed_bin_mps, b_v0, heading_half_rad,
                heading_bin_rad, b_psi0):
    """The serial search's hypothesis grids: north and east offsets (m), speed and heading references."""
    dn = hypothesis_grid(position_half_m, position_bin_m)
    return (dn, dn.copy(), b_v0 + hypothesis_grid(speed_half_mps, speed_bin_mps),
            b_psi0 + hypothesis_grid(heading_half_rad, heading_bin_rad))


def search_grid(cfg, position_half_m: float | None = None) -> dict:
    """serial_search's grid keywords from the navigator's settings cfg (AcqTrackConfig): the position,
    speed and heading half-spans and bins (the heading's from deg to rad), distinct_ratio and exclusion_m;
    position_half_m (m) in place of the setting's (the navigator widens it with its uncertainty)."""
    return dict(
        position_half_m=cfg.acquisition_position_half_m if position_half_m is None else position_half_m,
        position_bin_m=cfg.acquisition_position_bin_m,
        speed_half_mps=cfg.acquisition_speed_half_mps,
        speed_bin_mps=cfg.acquisition_speed_bin_mps,
        heading_half_rad=math.radians(cfg.acquisition_heading_half_deg),
        heading_bin_rad=math.radians(cfg.acquisition_heading_bin_deg),
        distinct_ratio=cfg.acquisition_distinct_ratio,
        exclusion_m=cfg.acquisition_exclusion_m,
    )


def serial_search(
    rec,
    lat_c: float,
    lon_c: float,
    dt: np.ndarray,
    m_v: np.ndarray,
    m_psi: np.ndarray,
    b_v0: float,
    b_psi0: float,
    r_n: float,
    r_e_cos: float,
    d: np.ndarray,
    valid: np.ndarray,
    *,
    position_half_m: float,
    position_bin_m: float,
    speed_half_mps: float,
    speed_bin_mps: float,
    heading_half_rad: float,
    heading_bin_rad: float,
    cost: int,
    remove_bias: bool,
    n_min: int,
    distinct_ratio: float,
    exclusion_m: float,
) -> AcquisitionResult:
    """Search the hypothesis grid around start (lat_c, lon_c) and references (b_v0, b_psi0) on the map
    record rec (terrain.kernels.MapRecord: its interpolation is the search's)."""
    dn, de, bv, bp = _hypotheses(position_half_m, position_bin_m, speed_half_mps, speed_bin_mps, b_v0,
                                 heading_half_rad, heading_bin_rad, b_psi0)
    out_abij = np.empty((bv.size, bp.size, dn.size, de.size))
    motion = Motion(np.ascontiguousarray(dt, float), np.ascontiguousarray(m_v, float),
                    np.ascontiguousarray(m_psi, float), float(r_n), float(r_e_cos))
    prof = Profile(np.ascontiguousarray(d, float), np.ascontiguousarray(valid, np.bool_), int(cost),
                   bool(remove_bias), int(n_min))
    bounded_search_kernel(
        rec, float(lat_c), float(lon_c), (dn, de, bv, bp), centre_out(bv.size), centre_out(bp.size), motion,
        prof, float(distinct_ratio), np.inf, out_abij,
    )  # fmt: skip
    out = out_abij.transpose(2, 3, 0, 1)
    return _decide(out, dn, de, bv, bp, distinct_ratio, exclusion_m)


def _decide(out, dn, de, bv, bp, distinct_ratio, exclusion_m) -> AcquisitionResult:
    n_hyp = int(out.size)
    if not np.isfinite(out).any():
        return AcquisitionResult(
            False,
            0.0,
            0.0,
            float(bv[bv.size // 2]),
            float(bp[bp.size // 2]),
            np.inf,
            np.inf,
            n_hyp,
            "no replica on the map",
        )
    flat = np.where(np.isfinite(out), out, np.inf)
    i, j, a, b = np.unravel_index(int(np.argmin(flat)), flat.shape)
    best = float(flat[i, j, a, b])
    surface = flat.min(axis=(2, 3))
    far = np.hypot(dn[:, None] - dn[i], de[None, :] - de[j]) > exclusion_m
    second = float(surface[far].min()) if far.any() else np.inf
    distinct = bool(best < distinct_ratio * second) if np.isfinite(second) else True
    reason = (
        "" if distinct else f"no distinct minimum (best {best:.3g} vs {second:.3g} outside {exclusion_m:g} m)"
    )
    return AcquisitionResult(
        distinct, float(dn[i]), float(de[j]), float(bv[a]), float(bp[b]), best, second, n_hyp, reason
    )


def serial_search_reference(
    rec,
    lat_c,
    lon_c,
    dt,
    m_v,
    m_psi,
    b_v0,
    b_psi0,
    r_n,
    r_e_cos,
    d,
    valid,
    *,
    position_half_m,
    position_bin_m,
    speed_half_mps,
    speed_bin_mps,
    heading_half_rad,
    heading_bin_rad,
    cost="mad",
    remove_bias=True,
    n_min=1,
    distinct_ratio=0.8,
    exclusion_m=200.0,
) -> AcquisitionResult:
    """Brute-force numpy twin of serial_search (bilinear, whatever rec's interpolation; for tests on small
    grids)."""
    from ...terrain.kernels import bilinear_batch
    from .correlation import (
        profile_cost_reference,
        replica_positions_reference,
    )

    heights, lat0, lon0, dlat, dlon, _ = rec
    dn, de, bv, bp = _hypotheses(position_half_m, position_bin_m, speed_half_mps, speed_bin_mps, b_v0,
                                 heading_half_rad, heading_bin_rad, b_psi0)
    out = np.empty((dn.size, de.size, bv.size, bp.size))
    h = np.empty(dt.size)
    for i, n_ in enumerate(dn):
        for j, e_ in enumerate(de):
            for a, v in enumerate(bv):
                for b, p in enumerate(bp):
                    la, lo = replica_positions_reference(
                        lat_c + n_ / r_n, lon_c + e_ / r_e_cos, dt, m_v, m_psi, v, p, r_n, r_e_cos
                    )
                    bilinear_batch(heights, lat0, lon0, dlat, dlon, la, lo, h)
                    out[i, j, a, b] = profile_cost_reference(d, valid, h, cost, remove_bias, n_min)
    return _decide(out, dn, de, bv, bp, distinct_ratio, exclusion_m)
