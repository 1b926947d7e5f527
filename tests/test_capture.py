"""The capture check the terrain filters share (navigators.core.capture), against independent computations.

- The free INS's horizontal position variance (closed form, Titterton & Weston 2004 eqs 12.20-12.21) against
  the 15-state INS error model (seed 002 eqs 16-22, navigators.inertial.error_model_15) propagated here by
  its matrix exponential (Van Loan) along a straight level flight from the same priors and noise densities;
  the two differ by the Schuler loop, the Earth's rate and the transport rate: under 10 % in the position's
  sigma over 600 s, the tilt's closed form above the model's (the Schuler loop bounds it) by under 15 %.
- The trigger: on the consumer grade the guard suspends where the 15-state model's attitude sigma has passed
  the small-angle limit and its 3-sigma position error has passed the capture range (within the closed
  form's agreement); on the navigation and tactical grades it never fires within 600 s for any filter's
  capture range (their gyros stay inside the small-angle model).
- The covariance floor: a point mass spread uniformly over a cell of width d has the variance d^2 / 12 per
  axis (computed here by quadrature); a covariance that is not positive definite is published floored, a
  positive-definite one above the floor unchanged (the same object: the same bits).
- A pmf whose belief gives a covariance that is not positive definite publishes a positive-definite one; a
  pmf beyond capture publishes its belief's covariance at the suspension plus the free INS's growth, Health
  degraded with the reason.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from trn_env.navigators import registry
from trn_env.navigators.core.capture import (
    CAPTURE_SIGMAS,
    CaptureGuard,
    floored_horizontal,
    free_ins_position_variance_m2,
    free_ins_tilt_sigma_rad,
)
from trn_env.navigators.core.imu_spec import SMALL_ANGLE_LIMIT_RAD
from trn_env.navigators.inertial.error_model_15 import discretise, noise_input_matrix, system_matrix
from trn_env.navigators.protocol import Estimate, Health

from trn_env import terrain
from trn_env.scenario.build import imu_spec

G = 9.80665
LAT = math.radians(36.55)
H_M = 2000.0
P0, V0, TILT0 = 30.0 ** 2, 0.5 ** 2, math.radians(0.1) ** 2


def _fifteen_state(grade: str, times_s, since_s: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(north position variance m^2, roll attitude variance rad^2) of the 15-state model at times_s (s) along
    a level flight north at 100 m/s, from the priors P0, V0, TILT0 and the grade's specification; since_s > 0:
    the variance of the north error's growth since since_s instead (the state augmented with a copy of its
    north position at since_s, which the propagation leaves unchanged)."""
    spec = imu_spec({"grade": grade})
    C = np.eye(3)
    A = system_matrix(LAT, H_M, np.array([100.0, 0.0, 0.0]), np.array([0.0, 0.0, -G]), C, True)
    q = np.r_[[spec.accel_noise_density_mps2_rthz ** 2] * 3, [spec.gyro_noise_density_rps_rthz ** 2] * 3]
    Phi, Qd = discretise(A, noise_input_matrix(C), q, 1.0)
    r = 6.371e6 + H_M
    P = np.diag(np.r_[P0 / r ** 2, P0 / (r * math.cos(LAT)) ** 2, 0.0, [V0] * 3, [TILT0] * 3,
                      [spec.body_accel_sigma_mps2 ** 2] * 3, [spec.gyro_bias_sigma_rps ** 2] * 3])
    out_p, out_a, t = [], [], 0
    while t < since_s:
        P = Phi @ P @ Phi.T + Qd
        t += 1
    if since_s:
        J = np.vstack([np.eye(15), np.eye(15)[:1]])      # x and the copy of its north position
        P = J @ P @ J.T
        Phi = np.block([[Phi, np.zeros((15, 1))], [np.zeros((1, 15)), np.ones((1, 1))]])
        Qd = np.block([[Qd, np.zeros((15, 1))], [np.zeros((1, 16))]])
    for t_want in times_s:
        while t < t_want:
            P = Phi @ P @ Phi.T + Qd
            t += 1
        out_p.append((P[0, 0] - 2 * P[0, 15] + P[15, 15] if since_s else P[0, 0]) * r ** 2)
        out_a.append(P[6, 6])
    return np.array(out_p), np.array(out_a)


