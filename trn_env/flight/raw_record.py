"""The per-step JSBSim record and its conversion to SI truth.

The hot loop (`_record_state`, `_record_state_wind`) copies the cached property nodes of `_RECORDED` into one
flat float64 buffer with one struct call per step; `_convert_raw` (numba) turns a chunk of it into the
scalar, vector and C_bn blocks `TruthChunk.from_blocks` views: units, Euler/C_bn, the Earth-rate part of
the body rates, air data and the flight's atmosphere at each row.
"""

from __future__ import annotations

import struct

import numpy as np
from numba import njit

from trn_env.flight.atmosphere import JSBSIM_P_SL_PA, static_p_T
from trn_env.flight.truth import SCALAR_FIELDS, VECTOR_FIELDS
from trn_env.terrain.geodesy import OMEGA_EARTH_RPS

M_PER_FT = 0.3048

# Properties copied every step, in buffer-column order (JSBSim units; converted after the loop). The three
# total-wind columns are read only when turbulence or gusts are configured; otherwise the wind is the steady
# wind Flight wrote. Pressure and temperature are not read: they are the flight's atmosphere (the model
# JSBSim flies in, atmosphere.static_p_T) evaluated at each row's own position (tests check it against
# atmosphere/P-psf, T-R).
_RECORDED = (
    "position/lat-geod-rad",                 # 0
    "position/long-gc-rad",                  # 1
    "position/geod-alt-ft",                  # 2
    "velocities/v-north-fps",                # 3
    "velocities/v-east-fps",                 # 4
    "velocities/v-down-fps",                 # 5
    "attitude/phi-rad",                      # 6
    "attitude/theta-rad",                    # 7
    "attitude/psi-rad",                      # 8
    "velocities/pi-rad_sec",                 # 9  body rates relative to inertial space
    "velocities/qi-rad_sec",                 # 10
    "velocities/ri-rad_sec",                 # 11
    "forces/fbx-total-lbs",                  # 12 total non-gravitational force, body x; f_b = force / mass
    "forces/fby-total-lbs",                  # 13 (accelerations/N{x,y,z} disagree with JSBSim's velocity
    "forces/fbz-total-lbs",                  # 14 history by up to 0.7 m/s^2 in turns: test_nav_ins_jsbsim)
    "inertia/mass-slugs",                    # 15 per step: fuel burn moves f_b by ~1 micro-g per second
    "atmosphere/total-wind-north-fps",       # 16 (only with turbulence or gusts)
    "atmosphere/total-wind-east-fps",        # 17
    "atmosphere/total-wind-down-fps",        # 18
)
_N_STATE = 16
_NAN_NAMES = ("lat_rad", "lon_rad", "h_msl_m", "v_ned_mps[north]", "v_ned_mps[east]", "v_ned_mps[down]",
              "roll_rad", "pitch_rad", "yaw_rad",
              "omega_ib_b_rps[x]", "omega_ib_b_rps[y]", "omega_ib_b_rps[z]",
              "f_b_mps2[x]", "f_b_mps2[y]", "f_b_mps2[z]", "mass",
              "wind_ned_mps[north]", "wind_ned_mps[east]", "wind_ned_mps[down]")

# Rows of the converted scalar block (one row per field) and of the vector block (5, 3, n): the layout of
# TruthChunk.from_blocks.
(_S_T, _S_LAT, _S_LON, _S_H, _S_ROLL, _S_PITCH, _S_YAW, _S_TAS, _S_ALPHA, _S_BETA, _S_P, _S_TK,
 _S_AGL) = (SCALAR_FIELDS.index(k) for k in (
    "t_s", "lat_rad", "lon_rad", "h_msl_m", "roll_rad", "pitch_rad", "yaw_rad", "tas_mps", "alpha_rad",
    "beta_rad", "p_static_pa", "T_static_K", "h_agl_m"))
_S_ROWS = len(SCALAR_FIELDS)
_V_V, _V_WIB, _V_WEB, _V_F, _V_WIND = (VECTOR_FIELDS.index(k) for k in (
    "v_ned_mps", "omega_ib_b_rps", "omega_eb_b_rps", "f_b_mps2", "wind_ned_mps"))
_V_ROWS = len(VECTOR_FIELDS)


@njit(cache=True)
def _std_atmosphere(lat_rad, lon_rad, h_m):  # pragma: no cover - compiled
    """(p_static_pa, T_static_K) of JSBSim's default standard atmosphere at a geodetic position."""
    return static_p_T(lat_rad, lon_rad, h_m, 0.0, JSBSIM_P_SL_PA)


