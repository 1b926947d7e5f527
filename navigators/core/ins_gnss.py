"""The INS + GNSS block: what every navigator that integrates the strapdown INS and takes GNSS fixes does the
same way.

Three families ride a strapdown INS (navigators.inertial.StrapdownIns, seed 000 section 2; seed 002 eqs 1-4)
and fuse GNSS while it is available (loosely coupled, our addition to the seeds):

- the INS + TERCOM error-state EKF (filters/ins_trn_ekf.py): the error state is fed back into the INS;
- the terrain filters (filters/terrain_filter.py: the PMF and the PF): the INS is never corrected, the
  belief is over its error;
- the RBPF (filters/rbpf.py, seed 002): particles over the position error, Kalman parts over the rest, fed
  back into the INS.

Their beliefs differ, so each keeps its own update; the block is what they did three times:

- `InsGnssBlock._imu_times(frames)`: the frame's IMU sample times, or None when the frame has none (counted
  "no_imu"); missing IMU data inside or before the frame is counted "imu_gap" (navigators.frames.imu_gap_s).
- `InsGnssBlock._strapdown(t, f_b, w_b, ok, t_baro, h_baro, baro_ok)`: the strapdown INS over samples,
  its invalid samples (held at the previous one) counted "imu_invalid".
- `gnss_fixes(frame, need_height, need_velocity)`: the frame's usable fixes (flagged valid, finite time and
  position, and the height and velocity where the filter uses them) as one time-ordered `GnssFixes`
  record, with the count of the others.
- `velocity_into_ins`: a GNSS velocity into the INS velocity axes a filter does not carry (scalar Kalman
  update per axis with the INS error model's variance).
- `InsGnssBlock._count_skip`: samples skipped for a reason (Health.skipped counts samples, one event).

The GNSS measurement itself (INS minus fix on the local radii, seed 000 eq 2; H; R; the log-likelihood over
hypotheses) is navigators.measurements.gnss.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..frames import GnssFrame, SensorFrames, imu_gap_s


@dataclass(frozen=True)
class GnssFixes:
    """A frame's usable GNSS fixes in time order (SI: s, rad, m, m/s NED); `n_invalid` fixes left out."""

    t_s: np.ndarray
    lat_rad: np.ndarray
    lon_rad: np.ndarray
    h_m: np.ndarray
    v_ned_mps: np.ndarray      # (n, 3)
    n_invalid: int

    @property
    def n(self) -> int:
        return int(self.t_s.shape[0])

    def nearest(self, t_s: float, max_dt_s: float = 0.5):
        """(t, lat, lon, h, v_ned copy) of the fix nearest t_s, or None when none lies within max_dt_s."""
        if self.n == 0:
            return None
        j = int(np.argmin(np.abs(self.t_s - t_s)))
        if abs(self.t_s[j] - t_s) > max_dt_s:
            return None
        return (float(self.t_s[j]), float(self.lat_rad[j]), float(self.lon_rad[j]), float(self.h_m[j]),
                self.v_ned_mps[j].copy())


def gnss_fixes(frame: GnssFrame | None, need_height: bool, need_velocity: bool) -> GnssFixes | None:
    """The usable fixes of a GNSS frame (flagged valid, finite time, latitude and longitude, and finite
    height / velocity where needed), stably ordered by time; None without a frame or samples."""
    if frame is None or frame.t_s.shape[0] == 0:
        return None
    t = np.asarray(frame.t_s, float)
    lat = np.asarray(frame.lat_rad, float)
    lon = np.asarray(frame.lon_rad, float)
    h = np.asarray(frame.h_m, float)
    v = np.asarray(frame.v_ned_mps, float).reshape(-1, 3)
    ok = np.asarray(frame.valid, bool) & np.isfinite(t) & np.isfinite(lat) & np.isfinite(lon)
    if need_height:
        ok &= np.isfinite(h)
    if need_velocity:
        ok &= np.all(np.isfinite(v), axis=1)
    order = np.argsort(t[ok], kind="stable")
    return GnssFixes(t[ok][order], lat[ok][order], lon[ok][order], h[ok][order], v[ok][order],
                     int(ok.shape[0] - ok.sum()))


def velocity_into_ins(ins_state: np.ndarray, p_vel: np.ndarray, v_gnss: np.ndarray, var_mps2: float,
                      carried: tuple[int, ...]) -> None:
    """GNSS velocity (NED, m/s) into the INS velocity (ins_state[3:6], in place) on the axes a filter does
    not carry: per axis a scalar Kalman update with the INS velocity error variance p_vel (m^2/s^2, in
    place) and the fix's variance var_mps2; nothing when the velocity is not finite."""
    if not np.all(np.isfinite(v_gnss)):
        return
    for a in range(3):
        if a in carried:
            continue
        k = p_vel[a] / (p_vel[a] + var_mps2)
        ins_state[3 + a] += k * (v_gnss[a] - ins_state[3 + a])
        p_vel[a] *= (1.0 - k)


class InsGnssBlock:
    """The INS front end the INS-riding navigators share (a mixin; the navigator owns `ins` and `health`)."""

    def _count_skip(self, t_s: float, reason: str, n: int, message: str) -> None:
        """n samples skipped for `reason` (Health.skipped counts samples; one event says so)."""
        self.health.skipped[reason] = self.health.skipped.get(reason, 0) + int(n)
        self.health.events.append((float(t_s), message))

    def _imu_times(self, frames: SensorFrames) -> np.ndarray | None:
        """The frame's IMU sample times (s), or None (counted "no_imu") when it has none; IMU data missing
        before or inside the frame is counted "imu_gap"."""
        imu = frames.imu
        if imu is None or imu.t_s.shape[0] == 0:
            self.health.skip(frames.t_end_s, "no_imu", "no IMU samples in the frame")
            return None
        t = np.ascontiguousarray(imu.t_s, float)
        gap_s = imu_gap_s(t, self.ins.t_s)
        if gap_s > 0.0:
            self.health.skip(float(t[0]), "imu_gap", f"{gap_s:.2f} s of IMU samples missing")
        return t

    def _strapdown(self, t, f_b, w_b, ok, t_baro=None, h_baro_m=None, baro_ok=None) -> np.ndarray:
        """The strapdown INS over IMU samples (baro-slaved vertical channel when baro samples are given);
        returns its (n, 10) state history. Invalid IMU samples (held at the previous one) are counted
        "imu_invalid"."""
        bad0 = self.ins.bad_imu_samples
        hist = self.ins.propagate(t, f_b, w_b, ok, t_baro, h_baro_m, baro_ok)
        nbad = self.ins.bad_imu_samples - bad0
        if nbad:
            self._count_skip(float(t[0]), "imu_invalid", nbad, f"{nbad} IMU samples invalid (held previous)")
        return hist


__all__ = ["GnssFixes", "InsGnssBlock", "gnss_fixes", "velocity_into_ins"]
