"""The trn-env sensor-log format, version 1: what is on disk, in which units, under which conventions.

A log is a folder of Parquet tables (Apache Arrow's columnar files, written with pyarrow in row groups as
a flight goes) and one ``metadata.json``::

    LOG/
      metadata.json          format name and version, units per column, conventions, sensors, map, scenario
      frames.parquet         one row per update interval: frame, t_start_s, t_end_s, <sensor>_present
      imu.parquet            one table per sensor fitted: frame, t_s, the sensor's columns, valid
      baro.parquet  radar_altimeter.parquet  ira.parquet  gnss.parquet  air_data.parquet  heading.parquet
      truth.parquet          optional: the true state (t_s, lat_rad, lon_rad, h_m, v_n_mps, ...)
      estimates.parquet      optional: the estimates of the run that recorded it (t_s, ..., cov_i_j)
      events.parquet         optional: (t_s, source, message)

Why a folder of Parquet tables (and not one HDF5 file): each table is written in row groups while the
flight goes, so memory stays flat over a long flight and a half-written table is detectable (Parquet's
footer is written last); pandas (``pandas.read_parquet``) and numpy (through pyarrow) read each table with no
extra dependency (pyarrow and pandas are already trn-env dependencies, h5py is not); sensors at different
rates stay separate tables with no padding; columns are typed float64/bool/int so values round-trip bit for
bit (NaN included), which the replay's bit-for-bit guarantee needs.

Conventions (stated here once; the reader converts a log to them, the builder checks they are stated):

- Time: float64 seconds since the flight's start, strictly increasing within a sensor table. Update
  interval (frame) k holds the samples with ``frame == k``; a builder assigns samples to intervals
  ``[t_start_s, t_end_s)`` by time. A navigator's estimate for frame k is at ``t_end_s``.
- IMU samples (``imu_sample`` in the metadata): ``"rate"``: ``f_x_mps2 ..`` and ``omega_x_rps ..`` are the
  mean specific force and inertial angular rate over the interval (t_{k-1}, t_k] ending at the sample's
  time (what an integrating IMU outputs divided by its interval; trn_env.sensors.imu's ``interval``
  sampling); ``"increment"``: ``dv_x_mps ..`` and ``dtheta_x_rad ..`` are the velocity and angle increments
  over that interval. The reader hands navigators rates (increment / interval; the first sample's
  interval is the median one).
- Frames: IMU, lever arms and look angles in body FRD (x forward, y right, z down); velocities in NED.
- Heights (``height_datum``): ``{"reference": "msl"}`` when heights (GNSS ``h_m``, truth ``h_m``) are above
  the map's vertical datum (the DEM's MSL), or ``{"reference": "ellipsoid", "geoid_offset_m": N}`` for
  WGS84 ellipsoid heights, N the geoid height above the ellipsoid over the log's area (h_msl = h_ell - N).
  Geoid models by name are not supported (no geoid grid ships with trn-env): give the offset.
  Barometric altitude is pressure altitude (ISA) whatever the datum.
- Lever arms (``lever_arms_m``): body-FRD offsets (m) of the radar altimeter's and the IRA's antennas from
  the IMU, whose point the navigation position refers to.
- Estimates: covariance over the error state [north_m, east_m, down_m, v_n, v_e, v_d, then three
  attitude angles] (navigators.protocol.Estimate, which names them roll, pitch, yaw). The attitude block
  is the covariance (rad^2) of the small-angle attitude error about the NED axes (the error-state filters'
  psi: C_true = (I + [psi x]) C_computed): its down component is the heading (yaw) error; the north and
  east components are tilts, equal to the roll and pitch errors only when flying north (in general they
  are those errors rotated by the heading).
"""

from __future__ import annotations

import math

import numpy as np

FORMAT_NAME = "trn-env sensor log"
FORMAT_VERSION = 1
METADATA_FILE = "metadata.json"

SENSORS = ("imu", "baro", "radar_altimeter", "ira", "gnss", "air_data", "heading")

# sensor -> [(column, SensorFrames field, component index or None, unit)]; besides these every sensor
# table has frame (int64), t_s (s) and valid (bool)
SENSOR_COLUMNS: dict[str, list[tuple[str, str, int | None, str]]] = {
    "imu": [("f_x_mps2", "f_b_mps2", 0, "m/s^2"), ("f_y_mps2", "f_b_mps2", 1, "m/s^2"),
            ("f_z_mps2", "f_b_mps2", 2, "m/s^2"), ("omega_x_rps", "omega_ib_b_rps", 0, "rad/s"),
            ("omega_y_rps", "omega_ib_b_rps", 1, "rad/s"), ("omega_z_rps", "omega_ib_b_rps", 2, "rad/s")],
    "baro": [("h_baro_m", "h_baro_m", None, "m")],
    "radar_altimeter": [("range_m", "range_m", None, "m")],
    "ira": [("range_m", "range_m", None, "m"), ("look_angle_rad", "look_angle_rad", None, "rad")],
    "gnss": [("lat_rad", "lat_rad", None, "rad"), ("lon_rad", "lon_rad", None, "rad"),
             ("h_m", "h_m", None, "m"),
             ("v_n_mps", "v_ned_mps", 0, "m/s"), ("v_e_mps", "v_ned_mps", 1, "m/s"),
             ("v_d_mps", "v_ned_mps", 2, "m/s")],
    "air_data": [("tas_mps", "tas_mps", None, "m/s"), ("alpha_rad", "alpha_rad", None, "rad"),
                 ("beta_rad", "beta_rad", None, "rad")],
    "heading": [("heading_rad", "heading_rad", None, "rad")],
}
# the IMU's increment columns (imu_sample = "increment") and the rate column each divides into
IMU_INCREMENT_COLUMNS = [("dv_x_mps", "f_x_mps2", "m/s"), ("dv_y_mps", "f_y_mps2", "m/s"),
                         ("dv_z_mps", "f_z_mps2", "m/s"), ("dtheta_x_rad", "omega_x_rps", "rad"),
                         ("dtheta_y_rad", "omega_y_rps", "rad"), ("dtheta_z_rad", "omega_z_rps", "rad")]

