"""Relative position of the IRA closest point from (R, theta) and the INS state (seed 000 section 3).

Four formulas, all vectorised over samples and all returning p, the vector from the antenna to the
closest terrain point in NED (metres, shape (n, 3)):

- ``simple``        seed 000 eq 3 (roll and pitch ignored),
- ``attitude``      seed 000 eqs 4-8 (look direction fixed in the body y-z plane, rotated by the attitude),
- ``conventional``  seed 000 eqs 9-13 (zero-Doppler plane from the velocity, angle theta combined with roll),
- ``proposed``      seed 000 eqs 14-36 (zero-Doppler plane from the velocity, effective look angle xi).

Conventions (project, not paper). The paper writes p in ENU with a body frame X right, Y forward, Z up;
here everything is NED / body FRD and the conversion sits at each formula. theta follows
``navigators.frames.IraFrame``: positive toward the right wing, and interferometric, i.e.
sin(theta) = (unit vector to the point) . (body right axis) - the far-field form of seed 000 eqs 18-27.
Roll is the 3-2-1 Euler roll of the FRD body (right wing down positive).

Departures from the printed equations (documented, deliberate):
- eq 3 as printed puts the cross-track displacement along the heading; here the cross-track direction is
  the heading's right-hand perpendicular (the formula's stated intent at zero roll and pitch).
- eq 10 is a quadrant-limited arctangent; here beta = atan2(v_e, v_n).
- Sign of roll in eq 13: with theta positive right and FRD roll positive right-wing-down, the body down
  axis sits at -roll in the zero-Doppler plane, so the exact no-wind angle is theta - roll. The paper's
  "theta + gamma" belongs to its opposite sign of theta (eqs 18-19 make theta positive toward the left
  antenna). ``conventional_angle`` therefore returns theta - roll; eq 40's (theta + gamma) - xi becomes
  (theta - roll) - xi here.
- eqs 30-35 are re-derived with theta positive right: t = y_b^T S (eq 31 with [+1 0 0]), and eq 35's
  atan(t1/t2) picks one branch of sin(eta + xi) = sin(theta)/|t|. Here eta = atan2(t1, t2) and of the two
  solutions of t1 cos(xi) + t2 sin(xi) = sin(theta) the one nearest the conventional angle theta - roll is
  taken (the two differ by ~pi - 2 theta, so the choice is unambiguous for look angles well inside +-90 deg).
"""

from __future__ import annotations

import numpy as np

from ...terrain.geodesy import euler_to_C_bn

FORMULAS = ("simple", "attitude", "conventional", "proposed")


def _as_n(x, n: int) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    return np.broadcast_to(a, (n,)) if a.ndim == 0 else a


