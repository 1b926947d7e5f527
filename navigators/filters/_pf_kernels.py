"""numba kernels of the particle filter (navigators.filters.pf): propagation of the INS error particles."""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, fastmath=False, error_model="numpy")
def propagate_particles(particles, dt, force, noise, z):
    """Advance every particle's INS error state by dt (s), in place. Records (numba tuples):

    particles = (dn, de, b, dv, dpsi, sn, se), the state (true minus INS unless said): dn, de (m), b (INS
    height minus true, m), dv (M, 2) horizontal velocity (m/s), dpsi heading (rad), and sn, se (m) the part of
    dn, de the INS built since its alignment (its velocity error integrated, and the position noise).
    force = (f_n, f_e, g_over_r). Error dynamics (psi-angle model, horizontal; Titterton & Weston 2004,
    sec. 12.2): a heading error turns the specific force, d(dv)/dt = dpsi * (-f_e, f_n) (f_n, f_e: the
    INS's horizontal specific force, m/s^2, NED), minus the Schuler term (g / R) (sn, se); d(dn, de)/dt = dv.
    The Schuler term acts on the position error built since the alignment only: the INS is levelled to the
    true vertical at its reset, so its tilt from its own (mis-placed) local level, psi = -(dn0, de0) / R,
    turns gravity by exactly what -(g / R) (dn0, de0) takes off; with the whole dn an initial error of 1 km
    would drive every particle's velocity by a spurious 1.5e-3 m/s^2. noise = (s_pos, s_vel, s_psi, s_b): z
    (M, 6) standard normals scaled by s_pos (m/sqrt(s)) on the position, s_vel (m/s/sqrt(s)) on the
    velocity, s_b (m/sqrt(s)) on b and s_psi (rad/sqrt(s)) on the heading."""
    dn, de, b, dv, dpsi, sn, se = particles
    f_n, f_e, g_over_r = force
    s_pos, s_vel, s_psi, s_b = noise
    sq = math.sqrt(dt)
    for k in range(dn.shape[0]):
        vn0 = dv[k, 0]
        ve0 = dv[k, 1]
        an = -dpsi[k] * f_e - g_over_r * sn[k]
        ae = dpsi[k] * f_n - g_over_r * se[k]
        vn1 = vn0 + an * dt + s_vel * sq * z[k, 3]
        ve1 = ve0 + ae * dt + s_vel * sq * z[k, 4]
        step_n = 0.5 * (vn0 + vn1) * dt + s_pos * sq * z[k, 0]
        step_e = 0.5 * (ve0 + ve1) * dt + s_pos * sq * z[k, 1]
        dn[k] += step_n
        de[k] += step_e
        sn[k] += step_n
        se[k] += step_e
        dv[k, 0] = vn1
        dv[k, 1] = ve1
        b[k] += s_b * sq * z[k, 2]
        dpsi[k] += s_psi * sq * z[k, 5]
