"""The INS propagation and measurement collection of the INS + TERCOM error-state EKF (seed 000).

Between fixes the strapdown INS runs on the IMU's samples with the barometer's height feeding the vertical
channel, the 15-state error covariance is propagated at ekf_rate_hz (P <- Phi P Phi^T + Q, Phi from the
error model's F over each step, Q from the IMU's noise densities and bias instabilities), and the
TERCOM batch collects the measured terrain heights (barometric height - radar range, or the IRA's
closest-point height, seed 000 eqs 1-2) along the INS track. A frame without a fix inside runs in one
numba call (_ekf_kernels.fused_segment); otherwise segment by segment.

A mixin of InsTrnNavigator (ins_trn_ekf.py), which owns the state these methods read and write.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.error_states import ACC_BIAS, BGZ, N_EKF13, PSID, PSIE, PSIN, VEL
from ..core.imu_spec import ImuSpec, equivalent_walk_density
from ..core.measured_consistency import grade_warning
from ..frames import SensorFrames
from ..inertial.strapdown import GRAVITY_MODELS, quat_to_dcm
from ..measurements.baro import geometric_height_m
from ..measurements.ira_closest_point import closest_point_ned
from . import _ekf_kernels as kern

_EMPTY = np.zeros(0)
_EMPTY_BOOL = np.zeros(0, np.bool_)
# the memory over which the error sources the 13 states do not carry (the x / y gyro biases) are matched by
# an equivalent random walk of the tilt (navigators.core.imu_spec): a GNSS-denied stretch of a flight
EKF_MEMORY_S = 200.0
# a turn of this angle builds the full scale-factor / misalignment error (the per-step share of a 90 deg turn)
TURN_REFERENCE_RAD = 0.5 * math.pi


class InsTrnPropagation:
    """INS propagation, covariance prediction and TERCOM batch collection of InsTrnNavigator; a mixin."""

    # ------------------------------------------------------------------ internals
    def _fused_ok(self, frames: SensorFrames, t: np.ndarray) -> bool:
        """The common frame - no fix falls due inside it, the INS height is initialised, and the aiding (if
        any) is the IRA with a closest-point formula of the kernels - runs as one kernel call."""
        if not self.fused:
            return False
        if self.init_height_from_baro and not self._height_initialised and frames.baro is not None:
            return False
        if self.aiding is None:
            return True
        return (self.aiding == "ira" and self.dp_min_m <= 0.0 and self.formula in kern.FORMULA_CODES
                and float(t[-1]) < self._t_batch0 + self.fix_period_s - 1e-9)

    def _fused_segment(self, frames: SensorFrames, t: np.ndarray) -> None:
        """_segment(frames, 0, n) as one numba call (navigators.filters._ekf_kernels.fused_segment)."""
        imu = frames.imu
        n = t.shape[0]
        ins = self.ins
        baro = frames.baro
        if baro is not None:  # (tau_baro_s is always set here: validated positive)
            tb, hb_raw, vb_raw = baro.t_s, baro.h_baro_m, baro.valid
        else:
            tb, hb_raw, vb_raw = _EMPTY, _EMPTY, _EMPTY_BOOL
        nb = tb.shape[0]
        if self._hist.shape[0] < n:
            self._hist = np.empty((max(n, 16), 10))
        if self._bbuf.shape[0] < nb:
            self._bbuf = np.empty(max(nb, 16))
            self._vbuf = np.empty(max(nb, 16), np.bool_)
        ira = frames.ira if self.aiding == "ira" else None
        collect = ira is not None and ira.t_s.shape[0] > 0
        if collect:
            ts, rng_m, theta, iv = ira.t_s, ira.range_m, ira.look_angle_rad, ira.valid
            if self._rows.shape[0] < ts.shape[0]:
                self._rows = np.empty((max(ts.shape[0], 64), 6))
        else:
            ts = rng_m = theta = _EMPTY
            iv = _EMPTY_BOOL
        if not np.isfinite(self._t_ekf):
            self._t_ekf = float(t[-1])
        if self._Q is None:
            self._Q = self._process_noise(self.dt_ekf)
            self.kf.Q = self._Q
        P = self.kf.P
        if not (P.flags.c_contiguous and P.dtype == np.float64):
            P = self.kf.P = np.ascontiguousarray(P, dtype=float)
        tau = 1e30 if ins.tau_baro_s is None else float(ins.tau_baro_s)
        bad, n_baro_bad, n_steps, pd, m, n_ret, n_nan = kern.fused_segment(
            (ins.state, ins.prev_imu, ins.baro_state), (t, imu.f_b_mps2, imu.omega_ib_b_rps, imu.valid),
            (tb, hb_raw, vb_raw),
            (ins.accel_bias_b, ins.gyro_bias_b, tau, GRAVITY_MODELS[ins.gravity_model],
             ins.imu_samples == "interval"),
            (P, self._Q, self._last_f_b, float(self._t_ekf), self.dt_ekf), (ts, rng_m, theta, iv),
            (collect, self.ira_decimation, kern.FORMULA_CODES.get(self.formula, 1), self.baro_geopotential,
             self.baro_lag_s),
            (self._vbuf[:nb], self._bbuf[:nb], self._hist[:n], self._rows))
        t0 = float(t[0])
        if n_baro_bad:
            self._count_skip(t0, "baro_invalid", n_baro_bad, "baro samples invalid")
        ins.bad_imu_samples += int(bad)
        ins.t_s = float(t[-1])
        if bad:
            self._count_skip(t0, "imu_invalid", bad, f"{bad} IMU samples invalid (held previous)")
        if n_steps > 0:
            if not pd:
                if np.all(np.isfinite(P)):
                    w, V = np.linalg.eigh(0.5 * (P + P.T))
                    self.kf.P = (V * np.clip(w, 1e-12, None)) @ V.T
                else:
                    self.kf.P = self._P_good.copy()
                self._count_skip(float(t[-1]), "covariance_not_pd", 1, "covariance repaired after prediction")
            self._t_ekf += n_steps * self.dt_ekf
        self._P_good[:] = self.kf.P
        self.kf.x[:] = 0.0
        self._add_collected(t0, n_ret, n_nan, m)
        self._log_kinematics(t, imu.f_b_mps2, self._hist[:n])
        self._turn_noise(self._hist[:n])

    def _baro(self, frames: SensorFrames):
        """(t, geometric height, usable mask, all usable) of the frame's baro samples, computed once per
        frame; None without a baro frame."""
        baro = frames.baro
        if baro is None:
            return None
        if self._baro_cache is not None and self._baro_cache[0] is baro:
            return self._baro_cache[1]
        tb, hb_raw = baro.t_s, baro.h_baro_m
        n = hb_raw.shape[0]
        vb = np.empty(n, np.bool_)
        hb = np.empty(n)
        all_ok = kern.baro_prepare(baro.valid, hb_raw, self.baro_geopotential, vb, hb)
        out = (tb, hb, vb, bool(all_ok), hb_raw)
        self._baro_cache = (baro, out)
        return out

    def _segment(self, frames: SensorFrames, a: int, b: int) -> None:
        imu = frames.imu
        if a == 0 and b == imu.t_s.shape[0]:
            t_seg, f_seg, w_seg, ok_seg = imu.t_s, imu.f_b_mps2, imu.omega_ib_b_rps, imu.valid
        else:
            t_seg, f_seg = imu.t_s[a:b], imu.f_b_mps2[a:b]
            w_seg, ok_seg = imu.omega_ib_b_rps[a:b], imu.valid[a:b]
        tb = hb = vb = None
        baro = self._baro(frames)
        if baro is not None:
            tb, hb, vb, vb_all, _ = baro
            if self.init_height_from_baro and not self._height_initialised and (vb_all or vb.any()):
                # vertical channel initialised from the first baro height: a height error left to the baro
                # loop would tilt the INS velocity while it converges, and a vertical velocity error dv_d
                # moves every IRA closest point along track by about R dv_d / V (the zero-Doppler plane).
                self.ins.state[2] = float(hb[np.argmax(vb)])
                self._height_initialised = True
            if not vb_all:
                in_seg = (tb > (imu.t_s[a - 1] if a > 0 else -np.inf)) & (tb <= imu.t_s[b - 1])
                nb = int((in_seg & ~vb).sum())
                if nb:
                    self._count_skip(float(imu.t_s[a]), "baro_invalid", nb, "baro samples invalid")
        hist = self._strapdown(t_seg, f_seg, w_seg, ok_seg, tb, hb, vb)   # (navigators.core.ins_gnss)
        kern.last_good_row(ok_seg, f_seg, self._last_f_b)
        self._predict_to(float(t_seg[-1]), t_seg, f_seg, hist)
        if self.aiding is not None:
            self._collect(frames, t_seg, hist)
        self._log_kinematics(t_seg, f_seg, hist)
        self._turn_noise(hist)

    def _process_noise(self, dt: float) -> np.ndarray:
        Q = np.zeros((N_EKF13, N_EKF13))
        Q[VEL, VEL] = np.eye(3) * self.q_acc * dt
        Q[6:9, 6:9] = np.eye(3) * self.q_gyr * dt
        Q[ACC_BIAS, ACC_BIAS] = np.eye(3) * max((0.01 * self.sig_ba) ** 2 / 3600.0, self._q_ba_walk) * dt
        Q[BGZ, BGZ] = max((0.01 * self.sig_bg) ** 2 / 3600.0, self._q_bg_walk) * dt
        if self._q_tilt > 0.0:  # the x / y gyro biases the states do not carry (apply_imu_spec)
            Q[PSIN, PSIN] += self._q_tilt * dt
            Q[PSIE, PSIE] += self._q_tilt * dt
        Q[2, 2] = 0.01 * dt  # baro noise entering through the loop
        return Q

    # ------------------------------------------------------------------ IMU specification
    _q_tilt = 0.0  # (rad^2/s) tilt random walk standing in for the x / y gyro biases
    _q_ba_walk = 0.0  # (m^2/s^5) accelerometer-bias random walk (its instability's Gauss-Markov drive)
    _q_bg_walk = 0.0  # (rad^2/s^3) z-gyro-bias random walk
    _turn_tilt2 = 0.0  # m^2 TURN_REFERENCE_RAD: level flight's tilt variance per rad turned (misalignment m)
    _turn_heading2 = 0.0  # s^2 TURN_REFERENCE_RAD: level flight's heading variance per rad (scale factor s)
    _yaw_prev = math.nan
    _heading_net_rad = 0.0  # net heading change of the INS's turning since the reset (turn_angle "excursion")
    _turn_angle = None  # navigators.core.imu_spec.TurnAngle (reset)
    _consistency_warning = ""

    def apply_imu_spec(self, spec: ImuSpec) -> None:
        """Take the error model from the IMU's specification (navigators.core.imu_spec), each figure a floor
        over the tuned setting: accelerometer-bias prior sig_ba = the body-fixed horizontal specific-force
        error (bias, instability, misalignment x g); z-gyro-bias prior the gyro bias and instability; velocity
        and attitude noise the noise densities; the biases' random walks their instabilities' Gauss-Markov
        drives (2 sigma^2 / tau); the x / y gyro biases (not states) as a tilt random walk matching them at
        tilt_memory_s; per turn the gyro misalignment (tilt) and scale factor (heading) times the angle."""
        self.sig_ba = max(self.sig_ba, spec.body_accel_sigma_mps2)
        self.sig_bg = max(self.sig_bg, spec.gyro_bias_sigma_rps)
        self.q_acc = max(self.q_acc, spec.accel_noise_density_mps2_rthz**2)
        self.q_gyr = max(self.q_gyr, spec.gyro_noise_density_rps_rthz**2)
        self._q_tilt = equivalent_walk_density(spec.gyro_bias_sigma_rps, self.tilt_memory_s) ** 2
        self._q_ba_walk = 2.0 * spec.accel_bias_instability_mps2**2 / spec.accel_bias_tau_s
        self._q_bg_walk = 2.0 * spec.gyro_bias_instability_rps**2 / spec.gyro_bias_tau_s
        self._turn_tilt2 = spec.turn_tilt_sigma_rad(1.0) ** 2 * TURN_REFERENCE_RAD
        self._turn_heading2 = spec.turn_heading_sigma_rad(1.0) ** 2 * TURN_REFERENCE_RAD
        self._consistency_warning = grade_warning(spec, EKF_MEMORY_S, self.name)
        self._Q = None

    @property
    def tilt_memory_s(self) -> float:
        """Memory (s) at which the tilt random walk matches the tilt of the x / y gyro biases: EKF_MEMORY_S
        for the free INS and for the aided filter with the fixed (Table 2) fix noise; for the aided filter
        with the batch fix covariance the fix period (at most EKF_MEMORY_S).

        A constant bias b tilts the INS by b t, an acceleration error g b t (a ramp) that the aided filter
        observes only through its TERCOM fixes: three successive fixes, fix_period_s apart, fix the
        acceleration error as their track's second difference, the mean over the span, whose middle lies
        one fix period before the last fix. The tilt the filter must allow for beyond its estimate is the
        ramp's change over that period, b fix_period_s, which the equivalent walk (navigators.core.imu_spec
        .equivalent_walk_density) matches at T = fix_period_s; matched at the free INS's EKF_MEMORY_S, the
        walk's variance over a fix period is EKF_MEMORY_S / fix_period_s times the ramp's. That holds when
        each fix's covariance is its own (fix_noise "batch"); the fixed noise weighs every fix alike,
        whatever the terrain resolved, so the fixes do not fix the ramp to within it, and the fixed mode
        keeps the free INS's memory (with the fix period there, the basin calibration route's true miss
        grew by half: docs/validation/fast_tier.md)."""
        if self.aiding is None or self.fix_noise != "batch":
            return EKF_MEMORY_S
        return min(EKF_MEMORY_S, float(self.fix_period_s))

    def _turn_noise(self, hist: np.ndarray) -> None:
        """Attitude variance the segment's turning builds through the gyro scale factor s and misalignment
        m, added after the segment's propagation.

        A heading change at rate r turns the body about the navigation frame's down axis, whose direction in
        the body frame is d = C_bn^T e_down (the third row of C_bn): w_b = r d. The gyro's error
        (S + M) w_b (S diagonal, M off-diagonal, independent entries of sigma s and m) moves the heading by
        r d^T (S + M) d = r (sum_i s_i d_i^2 + sum_(i != j) m_ij d_i d_j), variance per rad turned
        s^2 k + m^2 (1 - k) with k = sum_i d_i^4 ((sum_i d_i^2)^2 = 1 = k + sum_(i != j) d_i^2 d_j^2), and
        the horizontal attitude by the rest of |(S + M) d|^2 = s^2 + 2 m^2: s^2 (1 - k) + m^2 (1 + k) over
        the two tilt axes. Each tilt axis takes m^2 + s^2 (1 - k) / 2: the two sum to 2 m^2 + s^2 (1 - k),
        which bounds that share (k <= 1), and either axis can carry most of it in a turn short of a full
        circle (the body's x / y errors rotate with the heading only through the turn). Level (k = 1) the
        heading takes the scale factor and each tilt axis the misalignment; banked by phi,
        k = cos^4 phi + sin^4 phi and the heading takes 2 m^2 sin^2 phi cos^2 phi of the misalignment (in
        a 24 deg bank 0.27 m^2: on the tactical preset, m = 3.3 s, three times the scale factor's share).
        k is taken at the segment's last attitude.

        The error is a constant of the IMU times the angle turned, variance sigma^2 dpsi^2, and the 13
        states do not carry s and m, so it enters as a random walk in the angle, of density
        sigma^2 TURN_REFERENCE_RAD per rad: it matches sigma^2 dpsi^2 at dpsi = TURN_REFERENCE_RAD and bounds
        it from above for smaller turns (the equivalent walk of navigators.core.imu_spec, with the angle in
        place of the time). The angle (turn_angle): "total", the total variation of the INS yaw at the IMU's
        rate (the integral of |yaw rate| over the segment's samples hist: _ekf_kernels.yaw_total_variation;
        not a per-frame net change, which would depend on the frame rate), which counts the heading's
        back-and-forth on a straight leg as turning; "excursion", the growth of the largest net heading
        change since the reset (navigators.core.imu_spec.TurnAngle): the error of a constant s and m follows
        the net heading change, so a wander, or a turn undone, adds nothing beyond its largest excursion.
        The net change is the INS's own turning: a fix's heading correction re-anchors _yaw_prev
        (ins_trn_gnss._feed_back) and is not counted."""
        if self._turn_tilt2 == 0.0 and self._turn_heading2 == 0.0:
            return
        turn, yaw = kern.yaw_total_variation(hist, self._yaw_prev)
        if self.turn_angle == "excursion":
            if math.isfinite(self._yaw_prev) and math.isfinite(yaw):
                self._heading_net_rad += (yaw - self._yaw_prev + math.pi) % (2.0 * math.pi) - math.pi
            turn = self._turn_angle.advance(self._heading_net_rad)
        if turn > 0.0:
            k = 1.0
            ok = np.isfinite(hist[:, 6:10]).all(axis=1)
            if ok.any():
                d = quat_to_dcm(hist[np.flatnonzero(ok)[-1], 6:10])[2]
                k = float(np.sum(d**4))
            m2, s2 = self._turn_tilt2, self._turn_heading2     # (each x TURN_REFERENCE_RAD)
            tilt = (m2 + 0.5 * s2 * (1.0 - k)) * turn
            P = self.kf.P
            P[PSIN, PSIN] += tilt
            P[PSIE, PSIE] += tilt
            P[PSID, PSID] += (s2 * k + m2 * (1.0 - k)) * turn
            self._P_good[:] = P
        self._yaw_prev = yaw

    def _predict_to(self, t_end: float, t_imu: np.ndarray, f_b: np.ndarray, hist: np.ndarray) -> None:
        """Propagate the error covariance in steps of 1/ekf_rate_hz up to t_end along the INS history
        (_ekf_kernels.predict_covariance: F, Phi = I + F dt + (F dt)^2/2, P = Phi P Phi^T + Q)."""
        if not np.isfinite(self._t_ekf):
            self._t_ekf = t_end
        n_steps = int(np.floor((t_end - self._t_ekf) / self.dt_ekf + 1e-9))
        dt = self.dt_ekf
        if self._Q is None:
            self._Q = self._process_noise(dt)
            self.kf.Q = self._Q
        if n_steps > 0:
            P = self.kf.P
            if not (P.flags.c_contiguous and P.dtype == np.float64):
                P = self.kf.P = np.ascontiguousarray(P, dtype=float)
            kern.predict_covariance(P, self._Q, t_imu, f_b, hist, self.ins.state, self._last_f_b,
                                    self.ins.accel_bias_b, self._t_ekf, dt, n_steps,
                                    float(self.ins.tau_baro_s))
            if not kern.is_positive_definite(P):
                if np.all(np.isfinite(P)):
                    w, V = np.linalg.eigh(0.5 * (P + P.T))
                    self.kf.P = (V * np.clip(w, 1e-12, None)) @ V.T
                else:
                    self.kf.P = self._P_good.copy()
                self._count_skip(t_end, "covariance_not_pd", 1, "covariance repaired after prediction")
            self._t_ekf += n_steps * dt
        self._P_good[:] = self.kf.P
        self.kf.x[:] = 0.0

    def _collect(self, frames: SensorFrames, t_imu: np.ndarray, hist: np.ndarray) -> None:
        if self.aiding == "ira" and self.dp_min_m <= 0.0 and self.formula in kern.FORMULA_CODES:
            self._collect_ira_fast(frames, t_imu, hist)
        else:
            self._collect_general(frames, t_imu, hist)

    def _collect_ira_fast(self, frames: SensorFrames, t_imu: np.ndarray, hist: np.ndarray) -> None:
        """_collect_general's IRA path ("conventional"/"proposed", no dp selection) in one numba call."""
        src = frames.ira
        if src is None:
            return
        ts = src.t_s
        n = ts.shape[0]
        if n == 0:
            return
        baro = self._baro(frames)
        have_baro = False
        tb = hb = _EMPTY
        if baro is not None:
            t_b, _, bv, bv_all, h_raw = baro
            if bv_all and bv.size:
                tb, hb, have_baro = t_b, h_raw, True
            elif bv.any():
                tb, hb, have_baro = t_b[bv], h_raw[bv], True
        if self._rows.shape[0] < n:
            self._rows = np.empty((max(n, 64), 6))
        m, n_bad, n_nan = kern.collect_ira(
            float(t_imu[0]), float(t_imu[-1]), t_imu, hist, (ts, src.range_m, src.look_angle_rad, src.valid),
            self.ira_decimation, (tb, hb, have_baro, self.baro_geopotential, self.baro_lag_s),
            kern.FORMULA_CODES[self.formula], self._rows)
        self._add_collected(float(t_imu[0]), n_bad, n_nan, m)

    def _add_collected(self, t0: float, n_no_return: int, n_no_solution: int, m: int) -> None:
        """Count a frame's altimeter samples without a return and IRA samples without a closest-point
        solution (skips at t0 s), and queue the m measurement rows collected in self._rows."""
        if n_no_return:
            self._count_skip(t0, "altimeter_no_return", n_no_return,
                             f"{n_no_return} altimeter samples without a valid return")
        if n_no_solution:
            self._count_skip(t0, "ira_geometry", n_no_solution, "IRA samples with no closest-point solution")
        if m:
            self.batch.add_rows(self._rows[:m].copy())

    def _collect_general(self, frames: SensorFrames, t_imu: np.ndarray, hist: np.ndarray) -> None:
        t0, t1 = float(t_imu[0]), float(t_imu[-1])
        baro = frames.baro
        if self.aiding == "ira":
            src = frames.ira
            if src is None:
                return
            rng_m, theta = src.range_m, src.look_angle_rad
        else:
            src = frames.radar_altimeter
            if src is None:
                return
            rng_m, theta = src.range_m, np.zeros_like(src.range_m)
        ts = np.asarray(src.t_s, float)
        sel = (ts >= t0) & (ts <= t1)
        if self.aiding == "ira" and self.ira_decimation > 1:
            idx = np.nonzero(sel)[0]
            keep = np.zeros_like(sel)
            keep[idx[:: self.ira_decimation]] = True
            sel = keep
        if not sel.any():
            return
        ok = sel & src.valid & np.isfinite(rng_m) & np.isfinite(theta) & (rng_m > 0)
        nbad = int((sel & ~ok).sum())
        if nbad:
            self._count_skip(
                t0, "altimeter_no_return", nbad, f"{nbad} altimeter samples without a valid return"
            )
        if not ok.any():
            return
        ts_ok = ts[ok]
        k = np.clip(np.searchsorted(t_imu, ts_ok), 0, t_imu.size - 1)
        st = hist[k]
        good_state = np.all(np.isfinite(st), axis=1)
        st, ts_ok = st[good_state], ts_ok[good_state]
        R = rng_m[ok][good_state]
        th = theta[ok][good_state]
        if st.shape[0] == 0:
            return
        # baro height at the sample times (fall back to the baro-damped INS height)
        h_ref = st[:, 2].copy()
        if baro is not None:
            bv = baro.valid & np.isfinite(baro.h_baro_m)
            if bv.sum() >= 1:
                h_ref = np.interp(ts_ok, baro.t_s[bv], baro.h_baro_m[bv])
                if self.baro_geopotential:
                    h_ref = geometric_height_m(h_ref)
                h_ref = h_ref - self.baro_lag_s * st[:, 5]   # the baro's lag (_ekf_kernels.collect_ira)
        if self.aiding == "ira":
            C = np.stack([quat_to_dcm(q) for q in st[:, 6:10]])
            p = closest_point_ned(R, th, None, None, None, st[:, 3:6], formula=self.formula, C_bn=C)
            if self.dp_min_m > 0.0:  # seed 000 Table 3: keep samples where the formulas differ by > dp
                pa, pb = (
                    closest_point_ned(R, th, None, None, None, st[:, 3:6], formula=f, C_bn=C)
                    for f in ("proposed", self.dp_reference_formula)
                )
                dp = np.hypot(pa[:, 0] - pb[:, 0], pa[:, 1] - pb[:, 1])  # eqs 37-39
                keep = dp > self.dp_min_m
                p, st, h_ref, ts_ok = p[keep], st[keep], h_ref[keep], ts_ok[keep]
            nan = ~np.all(np.isfinite(p), axis=1)
            if nan.any():
                self._count_skip(
                    t0, "ira_geometry", int(nan.sum()), "IRA samples with no closest-point solution"
                )
            h_meas = h_ref - np.abs(p[:, 2])  # seed 000 eq 2: h_baro - |p_alt|
            self.batch.add(ts_ok, st[:, 0], st[:, 1], h_meas, p[:, 0], p[:, 1])
        else:
            h_meas = h_ref - R  # seed 000 eq 1
            self.batch.add(ts_ok, st[:, 0], st[:, 1], h_meas)
