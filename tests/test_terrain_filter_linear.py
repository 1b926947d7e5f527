"""PMF and PF against a Kalman filter on a linear-Gaussian problem (STYLE: a nonlinear filter checked on a
linear problem, filterpy's KalmanFilter as the exact answer).

Synthetic planar terrain h = h0 + g_n n + g_e e; level flight north with the IRA looking straight down
(theta = 0: the closest point is p = (0, 0, R) whatever the heading or horizontal velocity offset), so the
measured terrain height h_INS - R = g_n dn + g_e de + b + h0 + noise is linear in the state (horizontal
offset dn, de and vertical offset b). The outlier weight is 0 (pure Gaussian likelihood); the sensor noise
is the IRA's 3.5 m. Process noise: the PMF's horizontal random walk, its velocity random walk and constant
tilt, accelerometer bias and heading offsets (a 10-state Kalman filter); the PF's velocity random walk
integrated into position (its trapezoid: Q of a discretised white-acceleration model).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from trn_env.navigators.filters.pf import ParticleFilter
from trn_env.navigators.filters.pmf import PointMassFilter
from trn_env.navigators.inertial.strapdown import quat_from_C_bn
from trn_env.navigators.measurements.terrain_models import radii_m
from trn_env.navigators.protocol import Estimate
from trn_env.terrain.dem import Dem
from trn_env.terrain.geodesy import euler_to_C_bn

LAT0, LON0, H_ANT = 0.63, -1.47, 2000.0
G_N, G_E, H0 = 0.25, -0.15, 400.0
SIGMA_R = 3.5


def planar_dem() -> Dem:
    d = math.radians(3.0 / 3600.0)
    n = 300
    lat = LAT0 + (np.arange(n) - n / 2) * d
    lon = LON0 + (np.arange(n) - n / 2) * d
    r_lat, r_lon = radii_m(LAT0, H_ANT)
    h = H0 + G_N * (lat[:, None] - LAT0) * r_lat + G_E * (lon[None, :] - LON0) * r_lon
    return Dem(h, lat[0], lon[0], d, d, "plane")


def ins_state() -> np.ndarray:
    st = np.empty(10)
    st[:3] = (LAT0, LON0, H_ANT)
    st[3:6] = (80.0, 0.0, 0.0)
    st[6:] = quat_from_C_bn(euler_to_C_bn(0.0, 0.0, 0.0))
    return st


def initial(sig_h: float) -> Estimate:
    cov = np.diag([sig_h**2, sig_h**2, 1.0, 0.01, 0.01, 0.01, 1e-8, 1e-8, 1e-6])
    return Estimate(0.0, LAT0, LON0, H_ANT, np.array([80.0, 0.0, 0.0]), 0.0, 0.0, 0.0, cov)


def measurements(n: int, seed: int, x_true: np.ndarray) -> np.ndarray:
    """Ranges R_k whose h_INS - R_k = g . (dn, de) + b + h0 + noise, for a fixed true offset."""
    rng = np.random.default_rng(seed)
    terrain_true = H0 + G_N * x_true[0] + G_E * x_true[1]
    return (H_ANT - x_true[2]) - terrain_true + rng.normal(0.0, SIGMA_R, n)


def kf(n_state: int, P0: np.ndarray, F: np.ndarray, Q: np.ndarray) -> KalmanFilter:
    k = KalmanFilter(dim_x=n_state, dim_z=1)
    k.x = np.zeros((n_state, 1))
    k.P = P0.copy()
    k.F = F
    k.Q = Q
    k.R = np.array([[SIGMA_R**2]])
    H = np.zeros((1, n_state))
    H[0, :3] = (G_N, G_E, 1.0)
    k.H = H
    return k


COMMON = dict(outlier_prob=0.0, terrain_model_sigma_m=0.0, map_sigma_m=0.0, ira_range_sigma_m=SIGMA_R,
              ira_look_angle_sigma_deg=0.1, baro_bias_sigma_m=3.0, vertical_noise_m_per_sqrt_s=0.0)


def step_both(nav, k: KalmanFilter, t: float, R: float, st: np.ndarray) -> None:
    """Predict the terrain filter and the KF to t (s) and update both with the IRA range R (m)."""
    nav._predict_to(t, st)
    k.predict()
    nav._terrain_update(t, "ira", R, 0.0, st, None)
    k.update(np.array([[H_ANT - R - H0]]))


def moments_beside(nav, k: KalmanFilter):
    """(filter mean, filter covariance, KF mean, KF covariance, KF sigmas)."""
    mean, cov = nav._moments()
    return mean, cov, k.x.ravel(), k.P, np.sqrt(np.diag(k.P))


def test_pmf_matches_the_kalman_filter_on_a_linear_gaussian_problem():
    dem = planar_dem()
    q = 1.0
    s_a = 0.01      # large enough that the accelerometer bias moves the position by metres in 25 s
    nav = PointMassFilter(dem, grid_size=301, spacing_min_m=0.2, span_sigmas=4.5,
                          position_noise_m_per_sqrt_s=q, accel_bias_sigma_mps2=s_a, **COMMON)
    nav.reset(initial(40.0))
    # state [dn, de, b, dvn, dve, tilt acceleration n, e, accelerometer bias x, y, heading error]: the PMF
    # carries the INS's horizontal velocity error model as a Gaussian regressed on the grid's position
    # (x' = x + v dt + a dt^2 / 2, v' = v + a dt + eps J, a = t + R b; level flight north at constant
    # velocity: R = I, J = 0; v a random walk, the rest constant)
    s_v = nav.velocity_noise
    s_t2 = 9.80665**2 * 1e-8                          # g^2 times initial()'s roll/pitch variance
    P0 = np.diag([40.0**2, 40.0**2, 3.0**2, 0.01, 0.01, s_t2, s_t2, s_a**2, s_a**2, 1e-6])
    F = np.eye(10)
    F[0, 3] = F[1, 4] = F[3, 5] = F[4, 6] = F[3, 7] = F[4, 8] = 1.0
    F[0, 5] = F[1, 6] = F[0, 7] = F[1, 8] = 0.5
    k = kf(10, P0, F, np.diag([q**2, q**2, 0.0, s_v**2, s_v**2, 0.0, 0.0, 0.0, 0.0, 0.0]))
    x_true = np.array([25.0, -30.0, 4.0])
    ranges = measurements(25, 7, x_true)
    st = ins_state()
    mean0, cov0 = nav._moments()
    np.testing.assert_allclose(mean0[:3], 0.0, atol=1e-6)
    np.testing.assert_allclose(cov0[:2, :2], P0[:2, :2], rtol=0.01, atol=1e-6)
    nav._predict_to(0.0, st)                        # a zero-time predict leaves the belief
    np.testing.assert_allclose(nav._moments()[1][:2, :2], cov0[:2, :2])
    for i, R in enumerate(ranges):
        t = 1.0 + i
        step_both(nav, k, t, float(R), st)
    mean, cov, xk, Pk, sig = moments_beside(nav, k)
    scale_pv = np.sqrt(np.outer(np.diag(Pk)[0:2], np.diag(Pk)[3:5]))
    print(f"PMF vs KF (straight): means off by {np.max(np.abs(mean[:3] - xk[:3]) / sig[:3]):.4f} sigma "
          f"(position, vertical), {np.max(np.abs(mean[3:5] - xk[3:5]) / sig[3:5]):.4f} (velocity), "
          f"{np.max(np.abs(nav.u_mean[2:7] - xk[5:10]) / sig[5:10]):.4f} (acceleration, heading); variances "
          f"{np.max(np.abs(np.diag(cov)[:5] / np.diag(Pk)[:5] - 1)):.4f} relative; position-velocity "
          f"correlations {np.max(np.abs(cov[0:2, 3:5] - Pk[0:2, 3:5]) / scale_pv):.4f}")
    # velocity and acceleration get the wider margin: the grid's prediction adds the growth from u as a
    # convolution of exact variance, not as the stretch it is (the figures behind these margins:
    # docs/validation/terrain_filters.md, regression tests' bounds)
    assert np.all(np.abs(mean[:3] - xk[:3]) < 0.01 * sig[:3]), (mean[:3], xk, sig)
    assert np.all(np.abs(mean[3:5] - xk[3:5]) < 0.02 * sig[3:5]), (mean[3:5], xk, sig)
    np.testing.assert_allclose(np.diag(cov)[:5], np.diag(Pk)[:5], rtol=0.01)
    np.testing.assert_allclose(cov[0, 1], Pk[0, 1], rtol=0.01)
    # position-velocity covariance: its correlation coefficients within 0.003 of the KF's (what is left is
    # the pending noise's north-east term, which the separable convolution drops)
    scale = np.sqrt(np.outer(np.diag(Pk)[0:2], np.diag(Pk)[3:5]))
    assert np.all(np.abs(cov[0:2, 3:5] - Pk[0:2, 3:5]) < 0.003 * scale), (cov[0:2, 3:5], Pk[0:2, 3:5])
    # the acceleration and heading offsets (not in the Estimate): means, variances, covariance with position
    assert np.all(np.abs(nav.u_mean[2:7] - xk[5:10]) < 0.02 * sig[5:10]), (nav.u_mean, xk[5:10])
    np.testing.assert_allclose(np.diag(nav.C_uu)[2:7], np.diag(Pk)[5:10], rtol=0.01)
    scale = np.sqrt(np.outer(np.diag(Pk)[5:10], np.diag(Pk)[0:2]))
    assert np.all(np.abs(nav.C_uz[2:7, :2] - Pk[5:10, 0:2]) < 0.003 * scale), (nav.C_uz[2:7, :2],
                                                                               Pk[5:10, 0:2])
    # the one informative combination u . x = g . (dn, de) + b, known to ~1 m: a filter assuming 4.5 m of
    # noise instead of 3.5 m misses its mean by 0.12 sigma, so 0.03 sigma catches a wrong likelihood
    u = np.array([G_N, G_E, 1.0])
    su = math.sqrt(u @ Pk[:3, :3] @ u)
    assert abs(u @ mean[:3] - u @ xk[:3]) < 0.03 * su


def test_pf_matches_the_kalman_filter_on_a_linear_gaussian_problem():
    dem = planar_dem()
    s_vel, s_pos = 0.2, 0.3
    M = 40_000
    nav = ParticleFilter(dem, n_particles=M, ess_threshold=0.5, roughening=0.0,
                         position_noise_m_per_sqrt_s=s_pos, velocity_noise_mps_per_sqrt_s=s_vel,
                         heading_noise_rad_per_sqrt_s=0.0, rng=np.random.default_rng(11), **COMMON)
    nav.reset(initial(40.0))
    dt = 1.0
    F = np.eye(5)
    F[0, 3] = F[1, 4] = dt
    qv, qp = s_vel**2 * dt, s_pos**2 * dt
    Q = np.zeros((5, 5))
    for a, v in ((0, 3), (1, 4)):
        Q[a, a] = 0.25 * dt**2 * qv + qp
        Q[a, v] = Q[v, a] = 0.5 * dt * qv
        Q[v, v] = qv
    P0 = np.diag([40.0**2, 40.0**2, 3.0**2, 0.01, 0.01])
    k = kf(5, P0, F, Q)
    x_true = np.array([25.0, -30.0, 4.0])
    ranges = measurements(20, 8, x_true)
    st = ins_state()
    nav._predict_to(0.0, st)
    for i, R in enumerate(ranges):
        t = dt * (1 + i)
        step_both(nav, k, t, float(R), st)
    mean, cov, xk, Pk, sig = moments_beside(nav, k)
    # Monte Carlo tolerance: the mean's error ~ sigma / sqrt(ESS) (ESS >= 0.5 M after resampling, but the
    # resamplings' own noise adds ~ sigma / sqrt(M) each: 0.06 sigma covers 20 updates with margin)
    assert np.all(np.abs(mean[:5] - xk) < 0.06 * sig + 0.05), (mean[:5], xk, sig)
    np.testing.assert_allclose(np.diag(cov)[:3], np.diag(Pk)[:3], rtol=0.10)
    np.testing.assert_allclose(np.diag(cov)[3:5], np.diag(Pk)[3:5], rtol=0.15)
    u = np.zeros(6)
    u[:3] = (G_N, G_E, 1.0)
    uk = u[:5]
    su = math.sqrt(uk @ Pk @ uk)
    assert abs(u @ mean - uk @ xk) < 0.1 * su
    assert abs(math.sqrt(u @ cov @ u) / su - 1.0) < 0.1
    assert nav.n_resampled >= 1                   # the comparison went through resampling


def test_pmf_matches_the_kalman_filter_in_a_turn():
    """The INS error model's time-varying part: a level 3 deg/s turn at 80 m/s, so the accelerometer bias
    turns with the heading (a = t + R_k b) and the heading error turns each INS velocity change
    (v += eps J_k, J_k = (dv_e, -dv_n)); the same F_k in a 10-state Kalman filter. A 3 mrad heading sigma
    (the default scenario's is 1 mrad): a larger one would widen the gap, as the grid adds the growth as a
    convolution, not the stretch it is (figures: docs/validation/terrain_filters.md)."""
    dem = planar_dem()
    q, s_a, var_yaw = 0.3, 0.01, 1e-5
    nav = PointMassFilter(dem, grid_size=301, spacing_min_m=0.2, span_sigmas=4.5,
                          position_noise_m_per_sqrt_s=q, accel_bias_sigma_mps2=s_a, **COMMON)
    cov9 = np.diag([20.0**2, 20.0**2, 1.0, 0.01, 0.01, 0.01, 1e-8, 1e-8, var_yaw])
    nav.reset(Estimate(0.0, LAT0, LON0, H_ANT, np.array([80.0, 0.0, 0.0]), 0.0, 0.0, 0.0, cov9))
    s_v = nav.velocity_noise
    s_t2 = 9.80665**2 * 1e-8
    k = kf(10, np.diag([20.0**2, 20.0**2, 3.0**2, 0.01, 0.01, s_t2, s_t2, s_a**2, s_a**2, var_yaw]),
           np.eye(10), np.diag([q**2, q**2, 0.0, s_v**2, s_v**2, 0.0, 0.0, 0.0, 0.0, 0.0]))
    ranges = measurements(30, 8, np.array([12.0, -9.0, 2.0]))
    v_prev = None
    for i, R in enumerate(ranges):
        t = 1.0 + i
        yaw = 0.05 * t
        st = ins_state()
        st[3:5] = 80.0 * math.cos(yaw), 80.0 * math.sin(yaw)
        st[6:] = quat_from_C_bn(euler_to_C_bn(0.0, 0.0, yaw))
        Rk = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
        J = np.zeros(2) if v_prev is None else np.array([st[4] - v_prev[1], v_prev[0] - st[3]])
        v_prev = st[3:5].copy()
        F = np.eye(10)
        F[0:2, 3:5] = np.eye(2)
        F[0:2, 5:7] = 0.5 * np.eye(2)
        F[0:2, 7:9] = 0.5 * Rk
        F[3:5, 5:7] = np.eye(2)
        F[3:5, 7:9] = Rk
        F[3:5, 9] = J
        k.F = F
        step_both(nav, k, t, float(R), st)
    mean, cov, xk, Pk, sig = moments_beside(nav, k)
    print(f"PMF vs KF (turn): means off by {np.max(np.abs(mean[:5] - xk[:5]) / sig[:5]):.4f} sigma, "
          f"velocity variances {np.max(np.abs(np.diag(cov)[3:5] / np.diag(Pk)[3:5] - 1)):.4f} relative")
    assert np.all(np.abs(mean[:5] - xk[:5]) < 0.01 * sig[:5]), (mean[:5], xk, sig)
    assert np.all(np.abs(nav.u_mean[2:7] - xk[5:10]) < 0.01 * sig[5:10]), (nav.u_mean, xk[5:10])
    np.testing.assert_allclose(np.diag(cov)[:5], np.diag(Pk)[:5], rtol=0.025)
    np.testing.assert_allclose(np.diag(nav.C_uu)[2:7], np.diag(Pk)[5:10], rtol=0.01)
    # the turn makes the heading error matter: the measurements narrow it (to 0.93 of its prior variance)
    assert Pk[9, 9] < 0.95 * var_yaw


def test_pmf_ira_geometry_takes_its_velocity_and_heading_offsets():
    """The IRA closest point (seed 000 eqs 14-36) from the INS attitude and velocity corrected by the means of
    the filter's heading and velocity offsets: the same point the single-query formulas give for the true
    heading (INS yaw - eps) and velocity (INS + v), checked against navigators.measurements.ira's reference;
    and a 2 m/s cross-track velocity error left in would move it along track by its cross-track offset times
    dv / V (metres here)."""
    from trn_env.navigators.measurements import ira

    nav = PointMassFilter(planar_dem(), grid_size=101, **COMMON)
    nav.reset(initial(40.0))
    st = ins_state()
    st[6:] = quat_from_C_bn(euler_to_C_bn(0.2, 0.05, 0.0))       # banked: the point lies off to the side
    nav.u_mean[:2] = (0.3, -2.0)                                   # true minus INS velocity (m/s)
    nav.u_mean[6] = 2e-3                                           # INS yaw minus true yaw (rad)
    range_m, theta = 2000.0, 0.35
    C = euler_to_C_bn(0.2, 0.05, 0.0)
    nav._terrain_update(1.0, "ira", range_m, theta, st, None)
    p_filter = nav._ira_p[0].copy()
    p_true = ira.closest_points_reference(range_m, theta, C, st[3:6], np.array([-2e-3]),
                                          np.array([[0.3, -2.0]]), "proposed")[0]
    np.testing.assert_allclose(p_filter, p_true, atol=1e-6)
    p_ins = ira.closest_points_reference(range_m, theta, C, st[3:6], np.zeros(1), np.zeros((1, 2)),
                                         "proposed")[0]
    # the uncorrected geometry: along track (north) by the cross-track offset (east) times dv / V
    expected = abs(p_ins[1]) * 2.0 / 80.0
    assert abs(p_true[0] - p_ins[0]) == pytest.approx(expected, rel=0.1)
    assert abs(p_true[0] - p_ins[0]) > 5.0
