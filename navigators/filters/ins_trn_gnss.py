"""The GNSS update of the INS + TERCOM error-state EKF (seed 000; loosely coupled, our addition).

Each valid GNSS fix updates the 15-state error filter with its north and east position and NED velocity
(states 0, 1, 3, 4, 5; R from gnss_sigma_h_m and gnss_sigma_v_mps, gated at gnss_gate_chi2 on 5 dof),
and the correction is fed back into the INS. A loss longer than gnss_timeout_s is reported once in Health.

A mixin of InsTrnNavigator (ins_trn_ekf.py), which owns the state these methods read and write.
"""

from __future__ import annotations

import copy
import math

import numpy as np

from ..core.error_states import ACC_BIAS, ATT, BGZ, GNSS_STATES, N_EKF13, POS, VEL
from ..core.ins_gnss import GnssFixes, gnss_fixes
from ..core.linalg import is_positive_definite
from ..frames import SensorFrames
from ..measurements import gnss as gnss_model
from . import _ekf_kernels as kern


class InsTrnGnss:
    """The GNSS update of InsTrnNavigator; a mixin."""

    # ------------------------------------------------------------------ GNSS
    def _gnss_fixes(self, frames: SensorFrames) -> GnssFixes | None:
        """The frame's valid GNSS fixes in time order (navigators.core.ins_gnss), or None."""
        if not self.use_gnss:
            return None
        fixes = gnss_fixes(frames.gnss, need_height=False, need_velocity=True)
        if fixes is None:
            return None
        if fixes.n_invalid:
            self._count_skip(float(frames.t_start_s), "gnss_invalid", fixes.n_invalid,
                             f"{fixes.n_invalid} GNSS fixes invalid")
        return fixes if fixes.n else None

    def _gnss_check_loss(self, t_now: float) -> None:
        if self._gnss_up and t_now - self._t_gnss > self.gnss_timeout_s:
            self._gnss_up = False
            on = "the INS and TRN" if self.aiding is not None else "the INS alone"
            self.health.events.append(
                (self._t_gnss, f"GNSS lost: no valid fix after t = {self._t_gnss:.2f} s (navigating on "
                               f"{on})"))
            if self.aiding is None:
                self.health.status = "free_inertial"

    def _gnss_update(self, gnss: GnssFixes, i: int) -> None:
        """Loosely coupled GNSS update with fix i (module docstring)."""
        t_g, lat_g, lon_g, v_g = gnss.t_s[i], gnss.lat_rad[i], gnss.lon_rad[i], gnss.v_ned_mps[i]
        z, H, Rm = gnss_model.position_velocity(self.ins.state, lat_g, lon_g, v_g, self.gnss_sigma_h_m,
                                                self.gnss_sigma_v_mps, N_EKF13, GNSS_STATES)
        S = H @ self.kf.P @ H.T + Rm
        try:
            d2 = float((z.T @ np.linalg.solve(S, z))[0, 0])
        except np.linalg.LinAlgError:
            d2 = math.nan
        if not math.isfinite(d2) or d2 > self.gnss_gate_chi2:
            self._count_skip(t_g, "gnss_gated", 1, f"GNSS fix failed the chi-square gate ({d2:.1f})")
            return
        saved = copy.deepcopy((self.kf.x, self.kf.P))
        self.kf.update(z, R=Rm, H=H)
        dx = self.kf.x.ravel()
        P = self.kf.P
        floor2 = self.gnss_correlated_sigma_m**2
        if floor2 > 0.0 and np.all(np.isfinite(P)):
            d = np.ones(N_EKF13)
            for k in (0, 1):
                if 0.0 < P[k, k] < floor2:
                    d[k] = math.sqrt(floor2 / P[k, k])
            P = self.kf.P = P * d[:, None] * d[None, :]
        if not (is_positive_definite(P) and np.all(np.isfinite(dx))):
            self.kf.x, self.kf.P = saved
            self._count_skip(t_g, "covariance_not_pd", 1,
                             "GNSS fix skipped: covariance not positive definite")
            return
        self._feed_back(dx)
        self.kf.x[:] = 0.0
        self._P_good[:] = self.kf.P
        if not self._gnss_up:
            self.health.events.append((float(t_g), "GNSS fixes used" if self._t_gnss == -math.inf else
                                       f"GNSS recovered: fixes used again after {t_g - self._t_gnss:.1f} s"))
        self._gnss_up = True
        self._t_gnss = float(t_g)
        if self.aiding is not None:    # a TERCOM batch is collected with one rigid INS error: restart it
            self.batch.clear()
            self._t_batch0 = float(t_g)
        self.health.ok = True
        self.health.status = "ok"

    def _feed_back(self, dx: np.ndarray) -> None:
        """Correct the INS by the filter's error estimate dx (navigators.core.error_states: position,
        velocity, attitude, accelerometer biases, z-gyro bias); the caller zeroes the state."""
        self.ins.correct(dx[POS], dx[VEL], dx[ATT])
        self.ins.accel_bias_b += dx[ACC_BIAS]
        self.ins.gyro_bias_b[2] += dx[BGZ]
        if math.isfinite(self._yaw_prev):  # a heading correction is not a turn (_turn_noise)
            self._yaw_prev = kern.euler_from_quat(self.ins.state[6:10])[2]