@pytest.mark.parametrize("grade", ["tactical", "consumer"])
def test_free_ins_variance_against_the_15_state_model(grade):
    spec = imu_spec({"grade": grade})
    times = [30, 60, 120, 300, 600]
    p15, a15 = _fifteen_state(grade, times)
    closed = np.array([free_ins_position_variance_m2(spec, t, P0, V0, TILT0) for t in times])
    assert np.sqrt(closed / p15) == pytest.approx(np.ones(len(times)), rel=0.10)
    # the tilt without the Schuler loop, which bounds it: above the model's, by (w_s t)^2 / 6 ~ 9 % at 600 s
    tilt = np.array([free_ins_tilt_sigma_rad(spec, t, TILT0) for t in times])
    assert np.all(tilt >= 0.99 * np.sqrt(a15)) and tilt == pytest.approx(np.sqrt(a15), rel=0.15)


@pytest.mark.parametrize("grade", ["tactical", "consumer"])
def test_the_growth_since_a_time_against_the_15_state_model(grade):
    spec = imu_spec({"grade": grade})
    times, since = [130, 200, 350, 600], 100
    p15, _ = _fifteen_state(grade, times, since)
    closed = np.array([free_ins_position_variance_m2(spec, t, P0, V0, TILT0, since_s=since) for t in times])
    assert np.sqrt(closed / p15) == pytest.approx(np.ones(len(times)), rel=0.10)
    # far less than the error's whole variance shortly after, nearly all of it long after
    full = free_ins_position_variance_m2(spec, 130, P0, V0, TILT0)
    assert closed[0] < 0.5 * full


def _first_suspension_s(grade: str, capture_range_m: float, t_max_s: int = 600) -> float:
    g = CaptureGuard(capture_range_m, "test", imu_spec({"grade": grade}))
    g.anchor(0.0, P0, V0, TILT0)
    health = Health()
    for t in range(1, t_max_s + 1):
        if g.skips(float(t), lambda: np.eye(2), health):
            assert health.status == "degraded" and not health.ok and g.reason in health.events[-1][1]
            return float(t)
    return math.inf


# the filters' capture ranges with their default settings: TERCOM's widest search (100 cells of 5 m), the
# pf / rbpf's widest re-spread (3 x 100 m x 2^3), the pmf's half-span (199 / 2 x 100 m)
RANGES_M = (500.0, 2400.0, 9950.0)


@pytest.mark.parametrize("capture_range_m", RANGES_M)
def test_the_trigger_against_the_15_state_model(capture_range_m):
    times = np.arange(1, 601)
    p15, a15 = _fifteen_state("consumer", times)
    beyond = (np.sqrt(a15) > SMALL_ANGLE_LIMIT_RAD) & (CAPTURE_SIGMAS * np.sqrt(p15) > capture_range_m)
    t15 = float(times[np.argmax(beyond)])
    assert _first_suspension_s("consumer", capture_range_m) == pytest.approx(t15, rel=0.05)
    for grade in ("navigation", "tactical"):
        assert _first_suspension_s(grade, capture_range_m) == math.inf
        p, a = _fifteen_state(grade, [600])
        assert math.sqrt(a[0]) < SMALL_ANGLE_LIMIT_RAD


def test_published_covariance_grows_as_the_free_ins_and_a_gnss_anchor_ends_it():
    spec = imu_spec({"grade": "consumer"})
    g = CaptureGuard(500.0, "test", spec)
    g.anchor(0.0, P0, V0, TILT0)
    belief = np.array([[400.0, 100.0], [100.0, 300.0]])
    assert not g.check(10.0, belief)
    assert g.check(100.0, belief) and g.suspended and g.t_suspended_s == 100.0
    assert g.check(101.0, np.eye(2))          # latched
    for t in (100.0, 200.0, 400.0):
        expect = belief + np.eye(2) * free_ins_position_variance_m2(spec, t, P0, V0, TILT0, since_s=100.0)
        assert g.published_covariance(t) == pytest.approx(expect)
    assert g.published_covariance(100.0) == pytest.approx(belief)
    P = g.publish(np.eye(4) * 7.0 + 0.5, 200.0)
    assert P[:2, 2:] == pytest.approx(np.zeros((2, 2))) and P[2:, 2:] == pytest.approx(np.eye(2) * 7.0 + 0.5)
    g.anchor(300.0, 25.0, 0.01, TILT0)
    assert not g.suspended and not g.beyond(301.0)
    assert CaptureGuard(1.0, "test", None).beyond(1e6) is False      # no specification: never


