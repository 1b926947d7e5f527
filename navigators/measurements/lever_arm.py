"""Lever arms of the ranging antennas: their ranges transferred to the IMU's point, to first order.

The navigators' terrain measurement models (radar altimeter, IRA) predict ranges from the navigation
position, which is the IMU's. An antenna at body-FRD offset r_b from the IMU measures from its own point:
with u the unit line of sight from the antenna to the terrain point and d = C_bn r_b the antenna's offset
in NED, the range from the IMU is |R u + d| = R + u . d + O(|d|^2 / R). Since u . d = u_b . r_b with both
in body axes, no attitude is needed:

- IRA: u_b = (0, sin theta, cos theta) at the measured look angle theta (the line of sight's x_b component,
  a few degrees off the zero-Doppler plane, is dropped); the look angle is transferred with
  sin theta_imu = (R sin theta + r_y) / R_imu (seed 000 eqs 18-19: sin theta = y_b / R).
- Radar altimeter: u_b = (0, 0, 1) (the closest return near the boresight).

The residual is of order |r| x (angle dropped) + |r|^2 / R: centimetres for arms of a few metres at
hundreds of metres of range. `compensate_frames` returns new frames; the input is not modified.
"""

from __future__ import annotations

import numpy as np

from ..frames import IraFrame, RadarAltimeterFrame, SensorFrames


def _arm(arms: dict, name: str) -> np.ndarray | None:
    a = arms.get(name) if arms else None
    if a is None:
        return None
    a = np.asarray(a, float).reshape(3)
    return a if np.any(a != 0.0) else None


def has_lever_arms(arms: dict | None) -> bool:
    """True when the radar altimeter's or the IRA's arm is non-zero."""
    return any(_arm(arms or {}, n) is not None for n in ("radar_altimeter", "ira"))


def compensate_frames(frames: SensorFrames, arms: dict) -> SensorFrames:
    """frames with the radar altimeter's and the IRA's ranges (and the IRA's look angle) as seen from the
    IMU; `arms`: {"radar_altimeter": r_b, "ira": r_b}, body FRD metres (missing or zero: unchanged)."""
    out = SensorFrames(frames.t_start_s, frames.t_end_s, frames.imu, frames.baro, frames.radar_altimeter,
                       frames.ira, frames.gnss, frames.air_data, frames.heading, frames.extra)
    r = _arm(arms, "radar_altimeter")
    ra = frames.radar_altimeter
    if r is not None and ra is not None:
        out.radar_altimeter = RadarAltimeterFrame(ra.t_s, ra.range_m + r[2], ra.valid)
    r = _arm(arms, "ira")
    ira = frames.ira
    if r is not None and ira is not None:
        s, c = np.sin(ira.look_angle_rad), np.cos(ira.look_angle_rad)
        rng = ira.range_m + s * r[1] + c * r[2]
        look = np.arcsin(np.clip((ira.range_m * s + r[1]) / rng, -1.0, 1.0))
        out.ira = IraFrame(ira.t_s, rng, look, ira.valid)
    return out
