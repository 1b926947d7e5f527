"""The look angle's ambiguity (navigators.measurements.ira_seed002: the range of the coarse scan's best
sample more than 1.5 steps across track from the closest point, i.e. the other basin or the far side of a
flat minimum; navigators.filters.rbpf: range-only updates while the closest point can jump), against a
dense numpy minimisation over a synthetic terrain of two parallel ridges either side of the track: equal
ridges give a runner-up at the closest point's range (and the filter updates on the range alone); a lower
right ridge opens a gap, at most the difference of the two ridges' dense minima (the filter uses theta)."""

import math

import numpy as np
import pytest
from trn_env.navigators.filters.rbpf import RaoBlackwellizedPF
from trn_env.navigators.frames import ImuFrame, IraFrame, SensorFrames
from trn_env.navigators.measurements import ira_seed002 as m
from trn_env.navigators.protocol import EXTRA_NIS_DOF, Estimate
from trn_env.terrain.dem import Dem
from trn_env.terrain.geodesy import prime_vertical_radius_m

LAT0, LON0, H_ANT = math.radians(36.5), math.radians(-84.3), 2500.0
RIDGE_OFFSET_M, RIDGE_WIDTH_M = 600.0, 150.0


def _dem(h_left, h_right):
    n, d = 241, math.radians(0.0005)
    lat = LAT0 + (np.arange(n) - n // 2) * d
    lon = LON0 + (np.arange(n) - n // 2) * d
    east = (lon - LON0) * prime_vertical_radius_m(LAT0) * math.cos(LAT0)
    prof = (h_left * np.exp(-0.5 * ((east + RIDGE_OFFSET_M) / RIDGE_WIDTH_M) ** 2)
            + h_right * np.exp(-0.5 * ((east - RIDGE_OFFSET_M) / RIDGE_WIDTH_M) ** 2))
    return Dem(np.tile(prof, (n, 1)), float(lat[0]), float(lon[0]), d, d, name="two_ridges"), east, prof


def _dense_minimum(east, prof, side):
    """Minimum over one ridge of the distance from the antenna (the ZDL of a northbound level flight is
    the east-up plane), by brute force on a 0.5 m grid of the piecewise-linear cross-section."""
    x = np.arange(0.0, 1500.0, 0.5) * side
    z = np.interp(x, east, prof)
    return float(np.min(np.hypot(x, H_ANT - z)))


def _predict(dem):
    v = np.array([240.0, 0.0, 0.0])
    return m.predict_ira(dem, np.array([LAT0]), np.array([LON0]), np.array([H_ANT]), v, np.eye(3))[0]


def test_equal_ridges_give_two_minima_at_the_same_range():
    dem, east, prof = _dem(300.0, 300.0)
    o = _predict(dem)
    r_true = _dense_minimum(east, prof, 1.0)
    # the bilinear map of the 55 m grid against the sampled profile's linear interpolation: ~0.5 m
    assert o[m.OUT_R] == pytest.approx(r_true, abs=1.0)
    assert 0.0 <= o[m.OUT_R2] - o[m.OUT_R] < 2.0                 # the runner-up's coarse sample
    assert abs(math.degrees(o[m.OUT_THETA])) > 10.0


def test_lower_ridge_opens_the_gap_of_the_two_minima():
    dem, east, prof = _dem(300.0, 200.0)
    o = _predict(dem)
    r_left, r_right = _dense_minimum(east, prof, -1.0), _dense_minimum(east, prof, 1.0)
    assert r_right - r_left > 50.0
    assert o[m.OUT_R] == pytest.approx(r_left, abs=1.0)
    assert 3.0 < o[m.OUT_R2] - o[m.OUT_R] <= r_right - r_left + 1.0


def _frames(t0, r, theta):
    t = t0 + np.arange(1, 101) * 0.01
    imu = ImuFrame(t_s=t, f_b_mps2=np.tile([0.0, 0.0, -9.7996], (100, 1)),
                   omega_ib_b_rps=np.zeros((100, 3)), valid=np.ones(100, bool))
    ira = IraFrame(t_s=np.array([t[-1]]), range_m=np.array([r]), look_angle_rad=np.array([theta]),
                   valid=np.array([True]))
    return SensorFrames(t0, t[-1] + 0.01, imu=imu, ira=ira)


@pytest.mark.parametrize("h_right,dof", [(300.0, 1), (200.0, 2)])
def test_filter_uses_range_alone_while_the_closest_point_can_jump(h_right, dof):
    dem, east, prof = _dem(300.0, h_right)
    o = _predict(dem)
    nav = RaoBlackwellizedPF(dem=dem, rng=np.random.default_rng(0), n_particles=200, acquisition_particles=0,
                             init_pos_sigma_m=(2.0, 2.0, 1.0), imu_samples="instant",
                             prior_from_initial=False)
    nav.reset(Estimate(0.0, LAT0, LON0, H_ANT, np.array([240.0, 0.0, 0.0]), 0.0, 0.0, 0.0, np.eye(9)))
    est = nav.update(_frames(0.0, float(o[m.OUT_R]), float(o[m.OUT_THETA])))
    assert est.extra[EXTRA_NIS_DOF] == dof
    assert ("ira_theta_ambiguous" in est.health.skipped) == (dof == 1)


def test_look_angle_off_uses_the_range_alone_without_calling_it_ambiguous():
    # the geometry where the filter takes both (h_right 200 m: dof 2 above); look_angle=False: the range alone
    dem, _east, _prof = _dem(300.0, 200.0)
    o = _predict(dem)
    nav = RaoBlackwellizedPF(dem=dem, rng=np.random.default_rng(0), n_particles=200, acquisition_particles=0,
                             init_pos_sigma_m=(2.0, 2.0, 1.0), imu_samples="instant",
                             prior_from_initial=False, look_angle=False)
    nav.reset(Estimate(0.0, LAT0, LON0, H_ANT, np.array([240.0, 0.0, 0.0]), 0.0, 0.0, 0.0, np.eye(9)))
    est = nav.update(_frames(0.0, float(o[m.OUT_R]), float(o[m.OUT_THETA])))
    assert est.extra[EXTRA_NIS_DOF] == 1
    assert "ira_theta_ambiguous" not in est.health.skipped
