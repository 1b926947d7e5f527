"""TerrainNav-v0's observation (trn_env.env.terrain_nav, the table in its docstring) for N aircraft at once.

Every element is computed from what the aircraft knows (the estimate, the filter's sigma, the MAP and the
map's terrain-information map), element for element as TerrainNavEnv._obs does, with two local-frame
simplifications: offsets from the estimate to the goal and to the sampled points use the local level frame
with the ellipsoid's radii at the estimate (TerrainNav-v0 goes through ECEF; the two differ by well under
0.1 % over the tens of km of a route), and the candidate pursuit paths of elements 22-31 are marched as in
trn_env.env.route_info.pursuit_paths_ne (both step with its pursuit_step).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from trn_env.env.fast.dynamics import estimate_latlon, offset_to_goal, radii_m, wind_at
from trn_env.env.fast.state import (
    AGL_CMD,
    BARO,
    D_EST_START,
    DEGRADED,
    EV_E,
    EV_N,
    GUST_E,
    GUST_N,
    P00,
    PSI,
    TRK_CMD,
    H,
    T,
)
from trn_env.env.route_info import pursuit_step
from trn_env.terrain import kernels

# observation parameter vector
(
    OP_INFO_OFFSET,
    OP_MAX_EP,
    OP_TAS,
    OP_BARO_SIGMA,
    OP_UNHEALTHY,
    OP_GOAL_RADIUS,
    OP_OMEGA,
    OP_INFORMATIVE,
    OP_NO_INFO,
) = range(9)
N_OBS_PARAMS = 9
# bearings of the terrain-information samples from the commanded track (trn_env.scenario.build
# INFO_BEARINGS_RAD; NaN = at the estimate)
INFO_BEARINGS_RAD = np.array([np.nan, 0.0, -math.pi / 4, math.pi / 4, -math.pi / 2, math.pi / 2])
ROUTE_POINTS = 24


@njit(cache=True)
def _info_at(info, lat, lon, no_info):
    c = kernels.map_height(info, lat, lon)
    return c if c == c else no_info


@njit(cache=True, parallel=True)
def observe(
    X,
    mask,
    out,
    mapr,
    info,
    op,
    route_offsets,
    bearings,
    bounds,
    wind,
):
    """Write the observation (float32, N x 32) of every aircraft with mask[i] into out[i].

    Records (numba tuples): mapr, info = the map DEM and the information map (terrain.kernels.MapRecord,
    bilinear); bounds = the observation's (low, high) per element; wind = the wind layers' (altitudes m,
    north, east m/s)."""
    n_routes = route_offsets.size
    max_off = 0.0
    for k in range(n_routes):
        max_off = max(max_off, abs(route_offsets[k]))
    cap = int(math.ceil(ROUTE_POINTS / max(math.cos(max_off), 0.2))) + 2
    sin_abs = np.abs(np.sin(route_offsets))
    cos_off = np.cos(route_offsets)
    sin_off = np.sin(route_offsets)
    no_info = op[OP_NO_INFO]
    for i in prange(X.shape[0]):
        if mask[i]:
            # int64: the parallel loop's index is lowered as uint64 (dynamics.fly_decision says why)
            _observe_aircraft(np.int64(i), X, out, mapr, info, op, route_offsets, bearings, bounds, wind,
                              (cap, sin_abs, cos_off, sin_off, no_info))


@njit(cache=True)
def _observe_aircraft(i, X, out, mapr, info, op, route_offsets, bearings, bounds, wind, shared):
    """observe's work for aircraft i (a serial kernel the parallel loop calls). shared: observe's values
    common to all aircraft (the path's point cap, |sin|, cos and sin of the route offsets, the information
    of an unknown cell)."""
    obs_low, obs_high = bounds
    wind_alt, wind_n, wind_e = wind
    n_routes = route_offsets.size
    cap, sin_abs, cos_off, sin_off, no_info = shared
    o = np.empty(out.shape[1])
    lat_e, lon_e = estimate_latlon(X, i)
    rm, rn = radii_m(lat_e)
    m_lat = rm + X[i, H]
    m_lon = (rn + X[i, H]) * math.cos(lat_e)
    dn, de = offset_to_goal(X, i, lat_e, lon_e)
    d = math.hypot(dn, de)
    trk = X[i, TRK_CMD]
    o[0] = dn / 1000.0
    o[1] = de / 1000.0
    o[2] = d / 1000.0
    o[3] = math.sin(trk)
    o[4] = math.cos(trk)
    wn, we = wind_at(X[i, H], wind_alt, wind_n, wind_e)
    vn = op[OP_TAS] * math.cos(X[i, PSI]) + wn + X[i, GUST_N] + X[i, EV_N]
    ve = op[OP_TAS] * math.sin(X[i, PSI]) + we + X[i, GUST_E] + X[i, EV_E]
    o[5] = math.hypot(vn, ve) / 100.0
    hm = kernels.map_height(mapr, lat_e, lon_e)
    o[6] = (X[i, H] + X[i, BARO] - hm) / 1000.0 if hm == hm else 0.0
    o[7] = X[i, AGL_CMD] / 1000.0
    s_h = math.sqrt(max(X[i, P00], 0.0))
    o[8] = math.log10(1.0 + s_h)
    o[9] = math.log10(1.0 + s_h)
    o[10] = math.log10(1.0 + op[OP_BARO_SIGMA])
    for k in range(bearings.size):
        if bearings[k] != bearings[k]:
            c = _info_at(info, lat_e, lon_e, no_info)
        else:
            b = trk + bearings[k]
            c = _info_at(
                info,
                lat_e + op[OP_INFO_OFFSET] * math.cos(b) / m_lat,
                lon_e + op[OP_INFO_OFFSET] * math.sin(b) / m_lon,
                no_info,
            )
        o[11 + k] = math.log10(1.0 + max(c, 0.0))
    o[17] = X[i, T] / op[OP_MAX_EP]
    o[18] = 1.0 if X[i, DEGRADED] < 0.5 else 0.0
    rel = math.atan2(de, dn) - trk
    o[19] = math.sin(rel)
    o[20] = math.cos(rel)
    o[21] = d / max(X[i, D_EST_START], 1.0)
    # route information along the candidate pursuit paths (trn_env.env.route_info)
    path = (op[OP_GOAL_RADIUS], op[OP_OMEGA], op[OP_TAS], max(200.0, d / ROUTE_POINTS))
    for k in range(n_routes):
        turn = (route_offsets[k], sin_abs[k], cos_off[k], sin_off[k])
        pn = 0.0
        pe = 0.0
        total = 0.0
        count = 0
        run = 0.0
        longest = 0.0
        for j in range(cap):
            pn, pe, seg = pursuit_step(pn, pe, dn, de, turn, path)
            if seg == 0.0 and j > 0:
                break  # arrived: the remaining points repeat this one and change neither figure
            c = _info_at(
                info, lat_e + pn / m_lat, lon_e + pe / m_lon, no_info
            )
            if seg > 0.0 or j == 0:
                total += math.log10(1.0 + max(c, 0.0))
                count += 1
            run = run + seg if c > op[OP_INFORMATIVE] else 0.0
            longest = max(longest, run)
        o[22 + k] = total / count
        o[22 + n_routes + k] = longest / 1000.0
    for k in range(o.size):
        x = o[k]
        if x != x:
            x = 0.0
        out[i, k] = min(obs_high[k], max(obs_low[k], x))
