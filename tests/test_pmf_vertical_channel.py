"""The point-mass filter's model of the baro-damped INS's vertical channel (pmf._vertical_velocity_shift): the
closed-form down-velocity and height transients a constant vertical specific-force error drives
(pmf.baro_loop_velocity_response_s, baro_loop_height_response_s2) against the real strapdown INS
(navigators.inertial.StrapdownIns, its third-order baro loop) flown along an exact level reference trajectory
(tests/nav_reference_trajectory.py: perfect IMU samples, the true height as the baro) with a z accelerometer
bias added; and the filter's output removing the grid's closest-point shift D beta (`_output_moments`)."""

import sys
from pathlib import Path

import numpy as np
import pytest
from trn_env.navigators.core.imu_spec import ImuSpec
from trn_env.navigators.filters.pmf import (
    BETA,
    PointMassFilter,
    baro_loop_height_response_s2,
    baro_loop_velocity_response_s,
)
from trn_env.navigators.inertial.strapdown import StrapdownIns
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

sys.path.insert(0, str(Path(__file__).parent))
from nav_reference_trajectory import imu_and_truth  # noqa: E402
from test_terrain_filter_linear import COMMON, initial, planar_dem  # noqa: E402

LAT0, LON0, H = np.radians(33.2), np.radians(-98.2), 2500.0
V, TAU_S, BIAS_MPS2 = 83.0, 30.0, 0.01


def _lla(t):
    r_n, r_e = meridian_radius_m(LAT0) + H, (prime_vertical_radius_m(LAT0) + H) * np.cos(LAT0)
    return LAT0 + V * np.cos(0.4) * t / r_n, LON0 + V * np.sin(0.4) * t / r_e, np.full_like(t, H)


def _euler(t):
    return np.zeros_like(t), np.full_like(t, 0.02), np.full_like(t, 0.4)


def test_baro_loop_transients_match_the_strapdown_ins():
    t = np.arange(0.0, 300.0 + 1e-9, 0.01)
    f_b, w_ib, (lat, lon, h, v, eu) = imu_and_truth(t, _lla, _euler)
    runs = {}
    for bias in (0.0, BIAS_MPS2):
        ins = StrapdownIns("j2", TAU_S)
        ins.reset(t[0], lat[0], lon[0], h[0], v[0], eu[0][0], eu[1][0], eu[2][0])
        fb = f_b.copy()
        fb[:, 2] += bias     # body z is down in level flight (pitch 0.02 rad: cos = 0.9998)
        runs[bias] = ins.propagate(t[1:], fb[1:], w_ib[1:], None, t[1::5], h[1::5], None)
    # the bias's effect: the difference of the two runs (the mechanisation's own errors cancel)
    dvd = runs[BIAS_MPS2][:, 5] - runs[0.0][:, 5]
    dh = runs[BIAS_MPS2][:, 2] - runs[0.0][:, 2]
    a = BIAS_MPS2 * np.cos(0.02)
    psi = np.array([baro_loop_velocity_response_s(x, TAU_S) for x in t[1:]])
    eta = np.array([baro_loop_height_response_s2(x, TAU_S) for x in t[1:]])
    print(f"\npeak down-velocity error {dvd.max():.4f} m/s at {t[1 + dvd.argmax()]:.1f} s (model "
          f"{a * psi.max():.4f} at {t[1 + psi.argmax()]:.1f} s); height {dh.min():.3f} m "
          f"(model {a * eta.min():.3f})")
    # 2 % of the peak: the baro samples' 50 ms hold and the loop's Euler steps at the IMU's 10 ms
    assert np.max(np.abs(dvd - a * psi)) < 0.02 * a * psi.max()
    assert np.max(np.abs(dh - a * eta)) < 0.02 * a * abs(eta.min())
    assert a * psi.max() == pytest.approx(0.840 * a * TAU_S, rel=1e-3)      # at t = 1.618 tau


def test_output_removes_the_closest_point_shift():
    """The Estimate reports x = y - D beta: its mean moves by -D E[beta] and its covariance by
    D C_bb D' - 2 sym(D C_by) against the grid's own moments."""
    nav = PointMassFilter(planar_dem(), grid_size=41, **COMMON)
    nav.apply_imu_spec(ImuSpec(accel_bias_mps2=0.01))
    nav.reset(initial(10.0))
    assert nav.C_uu[BETA, BETA] == pytest.approx(1e-4)
    nav._D = np.array([300.0, -100.0])
    nav.u_mean[BETA] = 0.004
    nav.C_uz[BETA, :2] = (1e-3, -2e-3)
    y_mean, y_cov = nav._moments()
    x_mean, x_cov = nav._output_moments()
    np.testing.assert_allclose(x_mean[:2], y_mean[:2] - nav._D * 0.004)
    D, c = nav._D, nav.C_uz[BETA, :2]
    want = y_cov[:2, :2] + np.outer(D, D) * 1e-4 - np.outer(D, c) - np.outer(c, D)
    np.testing.assert_allclose(x_cov[:2, :2], want)
