"""The particle filter's velocity process noise from the IMU's specification (navigators.filters.pf,
velocity_noise_model "imu_spec", opt-in, `ParticleFilter._velocity_step_var`): the acceleration error
the particles do not carry, a0 + j t, adds 2 rho sigma_v sigma_acc dt + sigma_acc^2 dt^2 + N^2 dt per step,
rho the free INS's correlation of the velocity error with it (restarted at a GNSS velocity fix); and its GNSS
update, an ensemble Kalman update of the particles (`ParticleFilter._gnss_ensemble_update`), checked
against the Kalman update of the cloud's Gaussian prior computed here.

Checked against figures written out here from the presets' data sheets (trn_env.sensors.imu: tactical 1 mg
bias, 0.1 mg instability, 0.5 mrad misalignment, 1 deg/h gyro bias + 0.3 deg/h instability, 100 ug/sqrt(Hz);
the default initial tilt 0.05 mrad): a cloud propagated for 100 s without measurements (10,000 particles:
the sample sigma's relative error ~0.7 %) grows as the free INS's velocity error, sqrt(sigma_v0^2 + N^2 t +
sigma_a^2 t^2 + j^2 t^4 / 4) (plus the steps' sigma_acc^2 dt^2); a cloud whose velocity is known gains only
the step's own share.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from trn_env.navigators import registry
from trn_env.navigators.protocol import Estimate

from trn_env import terrain
from trn_env.scenario.build import imu_spec

G = 9.80665
SIGMA_V0 = 0.1
TILT0 = 0.05e-3


def _initial() -> Estimate:
    cov = np.diag([30.0**2, 30.0**2, 15.0**2] + [SIGMA_V0**2] * 3 + [TILT0**2, TILT0**2, 1e-6])
    return Estimate(t_s=0.0, lat_rad=math.radians(36.55), lon_rad=math.radians(-84.3), h_m=2000.0,
                    v_ned_mps=np.array([85.0, 0.0, 0.0]), roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0,
                    covariance=cov)


@pytest.fixture(scope="module")
def dem():
    return terrain.load("jacksboro")


def _pf(dem, grade: str | None):
    nav = registry.create("pf", dem=dem, rng=np.random.default_rng(7), n_particles=10_000,
                          velocity_noise_model="imu_spec")
    if grade is not None:
        nav.apply_imu_spec(imu_spec({"grade": grade}))
    nav.reset(_initial())
    return nav


def _accel_terms(grade: str) -> tuple[float, float, float]:
    """(sigma_a, j, N) from the data sheets (see the module docstring)."""
    if grade == "tactical":
        body = G * math.sqrt(1e-3**2 + 1e-4**2 + 0.5e-3**2)           # bias, instability, misalignment x g
        turn = G * 0.5e-3 * math.pi / 2                                  # a 90 deg turn's gyro misalignment
        j = G * math.hypot(1.0, 0.3) * math.pi / 180 / 3600              # g x the gyro bias' tilt rate
        n = 100e-6 * G
    else:                                                                # navigation: 50 ug, 0.005 deg/h
        body, turn, j, n = G * 50e-6, 0.0, G * 0.005 * math.pi / 180 / 3600, 10e-6 * G
    return math.sqrt(body**2 + turn**2 + (G * TILT0) ** 2), j, n


@pytest.mark.parametrize("grade", ["navigation", "tactical"])
def test_an_unobserved_cloud_grows_its_velocity_sigma_by_the_acceleration_error(dem, grade):
    nav = _pf(dem, grade)
    sigma_a, j, n = _accel_terms(grade)
    T = 100
    for k in range(1, T + 1):
        nav._predict_to(float(k))
    sv = np.std(nav.dv, axis=0)
    free_ins = SIGMA_V0**2 + n**2 * T + sigma_a**2 * T**2 + j**2 * T**4 / 4
    steps = sum(sigma_a**2 + (j * k) ** 2 for k in range(1, T + 1))      # sigma_acc^2 dt^2 per 1 s step
    expect = math.sqrt(free_ins + steps)
    assert sv == pytest.approx([expect, expect], rel=0.03)
    if grade == "navigation":    # not the linear sum sigma_v0 + sigma_a t (v0 and a taken fully correlated)
        assert expect < 0.8 * (SIGMA_V0 + sigma_a * T)


def test_a_known_velocity_gains_only_the_step_share(dem):
    nav = _pf(dem, "tactical")
    sigma_a, j, n = _accel_terms("tactical")
    nav.dv[:] = 0.0                                   # the terrain has told the velocity apart
    t, dt = 50.0, 1.0
    q = nav._velocity_step_var(t, dt)
    assert q == pytest.approx(n**2 * dt + (sigma_a**2 + (j * t) ** 2) * dt**2, rel=1e-6)
    # a random walk matched at 120 s (sigma_a^2 T per s) would add 120 times more
    assert q < sigma_a**2 * 120.0 * dt / 50


def test_without_the_specification_the_setting_is_the_walk(dem):
    nav = _pf(dem, None)
    assert nav._velocity_step_var(10.0, 2.0) == pytest.approx(0.02**2 * 2.0)


def test_the_default_walk_keeps_the_equivalent_walk(dem):
    """velocity_noise_model "walk" (default): the specification's equivalent walk over the tuned floor, as
    before the model existed."""
    nav = registry.create("pf", dem=dem, rng=np.random.default_rng(7), n_particles=100)
    nav.apply_imu_spec(imu_spec({"grade": "tactical"}))
    nav.reset(_initial())
    assert nav._accel_model is None and nav.s_vel > 0.1
    assert nav._velocity_step_var(10.0, 1.0) == pytest.approx(nav.s_vel**2)


def test_the_gnss_fix_moves_the_cloud_as_the_kalman_update(dem):
    """A Gaussian cloud (30 m, 0.1 m/s per axis; 10,000 particles) and one fix of position (2 m) and velocity
    (0.05 m/s): the posterior mean and variance per axis of the Kalman update, sigma^2 r / (sigma^2 + r) and
    sigma^2 z / (sigma^2 + r), computed here; the weights stay uniform (no particle dropped), the heading,
    uncorrelated with what the fix observes, keeps its spread. Tolerances: the sample mean's 4 standard
    errors, 5 % on a variance (its sample error ~1.4 % at M = 10,000)."""
    nav = _pf(dem, "navigation")
    M = nav.M
    z_p, z_v = (5.0, -3.0), (0.05, -0.02)
    r_p, r_v = nav.gnss_sigma_m ** 2, nav.gnss_velocity_sigma_mps ** 2
    psi_sd = float(np.std(nav.dpsi))
    nav._gnss_ensemble_update(z_p[0], z_p[1], z_v, 3.0)
    for x, z, s2, r in ((nav.dn, z_p[0], 30.0**2, r_p), (nav.de, z_p[1], 30.0**2, r_p),
                        (nav.dv[:, 0], z_v[0], SIGMA_V0**2, r_v), (nav.dv[:, 1], z_v[1], SIGMA_V0**2, r_v)):
        var_post = s2 * r / (s2 + r)
        assert abs(np.mean(x) - s2 * z / (s2 + r)) < 4.0 * math.sqrt(var_post / M)
        assert np.var(x) == pytest.approx(var_post, rel=0.05)
    assert np.all(nav.logw == 0.0)
    assert float(np.std(nav.dpsi)) == pytest.approx(psi_sd, rel=0.03)


def test_a_velocity_fix_restarts_the_free_ins_correlation(dem):
    """After a GNSS velocity fix at t_f the growth is the free INS's from the fix, its velocity sigma the
    fix's posterior and its acceleration error a0 + j t (t since the reset): cov(v, a) = sigma_a^2 tau +
    j^2 t (t_f tau + tau^2 / 2), var v = v_f^2 + N^2 tau + sigma_a^2 tau^2 + j^2 (t_f tau + tau^2 / 2)^2,
    tau = t - t_f (written out here)."""
    nav = _pf(dem, "tactical")
    sigma_a, j, n = _accel_terms("tactical")
    t_f = 100.0
    nav._gnss_ensemble_update(0.0, 0.0, (0.0, 0.0), t_f)
    w = nav._weights()
    d = nav.dv - w @ nav.dv
    v_f2 = float(np.max(w @ (d * d)))
    sigma_v = math.sqrt(v_f2)
    for t in (t_f + 1.0, t_f + 30.0):
        tau = t - t_f
        ramp = t_f * tau + 0.5 * tau * tau
        acc2 = sigma_a**2 + (j * t) ** 2
        cov = sigma_a**2 * tau + j**2 * t * ramp
        var = v_f2 + n**2 * tau + sigma_a**2 * tau**2 + j**2 * ramp**2
        rho = min(cov / math.sqrt(var * acc2), 1.0)
        expect = n**2 + 2.0 * rho * sigma_v * math.sqrt(acc2) + acc2
        assert nav._velocity_step_var(t, 1.0) == pytest.approx(expect, rel=1e-9)
