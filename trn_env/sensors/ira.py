"""Interferometric radar altimeter (IRA): slant range R and look angle theta of the closest point on the
zero-Doppler line (seed 000 section 3.3).

Geometry. The zero-Doppler plane passes through the centre antenna perpendicular to the Earth-relative
velocity; its intersection with the terrain is the zero-Doppler line, and the IRA reports the closest point
on it (terrain.queries.ira_return). Three antennas sit on the body lateral axis: left at -L1, centre at the
origin (plus an optional lever arm), right at +L2 (seed 000 eqs 14-17, written in body FRD where the lateral
axis is +y; the paper's body frame has X right). Each antenna's range to the closest point is computed
exactly in NED (antenna offsets rotated with C_bn, closest point through ECEF), and theta follows from the
range differences, eqs 18-19 with the sign of navigators.frames.IraFrame (positive toward the right wing,
the right antenna closer):  R_l - R = L1 sin(theta),  R - R_r = L2 sin(theta).
- look_angle_method "range_difference" (default) adds the two: sin(theta) = (R_l - R_r) / (L1 + L2). For
  equal baselines the second-order far-field terms cancel, leaving O(L^3/R^2).
- "exact" solves the squared forms (eqs 20-23) without the L << R approximation of eqs 26-27:
  y_b . p = (R_l^2 - R^2 - L1^2) / (2 L1) = (R^2 + L2^2 - R_r^2) / (2 L2), sin(theta) = y_b . p / R.
Either way theta is the angle between the line of sight and the body x-z plane, so it is attitude
referenced while the zero-Doppler line is velocity referenced (the point of seed 000).

Noise: sigma_R = 3.5 m, sigma_theta = 0.1 deg (seed 002 Table 1); rate 50 Hz (seed 000 Table 2).

Search: each sample's closest-point search starts from the previous sample's return (carried in IraState
across chunks), which saves part of the search (docs/validation/benchmarks.md); the returns agree with
independent searches to the search's 5 mm range tolerance.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from trn_env.flight.truth import TruthChunk
from trn_env.navigators.core.settings import setting
from trn_env.navigators.frames import IraFrame
from trn_env.sensors.common import (
    EMPTY_B,
    EMPTY_F,
    MappingConfig,
    antenna_positions,
    due_samples,
    ned_vectors_kernel,
    trusted_frame,
)
from trn_env.terrain import queries

LOOK_ANGLE_METHODS = ("range_difference", "exact")


@dataclass(frozen=True)
class IraConfig(MappingConfig):
    """IRA model. Baselines and ranges in metres, angles in degrees, sigmas 1 sigma."""

    rate_hz: float = setting(50.0, "samples per second (seed 000 Table 2)", "Hz", gt=0.0)
    baseline_left_m: float = setting(0.25, "L1, centre to left antenna (ours; seed 000 gives none)", "m",
                                     gt=0.0)
    baseline_right_m: float = setting(0.25, "L2, centre to right antenna", "m", gt=0.0)
    range_noise_m: float = setting(3.5, "range noise sigma_R (seed 002 Table 1)", "m", ge=0.0)
    look_angle_noise_deg: float = setting(0.1, "look-angle noise sigma_theta (seed 002 Table 1)", "deg",
                                          ge=0.0)
    half_window_deg: float = setting(45.0, "angular window of the zero-Doppler line searched", "deg", gt=0.0,
                                     lt=90.0)
    max_range_m: float = setting(10000.0, "maximum range (no return beyond)", "m", gt=0.0)
    look_angle_method: str = setting("range_difference", "how the look angle is formed from the three "
                                                         "ranges", choices=LOOK_ANGLE_METHODS)
    lever_arm_b_m: tuple[float, float, float] = setting(
        (0.0, 0.0, 0.0), "centre antenna offset from the IMU, body FRD", "m", length=3)

    def resolve(self) -> None:
        # derived constants of the per-chunk hot path (not fields: eq, hash and replace ignore them)
        object.__setattr__(self, "_half_window_rad", float(np.deg2rad(self.half_window_deg)))
        object.__setattr__(self, "_look_angle_noise_rad", float(np.deg2rad(self.look_angle_noise_deg)))
        object.__setattr__(self, "_method_index", LOOK_ANGLE_METHODS.index(self.look_angle_method))
        object.__setattr__(self, "_has_lever_arm", any(x != 0.0 for x in self.lever_arm_b_m))

    ERROR_FIELDS = ("range_noise_m", "look_angle_noise_deg")   # zero in noise_free()


class IraState(NamedTuple):
    """Carried between chunks: the sample grid index, and the last valid return (lat, lon rad; NaN before the
    first), where the next sample's search starts (terrain.queries.ira_return's warm_start). The errors are
    white; carrying the return makes a flight sampled in chunks search exactly as in one call."""

    last_k: int | None
    last_return_rad: tuple[float, float] = (np.nan, np.nan)

    @classmethod
    def initial(cls, config: IraConfig, rng: np.random.Generator) -> IraState:
        return cls(None)


def _last_valid_return(ret, previous: tuple[float, float]) -> tuple[float, float]:
    """(lat, lon) of the last valid point of a TerrainReturn, else `previous`."""
    valid = ret.valid
    k = valid.shape[0] - 1
    if k < 0 or not valid[k]:
        hits = np.flatnonzero(valid)
        if hits.shape[0] == 0:
            return previous
        k = int(hits[-1])
    return float(ret.lat_rad[k]), float(ret.lon_rad[k])


def look_angle_from_ranges(r_m: np.ndarray, r_left_m: np.ndarray, r_right_m: np.ndarray, l1_m: float,
                           l2_m: float, method: str = "range_difference") -> np.ndarray:
    """Look angle (rad, + toward the right wing) from the three antennas' ranges (seed 000 eqs 18-23)."""
    if method not in LOOK_ANGLE_METHODS:
        raise ValueError(f"look_angle_method must be one of {LOOK_ANGLE_METHODS}, got {method!r}")
    r, rl, rr = (np.atleast_1d(np.asarray(a, float)) for a in (r_m, r_left_m, r_right_m))
    out = np.empty(r.shape[0])
    for i in range(r.shape[0]):
        out[i] = _look_angle(r[i], rl[i], rr[i], l1_m, l2_m, LOOK_ANGLE_METHODS.index(method))
    return out


