"""The INS/TERCOM navigators on synthetic sensor frames (no simulator): a straight flight over the real
jacksboro DEM with perfect IMU data, an initial position error, and terrain measurements generated here by
ray-casting the map (independent of navigators.measurements.ira_closest_point)."""

import sys
from pathlib import Path

import numpy as np
import pytest
from trn_env.navigators import registry
from trn_env.navigators.filters.ins_trn_ekf import initial_covariance
from trn_env.navigators.frames import BaroFrame, ImuFrame, IraFrame, RadarAltimeterFrame, SensorFrames
from trn_env.navigators.protocol import Estimate, Navigator
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

from trn_env import terrain

sys.path.insert(0, str(Path(__file__).parent))
from nav_reference_trajectory import C_bn, imu_and_truth  # noqa: E402

DEM = terrain.load("jacksboro")
LAT_C, LON_C = DEM.center_rad
H = 2500.0
V = 83.0
HEADING = np.radians(70.0)
CRAB = np.radians(8.0)  # crosswind: body yaw differs from the track by the crab angle
T_END = 130.0


def _lla(t):
    r_n = meridian_radius_m(LAT_C) + H
    r_e = (prime_vertical_radius_m(LAT_C) + H) * np.cos(LAT_C)
    n0, e0 = -5500.0, -9000.0
    return (
        LAT_C + (n0 + V * np.cos(HEADING) * t) / r_n,
        LON_C + (e0 + V * np.sin(HEADING) * t) / r_e,
        np.full_like(t, H),
    )


def _euler(t):
    return np.full_like(t, np.radians(3.0)), np.full_like(t, 0.02), np.full_like(t, HEADING - CRAB)


def _geopotential(h_m):
    """A perfect ISA baro reports geopotential height (US 1976 radius 6356766 m)."""
    return 6356766.0 * h_m / (6356766.0 + h_m)


def _ray_to_terrain(lat, lon, h, d_ned):
    """Bisection along unit directions d_ned (n, 3) from (lat, lon, h) to the DEM surface."""
    r_n = meridian_radius_m(lat) + h
    r_e = (prime_vertical_radius_m(lat) + h) * np.cos(lat)
    lo, hi = np.zeros(lat.size), np.full(lat.size, 3.0 * H)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        p = mid[:, None] * d_ned
        above = (h - p[:, 2]) > DEM.height(lat + p[:, 0] / r_n, lon + p[:, 1] / r_e)
        lo, hi = np.where(above, mid, lo), np.where(above, hi, mid)
    return 0.5 * (lo + hi)


@pytest.fixture(scope="module")
def flight():
    t = np.arange(0.0, T_END, 0.01)
    f_b, w_ib, (lat, lon, h, v, eu) = imu_and_truth(t, _lla, _euler)
    C = C_bn(*eu)
    # IRA at 10 Hz: a terrain point on the zero-Doppler plane, below and 5 deg right of the track
    k = np.arange(0, t.size, 10)
    vh = v[k] / np.linalg.norm(v[k], axis=1)[:, None]
    down = np.array([0.0, 0.0, 1.0]) - vh[:, 2:3] * vh
    down /= np.linalg.norm(down, axis=1)[:, None]
    right = np.cross(vh, down)
    d = np.cos(0.09) * down + np.sin(0.09) * right
    R = _ray_to_terrain(lat[k], lon[k], h[k], d)
    theta = np.arcsin(np.einsum("ni,ni->n", d, C[k][:, :, 1]))
    ra = _ray_to_terrain(lat[k], lon[k], h[k], np.tile([0.0, 0.0, 1.0], (k.size, 1)))
    return dict(t=t, f_b=f_b, w=w_ib, lat=lat, lon=lon, h=h, v=v, eu=eu, k=k, R=R, theta=theta, ra=ra)


def _frames(fl, a, b, ira_valid=None, imu_f=None):
    t = fl["t"][a:b]
    sel = (fl["k"] >= a) & (fl["k"] < b)
    kk = fl["k"][sel]
    ones = np.ones(t.size, bool)
    fb = fl["f_b"][a:b] if imu_f is None else imu_f
    iv = np.ones(kk.size, bool) if ira_valid is None else ira_valid[sel]
    R = np.where(iv, fl["R"][sel], np.nan)
    th = np.where(iv, fl["theta"][sel], np.nan)
    return SensorFrames(
        t[0],
        t[-1] + 0.01,
        imu=ImuFrame(t, fb, fl["w"][a:b], ones),
        baro=BaroFrame(t[::5], _geopotential(fl["h"][a:b][::5]), ones[::5]),
        ira=IraFrame(fl["t"][kk], R, th, iv),
        radar_altimeter=RadarAltimeterFrame(fl["t"][kk], fl["ra"][sel], np.ones(kk.size, bool)),
    )


def _initial(fl, dn=60.0, de=-45.0):
    r_n = meridian_radius_m(fl["lat"][0]) + H
    r_e = (prime_vertical_radius_m(fl["lat"][0]) + H) * np.cos(fl["lat"][0])
    return Estimate(
        0.0,
        fl["lat"][0] + dn / r_n,
        fl["lon"][0] + de / r_e,
        fl["h"][0],
        fl["v"][0].copy(),
        fl["eu"][0][0],
        fl["eu"][1][0],
        fl["eu"][2][0],
        initial_covariance(),
    )


