"""Episode starts of the fast tier: one numba call over the sub-envs being reset.

As TerrainNav-v0's reset: the start is the given point, else drawn uniformly (in latitude and longitude)
from the start region, else the scenario's initial position; the goal the given point, else drawn from the
goal region at least min_goal_distance_m from the start and outside held_out_radius_m of every held-out goal
(1000 draws at most), else the fixed goal. The aircraft starts level at the scenario's initial height above
the world terrain (or its MSL height), heading for the goal; the commanded track is the goal's bearing and
the commanded height above ground the initial one (kept within [agl_min_m, agl_max_m]); the navigation
errors and inertial error sources are drawn from the sub-env's stream (trn_env.env.fast.navigator).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from trn_env.env.fast import navigator as nv
from trn_env.env.fast import rng as frng
from trn_env.env.fast import state as S
from trn_env.env.fast import turns
from trn_env.env.fast.dynamics import radii_m
from trn_env.terrain import kernels

# init parameter vector: sig_pos, sig_vel, sig_tilt, accel bias, gyro bias, baro sigma, agl_min, agl_max,
# sig_yaw, the filter's accelerometer-bias prior, the gyros' misalignment (rad) and scale factor (fraction)
(
    IP_SIG_POS,
    IP_SIG_VEL,
    IP_SIG_TILT,
    IP_BA,
    IP_BG,
    IP_BARO,
    IP_AGL_MIN,
    IP_AGL_MAX,
    IP_SIG_YAW,
    IP_SIG_BA_PRIOR,
    IP_GYRO_MIS,
    IP_GYRO_SF,
) = range(12)


@njit(cache=True)
def _distance_m(lat0, lon0, lat1, lon1):
    rm, rn = radii_m(lat0)
    return math.hypot((lat1 - lat0) * rm, (lon1 - lon0) * rn * math.cos(lat0))


@njit(cache=True)
def _draw(state, i, region, k):
    lat = region[k, 0] + frng.uniform(state, i) * (region[k, 1] - region[k, 0])
    lon = region[k, 2] + frng.uniform(state, i) * (region[k, 3] - region[k, 2])
    return lat, lon


@njit(cache=True)
def reset_aircraft(
    X,
    state,
    mask,
    start_rad,
    goal_rad,
    draws,
    init,
    world,
    mapr,
):
    """New episodes for every sub-env with mask[i]; returns per sub-env 0, or 1 when no goal was found.

    Records (numba tuples): draws = (regions (2, 4) rad: start and goal regions, held (k, 2) rad: held-out
    goals, held_r m: their radius, min_goal_d m: the shortest start-goal distance); init = (h_agl_init m,
    h_msl_init m (NaN: fly h_agl_init above the world), ip: the initial-error parameters); world, mapr =
    the world and map DEMs (terrain.kernels.MapRecord, bilinear)."""
    regions, held, held_r, min_goal_d = draws
    h_agl_init, h_msl_init, ip = init
    n = X.shape[0]
    status = np.zeros(n, np.int64)
    for i in range(n):
        if not mask[i]:
            continue
        for c in range(X.shape[1]):
            X[i, c] = 0.0
        if start_rad[i, 0] == start_rad[i, 0]:
            lat, lon = start_rad[i, 0], start_rad[i, 1]
        else:
            lat, lon = _draw(state, i, regions, 0)
        if goal_rad[i, 0] == goal_rad[i, 0]:
            glat, glon = goal_rad[i, 0], goal_rad[i, 1]
        else:
            status[i] = 1
            for _ in range(1000):
                glat, glon = _draw(state, i, regions, 1)
                if _distance_m(lat, lon, glat, glon) < min_goal_d:
                    continue
                far = True
                for k in range(held.shape[0]):
                    if _distance_m(glat, glon, held[k, 0], held[k, 1]) < held_r:
                        far = False
                        break
                if far:
                    status[i] = 0
                    break
        X[i, S.LAT] = lat
        X[i, S.LON] = lon
        X[i, S.START_LAT] = lat
        X[i, S.START_LON] = lon
        X[i, S.GOAL_LAT] = glat
        X[i, S.GOAL_LON] = glon
        rm, rn = radii_m(lat)
        brg = math.atan2((glon - lon) * rn * math.cos(lat), (glat - lat) * rm)
        X[i, S.PSI] = brg
        X[i, S.TRK_CMD] = brg
        h_world = kernels.map_height(world, lat, lon)
        h_map = kernels.map_height(mapr, lat, lon)
        if h_msl_init == h_msl_init:
            X[i, S.H] = h_msl_init
            agl = h_msl_init - h_map
        else:
            X[i, S.H] = h_world + h_agl_init
            agl = h_agl_init
        X[i, S.AGL_CMD] = min(ip[IP_AGL_MAX], max(ip[IP_AGL_MIN], agl))
        sig = (ip[IP_SIG_POS], ip[IP_SIG_VEL], ip[IP_SIG_TILT], ip[IP_BA], ip[IP_BG], ip[IP_BARO],
               ip[IP_SIG_YAW], ip[IP_SIG_BA_PRIOR])
        nv.draw_initial_errors(X, i, state, sig)
        turns.draw_turn_errors(X, i, state, ip[IP_GYRO_MIS], ip[IP_GYRO_SF])
        X[i, S.NEXT_SAMPLE_T] = 1.0
    return status
