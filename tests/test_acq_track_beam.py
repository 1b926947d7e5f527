"""acq_track's "return" replica model (beam.py) and its north/east reference frame (reference_frame "ne").

Checked against independent computations: the shortest in-cone range over a flat map by the cone geometry,
the replica points by numpy, the loops' basis form against the direct replica, and the NE bias filter
against the wind a test flight is built with.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from acq_track_helpers import (
    H_MSL,
    LAT0,
    LON0,
    frames_for,
    horizontal_error_m,
    initial_estimate,
    radii_m,
    trajectory,
)
from trn_env.navigators.acquisition_tracking import AcqTrackNavigator, beam, loop_kernel
from trn_env.navigators.acquisition_tracking.correlation import (
    Motion,
    Profile,
    profile_cost,
    replica_positions_reference,
)

from trn_env import terrain


@pytest.fixture(scope="module")
def dem():
    return terrain.load("jacksboro")


@pytest.mark.parametrize("roll_deg, yaw_deg", [(25.0, 0.0), (-20.0, 40.0), (5.0, 10.0)])
def test_predicted_ray_over_flat_ground_is_the_cone_edge(dem, roll_deg, yaw_deg):
    """Flat ground 600 m below: beyond half the 17 deg beam the shortest range lies on the cone's edge nearest
    the vertical, off-nadir angle |roll| - 8.5 deg, on the side the bore sight leans to (body down axis:
    a right roll leans it left of the heading); inside the half beam it is the point below."""
    flat = dem.with_heights(np.full_like(dem.heights_m, 300.0), name="flat")
    h = 900.0
    r_n, r_e = radii_m(LAT0, h)
    theta, u_n, u_e = beam.predicted_ray(
        flat, LAT0, LON0, h, math.radians(roll_deg), 0.0, math.radians(yaw_deg), 17.0, r_n, r_e
    )
    expect = max(abs(roll_deg) - 8.5, 0.0)
    assert math.degrees(theta) == pytest.approx(expect, abs=0.3)
    if expect > 0:
        # left of the heading for a right roll
        side = math.radians(yaw_deg) - math.copysign(math.pi / 2, roll_deg)
        assert u_n == pytest.approx(math.cos(side), abs=0.02)
        assert u_e == pytest.approx(math.sin(side), abs=0.02)
    # the measured height by the ray: the slant range of that edge gives the ground's height back
    nav = AcqTrackNavigator(dem=flat, replica_model="return", aiding=False)
    nav.pos, nav.t_pos, nav.yaw = (LAT0, LON0), math.nan, math.radians(yaw_deg)
    slant = 600.0 / math.cos(math.radians(expect))
    d, off = nav._return_height(
        0.0, slant, h, 80.0, 0.0, math.radians(roll_deg), 0.0, math.radians(yaw_deg), math.nan
    )
    assert d == pytest.approx(300.0, abs=0.5)
    assert math.hypot(*off) == pytest.approx(600.0 * math.tan(math.radians(expect)), abs=3.0)
    # without roll compensation the prediction is level: the point below, the range taken as plumb
    nav_nc = AcqTrackNavigator(dem=flat, replica_model="return", aiding=False, roll_compensation=False)
    nav_nc.pos, nav_nc.t_pos = (LAT0, LON0), math.nan
    d_nc, off_nc = nav_nc._return_height(
        0.0, slant, h, 80.0, 0.0, math.radians(roll_deg), 0.0, math.radians(yaw_deg), math.nan
    )
    assert d_nc == pytest.approx(h - slant, abs=0.5) and math.hypot(*off_nc) < 1.0


def test_replica_points_and_the_basis_form_agree_with_numpy(dem):
    """beam.replica_points = numpy replica positions + the offsets turned by b_psi; the loops' basis form
    (loop_kernel.loop_epoch adds the offsets to the basis' P, R rows) gives the same cost as the direct
    replica at the offset points."""
    rng = np.random.default_rng(3)
    n = 25
    dt = np.r_[0.0, np.ones(n - 1)]
    m_v = 80.0 + rng.normal(0, 1.0, n)
    m_psi = np.cumsum(rng.normal(0, 0.02, n)) + 0.6
    o_n, o_e = rng.normal(0, 150.0, n), rng.normal(0, 150.0, n)
    r_n, r_e = radii_m(LAT0, H_MSL)
    for b_v, b_psi in ((0.0, 0.0), (1.5, 0.03), (-2.0, -0.05)):
        dla, dlo = np.empty(n), np.empty(n)
        beam.replica_points(dt, m_v, m_psi, b_v, b_psi, r_n, r_e, o_n, o_e, dla, dlo)
        la, lo = replica_positions_reference(0.0, 0.0, dt, m_v, m_psi, b_v, b_psi, r_n, r_e)
        c, s = math.cos(b_psi), math.sin(b_psi)
        np.testing.assert_allclose(dla, la + (c * o_n - s * o_e) / r_n, rtol=0, atol=1e-12)
        np.testing.assert_allclose(dlo, lo + (s * o_n + c * o_e) / r_e, rtol=0, atol=1e-12)
        # the basis form
        d = rng.normal(400.0, 50.0, n)
        valid = np.ones(n, bool)
        basis = np.empty((4, n))
        loop_kernel.replica_basis(dt, m_v, m_psi, basis)
        basis[0] += o_n
        basis[2] += o_e
        w = np.empty((3, n))
        c_basis = loop_kernel.basis_cost(
            dem.record(), LAT0, LON0, basis, b_v, b_psi, r_n, r_e, Profile(d, valid, 0, True, 5), w
        )
        h_p = np.empty(n)
        motion = Motion(dt, m_v, m_psi, r_n, r_e)
        beam.replica_heights_at(dem.record(), LAT0, LON0, motion, b_v, b_psi, o_n, o_e, h_p)
        assert c_basis == pytest.approx(profile_cost(d, valid, h_p, 0, True, 5), rel=1e-9)


def _wind_flight(dem, reference_frame, t_end=170):
    """Air data in a constant wind (3 N, -4 E m/s) through a 90 deg turn: the air vector is ground - wind
    exactly; GNSS for the first 10 s."""
    w = np.array([3.0, -4.0])

    def track(t):
        return math.radians(20.0 + 90.0 * min(max((t - 60.0) / 60.0, 0.0), 1.0))

    traj = trajectory(dem, LAT0, LON0, H_MSL, lambda t: 80.0, track, t_end + 1)

    def air(t):
        g = 80.0 * np.array([math.cos(track(t)), math.sin(track(t))]) - w
        return float(np.hypot(*g)), float(math.atan2(g[1], g[0]))

    nav = AcqTrackNavigator(dem=dem, reference_frame=reference_frame, wind_estimation=False)
    nav.reset(initial_estimate(traj, H_MSL, sigma_m=20.0))
    ests, errs = [], []
    t, lat, lon = traj[0], traj[1], traj[2]
    for k in range(t_end):
        fr = frames_for(
            dem, traj, H_MSL, float(k), float(k + 1), tas_fn=lambda x: air(x)[0], hdg_fn=lambda x: air(x)[1],
            gnss=k < 10,
        )  # fmt: skip
        est = nav.update(fr)
        i = int(np.argmin(np.abs(t - est.t_s)))
        ests.append(est)
        errs.append(horizontal_error_m(est, lat[i], lon[i]))
    return nav, ests, np.array(errs), w


def test_ne_frame_carries_a_wind_through_a_turn(dem):
    """reference_frame "ne": the wind is the aiding's north/east bias e_ne. GNSS sets it, and through the
    90 deg turn (its speed / track data bias changes by ~7 m/s and 5 deg) it stays the wind the flight was
    built with, the position stays bounded and within 3 sigma."""
    nav, ests, errs, w = _wind_flight(dem, "ne")
    assert np.allclose(nav.e_ne, w, atol=0.5)
    assert np.allclose(ests[-1].extra["wind_ne_mps"], w, atol=0.5)
    tail = slice(30, None)
    assert errs[tail].max() < 40.0
    sig = np.array([math.sqrt(e.covariance[0, 0] + e.covariance[1, 1]) for e in ests])
    assert np.mean(errs[tail] <= 3.0 * sig[tail]) > 0.95
    locked = np.mean([e.extra["lock_state"] == "tracking" for e in ests[tail]])
    assert locked > 0.9


@pytest.mark.parametrize(
    "settings, word",
    [
        ({"reference_frame": "polar"}, "reference_frame"),
        ({"replica_model": "cone"}, "replica_model"),
        ({"aiding_bias_walk_mps_per_sqrt_s": -0.1}, "aiding_bias_walk_mps_per_sqrt_s"),
        ({"aiding_bias_walk_mps_per_sqrt_s": math.nan}, "aiding_bias_walk_mps_per_sqrt_s"),
    ],
)
def test_new_settings_refused_by_name(dem, settings, word):
    with pytest.raises(ValueError, match=word):
        AcqTrackNavigator(dem=dem, **settings)