def _hor_err(est, fl, k):
    r_n = meridian_radius_m(fl["lat"][k]) + H
    r_e = (prime_vertical_radius_m(fl["lat"][k]) + H) * np.cos(fl["lat"][k])
    return np.hypot((est.lat_rad - fl["lat"][k]) * r_n, (est.lon_rad - fl["lon"][k]) * r_e)


def _run(nav, fl, step=100, **kw):
    nav.reset(_initial(fl))
    ests = []
    for a in range(0, fl["t"].size, step):
        ests.append(nav.update(_frames(fl, a, min(a + step, fl["t"].size), **kw)))
    return ests


@pytest.mark.parametrize("aiding,formula", [("ira", "proposed"), ("radar_altimeter", "proposed")])
def test_tercom_fixes_remove_initial_position_error(flight, aiding, formula):
    nav = registry.create("ins_tercom", dem=DEM, aiding=aiding, formula=formula, ira_decimation=1)
    assert isinstance(nav, Navigator)
    ests = _run(nav, flight)
    err0 = _hor_err(ests[0], flight, 99)
    err = _hor_err(ests[-1], flight, flight["t"].size - 1)
    assert err0 > 60.0  # the free-inertial start keeps the 75 m initial error
    assert len([f for f in nav.fixes if f.valid]) >= 3
    assert err < 8.0, (err, [(f.dn_m, f.de_m, f.reason) for f in nav.fixes])
    assert ests[-1].health.status == "ok"
    assert ests[-1].sigma_ned_m[0] < 15.0 and ests[-1].covariance.shape == (9, 9)


def test_free_inertial_keeps_initial_error(flight):
    nav = registry.create("ins")
    ests = _run(nav, flight, step=1000)
    err = _hor_err(ests[-1], flight, flight["t"].size - 1)
    assert 74.0 < err < 76.5  # perfect IMU: the 75 m initial offset stays
    assert ests[-1].health.status == "free_inertial" and ests[-1].sigma_ned_m[0] > 29.0


def test_bad_input_is_skipped_and_reported(flight):
    """No-returns, NaN IMU samples and the filter keep running; the estimate stays good."""
    rng = np.random.default_rng(0)
    ira_valid = rng.random(flight["k"].size) > 0.2
    nav = registry.create("ins_tercom", dem=DEM)
    nav.reset(_initial(flight))
    est = None
    for a in range(0, flight["t"].size, 100):
        b = min(a + 100, flight["t"].size)
        f = flight["f_b"][a:b].copy()
        if a == 3000:
            f[5] = np.nan
        est = nav.update(_frames(flight, a, b, ira_valid=ira_valid, imu_f=f))
    sk = est.health.skipped
    assert sk["altimeter_no_return"] == int((~ira_valid).sum())
    assert sk["imu_invalid"] == 1
    assert _hor_err(est, flight, flight["t"].size - 1) < 10.0
    assert np.all(np.isfinite(est.covariance))


def test_window_leaving_the_map_is_skipped(flight):
    """A navigator whose map is a small piece of the DEM: fixes off that map are rejected, never applied."""
    from trn_env.terrain.dem import Dem

    h, lat0, lon0, dlat, dlon = DEM.grid
    small = Dem(h[:40, :40], lat0, lon0, dlat, dlon, "corner")
    nav = registry.create("ins_tercom", dem=small)
    ests = _run(nav, flight, step=500)
    assert ests[-1].health.skipped.get("tercom_off_map", 0) >= 3
    assert np.isfinite(ests[-1].lat_rad) and ests[-1].health.status == "acquiring"


def test_covariance_not_positive_definite_is_repaired(flight):
    nav = registry.create("ins_tercom", dem=DEM)
    nav.reset(_initial(flight))
    nav.kf.P[0, 0] = -5.0  # corrupt the filter
    est = nav.update(_frames(flight, 0, 100))
    assert est.health.skipped.get("covariance_not_pd", 0) >= 1
    assert np.all(np.linalg.eigvalsh(nav.kf.P) > 0)


def test_registry_and_settings_errors():
    assert {"ins", "ins_tercom"} <= set(registry.available())
    with pytest.raises(ValueError, match="unknown navigator"):
        registry.create("nope")
    with pytest.raises(ValueError, match="dem"):
        registry.create("ins_tercom")
    with pytest.raises(ValueError, match="formula"):
        registry.create("ins_tercom", dem=DEM, formula="magic")
    with pytest.raises(ValueError, match="navigator 'ins': colour: unknown setting; known: accel_bias_mps2"):
        registry.create("ins", colour="red")


def test_height_initialised_from_baro_and_geopotential_converted(flight):
    nav = registry.create("ins")
    init = _initial(flight)
    init.h_m += 15.0
    nav.reset(init)
    est = nav.update(_frames(flight, 0, 100))
    assert abs(est.h_m - flight["h"][99]) < 0.05     # 1 m geopotential difference at 2500 m removed too
    nav = registry.create("ins", init_height_from_baro=False, baro_geopotential=False)
    nav.reset(init)
    est = nav.update(_frames(flight, 0, 100))
    assert est.h_m - flight["h"][99] > 10.0
