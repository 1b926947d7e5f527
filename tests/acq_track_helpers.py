"""Noise-free kinematic frames for the acquisition-and-tracking tests (no simulator: the navigator's inputs
built straight from a prescribed ground track over the bundled DEM)."""

from __future__ import annotations

import math

import numpy as np
from trn_env.navigators.frames import (
    AirDataFrame,
    BaroFrame,
    GnssFrame,
    HeadingFrame,
    RadarAltimeterFrame,
    SensorFrames,
)
from trn_env.navigators.protocol import Estimate
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

R0 = 6356766.0
# the acq_track tests' reference point (jacksboro) and flight height
LAT0, LON0 = math.radians(36.50), math.radians(-84.30)
H_MSL = 1400.0


def radii_m(lat, h=H_MSL):
    """(meridian radius + h, (prime-vertical radius + h) cos lat) m: the replica's lookup radii."""
    return meridian_radius_m(lat) + h, (prime_vertical_radius_m(lat) + h) * math.cos(lat)


def trajectory(dem, lat0, lon0, h_msl_m, speed_fn, track_fn, t_end_s, dt_s=0.05):
    """(t, lat, lon, speed, track) sampled every dt_s, integrated from (lat0, lon0) (rad)."""
    t = np.arange(0.0, t_end_s + 1e-9, dt_s)
    v = np.array([speed_fn(x) for x in t])
    psi = np.array([track_fn(x) for x in t])
    lat = np.empty(t.size)
    lon = np.empty(t.size)
    lat[0], lon[0] = lat0, lon0
    for i in range(1, t.size):
        vm = 0.5 * (v[i] + v[i - 1])
        pm = 0.5 * (psi[i] + psi[i - 1])
        r_n = meridian_radius_m(lat[i - 1]) + h_msl_m
        r_e = (prime_vertical_radius_m(lat[i - 1]) + h_msl_m) * math.cos(lat[i - 1])
        lat[i] = lat[i - 1] + vm * dt_s * math.cos(pm) / r_n
        lon[i] = lon[i - 1] + vm * dt_s * math.sin(pm) / r_e
    return t, lat, lon, v, psi


def frames_for(dem, traj, h_msl_m, t0, t1, tas_fn=None, hdg_fn=None, gnss=False, ra_override=None):
    """SensorFrames over [t0, t1) from a trajectory: plumb radar ranges (noise-free), baro (ISA geopotential
    of the true height), air data and compass (defaults: speed and track, i.e. no wind), optional GNSS."""
    t, lat, lon, v, psi = traj
    sel = (t >= t0 - 1e-9) & (t < t1 - 1e-9)
    ts = t[sel]
    h_ground = np.asarray(dem.height(lat[sel], lon[sel]), float)
    rng = h_msl_m - h_ground
    if ra_override is not None:
        rng = ra_override(ts, rng)
    ok = np.isfinite(rng)
    hb = np.full(ts.size, R0 * h_msl_m / (R0 + h_msl_m))
    tas = v[sel] if tas_fn is None else np.array([tas_fn(x) for x in ts])
    hdg = psi[sel] if hdg_fn is None else np.array([hdg_fn(x) for x in ts])
    fr = SensorFrames(
        t_start_s=t0,
        t_end_s=t1,
        radar_altimeter=RadarAltimeterFrame(ts, np.where(ok, rng, np.nan), ok),
        baro=BaroFrame(ts, hb, np.ones(ts.size, bool)),
        air_data=AirDataFrame(ts, tas, np.zeros(ts.size), np.zeros(ts.size), np.ones(ts.size, bool)),
        heading=HeadingFrame(ts, np.arctan2(np.sin(hdg), np.cos(hdg)), np.ones(ts.size, bool)),
    )
    if gnss:
        vn, ve = v[sel] * np.cos(psi[sel]), v[sel] * np.sin(psi[sel])
        fr.gnss = GnssFrame(
            ts,
            lat[sel],
            lon[sel],
            np.full(ts.size, h_msl_m),
            np.column_stack([vn, ve, np.zeros(ts.size)]),
            np.ones(ts.size, bool),
        )
    return fr


def initial_estimate(traj, h_msl_m, sigma_m=30.0, dn_m=0.0, de_m=0.0, dv_mps=0.0, dpsi_rad=0.0):
    t, lat, lon, v, psi = traj
    r_n = meridian_radius_m(lat[0]) + h_msl_m
    r_e = (prime_vertical_radius_m(lat[0]) + h_msl_m) * math.cos(lat[0])
    sp, tr = v[0] + dv_mps, psi[0] + dpsi_rad
    cov = np.diag([sigma_m**2, sigma_m**2, 100.0, 1, 1, 1, 1e-4, 1e-4, 1e-4])
    return Estimate(
        0.0,
        lat[0] + dn_m / r_n,
        lon[0] + de_m / r_e,
        h_msl_m,
        np.array([sp * math.cos(tr), sp * math.sin(tr), 0.0]),
        0.0,
        0.0,
        tr,
        cov,
    )


def fly(nav, dem, traj, h_msl_m, t_end_s, **kw):
    """Run nav over 1 s frames; returns (list of estimates, true lat/lon at each estimate's time)."""
    t, lat, lon, v, psi = traj
    ests, truth = [], []
    for k in range(int(t_end_s)):
        est = nav.update(frames_for(dem, traj, h_msl_m, float(k), float(k + 1), **kw))
        ests.append(est)
        i = int(np.argmin(np.abs(t - est.t_s)))
        truth.append((lat[i], lon[i], v[i], psi[i]))
    return ests, np.array(truth)


def horizontal_error_m(est, lat, lon):
    r = 6.371e6
    return math.hypot((est.lat_rad - lat) * r, (est.lon_rad - lon) * r * math.cos(lat))
