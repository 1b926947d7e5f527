"""The particle filter's Schuler term acts on the position error its INS built since the alignment, not on
the initial error (navigators.filters._pf_kernels.propagate_particles).

The premise is checked on the real strapdown INS, which no particle code touches: reset 1 km off the truth
with the true velocity and attitude and fed a noise-free IMU along a straight level flight, its velocity
error stays at zero (it was levelled to the true vertical, so its tilt from its own local level turns
gravity by exactly what the Schuler term would take off). The pf riding on it, told the offset by GNSS
fixes over the first GNSS_S seconds (which move its cloud, never its INS) and then by the terrain under it
(IRA samples over a map that is the world), must keep its cloud's velocity at zero too: with the Schuler
term on the whole error it would drift by g / R x 1 km x t per axis. The kernel's Schuler term on the built
error is checked against the analytic oscillation (period 2 pi sqrt(R / g), ~84 min)."""

from __future__ import annotations

import math

import numpy as np
from trn_env.navigators import registry
from trn_env.navigators.filters._pf_kernels import propagate_particles
from trn_env.navigators.frames import SensorFrames
from trn_env.navigators.protocol import Estimate
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

from trn_env import terrain
from trn_env.flight.kinematic import KinematicTruth, Segment
from trn_env.scenario.navigation import imu_spec
from trn_env.sensors.baro import BaroConfig, sample_baro
from trn_env.sensors.gnss import GnssConfig, sample_gnss
from trn_env.sensors.imu import ImuConfig, sample_imu
from trn_env.sensors.ira import IraConfig, sample_ira

LAT0, LON0, HEADING = math.radians(36.49), math.radians(-84.37), math.radians(8.0)
DURATION_S = 120.0
OFFSET_M = 1000.0
GNSS_S = 10.0
IMU = ImuConfig.noise_free(sampling="instant")


def _flight(world):
    kin = KinematicTruth(LAT0, LON0, 2200.0, 85.0, HEADING, [Segment("straight", DURATION_S)], rate_hz=100.0)
    chunks = [kin.advance(100)]
    while chunks[-1].t_s[-1] < DURATION_S - 1e-9:
        chunks.append(kin.advance(100))
    r_imu, r_baro, r_gnss, r_ira = (np.random.default_rng(s) for s in np.random.SeedSequence(3).spawn(4))
    imu_cfg, baro_cfg = IMU, BaroConfig()
    gnss_cfg = GnssConfig(outages=((GNSS_S, 1e9),))
    si = sb = sg = sa = None
    frames = []
    for ch in chunks:
        imu, si = sample_imu(ch, None, r_imu, imu_cfg, si)
        baro, sb = sample_baro(ch, None, r_baro, baro_cfg, sb)
        gnss, sg = sample_gnss(ch, None, r_gnss, gnss_cfg, sg)
        ira, sa = sample_ira(ch, world, r_ira, IraConfig(), sa)
        frames.append(SensorFrames(float(ch.t_s[0]), float(ch.t_s[-1]) + 0.01, imu=imu, baro=baro, gnss=gnss,
                                   ira=ira))
    return chunks, frames


def _offset_start(ch) -> Estimate:
    """The truth's first row moved OFFSET_M north and east, true velocity and attitude, 1 km sigma."""
    lat, h = float(ch.lat_rad[0]), float(ch.h_msl_m[0])
    r_n = meridian_radius_m(lat) + h
    r_e = (prime_vertical_radius_m(lat) + h) * math.cos(lat)
    cov = np.diag([OFFSET_M**2, OFFSET_M**2, 10.0**2, 1e-4, 1e-4, 1e-4, 1e-8, 1e-8, 1e-6])
    return Estimate(float(ch.t_s[0]), lat + OFFSET_M / r_n, float(ch.lon_rad[0]) + OFFSET_M / r_e, h,
                    ch.v_ned_mps[0].copy(), float(ch.roll_rad[0]), float(ch.pitch_rad[0]),
                    float(ch.yaw_rad[0]), cov)


def test_an_initial_position_error_drives_neither_the_ins_nor_the_clouds_velocity():
    the_map = terrain.load("jacksboro")
    chunks, frames = _flight(the_map)
    nav = registry.create("pf", dem=the_map, rng=np.random.default_rng(1), n_particles=4000)
    nav.apply_imu_spec(imu_spec(IMU))      # as a scenario with this IMU builds it (GNSS: the ensemble update)
    nav.reset(_offset_start(chunks[0]))
    for fr in frames:
        est = nav.update(fr)
        if fr.t_end_s <= GNSS_S + 1.0:
            cloud_n = float(nav._weights() @ nav.dn)
    assert abs(cloud_n + OFFSET_M) < 10.0, cloud_n       # the fixes moved the cloud onto the truth
    truth_v = chunks[-1].v_ned_mps[-1, :2]
    ins_v_error = np.asarray(nav.ins.state[3:5], float) - truth_v    # the real INS, no particle code
    cloud_v = nav._weights() @ nav.dv               # the cloud's velocity offset (true - INS)
    print(f"INS velocity error {ins_v_error} m/s, cloud's velocity {cloud_v} m/s, estimate's error "
          f"{est.v_ned_mps[:2] - truth_v} m/s after {DURATION_S:.0f} s")
    assert np.all(np.abs(ins_v_error) < 0.01)
    # the GNSS velocity fixes (0.05 m/s each) and the terrain leave ~0.02 m/s; the spurious drift ~0.17
    assert np.all(np.abs(cloud_v) < 0.04)
    assert np.all(np.abs(est.v_ned_mps[:2] - truth_v) < 0.04)


def test_the_schuler_term_on_the_built_error_oscillates_at_the_schuler_period():
    g_over_r = 9.81 / 6.371e6
    omega = math.sqrt(g_over_r)
    m = 3
    dn = np.array([0.0, 100.0, 100.0])       # particle 0: an initial error only (nothing built)
    sn = np.array([0.0, 100.0, 0.0])         # particle 1: 100 m built; particle 2: 100 m initial, none built
    dn[0] = 500.0
    de, se, b, dpsi = np.zeros(m), np.zeros(m), np.zeros(m), np.zeros(m)
    dv = np.zeros((m, 2))
    z = np.zeros((m, 6))
    dt = 0.5
    t_end = 0.25 * 2.0 * math.pi / omega       # a quarter of the Schuler period (~21 min)
    for _ in range(int(round(t_end / dt))):
        propagate_particles((dn, de, b, dv, dpsi, sn, se), dt, (0.0, 0.0, g_over_r), (0.0, 0.0, 0.0, 0.0), z)
    t = int(round(t_end / dt)) * dt
    # particle 1: sn = 100 cos(w t), dv = -100 w sin(w t)
    assert abs(sn[1] - 100.0 * math.cos(omega * t)) < 0.05
    assert abs(dv[1, 0] + 100.0 * omega * math.sin(omega * t)) < 1e-4
    assert abs(dn[1] - sn[1]) < 1e-9
    # particles 0 and 2: an initial error alone stays where it is
    assert dn[0] == 500.0 and dv[0, 0] == 0.0
    assert dn[2] == 100.0 and dv[2, 0] == 0.0
