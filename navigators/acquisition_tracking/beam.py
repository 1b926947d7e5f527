"""Where the pulse radar altimeter's shortest return lies: the "return" replica model (seed 001 ch. 4-5).

A pulse altimeter returns the shortest range in its beam (thesis 4.2.4, fig. 4.18): in a bank the beam's
bore sight leaves the vertical, and the return comes from a point displaced across the track (at 600 m above
ground, a 25 deg bank and a 17 deg beam, about 180 m to the outside of the turn, and over rough terrain
wherever a slope is nearest). The thesis' roll correction (5.2.4) scales the range back to a plumb height
once the roll exceeds half the beam; it still assigns that height to the point below the aircraft, the wrong
one. Our reading (spec section 8, "roll correction formula"): per sample, the navigator predicts the return
on its own map at its dead-reckoned position and its attitude (terrain.queries.radar_altimeter_return, the
shortest in-cone range), and takes from the prediction the ray's direction only:

    off-nadir angle  theta = atan2(|q - p|, h - h_q),   measured terrain height  d = h_baro - R cos(theta),
    horizontal offset  o = R sin(theta) (q - p) / |q - p|   (north, east m),

with R the measured range, p the aircraft's horizontal position and q the predicted return point. The
replica then samples the plain map at each sample's position + o (its offsets rotate with the replica's
heading). Over level ground and a tilt beyond half the beam this is the thesis' correction, R cos(tilt -
beam / 2), moved to the point it belongs to; inside the half beam over rough ground it is the footprint
effect (replica_model "footprint" models that by a grey dilation at the point below the aircraft). The ray
direction barely depends on the position error, so predicting it at the estimate is enough (the residuals
with and without position error: docs/validation/seed001.md). Without roll_compensation the prediction
uses a level attitude (roll = pitch = 0).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ...terrain.kernels import map_height
from ...terrain.queries.radar_altimeter import _ra_batch
from ...terrain.queries.shared import _ra_tables, _ra_workspace
from .correlation import replica_offsets, slope_sums


def _ray_work(dem) -> dict:
    """predicted_ray's buffers and the map's search tables (terrain.queries' _ra_tables), kept on the Dem."""
    work = getattr(dem, "_acq_track_ray_work", None)
    if work is not None and work["heights"] is dem.heights_m:
        return work
    bs, bmax, bmin, h_min, h_max, cell_m = _ra_tables(dem)
    work = {
        "heights": dem.heights_m,
        "grid": (dem.record(), cell_m),
        "tables": (bs, bmax, bmin, h_min, h_max),
        "pos": np.zeros((3, 1)),
        "C": np.zeros((1, 3, 3)),
        "valid": np.zeros(1, bool),
        "out": (np.zeros(1), np.zeros(1), np.zeros(1), np.zeros(1)),
    }
    dem._acq_track_ray_work = work
    return work


def predicted_ray(
    dem,
    lat_rad: float,
    lon_rad: float,
    h_m: float,
    roll_rad: float,
    pitch_rad: float,
    yaw_rad: float,
    beamwidth_deg: float,
    r_n: float,
    r_e_cos: float,
    max_range_m: float = 8000.0,
) -> tuple[float, float, float] | None:
    """(off-nadir angle rad, unit north, unit east) of the shortest in-beam return predicted on `dem` for
    an antenna at (lat, lon rad, h m) with the attitude (rad); None when the prediction has no return.
    r_n, r_e_cos: meridian radius + h and (prime vertical radius + h) cos(lat) (m)."""
    # terrain.queries.radar_altimeter_return's kernel on one antenna, called directly with buffers kept
    # between calls: its argument checks and array set-up cost more than its search (once per sample);
    # the kernel reads only the body down axis, C_bn[:, 2] of euler_to_C_bn
    work = _ray_work(dem)
    cr, sr = math.cos(roll_rad), math.sin(roll_rad)
    cp, sp = math.cos(pitch_rad), math.sin(pitch_rad)
    cy, sy = math.cos(yaw_rad), math.sin(yaw_rad)
    pos, C, outs = work["pos"], work["C"], work["out"]
    pos[0, 0], pos[1, 0], pos[2, 0] = lat_rad, lon_rad, h_m
    C[0, 0, 2] = cr * sp * cy + sr * sy
    C[0, 1, 2] = cr * sp * sy - sr * cy
    C[0, 2, 2] = cr * cp
    _ra_batch(
        *work["grid"], (pos[0], pos[1], pos[2], C), math.radians(0.5 * beamwidth_deg), float(max_range_m),
        work["tables"], _ra_workspace(work["tables"][1].size), (work["valid"], *outs),
    )  # fmt: skip
    if not bool(work["valid"][0]):
        return None
    ret_lat, ret_lon, ret_h = float(outs[1][0]), float(outs[2][0]), float(outs[3][0])
    dn = (ret_lat - lat_rad) * r_n
    de = (ret_lon - lon_rad) * r_e_cos
    rho = math.hypot(dn, de)
    theta = math.atan2(rho, h_m - ret_h)
    if rho <= 1e-9:
        return theta, 0.0, 0.0
    return theta, dn / rho, de / rho


def rotate_offsets(o_n: np.ndarray, o_e: np.ndarray, angle_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """Offsets turned by angle_rad (clockwise from north, as a heading): world offsets into the replica's
    frame at heading reference b_psi use angle -b_psi (the kernels turn them back by their b_psi)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.ascontiguousarray(c * o_n - s * o_e), np.ascontiguousarray(s * o_n + c * o_e)


@njit(cache=True)
def replica_points(dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, o_n, o_e, dlat_out, dlon_out):
    """Latitude/longitude offsets (rad) from the transect start of every replica sample's map point: the
    replica position (correlation.replica_offsets) + the beam offset (o_n, o_e m in the replica frame,
    turned by b_psi)."""
    replica_offsets(dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, dlat_out, dlon_out)
    c = math.cos(b_psi)
    s = math.sin(b_psi)
    for i in range(dt.shape[0]):
        dlat_out[i] += (c * o_n[i] - s * o_e[i]) / r_n
        dlon_out[i] += (s * o_n[i] + c * o_e[i]) / r_e_cos


@njit(cache=True)
def replica_heights_at(rec, lat_s, lon_s, motion, b_v, b_psi, o_n, o_e, h_out):
    """correlation.replica_heights with the beam offsets: heights (m) of the map record rec at the replica's
    map points (motion: correlation.Motion)."""
    dt, m_v, m_psi, r_n, r_e_cos = motion
    n = dt.shape[0]
    dla = np.empty(n)
    dlo = np.empty(n)
    replica_points(dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, o_n, o_e, dla, dlo)
    for i in range(n):
        h_out[i] = map_height(rec, lat_s + dla[i], lon_s + dlo[i])


@njit(cache=True)
def information_at(rec, lat_s, lon_s, motion, b_v, b_psi, o_n, o_e, valid, track_rad):
    """correlation.along_cross_information at the replica's map points (beam offsets included; motion:
    correlation.Motion): the sums of the squared along-track and cross-track map slopes over the valid
    samples (dimensionless)."""
    dt, m_v, m_psi, r_n, r_e_cos = motion
    n = dt.shape[0]
    dla = np.empty(n)
    dlo = np.empty(n)
    replica_points(dt, m_v, m_psi, b_v, b_psi, r_n, r_e_cos, o_n, o_e, dla, dlo)
    return slope_sums(rec, lat_s, lon_s, dla, dlo, valid, r_n, r_e_cos, track_rad)