@njit(cache=True)
def _convert_raw(raw, n, ncol, row_wind, row_terrain_m, first_step, dt_s, delta_T_K,
                 p_sl_pa, s, vb, c):  # pragma: no cover - compiled
    """The first n steps of recorded JSBSim values (flat float64 buffer, ncol per step) -> SI fields written
    into the preallocated scalar block s (_S_ROWS, n), vector block vb (_V_ROWS, 3, n) and C_bn c (n, 3, 3),
    in one pass. row_wind (n, 3): the steady wind written for each step (used when the total wind is not
    recorded); row_terrain_m (n,): the terrain elevation JSBSim had at each step. Returns the index of the
    first non-finite raw value, or -1. No Python objects."""
    bad = -1
    for k in range(n * ncol):
        if not np.isfinite(raw[k]):
            bad = k
            break
    for i in range(n):
        o = i * ncol
        lat, lon, h = raw[o], raw[o + 1], raw[o + 2] * M_PER_FT
        s[_S_T, i] = (first_step + i) * dt_s
        s[_S_LAT, i] = lat
        s[_S_LON, i] = lon
        s[_S_H, i] = h
        s[_S_AGL, i] = h - row_terrain_m[i]
        for k in range(3):
            vb[_V_V, k, i] = raw[o + 3 + k] * M_PER_FT
            vb[_V_WIB, k, i] = raw[o + 9 + k]
        if ncol > _N_STATE:
            for k in range(3):
                vb[_V_WIND, k, i] = raw[o + 16 + k] * M_PER_FT
        else:
            for k in range(3):
                vb[_V_WIND, k, i] = row_wind[i, k]
        ph, th, ps = raw[o + 6], raw[o + 7], raw[o + 8]
        if ps > np.pi:
            ps -= 2.0 * np.pi          # JSBSim gives [0, 2 pi); ours is (-pi, pi]
        s[_S_ROLL, i], s[_S_PITCH, i], s[_S_YAW, i] = ph, th, ps
        cr, sr, cp, sp, cy, sy = np.cos(ph), np.sin(ph), np.cos(th), np.sin(th), np.cos(ps), np.sin(ps)
        # 3-2-1 body (FRD) -> NED, as terrain.geodesy.euler_to_C_bn
        c[i, 0, 0] = cp * cy
        c[i, 0, 1] = sr * sp * cy - cr * sy
        c[i, 0, 2] = cr * sp * cy + sr * sy
        c[i, 1, 0] = cp * sy
        c[i, 1, 1] = sr * sp * sy + cr * cy
        c[i, 1, 2] = cr * sp * sy - sr * cy
        c[i, 2, 0] = -sp
        c[i, 2, 1] = sr * cp
        c[i, 2, 2] = cr * cp
        # Earth rate in NED at the geodetic latitude, into body axes: omega_eb = omega_ib - C_nb omega_ie^n
        wn = OMEGA_EARTH_RPS * np.cos(lat)
        wd = -OMEGA_EARTH_RPS * np.sin(lat)
        for k in range(3):
            vb[_V_WEB, k, i] = raw[o + 9 + k] - (c[i, 0, k] * wn + c[i, 2, k] * wd)
        for k in range(3):       # lbf / slug = ft/s^2
            vb[_V_F, k, i] = raw[o + 12 + k] * M_PER_FT / raw[o + 15]
        # air-relative velocity in body axes: C_nb (v - wind)
        an = vb[_V_V, 0, i] - vb[_V_WIND, 0, i]
        ae = vb[_V_V, 1, i] - vb[_V_WIND, 1, i]
        ad = vb[_V_V, 2, i] - vb[_V_WIND, 2, i]
        u = c[i, 0, 0] * an + c[i, 1, 0] * ae + c[i, 2, 0] * ad
        v = c[i, 0, 1] * an + c[i, 1, 1] * ae + c[i, 2, 1] * ad
        w = c[i, 0, 2] * an + c[i, 1, 2] * ae + c[i, 2, 2] * ad
        s[_S_TAS, i] = np.sqrt(u * u + v * v + w * w)
        s[_S_ALPHA, i] = np.arctan2(w, u)
        s[_S_BETA, i] = np.arctan2(v, np.sqrt(u * u + w * w))
        s[_S_P, i], s[_S_TK, i] = static_p_T(lat, lon, h, delta_T_K, p_sl_pa)
    return bad


_PACK_STATE = struct.Struct(f"{_N_STATE}d").pack_into


_PACK_STATE_WIND = struct.Struct(f"{len(_RECORDED)}d").pack_into


def _record_state(n: int, run, buf: np.ndarray, start: int, getters) -> int:
    """The hot loop: run() and copy the 16 cached state nodes' values into buf (float64) from byte
    `start` on, nothing else; returns the next offset. The getters are bound to locals and their values
    packed straight into the preallocated buffer by one struct call (no tuple, no list, no resizing)."""
    (g0, g1, g2, g3, g4, g5, g6, g7, g8, g9, g10, g11, g12, g13, g14, g15) = getters
    pack = _PACK_STATE
    step = 8 * _N_STATE
    for offset in range(start, start + n * step, step):
        run()
        pack(buf, offset, g0(), g1(), g2(), g3(), g4(), g5(), g6(), g7(), g8(), g9(), g10(), g11(), g12(),
             g13(), g14(), g15())
    return start + n * step


def _record_state_wind(n: int, run, buf: np.ndarray, start: int, getters) -> int:
    """As _record_state, plus the three total-wind nodes (turbulence or gusts configured)."""
    (g0, g1, g2, g3, g4, g5, g6, g7, g8, g9, g10, g11, g12, g13, g14, g15, g16, g17, g18) = getters
    pack = _PACK_STATE_WIND
    step = 8 * len(_RECORDED)
    for offset in range(start, start + n * step, step):
        run()
        pack(buf, offset, g0(), g1(), g2(), g3(), g4(), g5(), g6(), g7(), g8(), g9(), g10(), g11(), g12(),
             g13(), g14(), g15(), g16(), g17(), g18())
    return start + n * step
