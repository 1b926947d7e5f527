"""GNSS fusion in the INS/TRN EKF (navigators.filters.ins_trn_ekf) on synthetic frames, no simulator.

A straight 2,500 m flight with an exact IMU (tests/nav_reference_trajectory.py) plus a constant
accelerometer bias, an initial position error of 75 m, and GNSS fixes generated here: truth + white
noise of known sigma. The expectations are independent of the filter: the raw GNSS error the test draws,
a Rayleigh bound on a 2-D Gaussian error, and the drift of the INS alone.
"""

import sys
from pathlib import Path

import numpy as np
import pytest
from trn_env.navigators import registry
from trn_env.navigators.filters.ins_trn_ekf import initial_covariance
from trn_env.navigators.frames import BaroFrame, GnssFrame, ImuFrame, SensorFrames
from trn_env.navigators.protocol import Estimate
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

sys.path.insert(0, str(Path(__file__).parent))
from nav_reference_trajectory import imu_and_truth  # noqa: E402

H = 2500.0
V = 83.0
HEADING = np.radians(70.0)
LAT0, LON0 = np.radians(36.5), np.radians(-84.3)
T_END = 100.0
SIG_GNSS_M = 1.5            # white, per north/east axis
SIG_GNSS_V = 0.05
BIAS_X = 0.003              # m/s^2 (300 ug): the INS alone drifts 0.5 b t^2 = 15 m in 100 s on top
T_LOSS, T_BACK = 50.0, 80.0


def _lla(t):
    r_n = meridian_radius_m(LAT0) + H
    r_e = (prime_vertical_radius_m(LAT0) + H) * np.cos(LAT0)
    return (LAT0 + V * np.cos(HEADING) * t / r_n, LON0 + V * np.sin(HEADING) * t / r_e, np.full_like(t, H))


def _euler(t):
    return np.zeros_like(t), np.full_like(t, 0.02), np.full_like(t, HEADING)


@pytest.fixture(scope="module")
def flight():
    t = np.arange(0.0, T_END, 0.01)
    f_b, w_ib, (lat, lon, h, v, eu) = imu_and_truth(t, _lla, _euler)
    f_b = f_b + np.array([BIAS_X, 0.0, 0.0])
    rng = np.random.default_rng(5)
    k = np.arange(0, t.size, 100)               # GNSS at 1 Hz
    r_n = meridian_radius_m(lat[k]) + h[k]
    r_e = (prime_vertical_radius_m(lat[k]) + h[k]) * np.cos(lat[k])
    e_ne = rng.standard_normal((k.size, 2)) * SIG_GNSS_M
    g_lat = lat[k] + e_ne[:, 0] / r_n
    g_lon = lon[k] + e_ne[:, 1] / r_e
    g_v = v[k] + rng.standard_normal((k.size, 3)) * SIG_GNSS_V
    return dict(t=t, f_b=f_b, w=w_ib, lat=lat, lon=lon, h=h, v=v, eu=eu, k=k, g_lat=g_lat, g_lon=g_lon,
                g_v=g_v, g_err=np.hypot(e_ne[:, 0], e_ne[:, 1]))


def _frames(fl, a, b, with_gnss):
    t = fl["t"][a:b]
    ones = np.ones(t.size, bool)
    sel = (fl["k"] >= a) & (fl["k"] < b)
    gt = fl["t"][fl["k"][sel]]
    up = with_gnss(gt)
    gnss = GnssFrame(gt[up], fl["g_lat"][sel][up], fl["g_lon"][sel][up], fl["h"][fl["k"][sel]][up],
                     fl["g_v"][sel][up], np.ones(int(up.sum()), bool)) if up.any() else None
    return SensorFrames(t[0], t[-1] + 0.01, imu=ImuFrame(t, fl["f_b"][a:b], fl["w"][a:b], ones),
                        baro=BaroFrame(t[::5], _geopotential(fl["h"][a:b][::5]), ones[::5]),
                        gnss=gnss)


def _geopotential(h_m):
    """A perfect ISA baro reports geopotential height (US 1976 radius 6356766 m)."""
    return 6356766.0 * h_m / (6356766.0 + h_m)


