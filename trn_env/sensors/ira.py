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
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from navigators.frames import IraFrame
from trn_env.sensors.common import (
    antenna_positions,
    check_nonneg,
    check_positive,
    check_vector3,
    config_from_mapping,
    ned_vector_between,
    sample_steps,
)
from trn_env.truth import TruthChunk

LOOK_ANGLE_METHODS = ("range_difference", "exact")


@dataclass(frozen=True)
class IraConfig:
    """IRA model. Baselines and ranges in metres, angles in degrees, sigmas 1 sigma."""

    rate_hz: float = 50.0
    baseline_left_m: float = 0.25          # L1 (our choice; seed 000 gives no value)
    baseline_right_m: float = 0.25         # L2
    range_noise_m: float = 3.5
    look_angle_noise_deg: float = 0.1
    half_window_deg: float = 45.0          # angular window of the zero-Doppler line searched (terrain query)
    max_range_m: float = 10000.0
    look_angle_method: str = "range_difference"
    lever_arm_b_m: tuple[float, float, float] = (0.0, 0.0, 0.0)   # centre antenna, body FRD

    def __post_init__(self):
        name = "IraConfig"
        check_positive(name, "rate_hz", self.rate_hz)
        check_positive(name, "baseline_left_m", self.baseline_left_m)
        check_positive(name, "baseline_right_m", self.baseline_right_m)
        check_positive(name, "max_range_m", self.max_range_m)
        check_nonneg(name, "range_noise_m", self.range_noise_m)
        check_nonneg(name, "look_angle_noise_deg", self.look_angle_noise_deg)
        hw = self.half_window_deg
        if not (isinstance(hw, (int, float, np.floating)) and 0.0 < hw < 90.0):
            raise ValueError(f"IraConfig.half_window_deg must lie in (0, 90) deg, got {hw!r}")
        if self.look_angle_method not in LOOK_ANGLE_METHODS:
            raise ValueError(f"IraConfig.look_angle_method must be one of {LOOK_ANGLE_METHODS}, "
                             f"got {self.look_angle_method!r}")
        object.__setattr__(self, "lever_arm_b_m", check_vector3(name, "lever_arm_b_m", self.lever_arm_b_m))

    @classmethod
    def noise_free(cls, **overrides: Any) -> IraConfig:
        return replace(cls(range_noise_m=0.0, look_angle_noise_deg=0.0), **overrides)

    @classmethod
    def from_mapping(cls, mapping: dict[str, Any] | None) -> IraConfig:
        mapping = dict(mapping or {})
        if mapping.pop("noise_free", False):
            return config_from_mapping(cls, mapping, cls.noise_free())
        return config_from_mapping(cls, mapping)


@dataclass(frozen=True)
class IraState:
    last_k: int | None

    @classmethod
    def initial(cls, config: IraConfig, rng: np.random.Generator) -> IraState:
        return cls(last_k=None)


def look_angle_from_ranges(r_m: np.ndarray, r_left_m: np.ndarray, r_right_m: np.ndarray, l1_m: float,
                           l2_m: float, method: str = "range_difference") -> np.ndarray:
    """Look angle (rad, + toward the right wing) from the three antennas' ranges (seed 000 eqs 18-23)."""
    if method == "range_difference":
        s = (r_left_m - r_right_m) / (l1_m + l2_m)                      # eqs 18 + 19
    elif method == "exact":
        y_l = (r_left_m**2 - r_m**2 - l1_m**2) / (2.0 * l1_m)           # eqs 20, 22
        y_r = (r_m**2 + l2_m**2 - r_right_m**2) / (2.0 * l2_m)          # eqs 21, 23
        s = 0.5 * (y_l + y_r) / r_m
    else:
        raise ValueError(f"look_angle_method must be one of {LOOK_ANGLE_METHODS}, got {method!r}")
    return np.arcsin(np.clip(s, -1.0, 1.0))


def antenna_ranges(p_ned_m: np.ndarray, C_bn: np.ndarray, l1_m: float, l2_m: float):
    """Ranges (m) from the centre, left and right antennas to the point p (n, 3) NED from the centre.

    Antenna offsets x_l^b = [0, -L1, 0], x_r^b = [0, +L2, 0] (body FRD; seed 000 eqs 14-15) rotated to NED
    with C_bn (eqs 16-17).
    """
    y_n = C_bn[:, :, 1]                        # body lateral (+right) axis in NED
    r = np.linalg.norm(p_ned_m, axis=1)
    r_l = np.linalg.norm(p_ned_m + l1_m * y_n, axis=1)
    r_r = np.linalg.norm(p_ned_m - l2_m * y_n, axis=1)
    return r, r_l, r_r


def sample_ira(truth: TruthChunk, terrain, rng: np.random.Generator, config: IraConfig,
               state: IraState | None = None) -> tuple[IraFrame, IraState]:
    """IRA samples (R, theta) over the chunk against the true terrain `terrain` (a terrain.Dem)."""
    from terrain import queries

    if state is None:
        state = IraState.initial(config, rng)
    idx, last_k = sample_steps(truth.t_s, config.rate_hz, state.last_k)
    n = idx.shape[0]
    w = rng.standard_normal((n, 2))
    t = truth.t_s[idx].copy()
    if n == 0:
        empty = np.zeros(0)
        return IraFrame(t_s=t, range_m=empty, look_angle_rad=empty.copy(), valid=np.zeros(0, bool)), \
            replace(state, last_k=last_k)
    C_bn = np.ascontiguousarray(truth.C_bn[idx])
    lat, lon, h = antenna_positions(truth.lat_rad[idx], truth.lon_rad[idx], truth.h_msl_m[idx], C_bn,
                                    config.lever_arm_b_m)
    lat, lon, h = (np.ascontiguousarray(a, dtype=float) for a in (lat, lon, h))
    ret = queries.ira_return(terrain, lat, lon, h, np.ascontiguousarray(truth.v_ned_mps[idx]), C_bn,
                             np.deg2rad(config.half_window_deg), config.max_range_m)
    valid = np.asarray(ret.valid, bool).copy()
    p = ned_vector_between(lat, lon, h, np.asarray(ret.lat_rad, float), np.asarray(ret.lon_rad, float),
                           np.asarray(ret.h_m, float))
    r, r_l, r_r = antenna_ranges(p, C_bn, config.baseline_left_m, config.baseline_right_m)
    theta = look_angle_from_ranges(r, r_l, r_r, config.baseline_left_m, config.baseline_right_m,
                                   config.look_angle_method)
    valid &= np.isfinite(r) & np.isfinite(theta) & (r <= config.max_range_m)
    r_meas = np.where(valid, r + config.range_noise_m * w[:, 0], np.nan)
    theta_meas = np.where(valid, theta + np.deg2rad(config.look_angle_noise_deg) * w[:, 1], np.nan)
    frame = IraFrame(t_s=t, range_m=r_meas, look_angle_rad=theta_meas, valid=valid)
    return frame, replace(state, last_k=last_k)


__all__ = ["IraConfig", "IraState", "antenna_ranges", "look_angle_from_ranges", "sample_ira"]
