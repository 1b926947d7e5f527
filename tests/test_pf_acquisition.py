"""The particle filter's acquisition phase (acquisition_particles, acquisition_spread_m): a larger cloud from
each reset, resampled down to n_particles once its horizontal spread is below acquisition_spread_m
(navigators.filters.pf.ParticleFilter._handover)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from trn_env.navigators import registry
from trn_env.navigators.frames import SensorFrames
from trn_env.navigators.protocol import Estimate
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

from trn_env import terrain
from trn_env.flight.kinematic import KinematicTruth, Segment
from trn_env.scenario.navigation import imu_spec
from trn_env.sensors.baro import BaroConfig, sample_baro
from trn_env.sensors.imu import ImuConfig, sample_imu
from trn_env.sensors.ira import IraConfig, sample_ira

LAT0, LON0, HEADING = math.radians(36.49), math.radians(-84.37), math.radians(8.0)
IMU = ImuConfig(sampling="instant")


@pytest.fixture(scope="module")
def the_map():
    return terrain.load("jacksboro")


def _flight(world, duration_s: float):
    kin = KinematicTruth(LAT0, LON0, 2200.0, 85.0, HEADING, [Segment("straight", duration_s)], rate_hz=100.0)
    chunks = [kin.advance(100)]
    while chunks[-1].t_s[-1] < duration_s - 1e-9:
        chunks.append(kin.advance(100))
    r_imu, r_baro, r_ira = (np.random.default_rng(s) for s in np.random.SeedSequence(4).spawn(3))
    si = sb = sa = None
    frames = []
    for ch in chunks:
        imu, si = sample_imu(ch, None, r_imu, IMU, si)
        baro, sb = sample_baro(ch, None, r_baro, BaroConfig(), sb)
        ira, sa = sample_ira(ch, world, r_ira, IraConfig(), sa)
        frames.append(SensorFrames(float(ch.t_s[0]), float(ch.t_s[-1]) + 0.01, imu=imu, baro=baro, ira=ira))
    return chunks, frames


def _start(ch, sigma_m: float, rng) -> Estimate:
    lat, h = float(ch.lat_rad[0]), float(ch.h_msl_m[0])
    r_n = meridian_radius_m(lat) + h
    r_e = (prime_vertical_radius_m(lat) + h) * math.cos(lat)
    e = rng.normal(0.0, sigma_m, 2)
    cov = np.diag([sigma_m**2, sigma_m**2, 10.0**2, 0.01, 0.01, 0.01, 1e-8, 1e-8, 1e-6])
    return Estimate(float(ch.t_s[0]), lat + e[0] / r_n, float(ch.lon_rad[0]) + e[1] / r_e, h,
                    ch.v_ned_mps[0].copy(), float(ch.roll_rad[0]), float(ch.pitch_rad[0]),
                    float(ch.yaw_rad[0]), cov)


def _pf(the_map, **settings):
    nav = registry.create("pf", dem=the_map, rng=np.random.default_rng(5), **settings)
    nav.apply_imu_spec(imu_spec(IMU))
    return nav


def test_the_cloud_acquires_large_and_tracks_small(the_map):
    chunks, frames = _flight(the_map, 60.0)
    nav = _pf(the_map, n_particles=2000, acquisition_particles=8000)
    sizes = []
    for start in range(2):          # a second reset starts the acquisition again
        nav.reset(_start(chunks[0], 200.0, np.random.default_rng(start)))
        sizes.append([nav.M])
        for fr in frames:
            est = nav.update(fr)
            sizes[-1].append(nav.M)
        ch = chunks[-1]
        r_n = meridian_radius_m(float(ch.lat_rad[-1])) + float(ch.h_msl_m[-1])
        assert abs(est.lat_rad - float(ch.lat_rad[-1])) * r_n < 30.0        # converged
    for s in sizes:
        assert s[0] == 8000 and s[-1] == 2000
        k = s.index(2000)               # the handover, once, after some epochs of acquisition
        assert 1 < k < len(s) - 1 and set(s[k:]) == {2000}
    assert all(len(a) == 2000 for a in (nav.dn, nav.de, nav.b, nav.dv, nav.dpsi, nav.sn, nav.se, nav.logw))


def test_the_handover_resamples_by_weight_and_keeps_each_particles_state(the_map):
    nav = _pf(the_map, n_particles=5000, acquisition_particles=20000, roughening=0.0)
    chunks, _ = _flight(the_map, 6.0)
    nav.reset(_start(chunks[0], 5.0, np.random.default_rng(0)))
    rng = np.random.default_rng(1)
    m = nav.M
    nav.dn = rng.normal(0.0, 3.0, m)
    nav.de = rng.normal(0.0, 3.0, m)
    nav.sn = nav.dn - 7.0           # each particle's state travels whole: sn - dn, dv - dn stay fixed
    nav.se = nav.de + 2.0
    nav.dv = np.ascontiguousarray(np.column_stack([0.01 * nav.dn, -0.01 * nav.de]))
    nav.logw = -0.5 * (nav.dn - 2.0) ** 2 / 1.0**2          # weights centre the cloud's north on ~1.8 m
    w = np.exp(nav.logw - nav.logw.max())
    w /= w.sum()
    mean_n = float(w @ nav.dn)
    sd_n = math.sqrt(float(w @ (nav.dn - mean_n) ** 2))
    nav._handover()
    assert nav.M == 5000 and np.all(nav.logw == 0.0)
    np.testing.assert_allclose(nav.sn - nav.dn, -7.0)
    np.testing.assert_allclose(nav.se - nav.de, 2.0)
    np.testing.assert_allclose(nav.dv[:, 0], 0.01 * nav.dn)
    # systematic resampling: the equally weighted copies keep the weighted mean (well inside sd / sqrt(n))
    assert abs(float(nav.dn.mean()) - mean_n) < 0.2 * sd_n / math.sqrt(5000)
    nav._handover()                  # tracking: nothing more
    assert nav.M == 5000


def test_a_wide_cloud_stays_in_acquisition(the_map):
    nav = _pf(the_map, n_particles=1000, acquisition_particles=4000, acquisition_spread_m=10.0)
    chunks, _ = _flight(the_map, 6.0)
    nav.reset(_start(chunks[0], 100.0, np.random.default_rng(0)))
    nav._handover()
    assert nav.M == 4000


@pytest.mark.parametrize("settings, field", [
    ({"n_particles": 1000, "acquisition_particles": 500}, "acquisition_particles"),
    ({"acquisition_particles": -1}, "acquisition_particles"),
    ({"acquisition_spread_m": 0.0}, "acquisition_spread_m"),
    ({"acquisition_spread_m": float("nan")}, "acquisition_spread_m"),
    ({"acquisition_particles": 10**9}, "acquisition_particles"),
])
def test_bad_acquisition_settings_are_refused_naming_the_field(the_map, settings, field):
    with pytest.raises(ValueError, match=field):
        registry.create("pf", dem=the_map, **settings)


def test_off_by_default_and_zero_is_off(the_map):
    chunks, frames = _flight(the_map, 20.0)
    a = _pf(the_map, n_particles=2000)
    b = _pf(the_map, n_particles=2000, acquisition_particles=0)
    outs = []
    for nav in (a, b):
        nav.reset(_start(chunks[0], 30.0, np.random.default_rng(3)))
        outs.append([nav.update(fr) for fr in frames])
        assert nav.M == 2000
    for ea, eb in zip(*outs, strict=True):
        assert ea.lat_rad == eb.lat_rad and ea.lon_rad == eb.lon_rad
