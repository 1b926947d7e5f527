"""GNSS measurement model (loosely coupled): a receiver's position and velocity fix against the INS.

The fix is compared with the INS at the fix's time; horizontal differences go through the local radii of
curvature at the INS height (seed 000 eq 2: north = dlat (R_M + h), east = dlon (R_N + h) cos lat).
Uniform over the navigators (as the radar altimeter's and the IRA's models):

- EKF (error state, filters/ins_trn_gnss.py): `residual` z = INS minus fix (north, east m; NED velocity
  m/s), `jacobian` H the rows selecting the error states (navigators.core.error_states.GNSS_STATES for
  the 13-state EKF), `noise` R = diag(sigma_h^2 x 2, sigma_v^2 x 3); `position_velocity` returns
  (z, H, R) as pyins' measurements do.
- Grid and particle filters (filters/pmf.py, pf.py; belief over the INS error): `predict` the fix's offset
  from the INS (north, east m: what every hypothesis dn_k, de_k of the INS error should equal) and
  `likelihood` the log-likelihood of each hypothesis, -((g_n - dn_k)^2 + (g_e - de_k)^2) / (2 sigma^2)
  (without the normalising constant, which a filter adds where it reports it).
"""

from __future__ import annotations

import math

import numpy as np

from ...terrain.geodesy import meridian_radius_m, prime_vertical_radius_m
from .terrain_models import radii_m


def residual(ins_state: np.ndarray, lat_g: float, lon_g: float, v_g_ned) -> np.ndarray:
    """z (5, 1): INS minus the fix, north and east position (m) and NED velocity (m/s); ins_state = (lat,
    lon rad, h m, v_ned m/s, ...)."""
    lat, lon, h = float(ins_state[0]), float(ins_state[1]), float(ins_state[2])
    z = np.empty((5, 1))
    z[0, 0] = (lat - lat_g) * (meridian_radius_m(lat) + h)     # INS minus GNSS, north (m)
    z[1, 0] = (lon - lon_g) * (prime_vertical_radius_m(lat) + h) * math.cos(lat)
    z[2:, 0] = ins_state[3:6] - v_g_ned
    return z


def jacobian(n_states: int, states) -> np.ndarray:
    """H (5, n_states): ones at (row r, error state states[r]) (north, east position, NED velocity)."""
    H = np.zeros((5, n_states))
    for r, c in enumerate(states):
        H[r, c] = 1.0
    return H


def noise(sigma_h_m: float, sigma_v_mps: float) -> np.ndarray:
    """R (5, 5) = diag(sigma_h_m^2 twice, sigma_v_mps^2 three times)."""
    return np.diag([sigma_h_m**2] * 2 + [sigma_v_mps**2] * 3)


def position_velocity(ins_state: np.ndarray, lat_g: float, lon_g: float, v_g_ned, sigma_h_m: float,
                      sigma_v_mps: float, n_states: int, states) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(z (5, 1), H (5, n_states), R (5, 5)) of one fix (`residual`, `jacobian`, `noise`)."""
    return (residual(ins_state, lat_g, lon_g, v_g_ned), jacobian(n_states, states),
            noise(sigma_h_m, sigma_v_mps))


def predict(ins_state: np.ndarray, lat_g: float, lon_g: float) -> tuple[float, float]:
    """The fix minus the INS position, north and east (m, seed 000 eq 2 at the INS height)."""
    r_lat, r_lon = radii_m(float(ins_state[0]), float(ins_state[2]))
    return (lat_g - float(ins_state[0])) * r_lat, (lon_g - float(ins_state[1])) * r_lon


def likelihood(g_n_m: float, g_e_m: float, dn_m: np.ndarray, de_m: np.ndarray, sigma_m: float) -> np.ndarray:
    """log N of the fix's offset (g_n, g_e) (m) given each hypothesis (dn_k, de_k) of the INS's horizontal
    error (m), per-axis sigma_m, without the constant: -((g_n - dn)^2 + (g_e - de)^2) / (2 sigma^2)."""
    return -0.5 * ((g_n_m - dn_m) ** 2 + (g_e_m - de_m) ** 2) / sigma_m ** 2


__all__ = ["jacobian", "likelihood", "noise", "position_velocity", "predict", "residual"]
