"""Sensor frames: timestamped arrays per sensor with validity flags.

Produced by trn_env.sensors (or read from a log of a real flight) and consumed by navigators. They live
here, not in trn_env, because navigators must run without the simulator. Units are SI; frames are
body FRD and navigation NED unless a field name says otherwise. Every sample has a time `t_s`
(seconds since scenario start) and a boolean `valid`; an invalid sample's values are NaN. A frame's arrays
are C-contiguous and writable: one given as a strided or read-only view (a column of a table, a read-only
buffer) is copied when the frame is made, so a navigator's numba kernels compile for one array type.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np


def _check_lengths(frame) -> None:
    """Every array field has t_s's rows; each is made C-contiguous and writable (copied only where it is
    not: a strided slice, a read-only view), so the navigators' numba kernels see one array type whatever
    the frames were cut from, and compile once."""
    n = frame.t_s.shape[0]
    for f in fields(frame):
        v = getattr(frame, f.name)
        if isinstance(v, np.ndarray):
            if v.shape[:1] != (n,):
                raise ValueError(f"{type(frame).__name__}.{f.name} has {v.shape[0]} rows, t_s has {n}")
            if not (v.flags.c_contiguous and v.flags.writeable):
                setattr(frame, f.name, np.require(v, requirements=["C", "W"]))


@dataclass
class ImuFrame:
    """Accelerometer and gyro triads at the IMU rate (body FRD)."""

    t_s: np.ndarray
    f_b_mps2: np.ndarray         # (n, 3) measured specific force
    omega_ib_b_rps: np.ndarray   # (n, 3) measured inertial angular rate
    valid: np.ndarray

    def __post_init__(self):
        _check_lengths(self)


@dataclass
class BaroFrame:
    """Barometric (pressure) altitude, ISA, metres."""

    t_s: np.ndarray
    h_baro_m: np.ndarray
    valid: np.ndarray

    def __post_init__(self):
        _check_lengths(self)


@dataclass
class RadarAltimeterFrame:
    """Range to the closest terrain point in the beam cone, metres."""

    t_s: np.ndarray
    range_m: np.ndarray
    valid: np.ndarray

    def __post_init__(self):
        _check_lengths(self)


@dataclass
class IraFrame:
    """Interferometric radar altimeter: slant range R and look angle theta (seed 000 section 3.3).

    theta is measured in the antennas' cross-track plane (body y-z) from the body's down axis, positive
    toward the right wing (+y FRD). This is the sign of seed 000 eqs 11, 13 and 35 (the right antenna is
    the closer one for theta > 0); the paper's eqs 18-19 state the opposite sign, which its later equations
    do not use.

    Precisely, theta is what the interferometer measures from the antennas' range differences (seed 000
    eqs 18-19, seed 002 eq 26): sin(theta) = y_b / R for the closest point at body-frame offset
    (x_b, y_b, z_b), R = its range, i.e. the angle between the line of sight and the body x-z plane. It
    equals atan2(y_b, z_b) only when x_b = 0 (closest point abeam in the body y-z plane); the closest point
    is given by seed 000 eq 30: the unit line of sight u lies in the zero-Doppler plane and C_bn[:, 1] . u
    = sin(theta).
    """

    t_s: np.ndarray
    range_m: np.ndarray
    look_angle_rad: np.ndarray
    valid: np.ndarray

    def __post_init__(self):
        _check_lengths(self)


@dataclass
class GnssFrame:
    """GNSS position and velocity fixes."""

    t_s: np.ndarray
    lat_rad: np.ndarray
    lon_rad: np.ndarray
    h_m: np.ndarray
    v_ned_mps: np.ndarray   # (n, 3)
    valid: np.ndarray

    def __post_init__(self):
        _check_lengths(self)


@dataclass
class AirDataFrame:
    """Air data: true airspeed (m/s), angle of attack and sideslip (rad)."""

    t_s: np.ndarray
    tas_mps: np.ndarray
    alpha_rad: np.ndarray
    beta_rad: np.ndarray
    valid: np.ndarray

    def __post_init__(self):
        _check_lengths(self)


@dataclass
class HeadingFrame:
    """Compensated compass heading, converted to true heading (rad, clockwise from north)."""

    t_s: np.ndarray
    heading_rad: np.ndarray
    valid: np.ndarray

    def __post_init__(self):
        _check_lengths(self)


@dataclass
class SensorFrames:
    """Everything the sensors produced over one interval [t_start_s, t_end_s). Absent sensors are None."""

    t_start_s: float
    t_end_s: float
    imu: ImuFrame | None = None
    baro: BaroFrame | None = None
    radar_altimeter: RadarAltimeterFrame | None = None
    ira: IraFrame | None = None
    gnss: GnssFrame | None = None
    air_data: AirDataFrame | None = None
    heading: HeadingFrame | None = None
    extra: dict = field(default_factory=dict)


_SENSOR_FIELDS = tuple(f.name for f in fields(SensorFrames)
                       if f.name not in ("t_start_s", "t_end_s", "extra"))


def copy_frames(frames: SensorFrames) -> SensorFrames:
    """A copy of `frames` whose arrays (and `extra` dict) are its own: what a reader gets when others read
    the same frames after it (the loop's log and monitors), so a change it makes in place stays with it."""
    out = SensorFrames(frames.t_start_s, frames.t_end_s, extra=dict(frames.extra))
    for name in _SENSOR_FIELDS:
        fr = getattr(frames, name)
        if fr is not None:
            setattr(out, name, type(fr)(**{f.name: np.array(getattr(fr, f.name), copy=True)
                                          for f in fields(fr)}))
    return out


def imu_gap_s(t_s: np.ndarray, t_prev_s: float = float("nan"), factor: float = 1.5) -> float:
    """Seconds of IMU data missing in a frame: the sum of the sample intervals longer than `factor` times
    the frame's median interval, including the one from `t_prev_s` (the last sample before the frame; NaN:
    none) to its first sample. A navigator counts a positive value in its Health ("imu_gap"): the INS
    integrates across the gap in one long step."""
    t = np.asarray(t_s, float)
    if t.shape[0] == 0:
        return 0.0
    if np.isfinite(t_prev_s) and t_prev_s < t[0]:
        t = np.concatenate(([float(t_prev_s)], t))
    d = np.diff(t)
    if d.shape[0] < 2:
        return 0.0
    if d.max() <= factor * d.min():     # no interval can exceed factor x the median (>= the shortest)
        return 0.0
    nominal = float(np.median(d))
    long = d[d > factor * nominal]
    return float(np.sum(long - nominal)) if long.shape[0] else 0.0


def frame_defects(frames: SensorFrames, sensors: tuple[str, ...], last_t_s: dict[str, float],
                  factor: float = 1.5) -> list[tuple[float, str, str]]:
    """(t_s, reason, message) of the frame's defects in the named sensors: samples marked valid whose values
    are not finite ("invalid_sample") and gaps in a sensor's samples longer than `factor` times its median
    interval ("sample_gap", imu_gap_s). `last_t_s` (sensor -> last sample time seen) is updated in place,
    so a gap across frames is found too. For navigators to count in their Health."""
    out: list[tuple[float, str, str]] = []
    for name in sensors:
        fr = getattr(frames, name, None)
        if fr is None or fr.t_s.shape[0] == 0:
            continue
        t = np.asarray(fr.t_s, float)
        valid = np.asarray(fr.valid, bool)
        bad = np.zeros(t.shape[0], bool)
        for f in fields(fr):
            v = getattr(fr, f.name)
            if f.name not in ("t_s", "valid") and isinstance(v, np.ndarray) and v.dtype.kind == "f":
                bad |= ~np.isfinite(v.reshape(t.shape[0], -1)).all(axis=1)
        bad &= valid
        if bad.any():
            out.append((float(t[np.argmax(bad)]), "invalid_sample",
                        f"{name}: {int(bad.sum())} samples marked valid are not finite"))
        gap = imu_gap_s(t, last_t_s.get(name, float("nan")), factor)
        if gap > 0.0:
            out.append((float(t[0]), "sample_gap", f"{name}: {gap:.2f} s of samples missing"))
        last_t_s[name] = float(t[-1])
    return out
