"""IRA closest-point formulas (seed 000 section 3) against an independent geometric construction."""

import numpy as np
import pytest
from trn_env.navigators.measurements.ira_closest_point import (
    closest_point_ned,
    effective_look_angle,
    horizontal_difference_estimate_m,
)
from trn_env.terrain.geodesy import euler_to_C_bn


def _scene(n, rng, wind_mps, bank_max_deg=25.0):
    """Velocity with crosswind, banked attitude, and a terrain point on the zero-Doppler plane.
    theta is computed from its definition: the range difference between two antennas on the body's
    right axis (interferometer), R from the point itself."""
    roll = np.radians(rng.uniform(-bank_max_deg, bank_max_deg, n))
    pitch = np.radians(rng.uniform(-4, 6, n))
    yaw = rng.uniform(-np.pi, np.pi, n)
    C = euler_to_C_bn(roll, pitch, yaw)
    v_air_b = np.stack([np.full(n, 83.0), np.zeros(n), 83.0 * np.tan(np.radians(rng.uniform(-1, 3, n)))], 1)
    v_air = np.einsum("nij,nj->ni", C, v_air_b)
    wind = np.stack([rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), np.zeros(n)], 1)
    wind = wind_mps * wind / np.linalg.norm(wind, axis=1)[:, None]
    v = v_air + wind
    vh = v / np.linalg.norm(v, axis=1)[:, None]
    h_agl = rng.uniform(800, 5500, n)
    q = np.stack([rng.uniform(-0.3, 0.3, n) * h_agl, rng.uniform(-0.3, 0.3, n) * h_agl, h_agl], 1)
    p = q - np.einsum("ni,ni->n", q, vh)[:, None] * vh  # project onto the plane normal to v
    R = np.linalg.norm(p, axis=1)
    L = 0.05
    x_r = np.einsum("nij,j->ni", C, [0.0, L, 0.0])
    x_l = np.einsum("nij,j->ni", C, [0.0, -L, 0.0])
    sin_theta = (np.linalg.norm(x_l - p, axis=1) - np.linalg.norm(x_r - p, axis=1)) / (2 * L)
    theta = np.arcsin(sin_theta)
    return dict(R=R, theta=theta, roll=roll, pitch=pitch, yaw=yaw, C=C, v=v, p=p)


def test_proposed_recovers_closest_point_in_crosswind_and_bank():
    rng = np.random.default_rng(1)
    s = _scene(2000, rng, wind_mps=30.0)
    p = closest_point_ned(s["R"], s["theta"], s["roll"], s["pitch"], s["yaw"], s["v"], formula="proposed")
    err = np.linalg.norm(p - s["p"], axis=1)
    assert np.all(err < 1.0), err.max()
    # the conventional formula does not (this is the point of seed 000)
    pc = closest_point_ned(
        s["R"], s["theta"], s["roll"], s["pitch"], s["yaw"], s["v"], formula="conventional"
    )
    assert np.max(np.linalg.norm(pc - s["p"], axis=1)) > 20.0


def test_c_bn_input_equals_euler_input():
    rng = np.random.default_rng(2)
    s = _scene(50, rng, wind_mps=20.0)
    a = closest_point_ned(s["R"], s["theta"], s["roll"], s["pitch"], s["yaw"], s["v"])
    b = closest_point_ned(s["R"], s["theta"], None, None, None, s["v"], C_bn=s["C"])
    np.testing.assert_allclose(a, b, atol=1e-9)


def test_no_wind_all_velocity_formulas_agree_with_truth():
    rng = np.random.default_rng(3)
    s = _scene(500, rng, wind_mps=0.0)
    # no wind, and make the velocity lie along body x (no aerodynamic alpha) so the attitude formula is exact
    v = 83.0 * s["C"][:, :, 0]
    vh = s["C"][:, :, 0]
    q = s["p"]
    p = q - np.einsum("ni,ni->n", q, vh)[:, None] * vh
    R = np.linalg.norm(p, axis=1)
    theta = np.arcsin(np.einsum("ni,ni->n", p, s["C"][:, :, 1]) / R)
    for f in ("attitude", "conventional", "proposed"):
        got = closest_point_ned(R, theta, s["roll"], s["pitch"], s["yaw"], v, formula=f)
        assert np.max(np.linalg.norm(got - p, axis=1)) < 0.01, f


def test_simple_exact_for_level_flight():
    R = np.array([1000.0, 2000.0])
    theta = np.radians([10.0, -20.0])
    yaw = np.radians([0.0, 90.0])
    p = closest_point_ned(R, theta, 0.0, 0.0, yaw, np.array([[80.0, 0, 0], [0, 80.0, 0]]), formula="simple")
    # heading north, 10 deg right -> east; heading east, 20 deg left -> north
    np.testing.assert_allclose(
        p[0], [0, 1000 * np.sin(np.radians(10)), 1000 * np.cos(np.radians(10))], atol=1e-9
    )
    np.testing.assert_allclose(
        p[1], [2000 * np.sin(np.radians(20)), 0, 2000 * np.cos(np.radians(20))], atol=1e-9
    )


def test_conventional_minus_proposed_matches_eq40():
    """Horizontal difference conventional vs proposed ~ R tan((theta - roll) - xi) (eq 40, project signs).
    Tolerance: 6 % + 0.2 m (the horizontal projection of the chord differs from R tan by ~cos(xi) and the
    along-track tilt of s1)."""
    rng = np.random.default_rng(4)
    s = _scene(1000, rng, wind_mps=25.0, bank_max_deg=10.0)
    keep = np.abs(s["theta"] - s["roll"]) < np.radians(15)
    for k in s:
        s[k] = s[k][keep]
    pp = closest_point_ned(s["R"], s["theta"], s["roll"], s["pitch"], s["yaw"], s["v"], formula="proposed")
    pc = closest_point_ned(
        s["R"], s["theta"], s["roll"], s["pitch"], s["yaw"], s["v"], formula="conventional"
    )
    dp = np.hypot(pp[:, 0] - pc[:, 0], pp[:, 1] - pc[:, 1])  # eqs 37-39
    xi, ok = effective_look_angle(s["theta"], s["C"], s["v"])
    assert ok.all()
    est = np.abs(horizontal_difference_estimate_m(s["R"], s["theta"], s["roll"], xi))
    assert np.median(dp) > 5.0  # the wind makes a real difference
    np.testing.assert_array_less(np.abs(dp - est), 0.06 * est + 0.2)


def test_impossible_geometry_gives_nan_and_bad_formula_raises():
    C = euler_to_C_bn(0.0, 0.0, 0.0)[None]
    # body right axis along the velocity would make t = 0: theta has no solution
    v = np.array([[0.0, 80.0, 0.0]])
    p = closest_point_ned(np.array([1000.0]), np.array([0.3]), None, None, None, v, C_bn=C)
    assert np.isnan(p).all()
    with pytest.raises(ValueError, match="formula"):
        closest_point_ned([1.0], [0.0], 0, 0, 0, [[1.0, 0, 0]], formula="bogus")
