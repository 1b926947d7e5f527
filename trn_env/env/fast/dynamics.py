"""The fast tier's flight: N point-mass (3-DOF) King Airs with their guidance, sensors and navigator, one
numba call per decision.

Per aircraft, every `dt_s` (1 s, trn_env.env.fast.kernel_params.DT_S) of a decision:

- guidance on the ESTIMATE (as TerrainNav-v0): in pursuit mode the commanded track is the goal's bearing
  from the estimate plus the held offset (a fraction of asin(d omega / (2 v)), v the held airspeed,
  trn_env.env.task); the height
  above ground is flown on the estimated height minus the MAP under the estimate;
- the autopilot's laws (aircraft/kingair/Systems/kingair_autopilot.xml, figures in
  trn_env.env.fast.envelope): turn-rate command = track error x 0.2 1/s -> coordinated bank
  atan(V psi_dot / g0) limited to the measured bank limit, reached with the measured first-order bank time
  constant; heading rate g0 tan(bank) / V (a coordinated turn); vertical-speed command = 0.15 1/s x height
  error limited to the measured climb and descent rates, its target moving at most 1.5 m/s^2;
- true airspeed: the held one (the scenario's) less tas_per_vs x the vertical speed, through a first-order
  lag of tas_tau_s (trn_env.env.fast.envelope: the TAS hold's throttle saturates in sustained climbs and
  descents, so the aircraft trades speed for height), plus a slow wander (first-order Gauss-Markov,
  tas_wander_mps and tas_wander_tau_s: the along-track speed variation from seed to seed that the full
  loop shows beyond the gusts below, in light turbulence; none in calm air); ground velocity = air
  velocity + wind: the scenario's wind layers (linear in altitude between layers, constant beyond) plus
  turbulence as a first-order Gauss-Markov gust per
  horizontal axis (std and correlation time in trn_env.env.fast.kernel_params.TURBULENCE_*);
- position on the WGS84 ellipsoid (meridian and prime-vertical radii at the aircraft);
- navigator (trn_env.env.fast.navigator): INS error and covariance propagation every step, a 1 Hz sample
  of the terrain height under the TRUE position (the WORLD DEM) into the TERCOM profile, GNSS position and
  velocity updates before the outage, a TERCOM fix every fix_period_s;
- episode ends: terrain collision (true height below the WORLD terrain), off the map (world or map
  lookup NaN), arrival (estimated distance to the goal within the goal radius; in "progress" mode the
  true distance), the time limit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from trn_env.env.fast import navigator as nv
from trn_env.env.fast import rng as frng
from trn_env.env.fast import turns
from trn_env.env.fast.state import (
    AGL_CMD,
    ARRIVED,
    BANK,
    BARO,
    COLLISION,
    DIST_FLOWN,
    DTAS,
    END,
    EP_E,
    EP_N,
    EV_E,
    EV_N,
    GOAL,
    GOAL_LAT,
    GOAL_LON,
    GUST_E,
    GUST_N,
    LAT,
    LON,
    N_PROF,
    NEXT_SAMPLE_T,
    OFF_MAP,
    OFFSET_FRAC,
    PSI,
    T_LAST_FIX,
    TAS_WANDER,
    TIME_LIMIT,
    TRK_CMD,
    VS,
    VS_TGT,
    H,
    T,
)
from trn_env.terrain import kernels

G0_MPS2 = 9.80665
WGS84_A_M = 6378137.0
WGS84_E2 = 6.69437999014e-3

# flight parameter vector (float64), built by the vector env
(
    FP_DT,
    FP_TAS,
    FP_BANK_MAX,
    FP_BANK_TAU,
    FP_CLIMB,
    FP_DESCENT,
    FP_TRACK_GAIN,
    FP_HEIGHT_GAIN,
    FP_VS_ACCEL,
    FP_TURB_SIGMA,
    FP_TURB_TAU,
    FP_GOAL_RADIUS,
    FP_MAX_EP,
    FP_OMEGA,
    FP_OFFSET_MAX,
    FP_PURSUIT,
    FP_ARRIVAL,
    FP_SAMPLE_DT,
    FP_TAS_PER_VS,
    FP_TAS_TAU,
    FP_WANDER_SIGMA,
    FP_WANDER_TAU,
) = range(22)
N_FLIGHT_PARAMS = 22
CHUNK_AIRCRAFT = 8  # aircraft per chunk a thread takes from the parallel loops (numba.parallel_chunksize)


@njit(cache=True)
def radii_m(lat):
    """(meridian, prime-vertical) radii of curvature (m) of the WGS84 ellipsoid at latitude lat (rad)."""
    s = math.sin(lat)
    w = 1.0 - WGS84_E2 * s * s
    return WGS84_A_M * (1.0 - WGS84_E2) / (w * math.sqrt(w)), WGS84_A_M / math.sqrt(w)


@njit(cache=True)
def estimate_latlon(X, i):
    """Aircraft i's estimated latitude and longitude (rad): truth plus its navigation error."""
    lat = X[i, LAT]
    rm, rn = radii_m(lat)
    h = X[i, H]
    return lat + X[i, EP_N] / (rm + h), X[i, LON] + X[i, EP_E] / ((rn + h) * math.cos(lat))


