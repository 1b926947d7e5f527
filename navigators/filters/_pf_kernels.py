"""numba kernels of the particle filter (navigators.filters.pf): propagation of the INS error particles."""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, fastmath=False, error_model="numpy")
def propagate_particles(particles, dt, force, noise, z):
    """Advance every particle's INS error state by dt (s), in place. Records (numba tuples):

    particles = (dn, de, b, dv, dpsi), the state (true minus INS unless said): dn, de (m), b (INS height
    minus true, m), dv (M, 2) horizontal velocity (m/s), dpsi heading (rad). force = (f_n, f_e, g_over_r).
    Error dynamics (psi-angle model, horizontal): a heading error turns the specific force, d(dv)/dt =
    dpsi * (-f_e, f_n) (f_n, f_e: the INS's horizontal specific force, m/s^2, NED), minus the Schuler term
    (g / R) (dn, de); d(dn, de)/dt = dv. noise = (s_pos, s_vel, s_psi, s_b): z (M, 6) standard normals
    scaled by s_pos (m/sqrt(s)) on the position, s_vel (m/s/sqrt(s)) on the velocity, s_b (m/sqrt(s)) on
    b and s_psi (rad/sqrt(s)) on the heading."""
    dn, de, b, dv, dpsi = particles
    f_n, f_e, g_over_r = force
    s_pos, s_vel, s_psi, s_b = noise
    sq = math.sqrt(dt)
    for k in range(dn.shape[0]):
        vn0 = dv[k, 0]
        ve0 = dv[k, 1]
        an = -dpsi[k] * f_e - g_over_r * dn[k]
        ae = dpsi[k] * f_n - g_over_r * de[k]
        vn1 = vn0 + an * dt + s_vel * sq * z[k, 3]
        ve1 = ve0 + ae * dt + s_vel * sq * z[k, 4]
        dn[k] += 0.5 * (vn0 + vn1) * dt + s_pos * sq * z[k, 0]
        de[k] += 0.5 * (ve0 + ve1) * dt + s_pos * sq * z[k, 1]
        dv[k, 0] = vn1
        dv[k, 1] = ve1
        b[k] += s_b * sq * z[k, 2]
        dpsi[k] += s_psi * sq * z[k, 5]
