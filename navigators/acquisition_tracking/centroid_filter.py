"""The transect-centroid filter of the acquisition-and-tracking navigator (seed 001).

The centroid's covariance Pc (2 states, north/east m) or, with reference_frame "ne", X (4 states: centroid
north/east, the aiding's velocity bias e_ne north/east): prediction per sample on the references' sigmas
and the aiding's random walk, GNSS epochs, and the replica geometry (offsets of each sample from the
transect's start along the aided and referenced velocity, on the local radii of curvature), and the floor
the IMU's specification puts under e_ne's walk when the INS is the aiding (apply_imu_spec).

A mixin of AcqTrackNavigator (navigator.py), which owns the state these methods read and write.
"""

from __future__ import annotations

import math

import numpy as np

from ...terrain.geodesy import meridian_radius_m, prime_vertical_radius_m
from ..core.imu_spec import ImuSpec
from ..core.measured_consistency import grade_warning
from . import filter_kernels
from .aiding import (
    ground_vector,
    speed_track,
    wrap_rad,
)
from .buffers import (
    _rot_diag,
)
from .correlation import (
    replica_offsets,
)
from .ins_error import InsVelocityErrorGrowth
from .profile import (
    Sample,
)

# memory of the small-angle check of Health's consistency warning (navigators.core.imu_spec)
ACQ_MEMORY_S = 120.0