@njit(cache=True)
def offset_to_goal(X, i, lat, lon):
    """North/east (m) from (lat, lon) to aircraft i's goal in the local level frame there."""
    rm, rn = radii_m(lat)
    return (X[i, GOAL_LAT] - lat) * rm, (X[i, GOAL_LON] - lon) * rn * math.cos(lat)


@njit(cache=True)
def wind_at(h, wind_alt, wind_n, wind_e):
    """Steady wind (north, east m/s, the air's motion) at height h (m): linear between layers."""
    n = wind_alt.size
    if n == 0:
        return 0.0, 0.0
    if h <= wind_alt[0]:
        return wind_n[0], wind_e[0]
    for k in range(1, n):
        if h <= wind_alt[k]:
            f = (h - wind_alt[k - 1]) / (wind_alt[k] - wind_alt[k - 1])
            return (
                wind_n[k - 1] + f * (wind_n[k] - wind_n[k - 1]),
                wind_e[k - 1] + f * (wind_e[k] - wind_e[k - 1]),
            )
    return wind_n[n - 1], wind_e[n - 1]


@njit(cache=True)
def _wrap(a):
    return math.atan2(math.sin(a), math.cos(a))


@njit(cache=True, parallel=True)
def fly_decision(
    X,
    state,
    active,
    n_sub,
    prof,
    world,
    mapr,
    fp,
    nav,
    wind,
    scratch,
):
    """Fly every active aircraft n_sub steps of fp[FP_DT] s (or to its episode's end, X[:, END] != 0); the
    aircraft are independent (each writes only its own rows and draws from its own random stream), so the
    loop over them is spread over numba's threads (call it inside numba.parallel_chunksize(CHUNK_AIRCRAFT):
    the work per aircraft is uneven - a TERCOM fix costs tens of steps - and small chunks taken in turn keep
    both cores busy, also when one of them is taken by another process).

    Records (numba tuples): prof = the TERCOM profiles' (measured heights, latitudes, longitudes) rows (N,
    profile); world, mapr = the world and map DEMs (terrain.kernels.MapRecord, bilinear); wind = the wind
    layers' (altitudes m, north, east m/s); scratch = TERCOM's (diff (N, 3, profile): the search's rows, then
    the fix covariance's (navigator.tercom_fix, fix_noise.lad_fix_covariance), tables (N, 4, candidates,
    profile))."""
    dt = fp[FP_DT]
    v0 = fp[FP_TAS]
    tau_v = 1.0 - math.exp(-dt / fp[FP_TAS_TAU])
    wander_a = math.exp(-dt / fp[FP_WANDER_TAU])
    wander_b = fp[FP_WANDER_SIGMA] * math.sqrt(1.0 - wander_a * wander_a)
    tau_b = 1.0 - math.exp(-dt / fp[FP_BANK_TAU])
    turb_a = math.exp(-dt / fp[FP_TURB_TAU])
    turb_b = fp[FP_TURB_SIGMA] * math.sqrt(1.0 - turb_a * turb_a)
    vrw = math.sqrt(nav[nv.NP_Q_V] * dt)
    sin_off_max = math.sin(min(fp[FP_OFFSET_MAX], 0.5 * math.pi))
    steps = (dt, v0, tau_v, wander_a, wander_b, tau_b, turb_a, turb_b, vrw, sin_off_max)
    for i in prange(X.shape[0]):
        if active[i] and X[i, END] == 0.0:
            # int64: numba types the loop index int64, then lowers the parallel loop with a uint64 one, which
            # would compile the callee (and its callees) a second time
            _fly_aircraft(np.int64(i), X, state, n_sub, prof, world, mapr, fp, nav, wind, scratch, steps)


