"""Replica profiles from the map and their correlation with the measured profile (seed 001 ch. 3; spec 1-2).

Replica sample positions (spec section 1, [INF] in the thesis): p_0 = the transect's start point and
p_i = p_{i-1} + v_i t_i (sin psi_i, cos psi_i) (east, north), with v_i = m_v[i] + b_v and
psi_i = m_psi[i] + b_psi:
`m_v`, `m_psi` are the per-sample aiding values (zero without aiding) and `b_v`, `b_psi` the one unknown
reference the loops track (the thesis' V_ref / psi_ref; unaided, b is the speed and heading themselves).
The step from sample i-1 to i uses the mean of the two samples' speeds and headings (trapezoid). The
north/east steps go to latitude/longitude through the meridian and prime-vertical radii at the transect's
start (seed 000 eq 2; over a 2-4 km transect the radii change by < 1 m of position).

Costs (lower is better, so one minimiser serves both): MAD C = sum |d_i - h_i| / N (spec section 2, the
thesis' choice), optionally of the mean-removed difference (remove_bias: the barometer's and the map's
vertical biases then do not raise the minimum), Pearson as 1 - r, and MSD C = sum (d_i - h_i - o)^2 / N
with o = mean(d - h) under remove_bias, else 0.
MSD is the thesis' eq (3.4), which is garbled in print: its text says the squared differences are averaged
and "the standard deviation of the differences is added to reduce the effect of the systematic errors".
Our reading (spec section 8): removing the mean difference is what takes a systematic (vertical) error
out, so with remove_bias the MSD is the variance of the differences (1/N), without it the plain TERCOM
mean squared difference. It is a parabola around the minimum, not a V: the tracking loops correlate with
its square root (the RMS difference, V-shaped; loop_kernel.py), since the early-late discriminator (3.5)
on a parabola maps x -> -x and never locks. A replica sample off the map (NaN
height) or a measured sample that dropped out is left out of the sums; fewer than n_min samples left gives
inf (no correlation).

The map travels as one record (terrain.kernels.MapRecord: grid + interpolation, `Dem.record(cubic)`); the
navigator's `interpolation` setting is the record's `cubic` flag. The replica positions and the costs have
plain numpy `*_reference` twins: the tests' brute force.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ...terrain.kernels import bicubic, bilinear, bilinear_with_gradient, map_height

COST_MAD = 0
COST_PEARSON = 1
COST_MSD = 2
COSTS = {"mad": COST_MAD, "pearson": COST_PEARSON, "msd": COST_MSD}
INTERP_BILINEAR = 0
INTERP_BICUBIC = 1
INTERPOLATIONS = {"bilinear": INTERP_BILINEAR, "bicubic": INTERP_BICUBIC}


class Profile(NamedTuple):
    """The measured profile and how a replica is scored against it (profile_cost's arguments but the
    replica's heights): measured terrain heights d (m), their validity, the cost code (COSTS), remove_bias
    and the fewest usable samples n_min. numba passes it as a tuple."""

    d: np.ndarray
    valid: np.ndarray
    cost: int
    remove_bias: bool
    n_min: int


class Motion(NamedTuple):
    """A transect's motion for replica_offsets: sample times from the previous sample dt (s), aiding speed
    m_v (m/s) and track m_psi (rad) per sample, meridian radius + h r_n and (prime vertical radius + h)
    cos(lat) r_e_cos at its start (m). numba passes it as a tuple."""

    dt: np.ndarray
    m_v: np.ndarray
    m_psi: np.ndarray
    r_n: float
    r_e_cos: float


@njit(cache=True)
def _wrap(a):
    return math.atan2(math.sin(a), math.cos(a))


@njit(cache=True)
def replica_offsets(dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, dlat_out, dlon_out):
    """Latitude/longitude offsets (rad) of every replica sample from the transect start (sample 0).

    dt[i] (s): time from sample i-1 to i (dt[0] unused); r_n, r_e_cos: meridian radius + h and (prime
    vertical radius + h) cos(lat) at the start (m)."""
    n = dt.shape[0]
    dlat_out[0] = 0.0
    dlon_out[0] = 0.0
    dn = 0.0
    de = 0.0
    for i in range(1, n):
        v = 0.5 * (m_v[i - 1] + m_v[i]) + b_v
        psi = m_psi[i - 1] + 0.5 * _wrap(m_psi[i] - m_psi[i - 1]) + b_psi
        ds = v * dt[i]
        dn += ds * math.cos(psi)
        de += ds * math.sin(psi)
        dlat_out[i] = dn / r_n
        dlon_out[i] = de / r_e_cos
    return dn, de


@njit(cache=True)
def profile_cost(d, valid, h, cost, remove_bias, n_min):
    """Cost of measured heights d against map heights h over the samples valid and with finite h."""
    n = d.shape[0]
    m = 0
    sd = 0.0
    sh = 0.0
    for i in range(n):
        if valid[i] and h[i] == h[i]:
            m += 1
            sd += d[i]
            sh += h[i]
    if m < n_min or m == 0:
        return np.inf
    md = sd / m
    mh = sh / m
    if cost == COST_PEARSON:
        sxy = 0.0
        sxx = 0.0
        syy = 0.0
        for i in range(n):
            if valid[i] and h[i] == h[i]:
                a = d[i] - md
                b = h[i] - mh
                sxy += a * b
                sxx += a * a
                syy += b * b
        if sxx <= 0.0 or syy <= 0.0:
            return 1.0
        return 1.0 - sxy / math.sqrt(sxx * syy)
    off = (md - mh) if remove_bias else 0.0
    acc = 0.0
    if cost == COST_MSD:  # eq (3.4), our reading (module docstring)
        for i in range(n):
            if valid[i] and h[i] == h[i]:
                r = d[i] - h[i] - off
                acc += r * r
        return acc / m
    for i in range(n):
        if valid[i] and h[i] == h[i]:
            acc += abs(d[i] - h[i] - off)
    return acc / m


@njit(cache=True, forceinline=True)
def score(prof, h):
    """profile_cost of the replica heights h (m) against the Profile record prof."""
    d, valid, cost, remove_bias, n_min = prof
    return profile_cost(d, valid, h, cost, remove_bias, n_min)


@njit(cache=True)
def map_heights(rec, lat, lon, h_out):
    """h_out[i] = the height (m) of the map record rec at (lat[i], lon[i]) (rad): the interpolation chosen
    once, outside the loop (a branch per sample costs the loops' replicas about 1.7x)."""
    heights, lat0, lon0, dlat, dlon, cubic = rec
    if cubic:
        for i in range(lat.shape[0]):
            h_out[i] = bicubic(heights, lat0, lon0, dlat, dlon, lat[i], lon[i])
    else:
        for i in range(lat.shape[0]):
            h_out[i] = bilinear(heights, lat0, lon0, dlat, dlon, lat[i], lon[i])


@njit(cache=True)
def replica_heights(rec, lat_s, lon_s, motion, b_v, b_psi, dlat_w, dlon_w, h_out):
    """Map heights (m) of the replica from start (lat_s, lon_s) with the transect's motion (Motion) and
    references (b_v, b_psi) into h_out, on the map record rec; dlat_w, dlon_w: scratch (the offsets)."""
    dt, m_v, m_psi, r_n, r_e_cos = motion
    replica_offsets(dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, dlat_w, dlon_w)
    for i in range(dt.shape[0]):
        h_out[i] = map_height(rec, lat_s + dlat_w[i], lon_s + dlon_w[i])


@njit(cache=True)
def slope_sums(rec, lat_s, lon_s, dla, dlo, valid, r_n, r_e_cos, track_rad):
    """(sum of squared along-track, cross-track map slopes) at the points (lat_s + dla, lon_s + dlo) of the
    valid samples (the bilinear gradient of the map record rec's grid, whatever its interpolation;
    dimensionless)."""
    heights, lat0, lon0, dlat, dlon, _ = rec
    ca = math.cos(track_rad)
    sa = math.sin(track_rad)
    s_al = 0.0
    s_cr = 0.0
    for i in range(dla.shape[0]):
        if not valid[i]:
            continue
        _, g_lat, g_lon = bilinear_with_gradient(
            heights, lat0, lon0, dlat, dlon, lat_s + dla[i], lon_s + dlo[i]
        )
        if g_lat != g_lat or g_lon != g_lon:
            continue
        g_n = g_lat / r_n  # dh/dnorth (m/m)
        g_e = g_lon / r_e_cos  # dh/deast
        a = g_n * ca + g_e * sa
        c = -g_n * sa + g_e * ca
        s_al += a * a
        s_cr += c * c
    return s_al, s_cr


@njit(cache=True)
def along_cross_information(rec, lat_s, lon_s, dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, valid, track_rad):
    """(sum of squared along-track, cross-track map slopes) over the replica's valid samples (bilinear
    gradient; 1/m^2 x m^2 = dimensionless): the terrain information a match has in each direction."""
    n = dt.shape[0]
    dlat_w = np.empty(n)
    dlon_w = np.empty(n)
    replica_offsets(dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, dlat_w, dlon_w)
    return slope_sums(rec, lat_s, lon_s, dlat_w, dlon_w, valid, r_n, r_e_cos, track_rad)


# --------------------------------------------------------------------------------------- references


def replica_positions_reference(
    lat_s: float,
    lon_s: float,
    dt: np.ndarray,
    m_v: np.ndarray,
    m_psi: np.ndarray,
    b_v: float,
    b_psi: float,
    r_n: float,
    r_e_cos: float,
):
    """(lat, lon) arrays of the replica samples (numpy twin of replica_offsets)."""
    v = 0.5 * (m_v[:-1] + m_v[1:]) + b_v
    dpsi = np.arctan2(np.sin(m_psi[1:] - m_psi[:-1]), np.cos(m_psi[1:] - m_psi[:-1]))
    psi = m_psi[:-1] + 0.5 * dpsi + b_psi
    ds = v * dt[1:]
    dn = np.concatenate([[0.0], np.cumsum(ds * np.cos(psi))])
    de = np.concatenate([[0.0], np.cumsum(ds * np.sin(psi))])
    return lat_s + dn / r_n, lon_s + de / r_e_cos


def profile_cost_reference(
    d: np.ndarray,
    valid: np.ndarray,
    h: np.ndarray,
    cost: str = "mad",
    remove_bias: bool = True,
    n_min: int = 1,
) -> float:
    """numpy twin of profile_cost (cost 'mad', 'pearson' or 'msd')."""
    ok = valid & np.isfinite(h)
    if ok.sum() < max(n_min, 1):
        return np.inf
    x, y = d[ok], h[ok]
    if cost == "pearson":
        a, b = x - x.mean(), y - y.mean()
        den = math.sqrt(float((a * a).sum() * (b * b).sum()))
        return 1.0 if den <= 0 else 1.0 - float((a * b).sum()) / den
    off = (x.mean() - y.mean()) if remove_bias else 0.0
    if cost == "msd":
        return float(np.mean((x - y - off) ** 2))
    return float(np.mean(np.abs(x - y - off)))
