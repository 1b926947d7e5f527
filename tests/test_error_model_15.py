"""Seed 002's 15-state INS error model (eqs 16-22) against two strapdown INS runs and the Schuler period."""

import math

import numpy as np
from trn_env.navigators.inertial.error_model_15 import (
    noise_input_matrix,
    system_matrix,
    transition_over_history,
)
from trn_env.navigators.inertial.strapdown import StrapdownIns, gravity_ned, quat_to_dcm
from trn_env.terrain.geodesy import OMEGA_EARTH_RPS, euler_to_C_bn, meridian_radius_m, prime_vertical_radius_m

LAT0, LON0, H0 = math.radians(36.6), math.radians(-84.2), 2500.0
V0 = np.array([228.0, 75.0, 0.0])
DT = 0.02


YAW0 = math.atan2(75.0, 228.0)


def _imu(n, yaw=YAW0):
    """Samples of a level flight: f_b holding the INS level against gravity and Coriolis, rates following
    the Earth and transport rates (an exact truth is not needed: both INS runs share the samples)."""
    C = euler_to_C_bn(0.0, 0.0, yaw)
    g = gravity_ned(LAT0, H0, 1)
    rn = meridian_radius_m(LAT0) + H0
    re = prime_vertical_radius_m(LAT0) + H0
    w_ie = OMEGA_EARTH_RPS * np.array([math.cos(LAT0), 0.0, -math.sin(LAT0)])
    w_en = np.array([V0[1] / re, -V0[0] / rn, -V0[1] * math.tan(LAT0) / re])
    f_n = -g + np.cross(2 * w_ie + w_en, V0)
    t = np.arange(n) * DT
    f_b = np.tile(C.T @ f_n, (n, 1))
    w_b = np.tile(C.T @ (w_ie + w_en), (n, 1))
    return t, f_b, w_b, C


def _run(t, f_b, w_b, dx=None):
    ins = StrapdownIns("j2", tau_baro_s=None, imu_samples="instant")
    ins.reset(0.0, LAT0, LON0, H0, V0, 0.0, 0.0, math.atan2(75.0, 228.0))
    if dx is not None:
        ins.state[0] += dx[0]
        ins.state[1] += dx[1]
        ins.state[2] += dx[2]
        ins.state[3:6] += dx[3:6]
        ins.correct(None, None, -dx[6:9])  # C_computed = (I - [eps x]) C_true
        ins.accel_bias_b[:] = dx[9:12]     # estimated minus true bias (true bias 0)
        ins.gyro_bias_b[:] = dx[12:15]
    return ins.propagate(t, f_b, w_b)


def _state_error(ha, hb):
    """15-state error (b minus a) of the last rows, attitude from the quaternions."""
    e = np.zeros(9)
    e[0:3] = hb[-1, 0:3] - ha[-1, 0:3]
    e[3:6] = hb[-1, 3:6] - ha[-1, 3:6]
    Ca, Cb = quat_to_dcm(ha[-1, 6:10]), quat_to_dcm(hb[-1, 6:10])
    E = np.eye(3) - Cb @ Ca.T                    # = [eps x]
    e[6:9] = [0.5 * (E[2, 1] - E[1, 2]), 0.5 * (E[0, 2] - E[2, 0]), 0.5 * (E[1, 0] - E[0, 1])]
    return e


def test_error_model_matches_two_ins_runs_over_60_s():
    n = int(60.0 / DT) + 1
    t, f_b, w_b, C = _imu(n)
    ha = _run(t, f_b, w_b)
    r = meridian_radius_m(LAT0) + H0
    cases = {
        "position": np.r_[30.0 / r, -40.0 / r, 5.0, np.zeros(12)],
        "velocity": np.r_[0, 0, 0, 0.5, -0.4, 0.0, np.zeros(9)],
        "attitude": np.r_[np.zeros(6), 2e-4, -1.5e-4, 1e-3, np.zeros(6)],
        "accel_bias": np.r_[np.zeros(9), 2e-3, -1e-3, 5e-4, np.zeros(3)],
        "gyro_bias": np.r_[np.zeros(12), 2e-6, -1e-6, 3e-6],
    }
    Phi = transition_over_history(ha, f_b, np.zeros(3), 1, n, DT, True)
    for name, dx in cases.items():
        hb = _run(t, f_b, w_b, dx)
        got = _state_error(ha, hb)
        pred = (Phi @ dx)[:9]
        # compare in metres / m/s / rad; scale: the largest predicted component of each block
        to_m = np.array([r, r * math.cos(LAT0), 1.0])
        for blk, scale in ((slice(0, 3), to_m), (slice(3, 6), 1.0), (slice(6, 9), 1.0)):
            g, p = got[blk] * scale, pred[blk] * scale
            tol = 0.02 * np.max(np.abs(p)) + {0: 0.05, 3: 2e-3, 6: 2e-7}[blk.start]
            assert np.all(np.abs(g - p) <= tol), (name, blk, g, p)
        # and the error did grow (the check is not vacuous)
        assert np.max(np.abs(pred[:9] - dx[:9])) > 0


def test_schuler_period_84_minutes():
    """At rest, the horizontal channel's eigenvalues are +-i sqrt(g/R): period 2 pi sqrt(R/g) ~ 84.4 min."""
    C = np.eye(3)
    g = gravity_ned(LAT0, 0.0, 1)
    A = system_matrix(LAT0, 0.0, np.zeros(3), -g, C, False)
    lam = np.linalg.eigvals(A)
    periods = 2 * np.pi / np.abs(lam.imag[lam.imag > 1e-5]) / 60.0
    r = math.sqrt(meridian_radius_m(LAT0) * prime_vertical_radius_m(LAT0))
    expected = 2 * np.pi * math.sqrt(r / abs(g[2])) / 60.0
    assert abs(expected - 84.4) < 0.5
    # Schuler modulated by Foucault: frequencies w_s +- Omega sin L, and the 24-h (sidereal) mode
    w = np.sort(2 * np.pi / (periods * 60.0))
    w_s = 2 * np.pi / (expected * 60.0)
    assert abs(0.5 * (w[1] + w[2]) - w_s) < 5e-3 * w_s, periods  # Earth-rate couplings: 0.3 %
    assert abs(0.5 * (w[2] - w[1]) - OMEGA_EARTH_RPS * math.sin(LAT0)) < 0.02 * OMEGA_EARTH_RPS, periods
    assert abs(w[0] - OMEGA_EARTH_RPS) < 0.01 * OMEGA_EARTH_RPS


def test_noise_input_matrix_blocks():
    C = euler_to_C_bn(0.1, -0.05, 1.2)
    B = noise_input_matrix(C)
    assert np.allclose(B[3:6, 0:3], C) and np.allclose(B[6:9, 3:6], -C)
    assert np.all(B[:3] == 0) and np.all(B[9:] == 0)