def test_the_cell_floor_is_the_uniform_cells_variance():
    d = 37.0
    x = (np.arange(200_000) + 0.5) / 200_000 * d - 0.5 * d       # midpoint quadrature over one cell
    assert float(np.mean(x * x)) == pytest.approx(d * d / 12.0, rel=1e-6)
    floor = d * d / 12.0
    bad = np.array([[500.0, 600.0], [600.0, 500.0]])             # eigenvalues 1100 and -100
    out = floored_horizontal(bad, floor)
    w, V = np.linalg.eigh(out)
    assert w == pytest.approx([floor, 1100.0])
    assert abs(abs(V[0, 1]) - math.sqrt(0.5)) < 1e-12               # the eigenvectors kept
    good = np.array([[900.0, 50.0], [50.0, 400.0]])
    assert floored_horizontal(good, floor) is good
    nan = floored_horizontal(np.array([[np.nan, 0.0], [0.0, 50.0]]), floor)
    assert np.all(np.linalg.eigvalsh(nan) >= floor)


def _initial() -> Estimate:
    cov = np.diag([30.0 ** 2, 30.0 ** 2, 15.0 ** 2] + [0.5 ** 2] * 3 + [TILT0, TILT0, 1e-6])
    return Estimate(t_s=0.0, lat_rad=LAT, lon_rad=math.radians(-84.3), h_m=H_M,
                    v_ned_mps=np.array([85.0, 0.0, 0.0]), roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0,
                    covariance=cov)


@pytest.fixture(scope="module")
def dem():
    return terrain.load("jacksboro")


def test_a_pmf_never_publishes_a_covariance_that_is_not_positive_definite(dem, monkeypatch):
    nav = registry.create("pmf", dem=dem, grid_size=41)
    nav.reset(_initial())
    mean, cov = nav._moments()
    cov = cov.copy()
    cov[:2, :2] = [[100.0, 300.0], [300.0, 100.0]]                 # eigenvalues 400 and -200
    monkeypatch.setattr(nav, "_output_moments", lambda: (mean, cov))
    P = nav.estimate().covariance[:2, :2]
    assert np.linalg.eigvalsh(P).min() == pytest.approx(nav.spacing ** 2 / 12.0)


def test_a_pmf_beyond_capture_suspends_and_publishes_the_free_ins_growth(dem):
    spec = imu_spec({"grade": "consumer"})
    nav = registry.create("pmf", dem=dem, grid_size=41, spacing_max_m=5.0)   # capture range 100 m
    nav.apply_imu_spec(spec)
    nav.reset(_initial())
    assert nav._capture_range_m() == pytest.approx(100.0)
    t_first = _first_suspension_s("consumer", 100.0)
    assert nav._capture_suspends(t_first - 1.0, "ira") is False
    before = nav._output_moments()[1][:2, :2].copy()
    assert nav._capture_suspends(t_first, "ira") is True
    assert nav.health.status == "degraded" and "beyond capture" in nav.health.events[-1][1]
    nav.ins.t_s = t_first + 30.0
    nav._after_frame(t_first + 30.0)
    est = nav.estimate()
    free = free_ins_position_variance_m2(spec, t_first + 30.0, P0, 0.5 ** 2, TILT0, since_s=t_first)
    geo = nav._capture.geometry_variance_m2(t_first)     # no sample yet: range 0
    assert geo == 0.0
    assert est.covariance[:2, :2] == pytest.approx(before + np.eye(2) * free, rel=1e-9)
    assert not est.health.ok and est.health.status == "degraded"
    assert est.extra["hpl_m"] > 3.0 * math.sqrt(free)


