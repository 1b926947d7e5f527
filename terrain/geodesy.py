"""WGS84 geodesy shared by every component.

Positions are geodetic latitude/longitude in radians and height in metres. Small horizontal
displacements use the meridian radius R_N and the prime-vertical radius R_E (seed 000 eq 2:
p_lat = p_n / R_ns, p_lon = p_e / R_ew, with the radii evaluated at the current latitude and
offset by the height). Larger geometry goes through ECEF.
"""

from __future__ import annotations

import numpy as np
from numba import njit

WGS84_A_M = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)
WGS84_B_M = WGS84_A_M * (1.0 - WGS84_F)
OMEGA_EARTH_RPS = 7.292115e-5


@njit(cache=True, fastmath=False)
def meridian_radius_m(lat_rad: float) -> float:
    """Meridian radius of curvature R_N (north-south), metres."""
    s = np.sin(lat_rad)
    w = 1.0 - WGS84_E2 * s * s
    return WGS84_A_M * (1.0 - WGS84_E2) / (w * np.sqrt(w))


@njit(cache=True, fastmath=False)
def prime_vertical_radius_m(lat_rad: float) -> float:
    """Prime-vertical radius of curvature R_E (east-west), metres."""
    s = np.sin(lat_rad)
    return WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * s * s)


@njit(cache=True, fastmath=False, forceinline=True)
def radii_m(lat_rad: float) -> tuple[float, float]:
    """(meridian, prime-vertical) radii of curvature (m) at latitude lat_rad: meridian_radius_m's and
    prime_vertical_radius_m's formulas sharing one sin, for kernels that need both."""
    s = np.sin(lat_rad)
    w = 1.0 - WGS84_E2 * s * s
    return WGS84_A_M * (1.0 - WGS84_E2) / (w * np.sqrt(w)), WGS84_A_M / np.sqrt(w)


@njit(cache=True, fastmath=False)
def ned_offset_to_latlon(lat_rad: float, lon_rad: float, h_m: float, dn_m: float, de_m: float):
    """Add a small north/east displacement (metres) to a geodetic position (seed 000 eq 2)."""
    r_n = meridian_radius_m(lat_rad) + h_m
    r_e = prime_vertical_radius_m(lat_rad) + h_m
    return lat_rad + dn_m / r_n, lon_rad + de_m / (r_e * np.cos(lat_rad))


@njit(cache=True, fastmath=False)
def latlon_to_ned_offset(lat0_rad: float, lon0_rad: float, h_m: float, lat_rad: float, lon_rad: float):
    """North/east displacement (metres) from (lat0, lon0) to (lat, lon), small-offset form of eq 2; the
    longitude difference taken the short way round (across the antimeridian too)."""
    r_n = meridian_radius_m(lat0_rad) + h_m
    r_e = prime_vertical_radius_m(lat0_rad) + h_m
    dlon = lon_rad - lon0_rad
    if abs(dlon) > np.pi:
        dlon -= 2.0 * np.pi * np.round(dlon / (2.0 * np.pi))
    return (lat_rad - lat0_rad) * r_n, dlon * r_e * np.cos(lat0_rad)


def lon_difference_rad(lon_rad, lon0_rad):
    """lon - lon0 taken the short way round, in [-pi, pi] (exactly lon - lon0 where that is already
    inside): a longitude that wrapped at the antimeridian is 2 pi away from its neighbour, not 40,000 km."""
    d = np.asarray(lon_rad, float) - np.asarray(lon0_rad, float)
    return np.where(np.abs(d) > np.pi, d - 2.0 * np.pi * np.round(d / (2.0 * np.pi)), d)


@njit(cache=True, fastmath=False)
def lla_to_ecef(lat_rad: float, lon_rad: float, h_m: float):
    """Geodetic to Earth-centred Earth-fixed coordinates, metres."""
    r_e = prime_vertical_radius_m(lat_rad)
    cl = np.cos(lat_rad)
    x = (r_e + h_m) * cl * np.cos(lon_rad)
    y = (r_e + h_m) * cl * np.sin(lon_rad)
    z = (r_e * (1.0 - WGS84_E2) + h_m) * np.sin(lat_rad)
    return x, y, z


@njit(cache=True, fastmath=False)
def ecef_to_lla(x: float, y: float, z: float):
    """ECEF (metres) to geodetic (rad, rad, m); Bowring's iteration, converged to < 1 mm."""
    lon = np.arctan2(y, x)
    p = np.sqrt(x * x + y * y)
    lat = np.arctan2(z, p * (1.0 - WGS84_E2))
    h = 0.0
    for _ in range(8):
        r_e = prime_vertical_radius_m(lat)
        h = p / np.cos(lat) - r_e if abs(lat) < 1.4 else abs(z) / abs(np.sin(lat)) - r_e * (1.0 - WGS84_E2)
        lat = np.arctan2(z, p * (1.0 - WGS84_E2 * r_e / (r_e + h)))
    return lat, lon, h


@njit(cache=True, fastmath=False)
def C_en(lat_rad: float, lon_rad: float) -> np.ndarray:
    """Rotation from NED to ECEF at the given position (columns are N, E, D in ECEF)."""
    sl, cl = np.sin(lat_rad), np.cos(lat_rad)
    so, co = np.sin(lon_rad), np.cos(lon_rad)
    c = np.empty((3, 3))
    c[0, 0] = -sl * co
    c[1, 0] = -sl * so
    c[2, 0] = cl
    c[0, 1] = -so
    c[1, 1] = co
    c[2, 1] = 0.0
    c[0, 2] = -cl * co
    c[1, 2] = -cl * so
    c[2, 2] = -sl
    return c


def euler_to_C_bn(roll_rad, pitch_rad, yaw_rad) -> np.ndarray:
    """Body (FRD) to NED rotation from 3-2-1 Euler angles; scalars give (3, 3), arrays give (n, 3, 3)."""
    r, p, y = np.broadcast_arrays(np.asarray(roll_rad, float), np.asarray(pitch_rad, float),
                                  np.asarray(yaw_rad, float))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    c = np.empty(r.shape + (3, 3))
    c[..., 0, 0] = cp * cy
    c[..., 0, 1] = sr * sp * cy - cr * sy
    c[..., 0, 2] = cr * sp * cy + sr * sy
    c[..., 1, 0] = cp * sy
    c[..., 1, 1] = sr * sp * sy + cr * cy
    c[..., 1, 2] = cr * sp * sy - sr * cy
    c[..., 2, 0] = -sp
    c[..., 2, 1] = sr * cp
    c[..., 2, 2] = cr * cp
    return c