TRUTH_COLUMNS = [("t_s", "s"), ("lat_rad", "rad"), ("lon_rad", "rad"), ("h_m", "m"), ("v_n_mps", "m/s"),
                 ("v_e_mps", "m/s"), ("v_d_mps", "m/s"), ("roll_rad", "rad"), ("pitch_rad", "rad"),
                 ("yaw_rad", "rad")]
# optional truth columns (a recorded flight has them)
TRUTH_OPTIONAL = [("tas_mps", "m/s"), ("alpha_rad", "rad"), ("beta_rad", "rad"), ("wind_n_mps", "m/s"),
                  ("wind_e_mps", "m/s"), ("wind_d_mps", "m/s")]

ESTIMATE_COLUMNS = ([("t_s", "s"), ("lat_rad", "rad"), ("lon_rad", "rad"), ("h_m", "m"), ("v_n_mps", "m/s"),
                     ("v_e_mps", "m/s"), ("v_d_mps", "m/s"), ("roll_rad", "rad"), ("pitch_rad", "rad"),
                     ("yaw_rad", "rad")]
                    + [(f"cov_{i}_{j}", "SI^2") for i in range(9) for j in range(9)]
                    + [("hpl_m", "m")]
                    + [("nav_ok", "bool"), ("nav_status_code", "index into NAV_STATUS_CODES")])

# where a column of these names appears (sensor, truth and estimate tables, the initial estimate), its values
# lie in these closed ranges: a latitude beyond the poles is a unit slip (degrees in a _rad column), a
# negative range a sign slip; the reader refuses them rather than fly them
COLUMN_LIMITS: dict[str, tuple[float, float, str]] = {
    "lat_rad": (-math.pi / 2, math.pi / 2, "a latitude in radians (-pi/2 .. pi/2; degrees?)"),
    "lon_rad": (-math.pi, math.pi, "a longitude in radians (-pi .. pi; degrees?)"),
    "range_m": (0.0, math.inf, "a range in metres (at least 0)"),
    # a Unix or GPS time in seconds is ~1.4e9-1.8e9; one in microseconds or nanoseconds is beyond 1e12
    "t_s": (-1e11, 1e11, "a time in seconds (within +-1e11 s; microseconds or nanoseconds? name the column "
                         "t_us or t_ns)"),
}



def limit_violation(col: str, values, use=None) -> tuple[int, str] | None:
    """(row, what the column should hold) of the first value of a COLUMN_LIMITS column outside its range
    (among the rows where `use`; NaN is left to the finiteness checks), or None."""
    if col not in COLUMN_LIMITS:
        return None
    lo, hi, what = COLUMN_LIMITS[col]
    a = np.asarray(values, dtype=float)
    bad = (a < lo) | (a > hi)
    if use is not None:
        bad &= np.asarray(use, dtype=bool)
    return (int(np.flatnonzero(bad)[0]), what) if bad.any() else None


# the longest stretch without a valid IMU sample an INS is asked to bridge, in median sample intervals
IMU_MAX_GAP_INTERVALS = 2.5


def imu_gap(t_s, valid) -> tuple[float, float, float] | None:
    """(time it starts after, s; its length, s; the median sample interval, s) of the first stretch without
    a valid IMU sample longer than IMU_MAX_GAP_INTERVALS median intervals: samples missing, or marked
    invalid (the INS holds the last valid one across them). No valid sample at all: the whole log. None if
    there is no such stretch."""
    t = np.asarray(t_s, dtype=float)
    if t.size < 2:
        return None
    med = float(np.median(np.diff(t)))
    ok = np.asarray(valid, dtype=bool)
    if not ok.any():
        return float(t[0]), float(t[-1] - t[0]), med
    tv = t[ok]
    # from the log's first sample to the first valid one, between valid ones, from the last valid to the end
    edges = np.concatenate([[t[0] - med], tv, [t[-1] + med]])
    gaps = np.diff(edges)
    big = np.flatnonzero(gaps > IMU_MAX_GAP_INTERVALS * med)
    if big.size == 0:
        return None
    i = int(big[0])
    return float(edges[i]), float(gaps[i]), med


IMU_SAMPLE_CONVENTIONS = ("rate", "increment")
HEIGHT_REFERENCES = ("msl", "ellipsoid")


class LogError(ValueError):
    """A log (or a builder's input) that cannot be used: the message names the file or column and the fix."""


def units() -> dict[str, dict[str, str]]:
    """{table: {column: unit}} of format version 1 (written into every log's metadata)."""
    out = {name: {"frame": "index", "t_s": "s"} | {c: u for c, _, _, u in cols} | {"valid": "bool"}
           for name, cols in SENSOR_COLUMNS.items()}
    out["frames"] = {"frame": "index", "t_start_s": "s", "t_end_s": "s"} | {f"{s}_present": "bool"
                                                                         for s in SENSORS}
    out["truth"] = dict(TRUTH_COLUMNS + TRUTH_OPTIONAL)
    out["estimates"] = dict(ESTIMATE_COLUMNS)
    out["events"] = {"t_s": "s", "source": "text", "message": "text"}
    return out
