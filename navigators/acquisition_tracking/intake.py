"""Sensor intake of the acquisition-and-tracking navigator (seed 001): a frame's samples into the
sensors' tails, and one transect sample per sample_period_s (measured terrain height = barometric height -
radar range, corrected for attitude or by the predicted return's ray, with the aiding's speed and track
and any GNSS fix at the sample), handed to the navigator's epoch.

A mixin of AcqTrackNavigator (navigator.py), which owns the state these methods read and write.
"""

from __future__ import annotations

import math

import numpy as np

from ..frames import SensorFrames
from . import beam, filter_kernels
from .aiding import (
    air_vector_sum,
    coordinated_turn_roll_rad,
    ground_vector,
    speed_track,
    wrap_rad,
)
from .buffers import (
    _TURN_RATE_WINDOW_S,
)
from .profile import (
    Sample,
    geometric_height_m,
    plumb_height_m,
)


class SensorIntake:
    """Sensor intake of the acquisition-and-tracking navigator (seed 001); a mixin."""

    def _ingest(self, frames: SensorFrames) -> None:
        tl = self._tails
        if frames.baro is not None:
            hb = np.asarray(frames.baro.h_baro_m, float)
            if self.config.baro_geopotential:
                hb = geometric_height_m(hb)
            tl["baro"].extend(frames.baro.t_s, [hb], frames.baro.valid)
        # the radar altimeter is read from the frame itself (_add_sample): no tail
        # air data and compass enter only the air-data aiding (_add_sample, _air_vector): not kept otherwise
        air_aiding = self.config.aiding and self.config.aiding_source == "air_data"
        if air_aiding and frames.air_data is not None:
            ad = frames.air_data
            n_ad = ad.t_s.size
            beta = np.asarray(ad.beta_rad, float) if self.config.air_vector_sideslip else np.zeros(n_ad)
            tl["air"].extend(ad.t_s, [ad.tas_mps, beta], ad.valid & np.isfinite(beta))
        hd = frames.heading
        if air_aiding and hd is not None and hd.t_s.size:
            h = np.asarray(hd.heading_rad, float)
            ok = hd.valid & np.isfinite(h)
            if ok.any():  # continuous heading across frames (for the turn rate)
                h = h.copy()
                prev = tl["hdg"].v[-1, 0] if tl["hdg"].t.size else h[ok][0]
                hu = np.unwrap(np.concatenate([[prev], h[ok]]))[1:]
                h[ok] = hu
            tl["hdg"].extend(hd.t_s, [h], ok)
        g = frames.gnss
        if g is not None and g.t_s.size:
            tl["gnss"].extend(
                g.t_s, [g.lat_rad, g.lon_rad, g.h_m, g.v_ned_mps[:, 0], g.v_ned_mps[:, 1]], g.valid
            )
        if self.ins is not None and frames.imu is not None and frames.imu.t_s.size:
            if g is not None and g.t_s.size and g.valid.any():  # GNSS resets the INS position and velocity
                j = int(np.nonzero(g.valid)[0][-1])
                if abs(float(g.t_s[j]) - self.ins.t_s) < 1.0:
                    self.ins.state[0:3] = (g.lat_rad[j], g.lon_rad[j], g.h_m[j])
                    self.ins.state[3:6] = g.v_ned_mps[j]
            b = frames.baro
            hist = self.ins.propagate(
                frames.imu.t_s,
                frames.imu.f_b_mps2,
                frames.imu.omega_ib_b_rps,
                frames.imu.valid,
                None if b is None else b.t_s,
                None if b is None else b.h_baro_m,
                None if b is None else b.valid,
            )
            step = max(1, hist.shape[0] // 50)  # attitude at <= 50 points per frame is plenty at 1 s
            # (v_n, v_e, roll, pitch, yaw, finite) of every step-th row in one call (filter_kernels.ins_rows)
            rows = np.empty(((hist.shape[0] + step - 1) // step, 6))
            filter_kernels.ins_rows(hist, step, rows)
            tl["ins"].extend(frames.imu.t_s[::step], rows[:, :5].T, rows[:, 5] != 0.0)

    def _samples(self, frames: SensorFrames) -> None:
        cfg = self.config
        T = cfg.sample_period_s
        if self.next_k is None:
            self.next_k = int(math.ceil(frames.t_start_s / T - 1e-9))
        ra = frames.radar_altimeter
        if ra is None:
            self.health.skip(frames.t_start_s, "no_radar_altimeter", "acq_track: no radar-altimeter frame")
        while self.next_k * T < frames.t_end_s - 1e-9:
            t_k = self.next_k * T
            self.next_k += 1
            self._add_sample(t_k, ra)

    def _add_sample(self, t_k: float, ra) -> None:
        cfg = self.config
        tl = self._tails
        T = cfg.sample_period_s
        r_m = math.nan
        if ra is not None and ra.t_s.size:
            j = int(np.searchsorted(ra.t_s, t_k - 1e-6))
            if j < ra.t_s.size and ra.t_s[j] < t_k + 0.5 * T:
                r_m = float(ra.range_m[j]) if bool(ra.valid[j]) else math.nan
        hb, okb = tl["baro"].row(t_k, 0.5)
        h_baro = float(hb[0]) if okb else math.nan
        if math.isfinite(h_baro):
            self.h_m = h_baro
        # aiding values at the sample
        tas = hdg = math.nan
        roll = pitch = 0.0
        yaw = self.yaw
        m_v = m_psi = 0.0
        if cfg.aiding and cfg.aiding_source == "air_data":
            a, oka = tl["air"].row(t_k, 1.0)
            h, okh = tl["hdg"].row(t_k, 1.5 * T)
            tas = float(a[0]) if oka else math.nan
            hdg = float(wrap_rad(h[0])) if okh else math.nan
            if oka and okh:
                self.yaw = hdg
                tas, hdg = self._air_vector(t_k)
            rate = tl["hdg"].rate(t_k, 0, _TURN_RATE_WINDOW_S)
            if math.isfinite(rate) and math.isfinite(tas):
                roll = coordinated_turn_roll_rad(tas, rate)
            if not (math.isfinite(tas) and math.isfinite(hdg)):
                self.health.skip(t_k, "aiding_missing", "acq_track: air data or compass missing; aiding held")
                last = self.transect.samples[-1] if len(self.transect) else None
                m_v, m_psi = (last.m_v, last.m_psi) if last is not None else self._v0
            else:
                # "ne": the air vector itself, the wind is e_ne; else the wind estimator's prediction
                m_v, m_psi = (
                    self.wind.predict(tas, hdg) if cfg.wind_estimation and not self._ne_frame else (tas, hdg)
                )
        elif cfg.aiding:
            row, found = tl["ins"].row(t_k, 0.5)
            if found and np.all(np.isfinite(row[:4])):
                vn, ve, roll, pitch = (float(x) for x in row[:4])
                yaw = float(row[4]) if math.isfinite(row[4]) else yaw
                m_v, m_psi = speed_track(np.array([vn, ve]))
            else:
                self.health.skip(t_k, "aiding_missing", "acq_track: INS velocity missing; aiding held")
                last = self.transect.samples[-1] if len(self.transect) else None
                m_v, m_psi = (last.m_v, last.m_psi) if last is not None else self._v0
        self.roll, self.pitch = roll, pitch
        # measured terrain height; a no-return / NaN / missing baro drops out
        valid = math.isfinite(r_m) and math.isfinite(h_baro)
        if not math.isfinite(r_m):
            self.health.skip(
                t_k,
                "radar_no_return",
                f"acq_track: no radar-altimeter return at {t_k:.1f} s (sample drops out of the transect)",
            )
        elif not math.isfinite(h_baro):
            self.health.skip(
                t_k,
                "baro_missing",
                f"acq_track: no barometric height at {t_k:.1f} s (sample drops out of the transect)",
            )
        agl = float(plumb_height_m(r_m, roll, pitch, cfg.beamwidth_deg)) if cfg.roll_compensation else r_m
        d = h_baro - agl if valid else math.nan
        self._pending_offset = (0.0, 0.0)
        if valid and self._return_model:  # the ray of the predicted shortest return (beam.py)
            if cfg.aiding and cfg.aiding_source == "air_data" and math.isfinite(hdg):
                yaw = hdg
            d, self._pending_offset = self._return_height(t_k, r_m, h_baro, m_v, m_psi, roll, pitch, yaw, d)
        # GNSS at the sample
        g, have_gnss = tl["gnss"].row(t_k, 0.6)
        have_gnss = bool(have_gnss and np.all(np.isfinite(g)))
        glat, glon = (float(g[0]), float(g[1])) if have_gnss else (math.nan, math.nan)
        gv = (float(g[3]), float(g[4])) if have_gnss else (math.nan, math.nan)
        s = Sample(t_k, d, bool(valid), r_m, float(m_v), float(m_psi), tas, hdg, glat, glon, gv, roll)
        self._epoch(s, have_gnss)

    def _return_height(self, t_k, r_m, h_baro, m_v, m_psi, roll, pitch, yaw, d_fallback):
        """(measured terrain height m, beam offset (north, east) m) of a range r_m by the predicted return's
        ray (beam.py) at the dead-reckoned position of t_k; the fallback height and no offset when there is
        no position yet or the prediction has no return."""
        cfg = self.config
        lat, lon = self.pos
        if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(yaw)):
            return d_fallback, (0.0, 0.0)
        r_n, r_e = self._radii(lat, h_baro)
        if math.isfinite(self.t_pos) and cfg.aiding:  # one step of dead reckoning on this sample's aiding
            v_ne = ground_vector(m_v, m_psi) + (self.e_ne if self._ne_frame else 0.0)
            v, psi = speed_track(v_ne)
            v_ne = ground_vector(v + self.b_v, psi + self.b_psi)
            dtp = t_k - self.t_pos
            lat, lon = lat + v_ne[0] * dtp / r_n, lon + v_ne[1] * dtp / r_e
        if not cfg.roll_compensation:
            roll = pitch = 0.0
        ray = beam.predicted_ray(self.dem, lat, lon, h_baro, roll, pitch, yaw, cfg.beamwidth_deg, r_n, r_e)
        if ray is None:
            return d_fallback, (0.0, 0.0)
        theta, u_n, u_e = ray
        rho = r_m * math.sin(theta)
        return h_baro - r_m * math.cos(theta), (rho * u_n, rho * u_e)

    def _beam_arrays(self, b_psi: float) -> tuple[np.ndarray, np.ndarray]:
        """The transect's beam offsets (m) in the replica frame of heading reference b_psi."""
        n = len(self.transect)
        if not self._return_model or len(self._offs) != n:
            z = np.zeros(n)
            return z, z
        key = (self.transect.samples.version, b_psi)
        if self._beam_cache is not None and self._beam_cache[0] == key:
            return self._beam_cache[1]
        o = self._offs.rows()
        out = beam.rotate_offsets(o[:, 0], o[:, 1], -b_psi)
        self._beam_cache = (key, out)
        return out

    def _air_vector(self, t_k: float) -> tuple[float, float]:
        """(speed, direction) of the air vector over the sample interval (t_k - T, t_k]: the mean of
        tas (cos, sin)(heading + sideslip) over the air-data samples in it (settings aiding_interval_mean,
        air_vector_sideslip). The displacement between two samples is the integral of the velocity over the
        interval, and the mean also averages the gusts the ground track does not follow; the sideslip turns
        the compass heading into the air vector's direction (in a gust the aircraft weathercocks)."""
        cfg = self.config
        air, hdg = self._tails["air"], self._tails["hdg"]
        lo = t_k - cfg.sample_period_s if cfg.aiding_interval_mean else t_k - 1e-6
        sn, se, m = air_vector_sum(
            air.t, np.ascontiguousarray(air.v[:, 0]), np.ascontiguousarray(air.v[:, 1]), air.ok, hdg.t,
            np.ascontiguousarray(hdg.v[:, 0]), hdg.ok, lo, t_k, 1.5 * cfg.sample_period_s,
        )  # fmt: skip
        if m == 0:  # no air-data sample in the interval: the newest one (found by the caller)
            row, _ = air.row(t_k, 1.0)
            hr, _ = hdg.row(t_k, 1.5 * cfg.sample_period_s)
            return float(row[0]), float(wrap_rad(hr[0] + row[1]))
        return speed_track(np.array([sn / m, se / m]))