@njit(cache=True)
def _fly_aircraft(i, X, state, n_sub, prof, world, mapr, fp, nav, wind, scratch, steps):
    """fly_decision's work for aircraft i (a serial kernel: the parallel loop only calls it, so numba's
    parallel passes see a one-call body). steps: fly_decision's per-step constants (dt s, the TAS m/s, the
    first-order lags' and Gauss-Markov processes' factors, the INS velocity random walk per step, the sine
    of the pursuit's offset limit)."""
    prof_meas, prof_lat, prof_lon = prof
    wind_alt, wind_n, wind_e = wind
    diff, tables = scratch
    dt, v0, tau_v, wander_a, wander_b, tau_b, turb_a, turb_b, vrw, sin_off_max = steps
    for _ in range(n_sub):
        lat = X[i, LAT]
        lon = X[i, LON]
        h = X[i, H]
        lat_e, lon_e = estimate_latlon(X, i)
        # ---- guidance on the estimate
        gn, ge = offset_to_goal(X, i, lat_e, lon_e)
        if fp[FP_PURSUIT] > 0.5:
            d = math.hypot(gn, ge)
            x = 0.5 * d * fp[FP_OMEGA] / v0  # task.bearing_offset_limit_rad
            lim = min(fp[FP_OFFSET_MAX], 0.5 * math.pi) if x >= sin_off_max else math.asin(x)
            X[i, TRK_CMD] = _wrap(math.atan2(ge, gn) + X[i, OFFSET_FRAC] * lim)
        h_map_e = kernels.map_height(mapr, lat_e, lon_e)
        if h_map_e != h_map_e:
            X[i, END] = OFF_MAP
            break
        # ---- lateral: ground track hold
        v = v0 + X[i, DTAS] + X[i, TAS_WANDER]
        wn, we = wind_at(h, wind_alt, wind_n, wind_e)
        wn += X[i, GUST_N]
        we += X[i, GUST_E]
        psi = X[i, PSI]
        vgn = v * math.cos(psi) + wn
        vge = v * math.sin(psi) + we
        err = _wrap(X[i, TRK_CMD] - math.atan2(vge, vgn))
        bank_cmd = math.atan(v * err * fp[FP_TRACK_GAIN] / G0_MPS2)
        bank_cmd = min(fp[FP_BANK_MAX], max(-fp[FP_BANK_MAX], bank_cmd))
        X[i, BANK] += (bank_cmd - X[i, BANK]) * tau_b
        X[i, PSI] = _wrap(psi + G0_MPS2 * math.tan(X[i, BANK]) / v * dt)
        # ---- vertical: height above the map under the estimate
        agl_e = h + X[i, BARO] - h_map_e
        vs_raw = fp[FP_HEIGHT_GAIN] * (X[i, AGL_CMD] - agl_e)
        vs_raw = min(fp[FP_CLIMB], max(-fp[FP_DESCENT], vs_raw))
        dv = vs_raw - X[i, VS_TGT]
        lim_dv = fp[FP_VS_ACCEL] * dt
        X[i, VS_TGT] += min(lim_dv, max(-lim_dv, dv))
        X[i, VS] = X[i, VS_TGT]
        X[i, DTAS] += (-fp[FP_TAS_PER_VS] * X[i, VS] - X[i, DTAS]) * tau_v
        X[i, TAS_WANDER] = wander_a * X[i, TAS_WANDER] + wander_b * frng.normal(state, i)
        # ---- position (trapezoid on the ground velocity)
        psi1 = X[i, PSI]
        vgn = 0.5 * (vgn + v * math.cos(psi1) + wn)
        vge = 0.5 * (vge + v * math.sin(psi1) + we)
        rm, rn = radii_m(lat)
        X[i, LAT] = lat + vgn * dt / (rm + h)
        X[i, LON] = lon + vge * dt / ((rn + h) * math.cos(lat))
        X[i, H] = h + X[i, VS] * dt
        X[i, DIST_FLOWN] += math.hypot(vgn, vge) * dt
        g_n, g_e = frng.normal_pair(state, i)
        X[i, GUST_N] = turb_a * X[i, GUST_N] + turb_b * g_n
        X[i, GUST_E] = turb_a * X[i, GUST_E] + turb_b * g_e
        # ---- navigator
        w_n, w_e = frng.normal_pair(state, i)
        f_turn = G0_MPS2 * math.tan(X[i, BANK])  # centripetal specific force, right of the heading
        dpsi = _wrap(psi1 - psi)
        turns.turn_truth_step(X, i, dpsi, X[i, BANK], psi + 0.5 * dpsi)
        nv.ins_step(X, i, dt, vrw * w_n, vrw * w_e, -f_turn * math.sin(psi1), f_turn * math.cos(psi1))
        turns.turn_noise(X, i, dpsi, X[i, BANK], nav)
        k_t = int(X[i, T] + 0.5)
        if k_t % nv.BI_STEP_S == 0:
            b0, b1 = frng.normal_pair(state, i)
            b2, b3 = frng.normal_pair(state, i)
            nv.bias_instability_step(X, i, float(nv.BI_STEP_S), nav, b0, b1, b2, b3)
        X[i, T] += dt
        nv.covariance_step(X, i, dt, nav[nv.NP_QF_V], nav[nv.NP_Q_A])
        t = X[i, T]
        h_world = kernels.map_height(world, X[i, LAT], X[i, LON])
        if h_world != h_world:
            X[i, END] = OFF_MAP
            break
        if t >= X[i, NEXT_SAMPLE_T] - 1e-9:
            X[i, NEXT_SAMPLE_T] += fp[FP_SAMPLE_DT]
            if t < nav[nv.NP_GNSS_UNTIL] - 1e-9:  # the outage starts at its start time
                s = nav[nv.NP_GNSS_SIGMA]
                sv = nav[nv.NP_GNSS_SIGMA_V]
                g_n, g_e = frng.normal_pair(state, i)
                gv_n, gv_e = frng.normal_pair(state, i)
                nv.gnss_update(
                    X,
                    i,
                    X[i, EP_N] + s * g_n,
                    X[i, EP_E] + s * g_e,
                    X[i, EV_N] + sv * gv_n,
                    X[i, EV_E] + sv * gv_e,
                    nav,
                )
                X[i, T_LAST_FIX] = t
                X[i, N_PROF] = 0.0
            elif nav[nv.NP_TERCOM] > 0.5:
                k = int(X[i, N_PROF])
                if k < prof_meas.shape[1]:
                    lat_e, lon_e = estimate_latlon(X, i)
                    w_n = nav[nv.NP_PROFILE_NOISE] * frng.normal(state, i)
                    # the lagged barometer reads the height tau earlier: h - tau dh/dt on a steady climb
                    prof_meas[i, k] = h_world + X[i, BARO] - nav[nv.NP_BARO_LAG] * X[i, VS] + w_n
                    prof_lat[i, k] = lat_e
                    prof_lon[i, k] = lon_e
                    X[i, N_PROF] = k + 1
                if t - X[i, T_LAST_FIX] >= nav[nv.NP_FIX_PERIOD] - 1e-9:
                    rm_e, rn_e = radii_m(lat_e)
                    nv.tercom_fix(
                        X, i, prof, mapr, nav, (rm_e + X[i, H], (rn_e + X[i, H]) * math.cos(lat_e)),
                        (diff[i], tables[i]),
                    )
                    X[i, T_LAST_FIX] = t
        # ---- episode ends
        if X[i, H] - h_world < 0.0:
            X[i, END] = COLLISION
            break
        if fp[FP_ARRIVAL] > 0.5:
            lat_e, lon_e = estimate_latlon(X, i)
            gn, ge = offset_to_goal(X, i, lat_e, lon_e)
            if math.hypot(gn, ge) <= fp[FP_GOAL_RADIUS]:
                X[i, END] = ARRIVED
                break
        else:
            gn, ge = offset_to_goal(X, i, X[i, LAT], X[i, LON])
            if math.hypot(gn, ge) <= fp[FP_GOAL_RADIUS]:
                X[i, END] = GOAL
                break
        if t >= fp[FP_MAX_EP] - 1e-6:
            X[i, END] = TIME_LIMIT
            break