class CentroidFilter:
    """The transect-centroid filter of the acquisition-and-tracking navigator (seed 001); a mixin."""

    def _radii(self, lat: float, h: float) -> tuple[float, float]:
        key = (lat, h)
        if getattr(self, "_radii_key", None) == key:  # an epoch asks several times for the same start
            return self._radii_val
        h = h if math.isfinite(h) else 0.0
        r = float(meridian_radius_m(lat)) + h, (float(prime_vertical_radius_m(lat)) + h) * math.cos(lat)
        self._radii_key, self._radii_val = key, r
        return r

    def _offsets(self, dt, m_v, m_psi, b_v, b_psi, lat, radii=None):
        """Replica offsets (rad) from the start at latitude lat; radii: its (r_n, r_e) when known."""
        r_n, r_e = self._radii(lat, self.h_m) if radii is None else radii
        dla = np.empty(dt.size)
        dlo = np.empty(dt.size)
        replica_offsets(dt, m_v, m_psi, b_v, b_psi, r_n, r_e, dla, dlo)
        return dla, dlo

    def _corrected(self, s: Sample) -> tuple[float, float]:
        """The sample's aiding (speed, track) corrected by e_ne (reference_frame "ne"), else as measured."""
        if not self._ne_frame:
            return s.m_v, s.m_psi
        # speed_track(ground_vector(m_v, m_psi) + e_ne) in plain floats (the same operations)
        e_n, e_e = self.e_ne.tolist()
        vn = s.m_v * math.cos(s.m_psi) + e_n
        ve = s.m_v * math.sin(s.m_psi) + e_e
        return math.hypot(vn, ve), math.atan2(ve, vn)

    def _aided_speed(self, s: Sample) -> float:
        return self._corrected(s)[0] + self.b_v

    def _aided_track(self, s: Sample) -> float:
        return self._corrected(s)[1] + self.b_psi

    def _gnss_epoch(self, s: Sample) -> None:
        cfg = self.config
        g_speed, g_track = speed_track(np.array(s.gnss_v_ne))
        if (
            cfg.aiding
            and cfg.aiding_source == "air_data"
            and cfg.wind_estimation
            and math.isfinite(s.tas_mps)
        ):
            self.wind.update(np.array(s.gnss_v_ne), s.tas_mps, s.heading_rad, gain=max(cfg.wind_gain, 0.2))
        if math.isfinite(g_speed) and g_speed > 1.0 and self._ne_frame:
            # the triangle GNSS velocity - aiding vector (the wind with air data); the first one sets it
            k = 0.2 if self._gnss_epochs else 1.0
            self.e_ne = self.e_ne + k * (np.array(s.gnss_v_ne) - ground_vector(s.m_v, s.m_psi) - self.e_ne)
            self.e_mean = self.e_ne.copy()
            self._gnss_epochs += 1
        elif math.isfinite(g_speed) and g_speed > 1.0:
            k = 0.2
            self.b_v += k * (g_speed - s.m_v - self.b_v)
            self.b_psi += k * float(wrap_rad(g_track - s.m_psi - self.b_psi))
            self.b_mean = (self.b_v, self.b_psi)
        # the transect's start from this sample's fix back along the references (its first sample may have
        # had no fix, e.g. before the first GNSS epoch, and kept the initial estimate's error)
        _, _, _, dt, m_v, m_psi, _ = self._aid_arrays()
        dla, dlo = self._offsets(dt, m_v, m_psi, self.b_v, self.b_psi, s.gnss_lat)
        self.p0 = (s.gnss_lat - dla[-1], s.gnss_lon - dlo[-1])
        self.pos = (s.gnss_lat, s.gnss_lon)
        self.t_pos = s.t_s
        self.P = np.eye(2) * cfg.gnss_sigma_m**2
        self.Pc = self.P.copy()
        # e_ne's sigma after the GNSS triangles: the aiding's per-sample noise through the gain-0.2 low-pass
        # (steady-state variance k / (2 - k) of the noise's); an INS is reset by GNSS, air data carries gusts
        self._set_centroid_cov(self.Pc, bias_sigma_mps=cfg.aiding_speed_sigma_mps * math.sqrt(0.2 / 1.8))
        if self._ins_growth is not None and math.isfinite(g_speed):  # the fix reset the INS velocity: anew
            self._ins_growth.restart(s.t_s, s.gnss_v_ne)
        self.sigma_v = 0.1
        self.sigma_psi = math.radians(0.2)
        self.bad_epochs = 0
        self.need_acquisition = False
        self.out_speed, self.out_track = self.average.push(g_speed, g_track)
        self._anchored = True
        self._set_lock("gnss", s.t_s, "ok", "GNSS available")

    def _propagate_cov(self, s: Sample) -> None:
        cfg = self.config
        T = cfg.sample_period_s
        cv, cp = self._corrected(s)  # _aided_speed / _aided_track in one
        v = max(cv + self.b_v, 0.0)
        psi = cp + self.b_psi
        if self.lock_state == "tracking":
            sv, sp = self.sigma_v, self.sigma_psi
        elif cfg.aiding:
            sv, sp = cfg.aiding_speed_sigma_mps, math.radians(cfg.aiding_heading_sigma_deg)
        else:
            sv, sp = cfg.unaided_speed_sigma_mps, math.radians(cfg.unaided_heading_sigma_deg)
        walk = self._walk2 * T
        P = self.P
        if self._ne_frame:  # the centroid moves one sample on the aiding + e_ne; e_ne's error walks
            X = self.X
            growth = self._ins_growth
            if growth is None:
                q_e = self._bias_walk2 * T
            else:
                q_e = growth.step(s.t_s, T, psi, ground_vector(v, psi))
            filter_kernels.ne_predict(X, T, walk, q_e)
            self.Pc = X[:2, :2].copy()
            if self.lock_state == "tracking" or growth is not None:
                # the output: the centroid + the lever to the newest sample (out of lock the 4-state filter's
                # own propagation: e_ne's variance then grows as the INS's velocity error does)
                self.P = self._ne_output_cov(0.5 * cfg.transect_duration_s)
            else:  # out of lock the output is dead-reckoned from the last in-lock newest sample; e_ne's walk
                # grows slower than a bias' ramp, so its sigma is taken as constant over each step (a bound)
                self.P = P + _rot_diag(psi, walk, walk) + self._ne_growth(P, T)
            return
        # the aiding's errors are biases over a transect: sigma grows linearly, sqrt(P) + T sigma_v per epoch
        c, sn = math.cos(psi), math.sin(psi)
        p01 = float(P[0, 1] + P[1, 0])
        p_al = c * c * P[0, 0] + c * sn * p01 + sn * sn * P[1, 1]  # (G^T P G) diagonal
        p_cr = sn * sn * P[0, 0] - c * sn * p01 + c * c * P[1, 1]
        s_al, s_cr = math.sqrt(max(p_al, 0.0)), math.sqrt(max(p_cr, 0.0))
        d_al, d_cr = T * sv, v * T * sp
        self.P = P + _rot_diag(psi, 2.0 * s_al * d_al + d_al**2 + walk, 2.0 * s_cr * d_cr + d_cr**2 + walk)
        # the transect centroid's filter: one sample of dead reckoning on the references and the aiding
        self.Pc = self.Pc + _rot_diag(psi, d_al**2 + walk, d_cr**2 + walk)

    def _aid_arrays(self):
        """The transect's arrays with the aiding per sample corrected by the north/east bias e_ne
        (reference_frame "ne"; cached until the samples or e_ne change), else transect.arrays()."""
        arr = self.transect.arrays()
        if not self._ne_frame:
            return arr
        key = (arr, float(self.e_ne[0]), float(self.e_ne[1]))
        if self._aid_key is not None and self._aid_key[0] is arr and self._aid_key[1:3] == key[1:]:
            return self._aid_key[3]
        t, d, valid, dt, m_v, m_psi, rng = arr
        v_c, psi_c = np.empty(m_v.size), np.empty(m_v.size)
        filter_kernels.corrected_aiding(m_v, m_psi, key[1], key[2], v_c, psi_c)
        out = (t, d, valid, dt, v_c, psi_c, rng)
        self._aid_key = (arr, key[1], key[2], out)
        return out

    def _set_centroid_cov(self, Pc: np.ndarray, bias_sigma_mps: float | None = None) -> None:
        """Centroid covariance (reference_frame "ne"); the velocity bias' block kept (or set to
        bias_sigma_mps), their correlation cleared."""
        self.X[:2, :2] = Pc
        self.X[:2, 2:] = 0.0
        self.X[2:, :2] = 0.0
        if bias_sigma_mps is not None:
            self.X[2:, 2:] = np.eye(2) * bias_sigma_mps**2

    def _ne_output_cov(self, lever_s: float) -> np.ndarray:
        """Covariance (north, east m^2) of the point lever_s seconds of dead reckoning past the centroid."""
        X = self.X.tolist()  # plain floats: numpy on 2 x 2 blocks costs more in its calls than the sums
        L2, w = lever_s**2, self._walk2 * lever_s
        p = [
            [X[i][j] + lever_s * (X[i][j + 2] + X[i + 2][j]) + L2 * X[i + 2][j + 2] + (w if i == j else 0.0)
             for j in (0, 1)]
            for i in (0, 1)
        ]  # fmt: skip
        return np.array(p)

    def _ne_growth(self, P: np.ndarray, T: float) -> np.ndarray:
        """One step's growth of a dead-reckoned point's covariance P on the velocity bias' sigma: sigma
        grows linearly by T sigma_e (the bias is constant over the step; bounds the correlation)."""
        Xe = self.X[2:, 2:]
        s_p = math.sqrt(max(P[0, 0] + P[1, 1], 0.0))
        s_e = math.sqrt(max(Xe[0, 0] + Xe[1, 1], 0.0))
        if s_e <= 0:
            return np.zeros((2, 2))
        return (2.0 * s_p * T / s_e + T * T) * Xe

    @staticmethod
    def _ne_change(b_v: float, b_psi: float, m_v: np.ndarray, m_psi: np.ndarray) -> np.ndarray:
        """North/east velocity change (m/s) equivalent to references (b_v, b_psi) on top of the aiding
        (m_v, m_psi): the mean over the samples of (m_v + b_v) u(m_psi + b_psi) - m_v u(m_psi)."""
        return np.array(filter_kernels.ne_change(b_v, b_psi, m_v, m_psi))

    def _fold_references(self, b_v: float, b_psi: float, m_v: np.ndarray, m_psi: np.ndarray) -> None:
        """reference_frame "ne": move the loops' speed / track references (b_v, b_psi on top of the
        corrected aiding m_v, m_psi) into the north/east bias e_ne and zero them: the least-squares constant
        velocity vector of b_v along and v b_psi across each sample's track."""
        self.e_ne = self.e_ne + self._ne_change(b_v, b_psi, m_v, m_psi)
        self.b_v = self.b_psi = 0.0

    def _arrays(self):
        t, d, valid, dt, m_v, m_psi, rng = self._aid_arrays()
        r_n, r_e = self._radii(self.p0[0], self.h_m)
        return t, d, valid, dt, m_v, m_psi, rng, r_n, r_e

    def _finish(self, s: Sample) -> None:
        """Newest position from the replica; output speed/track through the moving average."""
        _, _, _, dt, m_v, m_psi, _ = self._aid_arrays()
        dla, dlo = self._offsets(dt, m_v, m_psi, self.b_v, self.b_psi, self.p0[0])
        self.pos = (self.p0[0] + dla[-1], self.p0[1] + dlo[-1])
        self.t_pos = s.t_s
        cv, cp = self._corrected(s)
        v, psi = cv + self.b_v, cp + self.b_psi  # _aided_speed, _aided_track
        if self.lock_state == "tracking":
            if self.config.aiding:  # average the references: the aiding carries ramps without lag
                ref_v, ref_psi = self.b_v, self.b_psi
                if self._ne_frame:  # the NE bias as the newest sample's speed / track reference
                    ref_v, ref_psi = cv - s.m_v + self.b_v, float(wrap_rad(cp - s.m_psi)) + self.b_psi
                ab_v, ab_psi = self.average.push(ref_v, ref_psi)
                self.out_speed, self.out_track = s.m_v + ab_v, float(wrap_rad(s.m_psi + ab_psi))
            else:
                self.out_speed, self.out_track = self.average.push(v, psi)
            if (
                self.config.aiding
                and self.config.aiding_source == "air_data"
                and self.config.wind_estimation
                and not self._ne_frame
                and math.isfinite(s.tas_mps)
            ):
                self.wind.update(ground_vector(v, psi), s.tas_mps, s.heading_rad)
                # the references keep the ground vector the loops found (the wind took over part of it)
                m_v2, m_psi2 = self.wind.predict(s.tas_mps, s.heading_rad)
                self.b_v += s.m_v - m_v2
                self.b_psi += float(wrap_rad(s.m_psi - m_psi2))
                tr = self.transect.samples
                tr[-1] = Sample(
                    s.t_s,
                    s.d_m,
                    s.valid,
                    s.range_m,
                    m_v2,
                    m_psi2,
                    s.tas_mps,
                    s.heading_rad,
                    s.gnss_lat,
                    s.gnss_lon,
                    s.gnss_v_ne,
                    s.roll_rad,
                )
        else:
            self.average.reset()
            self.out_speed, self.out_track = v, float(wrap_rad(psi))

    _consistency_warning = ""
    _imu_spec: ImuSpec | None = None   # apply_imu_spec's, with the INS as aiding and reference_frame "ne"
    _ins_growth: InsVelocityErrorGrowth | None = None   # the INS velocity error's growth, set by reset

    def _start_ins_growth(self, cov0: np.ndarray, v0_ne: np.ndarray, t0_s: float) -> None:
        """At the reset, with the IMU's specification (apply_imu_spec): e_ne's prior is the initial estimate's
        velocity covariance (the INS starts from that velocity) and its growth the INS's (ins_error.py), from
        the initial estimate's tilt and heading sigmas (cov0: its 9 x 9 covariance)."""
        spec = self._imu_spec
        if spec is None:
            self._ins_growth = None
            return
        tilt0 = math.sqrt(max(0.5 * float(cov0[6, 6] + cov0[7, 7]), 0.0))
        self._ins_growth = InsVelocityErrorGrowth(spec, tilt0, math.sqrt(max(float(cov0[8, 8]), 0.0)), v0_ne,
                                                  t0_s)
        self.X[2:, 2:] = 0.5 * (cov0[3:5, 3:5] + cov0[3:5, 3:5].T)

    def apply_imu_spec(self, spec: ImuSpec) -> None:
        """With the INS as aiding (aiding_source "ins", reference_frame "ne"), e_ne is the INS's north/east
        velocity error, and the IMU's specification gives its model in place of the walk
        aiding_bias_walk_mps_per_sqrt_s and the prior aiding_speed_sigma_mps: from the reset on, its prior is
        the initial estimate's velocity covariance and its variance grows as the free INS's velocity error
        (ins_error.InsVelocityErrorGrowth: the accelerometer noise, the initial tilt's and the body-fixed
        specific-force error's accelerations turned by the flown heading, the gyro biases' tilt ramp, the
        initial heading error on the velocity change), and out of lock the output covariance is the 4-state
        filter's own propagation (_propagate_cov). Air-data aiding does not use the IMU: no change."""
        if self.ins is None or not self._ne_frame:
            return
        self._imu_spec = spec
        if getattr(self, "_init_state", None) is not None:  # applied after a reset: from that reset on
            self._start_ins_growth(*self._init_state)
        self._consistency_warning = grade_warning(spec, ACQ_MEMORY_S, self.name)
