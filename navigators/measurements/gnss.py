"""GNSS measurement model (loosely coupled): a receiver's position and velocity fix against an INS state.

`position_velocity(ins_state, lat_g, lon_g, v_g_ned, sigma_h_m, sigma_v_mps, n_states, states)` returns
(z, H, R) as pyins' measurements do: z the INS minus the fix, north and east position (m, on the local radii
of curvature at the INS height) and NED velocity (m/s); H the rows selecting the error states `states`
(north, east position, NED velocity: navigators.core.error_states.GNSS_STATES for the 13-state EKF); R the
diagonal noise (sigma_h_m^2 twice, sigma_v_mps^2 three times).
"""

from __future__ import annotations

import math

import numpy as np

from ...terrain.geodesy import meridian_radius_m, prime_vertical_radius_m


def position_velocity(ins_state: np.ndarray, lat_g: float, lon_g: float, v_g_ned, sigma_h_m: float,
                      sigma_v_mps: float, n_states: int, states) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(z (5, 1), H (5, n_states), R (5, 5)) of one fix; ins_state = (lat, lon rad, h m, v_ned m/s, ...)."""
    lat, lon, h = float(ins_state[0]), float(ins_state[1]), float(ins_state[2])
    z = np.empty((5, 1))
    z[0, 0] = (lat - lat_g) * (meridian_radius_m(lat) + h)     # INS minus GNSS, north (m)
    z[1, 0] = (lon - lon_g) * (prime_vertical_radius_m(lat) + h) * math.cos(lat)
    z[2:, 0] = ins_state[3:6] - v_g_ned
    H = np.zeros((5, n_states))
    for r, c in enumerate(states):
        H[r, c] = 1.0
    R = np.diag([sigma_h_m**2] * 2 + [sigma_v_mps**2] * 3)
    return z, H, R


__all__ = ["position_velocity"]
