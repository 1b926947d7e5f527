"""An independently generated sensor log for trn_env.logs tests: a trajectory and sensor samples made here,
not by trn_env's sensor code, with WGS84 ellipsoid heights (a stated geoid offset) and antenna lever arms.

Truth and perfect IMU from tests/nav_reference_trajectory.py (ECEF, J2 gravity). IMU: velocity and angle
increments over each 0.01 s interval (Simpson's rule over the instantaneous specific force and rate at the
interval's ends and middle) plus navigation-grade white noise and a constant bias. IRA: the closest terrain
point on the zero-Doppler line (brute force over the plane's directions, 1 deg then 0.02 deg), from the IRA
antenna (lever arm r_ira from the IMU). Radar altimeter: the nadir range from its antenna (r_ra). Baro:
geopotential height of the true MSL height (ISA pressure altitude in still ISA air) + a bias + noise.
GNSS: ellipsoid heights, 1 Hz, first 30 s. Air data (still air) and compass heading at 10 Hz.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

from trn_env import terrain

sys.path.insert(0, str(Path(__file__).parent))
from nav_reference_trajectory import C_bn, imu_and_truth  # noqa: E402

DEM = terrain.load("jacksboro")
LAT_C, LON_C = DEM.center_rad
H_MSL = 2500.0
V = 85.0
GEOID_N_M = -31.0              # geoid above the ellipsoid (h_ell = h_msl + N)
R_IRA = np.array([1.0, 0.4, 1.5])       # body FRD m from the IMU
R_RA = np.array([-2.0, 0.0, 1.2])
DT = 0.01
GNSS_UNTIL_S = 30.0


def _lla(t):
    r_n = meridian_radius_m(LAT_C) + H_MSL
    r_e = (prime_vertical_radius_m(LAT_C) + H_MSL) * np.cos(LAT_C)
    n = -6000.0 + V * 0.94 * t + 400.0 * np.sin(2 * np.pi * t / 120.0)
    e = -9000.0 + V * 0.34 * t
    return LAT_C + n / r_n, LON_C + e / r_e, H_MSL + 60.0 * np.sin(2 * np.pi * t / 90.0)


def _euler(t):
    return (0.08 * np.sin(2 * np.pi * t / 120.0), 0.03 + 0.01 * np.sin(2 * np.pi * t / 90.0),
            np.arctan2(0.34, 0.94) + 0.05 * np.cos(2 * np.pi * t / 120.0))


def _offset(lat, lon, h, d_ned):
    r_n = meridian_radius_m(lat) + h
    r_e = (prime_vertical_radius_m(lat) + h) * np.cos(lat)
    return lat + d_ned[:, 0] / r_n, lon + d_ned[:, 1] / r_e, h - d_ned[:, 2]


def _ray(lat, lon, h, d_ned):
    """Range along unit directions d_ned from (lat, lon, h MSL) to the DEM surface (bisection)."""
    lo, hi = np.zeros(lat.size), np.full(lat.size, 3.0 * H_MSL)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        la, lo_, hh = _offset(lat, lon, h, mid[:, None] * d_ned)
        above = hh > DEM.height(la, lo_)
        lo, hi = np.where(above, mid, lo), np.where(above, hi, mid)
    return 0.5 * (lo + hi)


def flight(duration_s: float = 150.0, seed: int = 7) -> dict:
    """Columns for trn_env.logs.LogBuilder (DataFrame-ready dicts), the truth (MSL) and the settings."""
    rng = np.random.default_rng(seed)
    th = np.arange(0.0, duration_s + DT / 2, DT / 2)          # half-step grid for Simpson
    f_b, w_ib, (lat, lon, h, v, eu) = imu_and_truth(th, _lla, _euler)
    even = slice(0, None, 2)
    t = th[even]
    # IMU increments over (t_{k-1}, t_k], k >= 1
    dv = DT / 6.0 * (f_b[0:-2:2] + 4.0 * f_b[1:-1:2] + f_b[2::2])
    dth = DT / 6.0 * (w_ib[0:-2:2] + 4.0 * w_ib[1:-1:2] + w_ib[2::2])
    vrw, arw = 9.81e-5, 1.45e-6                      # navigation grade densities (per sqrt s)
    dv += rng.standard_normal(dv.shape) * vrw * np.sqrt(DT) + rng.normal(0, 50e-6 * 9.80665, 3) * DT
    dth += (rng.standard_normal(dth.shape) * arw * np.sqrt(DT)
            + rng.normal(0, np.radians(0.005) / 3600, 3) * DT)
    imu = {"t_s": t[1:]} | {f"dv_{a}_mps": dv[:, i] for i, a in enumerate("xyz")} | {
        f"dtheta_{a}_rad": dth[:, i] for i, a in enumerate("xyz")}
    lat, lon, h, v = lat[even], lon[even], h[even], v[even]
    roll, pitch, yaw = (x[even] for x in eu)
    C = C_bn(roll, pitch, yaw)
    # IRA, 10 Hz, from its antenna
    k = np.arange(10, t.size, 10)
    ant = _offset(lat[k], lon[k], h[k], np.einsum("nij,j->ni", C[k], R_IRA))
    vh = v[k] / np.linalg.norm(v[k], axis=1)[:, None]
    down = np.array([0.0, 0.0, 1.0]) - vh[:, 2:3] * vh
    down /= np.linalg.norm(down, axis=1)[:, None]
    right = np.cross(vh, down)
    # the closest terrain point on the zero-Doppler line (brute force over the plane's directions)
    best_r, best_d = np.full(k.size, np.inf), np.zeros((k.size, 3))
    for grid in (np.radians(np.arange(-45.0, 45.01, 1.0)), None):
        if grid is None:       # refine around the coarse minimum
            base = np.arctan2(np.einsum("ni,ni->n", best_d, right), np.einsum("ni,ni->n", best_d, down))
            grid = base[:, None] + np.radians(np.arange(-1.0, 1.001, 0.02))[None, :]
        else:
            grid = np.broadcast_to(grid, (k.size, grid.size))
        for j in range(grid.shape[1]):
            d = np.cos(grid[:, j])[:, None] * down + np.sin(grid[:, j])[:, None] * right
            r = _ray(*ant, d)
            better = r < best_r
            best_r = np.where(better, r, best_r)
            best_d = np.where(better[:, None], d, best_d)
    rng_ira, d = best_r, best_d
    theta = np.arcsin(np.einsum("ni,ni->n", d, C[k][:, :, 1]))
    ira = {"t_s": t[k], "range_m": rng_ira + rng.normal(0, 3.5, k.size),
           "look_angle_deg": np.degrees(theta) + rng.normal(0, 0.1, k.size)}
    ant = _offset(lat[k], lon[k], h[k], np.einsum("nij,j->ni", C[k], R_RA))
    ra_true = _ray(*ant, np.tile([0.0, 0.0, 1.0], (k.size, 1)))
    ra = {"t_s": t[k], "range_m": ra_true + rng.normal(0, 1.0, k.size) * (0.6 + 0.02 * ra_true)}
    kb = np.arange(10, t.size, 10)
    baro = {"t_s": t[kb], "h_baro_m": 6356766.0 * h[kb] / (6356766.0 + h[kb]) + rng.normal(0, 10.0)
            + rng.normal(0, 0.5, kb.size)}
    kg = np.arange(100, int(GNSS_UNTIL_S / DT) + 1, 100)
    gnss = {"t_s": t[kg], "lat_rad": lat[kg] + rng.normal(0, 1.0, kg.size) / meridian_radius_m(lat[kg]),
            "lon_rad": lon[kg] + rng.normal(0, 1.0, kg.size) / (prime_vertical_radius_m(lat[kg])
                                                                 * np.cos(lat[kg])),
            "h_m": h[kg] + GEOID_N_M + rng.normal(0, 2.0, kg.size),
            "v_n_mps": v[kg, 0] + rng.normal(0, 0.05, kg.size),
            "v_e_mps": v[kg, 1] + rng.normal(0, 0.05, kg.size),
            "v_d_mps": v[kg, 2] + rng.normal(0, 0.05, kg.size)}
    # air data (still air: the air-relative velocity is the ground velocity) and compass heading, 10 Hz
    v_b = np.einsum("nji,nj->ni", C[kb], v[kb])          # body-frame velocity, C_bn^T v_ned
    tas = np.linalg.norm(v_b, axis=1)
    air = {"t_s": t[kb], "tas_mps": tas + rng.normal(0, 0.5, kb.size),
           "alpha_rad": np.arctan2(v_b[:, 2], v_b[:, 0]) + rng.normal(0, 0.002, kb.size),
           "beta_rad": np.arcsin(v_b[:, 1] / tas) + rng.normal(0, 0.002, kb.size)}
    heading = {"t_s": t[kb], "heading_deg": np.degrees(np.angle(np.exp(1j * yaw[kb])))
               + rng.normal(0, 0.2, kb.size) + rng.normal(0, 0.3)}
    truth = {"t_s": t, "lat_rad": lat, "lon_rad": lon, "h_m": h + GEOID_N_M, "v_n_mps": v[:, 0],
             "v_e_mps": v[:, 1], "v_d_mps": v[:, 2], "roll_rad": roll, "pitch_rad": pitch, "yaw_rad": yaw}
    return {"imu": imu, "ira": ira, "radar_altimeter": ra, "baro": baro, "gnss": gnss, "air_data": air,
            "heading": heading, "truth": truth, "h_msl_m": h}


SENSORS = {"imu": {"grade": "navigation", "rate_hz": 100.0}, "ira": {"rate_hz": 10.0},
           "radar_altimeter": {"rate_hz": 10.0}, "baro": {"rate_hz": 10.0}, "gnss": {"rate_hz": 1.0},
           "air_data": {"rate_hz": 10.0}, "heading": {"rate_hz": 10.0}}


def build(out, duration_s: float = 150.0, seed: int = 7, navigator: str = "ins_tercom"):
    """Write the log with trn_env.logs.builder.LogBuilder (pandas DataFrames); returns its path."""
    import pandas as pd

    from trn_env.logs.builder import LogBuilder
    fl = flight(duration_s, seed)
    b = LogBuilder(map="jacksboro", imu_sample="increment",
                   height_datum={"reference": "ellipsoid", "geoid_offset_m": GEOID_N_M},
                   lever_arms_m={"ira": R_IRA.tolist(), "radar_altimeter": R_RA.tolist()}, sensors=SENSORS,
                   navigator={"name": navigator, "settings": {}}, seed=seed,
                   initial_errors={"position_ned_m": [30.0, 30.0, 15.0], "velocity_ned_mps": [0.1, 0.1, 0.1],
                                   "attitude_mrad": [0.05, 0.05, 1.0]})
    for s in ("imu", "ira", "radar_altimeter", "baro", "gnss", "air_data", "heading"):
        b.add(s, pd.DataFrame(fl[s]))
    b.add_truth(pd.DataFrame(fl["truth"]))
    return b.write(out)
