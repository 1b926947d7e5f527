"""Terrain information ahead along candidate routes to the goal, from the navigator's MAP only.

A candidate route is the path an aircraft flies when it holds its ground track at a fixed offset phi from
the goal's bearing (the env's "pursuit" action with a constant action): a logarithmic spiral into the goal,
length d / cos(phi) from distance d, with the offset cut near the goal to what the turn rate can hold,
asin(d omega / (2 v)) (as the env does: trn_env.env.task.bearing_offset_limit_rad). The path is marched in
the estimate's local level frame (north, east; flat-earth over the tens of km of a route) in steps of
`step_m`, and the map's horizontal-position CRLB
(`trn_env.scenario.build.terrain_information_map`) is read at each point. Two figures per route:

- mean of log10(1 + CRLB / m) over its points (0 for ideal terrain, ~4 where it is featureless);
- the longest featureless stretch (km): the longest run of consecutive points whose CRLB exceeds
  `informative_crlb_m` - the longest distance the navigator dead-reckons on that route, which sets the
  error it has to recover from before the goal (the planner's `max_featureless_m` bounds the same).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

import trn_env.scenario.build as components
from trn_env.terrain.geodesy import ned_offset_to_latlon


@njit(cache=True, forceinline=True)
def pursuit_step(pn_m: float, pe_m: float, dn_m: float, de_m: float, turn, path):  # pragma: no cover
    """One step of a constant-offset pursuit path: from the point (pn_m, pe_m) to (north, east, step length)
    m, all in the frame where the goal is at (dn_m, de_m). turn = (phi, |sin phi|, cos phi, sin phi) of the
    offset phi (rad, + = right of the goal's bearing, |phi| <= 90 deg), computed once per path; path =
    (goal radius m, turn rate omega rad/s, true airspeed v m/s, step m). The step is min(step, d) along the
    goal's unit bearing rotated by phi, the offset cut near the goal to what the turn rate holds,
    asin(d omega / (2 v)) (the env's pursuit action); within the goal radius the point stays (length 0)."""
    goal_radius_m, omega_rps, tas_mps, step_m = path
    rn = dn_m - pn_m
    re = de_m - pe_m
    d = math.hypot(rn, re)
    if not d > goal_radius_m:
        return pn_m, pe_m, 0.0
    phi0, sin_abs, cphi, sphi = turn
    ux = rn / d
    uy = re / d
    x = 0.5 * d * omega_rps / tas_mps         # task.bearing_offset_limit_rad
    if not x >= sin_abs:   # (NaN x too)
        phi = math.copysign(math.asin(x), phi0)
        cphi = math.cos(phi)
        sphi = math.sin(phi)
    seg = min(step_m, d)
    return pn_m + seg * (ux * cphi - uy * sphi), pe_m + seg * (uy * cphi + ux * sphi), seg


@njit(cache=True)
def pursuit_paths_ne(dn_m: float, de_m: float, offsets_rad: np.ndarray, goal_radius_m: float,
                     omega_rps: float, tas_mps: float, step_m: float,
                     max_points: int = 64) -> np.ndarray:  # pragma: no cover - compiled
    """Points (K, n, 2) north/east m from the estimate (the goal at (dn_m, de_m)) of the constant-offset
    pursuit paths, one per offset (rad, + = right of the goal's bearing; |offset| <= 90 deg), marched by
    pursuit_step; a path's points stop changing once it is within goal_radius_m of the goal (it has
    arrived). A compiled kernel: the env asks for it at every decision."""
    path = (goal_radius_m, omega_rps, tas_mps, step_m)
    out = np.empty((offsets_rad.shape[0], max_points, 2))
    for i in range(offsets_rad.shape[0]):
        phi = offsets_rad[i]
        turn = (phi, abs(math.sin(phi)), math.cos(phi), math.sin(phi))
        pn = pe = 0.0
        for j in range(max_points):
            pn, pe, _ = pursuit_step(pn, pe, dn_m, de_m, turn, path)
            out[i, j, 0] = pn
            out[i, j, 1] = pe
    return out


def route_information(info_map, lat_rad: float, lon_rad: float, dn_m: float, de_m: float,
                      offsets_rad: np.ndarray, goal_radius_m: float, omega_rps: float, tas_mps: float,
                      informative_crlb_m: float, n_points: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """(mean log10(1 + CRLB), longest featureless stretch in km), one of each per offset, of the
    pursuit paths from the estimate (lat_rad, lon_rad) to the goal (dn_m, de_m from it). The step is the
    straight distance / n_points (at least 200 m), so every path has about n_points / cos(phi) points."""
    d = math.hypot(dn_m, de_m)
    step = max(200.0, d / n_points)
    cap = int(math.ceil(n_points / max(math.cos(float(np.max(np.abs(offsets_rad)))), 0.2))) + 2
    pts = pursuit_paths_ne(float(dn_m), float(de_m), np.ascontiguousarray(offsets_rad, float),
                           float(goal_radius_m), float(omega_rps), float(tas_mps), float(step), cap)
    k, n, _ = pts.shape
    lat, lon = ned_offset_to_latlon(lat_rad, lon_rad, 0.0, pts[..., 0].ravel(), pts[..., 1].ravel())
    crlb = components.world_height(info_map, lat, lon).reshape(k, n)
    crlb = np.where(np.isfinite(crlb), crlb, components.NO_INFORMATION_SIGMA_M)
    seg = np.hypot(*np.diff(np.concatenate([np.zeros((k, 1, 2)), pts], axis=1), axis=1).transpose(2, 0, 1))
    moving = seg > 0.0
    moving[:, 0] = True                           # the first point counts even when already arrived
    logc = np.log10(1.0 + np.clip(crlb, 0.0, None))
    mean = np.array([logc[i, moving[i]].mean() for i in range(k)])
    featureless = np.zeros(k)
    for i in range(k):            # a point's segment (from the previous point) counts where it is featureless
        run = 0.0
        for j in range(n):
            run = run + seg[i, j] if crlb[i, j] > informative_crlb_m else 0.0
            featureless[i] = max(featureless[i], run)
    return mean, featureless / 1000.0


__all__ = ["pursuit_paths_ne", "pursuit_step", "route_information"]