def velocity_angles(v_ned_mps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Effective observation angles (rad): alpha = flight-path angle (seed 000 eq 9, up positive) and
    beta = ground-track angle from north (eq 10, computed with atan2 over all quadrants)."""
    v = np.atleast_2d(np.asarray(v_ned_mps, dtype=float))
    v_h = np.hypot(v[:, 0], v[:, 1])
    alpha = np.arctan2(-v[:, 2], v_h)  # eq 9: atan(v_u / sqrt(v_e^2 + v_n^2)), v_u = -v_d
    beta = np.arctan2(v[:, 1], v[:, 0])  # eq 10 (atan2 form)
    return alpha, beta


def zero_doppler_basis(v_ned_mps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Columns of seed 000's S (eq 12) in NED: s1 (the "down" direction of the zero-Doppler plane, in the
    vertical plane of the velocity) and s2 (horizontal, to the right of the track). Both (n, 3), both
    perpendicular to the velocity.

    eq 12 in ENU: s1 = [sin a sin b, sin a cos b, -cos a], s2 = [cos b, -sin b, 0]; NED = (N, E, -U).
    """
    alpha, beta = velocity_angles(v_ned_mps)
    sa, ca, sb, cb = np.sin(alpha), np.cos(alpha), np.sin(beta), np.cos(beta)
    s1 = np.stack([sa * cb, sa * sb, ca], axis=1)
    s2 = np.stack([-sb, cb, np.zeros_like(sb)], axis=1)
    return s1, s2


def conventional_angle(theta_rad, roll_rad) -> np.ndarray:
    """Angle in the zero-Doppler plane used by the conventional method (seed 000 eq 13's substitution,
    with the project's signs: theta - roll; see the module docstring)."""
    return np.asarray(theta_rad, float) - np.asarray(roll_rad, float)


def effective_look_angle(theta_rad, C_bn: np.ndarray, v_ned_mps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Effective look angle xi (rad) of seed 000 eqs 30-35 and a validity mask (|sin theta| <= |t|).

    t = [t1, t2] = y_b^T S (eq 31 with theta positive right), t1 cos xi + t2 sin xi = sin theta (eq 30).
    """
    C = np.asarray(C_bn, dtype=float).reshape(-1, 3, 3)
    n = C.shape[0]
    theta = _as_n(theta_rad, n)
    s1, s2 = zero_doppler_basis(v_ned_mps)
    y_b = C[:, :, 1]  # body right axis in NED
    t1 = np.einsum("ij,ij->i", y_b, s1)  # eq 31
    t2 = np.einsum("ij,ij->i", y_b, s2)
    rho = np.hypot(t1, t2)
    ratio = np.sin(theta) / np.where(rho > 0.0, rho, np.nan)  # eq 32
    valid = np.isfinite(ratio) & (np.abs(ratio) <= 1.0)
    asn = np.arcsin(np.clip(ratio, -1.0, 1.0))  # eq 34
    eta = np.arctan2(t1, t2)  # eq 33: sin eta = t1/rho, cos eta = t2/rho
    xi_a = asn - eta  # eq 35, first branch
    xi_b = np.pi - asn - eta  # second solution of sin(eta + xi) = sin theta / rho
    # roll of the body about the velocity: the branch nearest the conventional angle is the physical one.
    roll = np.arctan2(C[:, 2, 1], C[:, 2, 2])
    ref = conventional_angle(theta, roll)
    da = np.abs(np.angle(np.exp(1j * (xi_a - ref))))
    db = np.abs(np.angle(np.exp(1j * (xi_b - ref))))
    xi = np.where(da <= db, xi_a, xi_b)
    xi = np.angle(np.exp(1j * xi))
    return xi, valid


def _in_plane(range_m: np.ndarray, angle: np.ndarray, v_ned_mps: np.ndarray) -> np.ndarray:
    """p = R S [cos a, sin a] (seed 000 eqs 11 / 13 / 36) in NED."""
    s1, s2 = zero_doppler_basis(v_ned_mps)
    return range_m[:, None] * (np.cos(angle)[:, None] * s1 + np.sin(angle)[:, None] * s2)


def closest_point_ned(
    range_m,
    theta_rad,
    roll_rad,
    pitch_rad,
    yaw_rad,
    v_ned_mps,
    formula: str = "proposed",
    C_bn: np.ndarray | None = None,
) -> np.ndarray:
    """Relative position (m, NED, shape (n, 3)) from the antenna to the IRA closest point.

    range_m: slant range R (n,); theta_rad: look angle (n,), IraFrame convention; roll/pitch/yaw (n,) INS
    Euler angles (3-2-1, FRD -> NED) or C_bn (n, 3, 3) given directly (then the angles are only used by
    ``simple``/``conventional`` for yaw/roll and may be None if C_bn is given); v_ned_mps (n, 3) INS
    velocity. formula: "simple" | "attitude" | "conventional" | "proposed" (default).
    Samples whose geometry has no solution (proposed: |sin theta| > |t|) come back as NaN rows.
    """
    if formula not in FORMULAS:
        raise ValueError(f"formula must be one of {FORMULAS}, got {formula!r}")
    R = np.atleast_1d(np.asarray(range_m, dtype=float))
    n = R.shape[0]
    theta = _as_n(theta_rad, n)
    v = np.asarray(v_ned_mps, dtype=float).reshape(n, 3)
    if C_bn is None:
        C = euler_to_C_bn(_as_n(roll_rad, n), _as_n(pitch_rad, n), _as_n(yaw_rad, n)).reshape(n, 3, 3)
    else:
        C = np.asarray(C_bn, dtype=float).reshape(n, 3, 3)
    roll = np.arctan2(C[:, 2, 1], C[:, 2, 2])
    yaw = np.arctan2(C[:, 1, 0], C[:, 0, 0])
    if formula == "simple":
        # eq 3: p_(e,n) = R sin(theta) x (cross-track unit vector), p_u = -R cos(theta); in NED the
        # cross-track (right) direction of heading psi is [-sin psi, cos psi, 0].
        return np.stack(
            [-R * np.sin(theta) * np.sin(yaw), R * np.sin(theta) * np.cos(yaw), R * np.cos(theta)], axis=1
        )
    if formula == "attitude":
        # eqs 4-8: body look vector [0, sin theta, cos theta] (FRD; paper: [0, 0, -R] rotated by the look
        # angle about the forward axis) taken to NED with the INS attitude matrix.
        d_b = np.stack([np.zeros(n), np.sin(theta), np.cos(theta)], axis=1)
        return R[:, None] * np.einsum("nij,nj->ni", C, d_b)
    if formula == "conventional":
        return _in_plane(R, conventional_angle(theta, roll), v)  # eqs 9-13
    xi, valid = effective_look_angle(theta, C, v)  # eqs 14-35
    p = _in_plane(R, xi, v)  # eq 36
    p[~valid] = np.nan
    return p


def horizontal_difference_estimate_m(range_m, theta_rad, roll_rad, xi_rad) -> np.ndarray:
    """Seed 000 eq 40: |dp| ~ R tan((theta + gamma) - xi), with this module's signs (theta - roll)."""
    return np.asarray(range_m, float) * np.tan(conventional_angle(theta_rad, roll_rad) - np.asarray(xi_rad))
