"""The angle the turn terms' random walk advances by (navigators.core.imu_spec.TurnAngle) and the rbpf's
use of it (setting turn_angle). In the "excursion" mode: the gyro misalignment and scale factor build an
attitude error proportional to the NET heading change since the anchor, so a heading that wanders about a
straight leg, or a turn undone by the opposite turn, must not add the variance of the angle travelled back
and forth. Checked against headings built here: a monotone turn gives its whole angle, a wander its largest
excursion, and at every step of a random heading path the walk's variance (density sigma^2 TURN_REFERENCE
per rad) bounds sigma^2 (net change)^2 up to TURN_REFERENCE, computed independently from the path; "total"
(the rbpf's default) gives the summed heading changes."""

import math

import numpy as np
import pytest
from synthetic_terrain import wave_map
from trn_env.navigators.core.imu_spec import ImuSpec, TurnAngle
from trn_env.navigators.filters.rbpf import TURN_REFERENCE_RAD, RaoBlackwellizedPF
from trn_env.navigators.inertial.strapdown import quat_from_C_bn
from trn_env.terrain.geodesy import euler_to_C_bn


def _growth(yaws, mode="excursion"):
    t = TurnAngle(mode)
    return [t.advance(float(y)) for y in yaws]


def test_a_monotone_turn_counts_its_whole_angle_and_wraps_through_pi():
    g = _growth(np.radians(np.arange(150.0, 240.5, 1.0)))      # 150 -> 240 deg, through +-180
    yaws = (np.radians(np.arange(150.0, 240.5, 1.0)) + math.pi) % (2 * math.pi) - math.pi
    assert sum(_growth(yaws)) == pytest.approx(math.radians(90.0), abs=1e-12)
    assert sum(g) == pytest.approx(math.radians(90.0), abs=1e-12)


def test_a_wander_counts_its_largest_excursion_and_an_undone_turn_once():
    t = np.arange(0.0, 200.0)
    wander = math.radians(30.0) + math.radians(2.0) * np.sin(0.7 * t) * np.cos(0.13 * t)
    g = _growth(wander)
    net = np.abs(wander - wander[0])
    assert sum(g) == pytest.approx(net.max(), abs=1e-12)
    assert sum(g) < 0.05 * float(np.abs(np.diff(wander)).sum())     # against the summed back-and-forth
    there_and_back = np.radians(np.r_[np.arange(0.0, 60.5, 1.0), np.arange(59.0, -0.5, -1.0)])
    assert sum(_growth(there_and_back)) == pytest.approx(math.radians(60.0), abs=1e-12)
    assert _growth([0.1, math.nan, 0.2]) == [0.0, 0.0, pytest.approx(0.1)]
    # "total": the summed heading changes, the back-and-forth included
    assert sum(_growth(wander, "total")) == pytest.approx(float(np.abs(np.diff(wander)).sum()), rel=1e-12)
    with pytest.raises(ValueError, match="excursion"):
        TurnAngle("net")


def test_the_walk_bounds_the_net_turns_variance_up_to_the_reference():
    rng = np.random.default_rng(5)
    yaw = np.cumsum(rng.normal(0.004, 0.02, 2000))      # drifting, wandering heading, < 90 deg net
    ex = TurnAngle("excursion")
    walk = 0.0
    for y in yaw:
        walk += TURN_REFERENCE_RAD * ex.advance(float(y))
        net = abs(y - yaw[0])
        if net <= TURN_REFERENCE_RAD:
            assert walk >= net ** 2 - 1e-12


def test_rbpf_adds_the_turn_variance_of_the_excursion():
    spec = ImuSpec(gyro_scale_factor_ppm=150.0, gyro_misalignment_rad=5e-4)
    nav = RaoBlackwellizedPF(dem=wave_map(0), turn_angle="excursion")
    nav.apply_imu_spec(spec)
    nav._turn_angle = TurnAngle(nav.turn_angle)
    yaws = math.radians(10.0) + np.radians(np.r_[np.zeros(5), [1.5, -1.0, 2.0, -2.0, 1.0], np.arange(0, 31)])
    added = np.zeros(3)
    for y in yaws:
        nav.ins.state[6:10] = quat_from_C_bn(euler_to_C_bn(0.02, 0.01, float(y)))
        added += nav._epoch_ql_var()[3:6] - nav.ql_var[3:6]
    expect = np.array([5e-4 ** 2, 5e-4 ** 2, 150e-6 ** 2]) * TURN_REFERENCE_RAD * math.radians(30.0)
    assert added == pytest.approx(expect, rel=1e-6)
