"""Navigator integrity of the point-mass, particle and Rao-Blackwellised particle filters (issue 19): each
feeds its terrain updates' NIS to navigators.integrity.InnovationMonitor, says "degraded" when the window's
sum leaves its chi-square band, re-spreads its belief (logged) and returns to "ok" once consistent data
resumes; on consistent data it never flags.

The flight: an aircraft in level flight at 85 m/s over the real Jacksboro map, GNSS denied. Its true path
is an INS's own path from the IMU samples (so the IMU is exact for it) shifted by a constant 40 m / -25 m
horizontal offset; the IRA samples come from the simulator's sensor model (trn_env.sensors.ira, with its
noise) over that path and the same map. Inconsistent data: +120 m added to the IRA ranges for 15 s (over
30 range sigmas). The band is checked against scipy's chi-square quantiles computed here."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2
from trn_env.navigators import registry
from trn_env.navigators.frames import BaroFrame, ImuFrame, IraFrame, SensorFrames
from trn_env.navigators.inertial.strapdown import StrapdownIns, euler_from_C_bn, quat_to_dcm
from trn_env.navigators.protocol import (
    EXTRA_INTEGRITY_BAND,
    EXTRA_INTEGRITY_DOF,
    EXTRA_INTEGRITY_STATISTIC,
    EXTRA_NIS,
    Estimate,
)
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

from trn_env import terrain
from trn_env.flight.truth import TruthChunk
from trn_env.sensors.ira import IraConfig, sample_ira

DURATION_S = 80.0
BIAS_START_S, BIAS_END_S, BIAS_M = 30.0, 45.0, 120.0
OFFSET_NE_M = (40.0, -25.0)
H0_M = 2000.0
V0_NED = np.array([60.0, 60.0, 0.0])
WINDOW = 3


@pytest.fixture(scope="module")
def dem():
    return terrain.load("jacksboro")


def _truth_and_frames(dem, baro_slaved: bool, bias_m: float, seed: int = 3):
    """(truth arrays at 100 Hz, initial Estimate of the INS, list of 1 s SensorFrames)."""
    dt = 0.01
    t = np.arange(1, int(DURATION_S / dt) + 1) * dt
    n = t.size
    f_b = np.tile([0.0, 0.0, -9.797], (n, 1))
    w_b = np.zeros((n, 3))
    ok = np.ones(n, bool)
    lat0, lon0 = dem.center_rad
    yaw0 = math.atan2(V0_NED[1], V0_NED[0])
    ins = StrapdownIns("j2", 30.0 if baro_slaved else None, "interval")
    ins.reset(0.0, lat0, lon0, H0_M, V0_NED, 0.0, 0.0, yaw0)
    tb = t[::5]
    hb = np.full(tb.size, H0_M)
    vb = np.ones(tb.size, bool)
    hist = ins.propagate(t, f_b, w_b, ok, tb, hb, vb) if baro_slaved else ins.propagate(t, f_b, w_b, ok)
    r_n = meridian_radius_m(lat0) + H0_M
    r_e = (prime_vertical_radius_m(lat0) + H0_M) * math.cos(lat0)
    lat = hist[:, 0] + OFFSET_NE_M[0] / r_n
    lon = hist[:, 1] + OFFSET_NE_M[1] / r_e
    C = np.stack([quat_to_dcm(q) for q in hist[:, 6:10]])
    eul = np.array([euler_from_C_bn(c) for c in C])
    z3 = np.zeros((n, 3))
    z1 = np.zeros(n)
    truth = TruthChunk(t_s=t, lat_rad=lat, lon_rad=lon, h_msl_m=hist[:, 2].copy(),
                       v_ned_mps=hist[:, 3:6].copy(), roll_rad=eul[:, 0], pitch_rad=eul[:, 1],
                       yaw_rad=eul[:, 2], C_bn=C, omega_ib_b_rps=w_b, omega_eb_b_rps=z3, f_b_mps2=f_b,
                       tas_mps=np.hypot(hist[:, 3], hist[:, 4]), alpha_rad=z1, beta_rad=z1, p_static_pa=z1,
                       T_static_K=z1, wind_ned_mps=z3, h_agl_m=z1)
    ira, _ = sample_ira(truth, dem, np.random.default_rng(seed), IraConfig(rate_hz=2.0))
    rng_m = ira.range_m.copy()
    bad = (ira.t_s >= BIAS_START_S) & (ira.t_s < BIAS_END_S)
    rng_m[bad] += bias_m
    frames = []
    for k in range(int(DURATION_S)):
        a, b = np.searchsorted(t, [k + 1e-9, k + 1 + 1e-9])
        ia, ib = np.searchsorted(ira.t_s, [k + 1e-9, k + 1 + 1e-9])
        ba, bb = np.searchsorted(tb, [k + 1e-9, k + 1 + 1e-9])
        frames.append(SensorFrames(
            float(k), float(t[b - 1]),
            imu=ImuFrame(t[a:b], f_b[a:b], w_b[a:b], ok[a:b]),
            baro=BaroFrame(tb[ba:bb], hb[ba:bb], vb[ba:bb]),
            ira=IraFrame(ira.t_s[ia:ib], rng_m[ia:ib], ira.look_angle_rad[ia:ib], ira.valid[ia:ib]),
        ))
    cov = np.diag([50.0**2, 50.0**2, 10.0**2, 0.1**2, 0.1**2, 0.1**2, 1e-6, 1e-6, 1e-6])
    init = Estimate(0.0, lat0, lon0, H0_M, V0_NED.copy(), 0.0, 0.0, yaw0, cov)
    return (t, lat, lon), init, frames


def _horizontal_error_m(est, truth) -> float:
    t, lat, lon = truth
    k = min(int(np.searchsorted(t, est.t_s - 1e-6)), t.size - 1)
    return math.hypot((est.lat_rad - lat[k]) * meridian_radius_m(lat[k]),
                      (est.lon_rad - lon[k]) * prime_vertical_radius_m(lat[k]) * math.cos(lat[k]))


NAVS = {
    "pmf": (True, dict(grid_size=50, baro_geopotential=False)),
    "pf": (True, dict(n_particles=1500, baro_geopotential=False)),
    "rbpf": (False, dict(n_particles=1000, terrain_model_sigma_m=0.0)),   # map = world
}


def _run(dem, name: str, bias_m: float):
    baro_slaved, settings = NAVS[name]
    truth, init, frames = _truth_and_frames(dem, baro_slaved, bias_m)
    kw = dict(dem=dem, integrity_window=WINDOW, integrity_alpha=0.01, **settings)
    if name != "pmf":
        kw["rng"] = np.random.default_rng(11)
    nav = registry.create(name, **kw)
    nav.reset(init)
    ests = [nav.update(f) for f in frames]
    return nav, ests, truth


def _band_is_chi_square(est) -> None:
    dof = est.extra[EXTRA_INTEGRITY_DOF]
    lo, hi = est.extra[EXTRA_INTEGRITY_BAND]
    assert lo == pytest.approx(chi2.ppf(0.005, dof)) and hi == pytest.approx(chi2.isf(0.005, dof))
    assert math.isfinite(est.extra[EXTRA_NIS])


@pytest.mark.parametrize("name", sorted(NAVS))
def test_consistent_flight_never_flags(dem, name):
    nav, ests, truth = _run(dem, name, 0.0)
    statuses = [e.health.status for e in ests]
    assert "degraded" not in statuses, statuses
    assert not any("innovation test" in m for e in ests for _, m in e.health.events)
    assert statuses[-1] == "ok"
    _band_is_chi_square(ests[-1])
    stat = ests[-1].extra[EXTRA_INTEGRITY_STATISTIC]
    assert stat <= ests[-1].extra[EXTRA_INTEGRITY_BAND][1]
    assert _horizontal_error_m(ests[-1], truth) < 25.0


@pytest.mark.parametrize("name", sorted(NAVS))
def test_biased_ranges_flag_recover_and_return(dem, name):
    nav, ests, truth = _run(dem, name, BIAS_M)
    t_end = np.array([e.t_s for e in ests])
    status = np.array([e.health.status for e in ests])
    before = t_end < BIAS_START_S
    during = (t_end > BIAS_START_S) & (t_end < BIAS_END_S)
    assert "degraded" not in status[before]
    assert _horizontal_error_m(ests[int(np.nonzero(before)[0][-1])], truth) < 25.0
    # flagged at the first or second biased update, and for most of the bias (a re-spread belief can settle
    # for a while where the biased ranges fit: no innovation test sees that); ok False while flagged
    first = int(np.nonzero(during)[0][0])
    assert "degraded" in status[first:first + 2], status
    assert np.mean(status[during] == "degraded") >= 1.0 / 3.0, status
    above = [e for e in ests if EXTRA_INTEGRITY_STATISTIC in e.extra
             and e.extra[EXTRA_INTEGRITY_STATISTIC] > e.extra[EXTRA_INTEGRITY_BAND][1]]
    assert above and all(e.health.status == "degraded" and not e.health.ok for e in above)
    events = [m for e in ests for _, m in e.health.events]
    assert sum("above its band" in m for m in events) >= 1
    assert sum(m.startswith("recovery:") for m in events) >= 1
    assert nav.recoveries >= 1
    # consistent data again: back in band within WINDOW + a few updates, then "ok" and re-converged
    assert any("back in band" in m for m in events)
    after = t_end > BIAS_END_S + WINDOW + 3.0
    assert np.mean(status[after] == "degraded") < 0.2, status
    # "ok" again within the last 15 s: re-acquiring a cloud re-spread over hundreds of metres is chaotic in
    # the particles' draws, and the rbpf's status waits for a spread under 30 m (the figures per rng seed:
    # docs/validation/integrity.md, regression tests' bounds)
    assert "ok" in status[t_end > t_end[-1] - 15.0], status
    assert status[-1] != "degraded", status
    _band_is_chi_square(ests[-1])
    # re-converged: 35 m for rbpf and pf; 45 m for the pmf, which with the INS's process noise model (a
    # 0.1 m/sqrt(s) floor and a velocity offset instead of a 1.0 m/sqrt(s) random walk) leaves a
    # neighbouring mode of the re-spread grid more slowly (the figures: docs/validation/integrity.md)
    assert _horizontal_error_m(ests[-1], truth) < (45.0 if name == "pmf" else 35.0)


@pytest.mark.parametrize("name", sorted(NAVS))
def test_integrity_settings_are_validated(dem, name):
    kw = {} if name == "pmf" else {"rng": np.random.default_rng(0)}
    with pytest.raises(ValueError, match="integrity_window"):
        registry.create(name, dem=dem, integrity_window=0, **kw)
    with pytest.raises(ValueError, match="integrity_alpha"):
        registry.create(name, dem=dem, integrity_alpha=float("nan"), **kw)
    with pytest.raises(ValueError, match="recovery_sigma_m"):
        registry.create(name, dem=dem, recovery_sigma_m=-1.0, **kw)


def test_acq_track_reports_the_windowed_statistic_and_flags_consistently(dem):
    """acq_track in lock (the flight of tests/test_acq_track.py): the windowed statistic is the sum of the
    last WINDOW in-lock NIS values (summed here by hand, each read once per new measurement time), its band
    scipy's, and an in-lock epoch is "degraded" exactly when the sum is above the band."""
    from acq_track_helpers import fly, initial_estimate, trajectory
    from trn_env.navigators.acquisition_tracking import AcqTrackNavigator

    lat0, lon0, h = math.radians(36.50), math.radians(-84.30), 1400.0
    traj = trajectory(dem, lat0, lon0, h, lambda t: 81.0, lambda t: math.radians(33.0), 80.0)
    nav = AcqTrackNavigator(dem=dem, aiding=False, integrity_window=WINDOW)
    nav.reset(initial_estimate(traj, h, sigma_m=300.0, dn_m=300.0, de_m=-400.0, dv_mps=7.0,
                               dpsi_rad=math.radians(-6.0)))
    ests, _ = fly(nav, dem, traj, h, 60)
    nis, ts, checked = [], [], 0
    dt = nav.config.sample_period_s
    for e in ests:
        te = e.extra.get("measurement_t_s")
        if te is None or (ts and te == ts[-1]):
            continue
        ts.append(te)
        nis.append(e.extra[EXTRA_NIS])
        # only where the last WINDOW in-lock epochs are consecutive and each was seen in its own frame
        if len(ts) < WINDOW or not np.allclose(np.diff(ts[-WINDOW:]), dt):
            continue
        assert e.extra[EXTRA_INTEGRITY_STATISTIC] == pytest.approx(sum(nis[-WINDOW:]))
        _band_is_chi_square(e)
        if e.extra["lock_state"] == "tracking":
            above = e.extra[EXTRA_INTEGRITY_STATISTIC] > e.extra[EXTRA_INTEGRITY_BAND][1]
            assert (e.health.status == "degraded") == above
        checked += 1
    assert checked >= 10
    with pytest.raises(ValueError, match="integrity_window"):
        AcqTrackNavigator(dem=dem, integrity_window=0)
    with pytest.raises(ValueError, match="integrity_alpha"):
        AcqTrackNavigator(dem=dem, integrity_alpha=1.5)