def _run(fl, with_gnss, **settings):
    nav = registry.create("ins", **settings)
    r_n = meridian_radius_m(fl["lat"][0]) + H
    r_e = (prime_vertical_radius_m(fl["lat"][0]) + H) * np.cos(fl["lat"][0])
    nav.reset(Estimate(0.0, fl["lat"][0] + 60.0 / r_n, fl["lon"][0] - 45.0 / r_e, fl["h"][0],
                       fl["v"][0].copy(), fl["eu"][0][0], fl["eu"][1][0], fl["eu"][2][0],
                       initial_covariance()))
    rows, events = [], []
    for a in range(0, fl["t"].size, 100):
        b = min(a + 100, fl["t"].size)
        est = nav.update(_frames(fl, a, b, with_gnss))
        j = b - 1
        r_n = meridian_radius_m(fl["lat"][j]) + H
        r_e = (prime_vertical_radius_m(fl["lat"][j]) + H) * np.cos(fl["lat"][j])
        err = np.hypot((est.lat_rad - fl["lat"][j]) * r_n, (est.lon_rad - fl["lon"][j]) * r_e)
        sig = np.sqrt(est.covariance[0, 0] + est.covariance[1, 1])
        rows.append((fl["t"][j], err, sig))
        events += est.health.events
    return np.array(rows), events


def _up(t):
    return (t < T_LOSS) | (t >= T_BACK)


def test_gnss_aided_beats_ins_alone_and_raw_gnss(flight):
    aided, _ = _run(flight, _up)
    alone, _ = _run(flight, lambda t: np.zeros(t.shape, bool))
    t = aided[:, 0]
    win = (t >= 20.0) & (t < T_LOSS)           # converged, GNSS up
    # INS alone: keeps the 75 m initial error and drifts with the bias
    assert alone[win, 1].min() > 60.0
    # INS + GNSS: every error below the raw fixes' 2-D error that a Rayleigh(1.5 m) exceeds with
    # probability exp(-r^2 / (2 sigma^2)) = 3e-4 (r = 6 m), and its RMS below the raw GNSS RMS it averages
    r99 = SIG_GNSS_M * np.sqrt(-2.0 * np.log(3e-4))
    assert aided[win, 1].max() < r99
    g_t = flight["t"][flight["k"]]
    raw_rms = np.sqrt(np.mean(flight["g_err"][(g_t >= 20.0) & (g_t < T_LOSS)] ** 2))
    assert np.sqrt(np.mean(aided[win, 1] ** 2)) < raw_rms
    # the sigma says so too: the GNSS level (the correlated-error floor, 1.5 m per axis), not the 42 m start
    assert np.all(aided[win, 2] < 3.0) and np.all(aided[win, 2] >= np.hypot(1.5, 1.5) - 1e-6)


def test_error_and_sigma_at_loss_are_gnss_aided_then_recovery(flight):
    rows, events = _run(flight, _up)
    t = rows[:, 0]
    at_loss = np.searchsorted(t, T_LOSS) - 1                 # last update before the loss
    r99 = SIG_GNSS_M * np.sqrt(-2.0 * np.log(3e-4))
    assert rows[at_loss, 1] < r99 and rows[at_loss, 2] < 3.0
    # during the outage the sigma grows (bias drift) and the error stays inside 3 sigma
    out = (t > T_LOSS + 5) & (t < T_BACK)
    assert np.all(rows[out, 1] <= 3.0 * rows[out, 2])
    # back at the GNSS level a few seconds after the recovery
    back = t >= T_BACK + 5
    assert rows[back, 1].max() < r99
    msgs = [(te, m) for te, m in events if m.startswith("GNSS")]
    lost = [te for te, m in msgs if m.startswith("GNSS lost")]
    rec = [te for te, m in msgs if m.startswith("GNSS recovered")]
    assert len(lost) == 1 and T_LOSS - 1.5 <= lost[0] < T_LOSS
    assert len(rec) == 1 and T_BACK <= rec[0] < T_BACK + 1.0


def test_use_gnss_false_ignores_it(flight):
    rows, events = _run(flight, _up, use_gnss=False)
    assert rows[:, 1].min() > 60.0
    assert not [m for _, m in events if m.startswith("GNSS")]