@njit(cache=True)
def _look_angle(r, r_l, r_r, l1, l2, method):
    if method == 0:
        s = (r_l - r_r) / (l1 + l2)                                  # eqs 18 + 19
    else:
        y_l = (r_l * r_l - r * r - l1 * l1) / (2.0 * l1)             # eqs 20, 22
        y_r = (r * r + l2 * l2 - r_r * r_r) / (2.0 * l2)             # eqs 21, 23
        s = 0.5 * (y_l + y_r) / r
    return np.arcsin(min(1.0, max(-1.0, s)))


@njit(cache=True)
def _gather(idx, t_s, lat, lon, h, C_bn, v_ned):
    """Rows idx of the truth fields the IRA needs, in one pass (contiguous copies)."""
    m = idx.shape[0]
    t, la, lo, hh = np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    c = np.empty((m, 3, 3))
    v = np.empty((m, 3))
    for i in range(m):
        j = idx[i]
        t[i], la[i], lo[i], hh[i] = t_s[j], lat[j], lon[j], h[j]
        for a in range(3):
            v[i, a] = v_ned[j, a]
            for b in range(3):
                c[i, a, b] = C_bn[j, a, b]
    return t, la, lo, hh, c, v


@njit(cache=True)
def _ira_kernel(lat, lon, h, ret, C_bn, geometry, w, noise):
    """R and theta from the closest points seen from antennas (lat, lon, h). Records (numba tuples): ret =
    (q_valid, q_lat, q_lon, q_h) the terrain query's closest points; geometry = (l1, l2 m the left and
    right baselines, method the look-angle method's index, max_range m); noise = (sigma_R m, sigma_theta
    rad) scaling the standard normals w (n, 2)."""
    q_valid, q_lat, q_lon, q_h = ret
    l1, l2, method, max_range = geometry
    sig_r, sig_th = noise
    n = lat.shape[0]
    p = ned_vectors_kernel(lat, lon, h, q_lat, q_lon, q_h)
    r_out = np.empty(n)
    th_out = np.empty(n)
    valid = np.empty(n, dtype=np.bool_)
    for i in range(n):
        r = r_l = r_r = 0.0
        for a in range(3):
            y = C_bn[i, a, 1]                  # body lateral (+right) axis, NED component a
            r += p[i, a] * p[i, a]
            r_l += (p[i, a] + l1 * y) ** 2     # left antenna at -L1 y_b (eqs 14, 16)
            r_r += (p[i, a] - l2 * y) ** 2     # right antenna at +L2 y_b (eqs 15, 17)
        r, r_l, r_r = np.sqrt(r), np.sqrt(r_l), np.sqrt(r_r)
        th = _look_angle(r, r_l, r_r, l1, l2, method)
        ok = q_valid[i] and np.isfinite(r) and np.isfinite(th) and r <= max_range
        valid[i] = ok
        r_out[i] = r + sig_r * w[i, 0] if ok else np.nan
        th_out[i] = th + sig_th * w[i, 1] if ok else np.nan
    return r_out, th_out, valid


def sample_ira(truth: TruthChunk, terrain, rng: np.random.Generator, config: IraConfig,
               state: IraState | None = None) -> tuple[IraFrame, IraState]:
    """IRA samples (R, theta) over the chunk against the true terrain `terrain` (a terrain.Dem)."""
    state, idx, last_k = due_samples(truth, config, rng, state, IraState)
    if idx is None:
        return trusted_frame(IraFrame, t_s=EMPTY_F, range_m=EMPTY_F, look_angle_rad=EMPTY_F,
                             valid=EMPTY_B), state
    w = rng.standard_normal((idx.shape[0], 2))
    if idx.shape[0] == 0:
        return trusted_frame(IraFrame, t_s=EMPTY_F, range_m=EMPTY_F, look_angle_rad=EMPTY_F,
                             valid=EMPTY_B), IraState(last_k, state.last_return_rad)
    t, lat, lon, h, C_bn, v_ned = _gather(idx, truth.t_s, truth.lat_rad, truth.lon_rad, truth.h_msl_m,
                                          truth.C_bn, truth.v_ned_mps)
    if config._has_lever_arm:
        lat, lon, h = antenna_positions(lat, lon, h, C_bn, config.lever_arm_b_m)
    ret = queries.ira_return(terrain, lat, lon, h, v_ned, C_bn, config._half_window_rad, config.max_range_m,
                             warm_start=state.last_return_rad)
    geometry = (config.baseline_left_m, config.baseline_right_m, config._method_index, config.max_range_m)
    r, theta, valid = _ira_kernel(lat, lon, h, (ret.valid, ret.lat_rad, ret.lon_rad, ret.h_m), C_bn, geometry,
                                  w, (config.range_noise_m, config._look_angle_noise_rad))
    state = IraState(last_k, _last_valid_return(ret, state.last_return_rad))
    return trusted_frame(IraFrame, t_s=t, range_m=r, look_angle_rad=theta, valid=valid), state


__all__ = ["IraConfig", "IraState", "look_angle_from_ranges", "sample_ira"]