def test_a_filter_that_estimated_its_biases_rebases_with_them():
    """The RBPF's rebase (it feeds its bias estimates back): the growth after the suspension takes its own
    bias variances, at most the specification's."""
    spec = imu_spec({"grade": "consumer"})
    c15 = np.eye(15) * 1e-8
    c15[:2, :2] = np.eye(2) * 400.0
    c15[12, 12] = c15[13, 13] = (0.1 * spec.gyro_bias_sigma_rps) ** 2
    g = CaptureGuard(100.0, "test", spec, rebase=True)
    g.anchor(0.0, P0, V0, TILT0)
    assert g.check(100.0, c15)
    tau = 200.0
    expect = free_ins_position_variance_m2(spec, tau, 0.0, 1e-8, 1e-8, 1e-8,
                                           (0.1 * spec.gyro_bias_sigma_rps) ** 2)
    assert g.published_covariance(100.0 + tau)[0, 0] == pytest.approx(400.0 + expect)
    # written out term by term (velocity, acceleration and tilt, gyro bias, velocity and angle random walks);
    # the specification caps a larger variance
    terms = (1e-8 * tau ** 2 + (1e-8 + G ** 2 * 1e-8) * tau ** 4 / 4
             + (G * 0.1 * spec.gyro_bias_sigma_rps) ** 2 * tau ** 6 / 36
             + spec.accel_noise_density_mps2_rthz ** 2 * tau ** 3 / 3
             + (G * spec.gyro_noise_density_rps_rthz) ** 2 * tau ** 5 / 20)
    assert expect == pytest.approx(terms, rel=1e-9)
    assert free_ins_position_variance_m2(spec, tau, 0.0, 0.0, 0.0, 1.0, 1.0) == pytest.approx(
        free_ins_position_variance_m2(spec, tau, 0.0, 0.0, 0.0))


@pytest.mark.parametrize("name", ["ins_tercom", "pmf", "pf", "rbpf"])
def test_health_states_the_capture_check_on_the_consumer_grade(dem, name):
    from trn_env.navigators.core.measured_consistency import CAPTURE_NOTE
    nav = registry.create(name, dem=dem)
    nav.apply_imu_spec(imu_spec({"grade": "consumer"}))
    assert CAPTURE_NOTE in nav._consistency_warning and "not calibrated" in nav._consistency_warning
    assert nav._capture_spec is not None
    for grade in ("navigation", "tactical"):
        nav = registry.create(name, dem=dem)
        nav.apply_imu_spec(imu_spec({"grade": grade}))
        assert CAPTURE_NOTE not in nav._consistency_warning
        # within its small-angle model the guard is inert, however long the flight since the last GNSS fix
        # (the free INS's attitude on the tactical grade passes the limit after ~2,000 s)
        assert nav._capture_spec is None
        guard = CaptureGuard(500.0, name, nav._capture_spec)
        assert not guard.beyond(3 * 3600.0)
    tactical = imu_spec({"grade": "tactical"})
    assert free_ins_tilt_sigma_rad(tactical, 3 * 3600.0, TILT0) > SMALL_ANGLE_LIMIT_RAD
    assert CaptureGuard(500.0, name, tactical).beyond(3 * 3600.0)      # what the gate keeps out


def test_the_closest_points_geometry_variance_past_the_small_angle_limit():
    """range x the free INS's attitude sigma (held against the 15-state model above), once past the limit."""
    spec = imu_spec({"grade": "consumer"})
    g = CaptureGuard(1e9, "test", spec, geometry=True)
    g.anchor(0.0, P0, V0, TILT0)
    g.range_m = 2000.0
    _, a15 = _fifteen_state("consumer", [10, 100])
    assert math.sqrt(a15[0]) < SMALL_ANGLE_LIMIT_RAD and g.geometry_variance_m2(10.0) == 0.0
    assert math.sqrt(g.geometry_variance_m2(100.0)) == pytest.approx(2000.0 * math.sqrt(a15[1]), rel=0.05)
    P = g.publish(np.eye(3) * 100.0, 100.0)
    assert P[:2, :2] == pytest.approx(np.eye(2) * (100.0 + g.geometry_variance_m2(100.0)))
    assert P[2, 2] == 100.0
    assert CaptureGuard(1e9, "test", spec).geometry_variance_m2(100.0) == 0.0     # not a geometry filter


def test_a_gnss_fix_ends_a_pmf_suspension(dem):
    nav = registry.create("pmf", dem=dem, grid_size=41, spacing_max_m=5.0)
    nav.apply_imu_spec(imu_spec({"grade": "consumer"}))
    nav.reset(_initial())
    t_first = _first_suspension_s("consumer", 100.0)
    assert nav._capture_suspends(t_first, "ira") and nav._capture.suspended
    assert nav._capture_suspends(t_first + 5.0, "ira")                  # latched
    assert nav._capture_suspends(t_first + 10.0, "gnss") is False
    assert not nav._capture.suspended and "ends the suspension" in nav.health.events[-1][1]
    assert np.all(np.linalg.eigvalsh(nav._moments()[1][:2, :2]) > 0.0)
