"""INS + batch TERCOM + error-state Kalman filter (seed 000 section 4.3), and the free-inertial navigator.

Error state (13, computed minus true, feedback form - corrected into the INS and zeroed after each fix):

    0-2   position error north, east, down (m)
    3-5   velocity error NED (m/s)
    6-8   attitude error psi (rad, NED small angles: C_true = (I + [psi x]) C_computed)
    9-11  accelerometer bias, body FRD (m/s^2)
    12    z-gyro bias (rad/s) - the least observable gyro term and the one that drives heading drift

Propagation at 50 Hz (seed 000 Table 2) with the psi-angle error model: d(dr) = dv;
d(dv) = f^n x psi + C_bn b_a - (2 w_ie + w_en) x dv + dg (dg = -g/R dr_h, +2g/R dr_d; the vertical is the
baro-damped channel of navigators.inertial); d(psi) = -w_in x psi - C_bn [0, 0, b_gz]. Measurement: the TERCOM
fix, z = -(correction) = INS - matched position (north, east), chi-square gated; the batch's rigid shift is
the INS error averaged over its samples, dr(t_k) = dr - dv tau_k + d(dv)/dt tau_k^2 / 2 (tau_k = t_fix -
t_k), so H takes the velocity error times the mean lag (-lag on states 3, 4). Its noise: fix_noise "fixed"
(the free INS's settings default; ins_tercom's opt-in) (fix_sigma_m)^2 per axis (Table 2: (10 m)^2); "batch"
(ins_tercom's default) the MAD shift's covariance from the batch's residuals, the map's slopes, the
terrain the map cannot hold and (without bias removal) the baro's bias (navigators.tercom.fix_noise), with
H the map-slope-weighted average of each sample's INS error run back from the fix along the INS's specific
force and attitude (navigators.filters.ins_trn_batch_error: the velocity error times the slope-weighted lag,
the attitude and bias errors through the specific force).
"Velocity-error estimates fed back to compensate the TRN inputs": the estimated errors and biases are fed
back into the INS at every fix, so the next batch is collected with the compensated INS. The error
model's priors and noise come from the IMU's specification where it gives more than the settings
(apply_imu_spec in ins_trn_propagation.py, navigators.core.imu_spec: bias priors and Gauss-Markov walks,
the x / y gyro biases the 13 states do not carry as a tilt random walk matched at the fix period, turns'
misalignment and scale factor per radian of the heading's excursion, turn_angle).

GNSS (loosely coupled, every valid fix of SensorFrames.gnss, at its own time): z = INS - GNSS, north and
east position (m) and NED velocity (m/s), H selects states 0, 1, 3, 4, 5, R = diag(gnss_sigma_h_m^2 x 2,
gnss_sigma_v_mps^2 x 3), chi-square gated (5 dof). The vertical position stays the baro channel's (the
filter does not estimate the baro bias). The receiver's position error is time-correlated (minutes), which
the 13 states do not model: averaging 1 Hz fixes as if white would shrink the horizontal sigma far below
the true error, so after each GNSS update the north/east variances are held at or above
gnss_correlated_sigma_m^2 (a congruence D P D, so P stays positive definite). While GNSS updates arrive
the TERCOM batch restarts at each one (a batch must be collected with one rigid INS error); the first TERCOM
fix falls due fix_period_s after the last GNSS fix. GNSS loss (no valid fix for gnss_timeout_s) and
recovery are reported as events.

Built on filterpy.kalman.KalmanFilter: its state and covariance hold the filter, the TERCOM fix goes
through its (Joseph-form) update; the 50 Hz covariance propagation P = Phi P Phi^T + Q (filterpy's predict
algebra with our Phi/Q) and the IRA batch collection run in numba kernels (filters._ekf_kernels), one
call per segment, for speed.
"""

from __future__ import annotations

import copy
import math
from collections import deque

import numpy as np

from ..core.capture import CaptureGuard, anchor_from_cov9, capture_spec
from ..core.error_states import ACC_BIAS, BGZ, DRE, DRN, DVE, DVN, N_EKF13
from ..core.imu_spec import TurnAngle
from ..core.ins_gnss import InsGnssBlock
from ..core.linalg import floored_psd, is_positive_definite
from ..core.maps import load_map
from ..core.measured_consistency import grade_warning
from ..core.recovery import IntegrityRecovery
from ..frames import SensorFrames
from ..inertial.strapdown import StrapdownIns
from ..integrity import protection_level as pl
from ..integrity.innovation_monitor import InnovationMonitor
from ..measurements.ira_map_noise import interpolation_sigma_m
from ..protocol import Estimate, Health, update_extra
from ..tercom.fix_noise import lad_fix_covariance, slope_weighted_mean
from ..tercom.mad import TercomBatch, TercomFix, correlate
from . import _ekf_kernels as kern
from .ins_trn_batch_error import BatchKinematics, sample_error_rows
from .ins_trn_gnss import InsTrnGnss
from .ins_trn_propagation import EKF_MEMORY_S, InsTrnPropagation
from .ins_trn_settings import INS_CAPABILITIES, InsTrnSettings, initial_covariance

__all__ = ["InsTrnNavigator", "initial_covariance"]   # initial_covariance: re-exported

FIX_HISTORY = 64      # TERCOM fixes kept in `fixes` (the newest)

G0 = 9.80665
N_ERR = N_EKF13


_is_pd = is_positive_definite


class InsTrnNavigator(InsTrnPropagation, InsTrnGnss, InsGnssBlock):
    """Strapdown INS + baro, optionally aided by batch TERCOM fixes through a 13-state error-state KF.

    aiding: None (free inertial, name "ins"), "ira" (seed 000 eq 2, default of "ins_tercom") or
    "radar_altimeter" (eq 1). formula: IRA closest-point formula ("proposed" default). dem: the navigator's
    terrain map (terrain.Dem, or a name/path for terrain.load) - required when aiding is set.
    Sensor noise settings (1 sigma) default to seed 000 Table 2. imu_samples: "interval" (each IMU sample is
    the mean over the step ending at its time, as trn_env.sensors' integrating IMU) or "instant".
    dp_min_m > 0 keeps only IRA samples whose proposed and dp_reference_formula closest points differ
    horizontally by more than dp_min_m (seed 000 Table 3 cases). baro_geopotential: the baro reports ISA
    pressure altitude, a geopotential height; convert it to geometric height (h = r0 H / (r0 - H), r0 =
    6356766 m, US 1976) before eq 1/2 (about +5 m at 5600 m). remove_bias: mean-removed MAD (tercom).
    init_height_from_baro: take the INS height from the first baro sample after reset (see _segment).
    baro_bias_sigma_m: 1-sigma bias of the barometric height the vertical channel is slaved to. The filter
    does not estimate it (the IRA/TERCOM fixes are horizontal), so the height error follows the baro's bias
    and the reported down-position variance adds baro_bias_sigma_m^2 (without it the baro loop's variance
    collapses to a metre while the true height error is the baro bias).
    GNSS (see the module docstring): gnss_sigma_h_m (1 sigma per north/east axis), gnss_sigma_v_mps (per
    NED velocity axis), gnss_correlated_sigma_m (floor of the north/east sigma after a GNSS update: the
    receiver's slowly wandering error), gnss_gate_chi2 (5 dof), gnss_timeout_s (no valid fix for this long
    = GNSS lost, reported as an event); use_gnss=False ignores SensorFrames.gnss.
    Integrity: every TERCOM fix that reaches the chi-square gate (accepted or gated) puts its innovation,
    S, NIS (2 dof), log-likelihood and time under the navigators.protocol EXTRA_* keys, and feeds an
    InnovationMonitor (integrity_window fixes, band probability integrity_alpha). While the NIS sum is above
    its band the status is "degraded" (Health.ok False) and the filter recovers (a fix whose best match lies
    on the edge of the search window counts as an infinite NIS): on entering that state the horizontal
    position covariance is inflated by recovery_sigma_m^2 and the TERCOM search widens to
    recovery_half_cells from the next batch on (both logged); back in band, the search returns to
    half_cells and the status to "ok".
    Capture (navigators.core.capture, with the IMU's specification): a TERCOM fix falling due when the
    free INS's error since the last absolute fix is past the small-angle model and, at 3 sigma, past the
    widest search (recovery_half_cells x cell_m) is skipped, and every later one until a GNSS fix; the
    published horizontal covariance is then the EKF's at the suspension plus the free INS error's growth
    since, Health "degraded".
    Speed: a frame with no fix due inside it and no GNSS fix runs as one numba call
    (_ekf_kernels.fused_segment); set the attribute `fused = False` for the step-by-step path (the same
    numbers, to round-off).
    """

    capabilities = INS_CAPABILITIES
    settings_class = InsTrnSettings          # what `trn-env navigators` lists as its settings
    integrity_risk = pl.DEFAULT_INTEGRITY_RISK   # per epoch, for the published HPL (registry sets it)
    map_horizontal_sigma_m = 0.0                 # the map's horizontal error in the HPL (registry sets it)

    def __init__(self, dem=None, settings: InsTrnSettings | None = None, name: str | None = None,
                 **overrides):
        s = self.settings = InsTrnSettings.build(settings, overrides)
        aiding = s.aiding
        if name is not None and not (isinstance(name, str) and name):
            raise ValueError(f"name must be a non-empty string, got {name!r}")
        if dem is not None and not isinstance(dem, str) and not hasattr(dem, "grid"):
            raise ValueError(f"dem must be a terrain.Dem or a DEM name or file path, got {dem!r}")
        if aiding is not None:
            dem = load_map(dem, "ins_tercom (aiding is set)")
        self.name = name or ("ins" if aiding is None else "ins_tercom")
        self.aiding = aiding
        self.dem = dem
        self.dt_ekf = 1.0 / s.ekf_rate_hz
        self.ins = StrapdownIns(s.gravity_model, s.tau_baro_s, s.imu_samples)
        self.sig_ba = s.accel_bias_mps2
        self.q_acc = s.accel_noise_mps2_rthz ** 2
        self.sig_bg = s.gyro_bias_rps
        self.q_gyr = s.gyro_noise_rps_rthz ** 2
        s.copy_to(self, "formula fix_period_s half_cells cell_m fix_sigma_m fix_noise ira_decimation "
                  "ira_average gate_chi2 min_samples dp_min_m dp_reference_formula baro_geopotential "
                  "baro_lag_s remove_bias init_height_from_baro baro_bias_sigma_m use_gnss gnss_sigma_h_m "
                  "gnss_sigma_v_mps gnss_correlated_sigma_m gnss_gate_chi2 gnss_timeout_s "
                  "recovery_half_cells recovery_sigma_m turn_angle")
        self.terrain_model_sigma_m = 0.0
        if aiding is not None and s.fix_noise == "batch":   # the map's unresolved terrain (tercom.fix_noise)
            self.terrain_model_sigma_m = (interpolation_sigma_m(dem) if s.terrain_model_sigma_m == "auto"
                                          else float(s.terrain_model_sigma_m))
        self._t_gnss = -math.inf        # time of the last GNSS fix used
        self._gnss_up = False           # GNSS fixes arriving (loss reported once gnss_timeout_s passes)
        self._height_initialised = False
        self.integrity = InnovationMonitor(s.integrity_window, s.integrity_alpha)
        self._integrity_extra: dict = {}
        self.nominal_half_cells = self.half_cells
        self._update_extra: dict = {}
        self._fault_allowance_m = 0.0       # the last accepted TERCOM fix's (protection_level)
        self._kf = None                     # filterpy's KalmanFilter, made at first use (see kf)
        self.health = Health()
        # the fix's MAD surface is summed while the batch fills (tercom.MadAccumulator), not all at the fix
        self.batch = TercomBatch(None if aiding is None or dem is None else
                                 (self.half_cells, self.cell_m, self.remove_bias, self.dem),
                                 self.ira_average if aiding == "ira" else 1)
        # the latest FIX_HISTORY fixes (each holds its correlation surface: a flight-long list grew without
        # bound); n_fixes counts them all
        self.fixes: deque[TercomFix] = deque(maxlen=FIX_HISTORY)
        self.n_fixes = 0
        self._t_ekf = np.nan
        self._t_batch0 = np.nan
        self._last_f_b = np.array([0.0, 0.0, -G0])
        self._Q = None
        self._rows = np.empty((0, 6))
        self._baro_cache = None
        self._hist = np.empty((0, 10))
        self._bbuf = np.empty(0)
        self._vbuf = np.empty(0, np.bool_)
        self._kinematics = BatchKinematics()   # the INS's specific force and attitude along the batch
        self.fused = True  # False: the step-by-step path (same numbers; kept for tests and fixes)

    # ------------------------------------------------------------------ protocol
    @property
    def kf(self):
        """The filterpy KalmanFilter holding the error state and covariance. Made at first use: filterpy
        imports scipy.stats (about a second), which checking a scenario's settings does not need."""
        if self._kf is None:
            from filterpy.kalman import KalmanFilter
            self._kf = KalmanFilter(dim_x=N_ERR, dim_z=2)
        return self._kf

    def reset(self, initial: Estimate) -> None:
        values = [initial.t_s, initial.lat_rad, initial.lon_rad, initial.h_m, initial.roll_rad,
                  initial.pitch_rad, initial.yaw_rad, *np.ravel(np.asarray(initial.v_ned_mps, float))]
        if len(values) != 10 or not all(math.isfinite(float(v)) for v in values):
            raise ValueError("initial: the initial estimate's time, position, velocity (3) and attitude must "
                             "be finite numbers")
        self.ins.reset(
            initial.t_s,
            initial.lat_rad,
            initial.lon_rad,
            initial.h_m,
            initial.v_ned_mps,
            initial.roll_rad,
            initial.pitch_rad,
            initial.yaw_rad,
        )
        P = np.zeros((N_ERR, N_ERR))
        cov = np.asarray(initial.covariance, float)
        if cov.shape != (9, 9) or not np.all(np.isfinite(cov)):
            raise ValueError("initial.covariance must be a finite 9 x 9 matrix")
        P[:9, :9] = floored_psd(cov, "initial.covariance")
        P[ACC_BIAS, ACC_BIAS] = np.eye(3) * self.sig_ba**2
        P[BGZ, BGZ] = self.sig_bg**2
        self.kf.x = np.zeros((N_ERR, 1))
        self.kf.P = P
        self._yaw_prev = math.nan
        self._heading_net_rad = 0.0
        self._turn_angle = TurnAngle("excursion")
        self._P_good = P.copy()
        self.health = Health(status="free_inertial" if self.aiding is None else "acquiring")
        self.batch.clear()
        self._kinematics.clear()
        self.fixes = deque(maxlen=FIX_HISTORY)
        self.n_fixes = 0
        self.integrity.reset()
        self._recovery = IntegrityRecovery(self.integrity, self.recovery_sigma_m, repeat=False, cap_nis=False)
        self._integrity_extra = {}
        self._set_search(self.nominal_half_cells)
        self._update_extra = {}
        self._fault_allowance_m = 0.0
        self._t_ekf = float(initial.t_s)
        self._t_batch0 = float(initial.t_s)
        self._height_initialised = False
        self._t_gnss = -math.inf
        self._gnss_up = False
        # navigators.core.capture: the widest TERCOM search (recovery_half_cells) is what a fix can cover
        self._capture = CaptureGuard(self.recovery_half_cells * self.cell_m, self.name,
                                     self._capture_spec if self.aiding is not None else None)
        anchor_from_cov9(self._capture, float(initial.t_s), P[:9, :9])

    _capture_spec = None    # the IMU's specification (apply_imu_spec)

    def apply_imu_spec(self, spec) -> None:
        """InsTrnPropagation's, and the specification kept for the capture check (navigators.core.capture)."""
        super().apply_imu_spec(spec)
        self._capture_spec = capture_spec(spec, EKF_MEMORY_S, self.name)
        if self.aiding is not None:
            self._consistency_warning = grade_warning(spec, EKF_MEMORY_S, self.name, capture=True)

    def update(self, frames: SensorFrames) -> Estimate:
        self.health.events = []
        self._baro_cache = None
        t = self._imu_times(frames)
        if t is None:
            return self.estimate().extrapolated(frames.t_end_s)
        n = t.size
        gnss = self._gnss_fixes(frames)
        if gnss is None:
            self._gnss_check_loss(float(t[-1]))
            if self._fused_ok(frames, t):
                self._fused_segment(frames, t)
                return self.estimate()
        t_g = gnss.t_s if gnss is not None else np.zeros(0)
        g = 0
        a = 0
        while a < n:  # split the chunk at fix and GNSS times so that each is applied when it falls due
            t_cut = math.inf if self.aiding is None else self._t_batch0 + self.fix_period_s
            if g < t_g.shape[0]:
                t_cut = min(t_cut, float(t_g[g]))
            if math.isinf(t_cut):
                b = n
            else:
                b = min(max(int(np.searchsorted(t, t_cut, side="left")) + 1, a + 1), n)
            self._segment(frames, a, b)
            if self.aiding is not None and t[b - 1] >= self._t_batch0 + self.fix_period_s - 1e-9:
                self._fix(float(t[b - 1]))
            while g < t_g.shape[0] and (t_g[g] <= t[b - 1] + 1e-9 or b == n):
                self._gnss_update(gnss, g)
                # a GNSS fix re-anchors the capture check (navigators.core.capture)
                anchor_from_cov9(self._capture, float(self.ins.t_s), self.kf.P[:9, :9])
                g += 1
            a = b
        return self.estimate()

    def _fix(self, t_s: float) -> None:
        self.batch.finish()
        s = self.batch.samples
        acc = self.batch.accumulator
        self.batch.clear()
        nxt = self._t_batch0 + self.fix_period_s
        self._t_batch0 = nxt if t_s - nxt < self.fix_period_s else t_s
        if s.shape[0] < self.min_samples:
            self._count_skip(t_s, "tercom_too_few_samples", 1, f"TERCOM batch with {s.shape[0]} samples")
            return
        if self._capture.skips(t_s, lambda: self.kf.P[:2, :2], self.health):   # navigators.core.capture
            return
        fix = correlate(
            self.dem,
            t_s,
            s[:, 1],
            s[:, 2],
            s[:, 3],
            s[:, 4],
            s[:, 5],
            half=self.half_cells,
            cell_m=self.cell_m,
            remove_bias=self.remove_bias,
            lat_ref_rad=None if acc is None else acc.lat_ref_rad,
            accumulator=acc,
        )
        self.fixes.append(fix)
        self.n_fixes += 1
        if not fix.valid:
            self._count_skip(t_s, f"tercom_{fix.reason}", 1, f"TERCOM fix rejected: {fix.reason}")
            if fix.reason == "edge":      # the best match lies beyond the search window: a failed test
                self._integrity_test(t_s, math.inf, 2)
            return
        z = -np.array([[fix.dn_m], [fix.de_m]])  # INS minus matched position
        H = np.zeros((2, N_ERR))
        H[0, DRN] = H[1, DRE] = 1.0
        # the batch's rigid shift is the INS error at the batch's mean sample time, not at the fix's: the
        # error then was the present one less the velocity error times the lag
        lag_s = t_s - float(np.mean(s[:, 0]))
        H[0, DVN] = H[1, DVE] = -lag_s
        if self.fix_noise == "batch":
            # the batch model: each sample's INS error run back from the fix along the INS's specific force
            # and attitude, averaged with the map's slope weights the match gives them (ins_trn_batch_error)
            M = sample_error_rows(s[:, 0], t_s, self._kinematics.since(float(s[0, 0]) - 1.0))
            Hw = slope_weighted_mean(self.dem, s[:, 1], s[:, 2], s[:, 3], s[:, 4], s[:, 5], fix.dn_m,
                                     fix.de_m, M)
            if Hw is not None:
                H = Hw
            Rm = lad_fix_covariance(self.dem, s[:, 1], s[:, 2], s[:, 3], s[:, 4], s[:, 5], fix.dn_m, fix.de_m,
                                    self.cell_m, self.remove_bias, self.terrain_model_sigma_m,
                                    self.baro_bias_sigma_m)
        else:
            Rm = np.eye(2) * self.fix_sigma_m**2
        S = H @ self.kf.P @ H.T + Rm
        d2 = float((z.T @ np.linalg.solve(S, z))[0, 0])
        gated = not np.isfinite(d2) or d2 > self.gate_chi2
        self._record_innovation(t_s, z, S, d2)
        if gated:
            self._count_skip(t_s, "tercom_gated", 1, f"TERCOM fix failed the chi-square gate ({d2:.1f})")
            return
        self._fault_allowance_m = pl.fault_allowance_m(self.kf.P[:2, :2], S, self.gate_chi2)
        saved = copy.deepcopy((self.kf.x, self.kf.P))
        self.kf.update(z, R=Rm, H=H)
        dx = self.kf.x.ravel()
        if not (_is_pd(self.kf.P) and np.all(np.isfinite(dx))):
            self.kf.x, self.kf.P = saved
            self._count_skip(t_s, "covariance_not_pd", 1, "fix skipped: covariance not positive definite")
            return
        self._feed_back(dx)
        self.kf.x[:] = 0.0
        if not self.integrity.degraded:
            self.health.ok, self.health.status = True, "ok"
        self.health.events.append(
            (t_s, f"TERCOM fix dn={fix.dn_m:.1f} m de={fix.de_m:.1f} m q={fix.quality:.2f}")
        )

    def _log_kinematics(self, t_s: np.ndarray, f_b_mps2: np.ndarray, hist: np.ndarray) -> None:
        """Log the segment's INS specific force and attitude for the batch fix's H (batch fix noise only)."""
        if self.aiding is not None and self.fix_noise == "batch":
            self._kinematics.add(t_s, f_b_mps2, hist, self.ins.accel_bias_b)

    def _set_search(self, half_cells: int) -> None:
        """TERCOM search half-width (cells) of the batches started from now on."""
        self.half_cells = int(half_cells)
        if self.batch.accumulate is not None:
            self.batch.accumulate = (self.half_cells, self.cell_m, self.remove_bias, self.dem)

    def _record_innovation(self, t_s: float, z: np.ndarray, S: np.ndarray, d2: float) -> None:
        """The fix's innovation under the protocol's EXTRA_* keys; the innovation test and its recovery."""
        sign, logdet = np.linalg.slogdet(2.0 * np.pi * S)
        log_lik = float(-0.5 * (d2 + logdet)) if sign > 0 else float("nan")
        self._update_extra = update_extra(z.ravel().copy(), S.copy(), d2, 2, log_lik, float(t_s))
        self._integrity_test(t_s, d2, 2)

    def _integrity_test(self, t_s: float, nis: float, dof: int) -> None:
        """Feed the innovation test through the shared recovery policy (navigators.core.recovery, once per
        entry into "degraded", uncapped NIS); on a recovery inflate the covariance and widen the search."""
        decision = self._recovery.add(t_s, nis, dof)
        verdict = decision.verdict
        self._integrity_extra = verdict.extra()
        if not verdict.changed:
            return
        self.health.events.append((t_s, verdict.message))
        if verdict.degraded:
            self.health.ok, self.health.status = False, "degraded"
            if decision.recover:
                P = self.kf.P
                P[0, 0] += decision.sigma_m**2
                P[1, 1] += decision.sigma_m**2
                self._P_good[:] = P
                self._set_search(self.recovery_half_cells)
                self.health.events.append((t_s, f"recovery: horizontal covariance inflated by "
                                                f"({decision.sigma_m:.0f} m)^2, TERCOM search widened to "
                                                f"+-{self.half_cells} cells"))
        else:
            self.health.ok, self.health.status = True, "ok"
            self._set_search(self.nominal_half_cells)
            self.health.events.append(
                (t_s, f"recovery ended: TERCOM search back to +-{self.half_cells} cells"))

    # ------------------------------------------------------------------ output
    def estimate(self) -> Estimate:
        st = self.ins.state
        roll, pitch, yaw = kern.euler_from_quat(st[6:10])
        P = self.kf.P[:9, :9].copy()
        P[2, 2] += self.baro_bias_sigma_m**2
        suspended = self._capture.suspended   # beyond capture (navigators.core.capture)
        P = self._capture.publish(P, float(self.ins.t_s))
        sig_h = math.sqrt(max(P[0, 0] + P[1, 1], 0.0))
        if not math.isfinite(float(st.sum())):
            self.health.ok, self.health.status = False, "diverged"
        elif suspended:
            self.health.ok, self.health.status = False, "degraded"
        elif self.aiding is not None and sig_h > 2000.0:
            self.health.ok, self.health.status = False, "degraded"
        elif self.integrity.degraded:
            self.health.ok, self.health.status = False, "degraded"
        extra = {
            "accel_bias_b_mps2": self.ins.accel_bias_b.copy(),
            "gyro_bias_z_rps": float(self.ins.gyro_bias_b[2]),
        }
        if self.fixes:
            f = self.fixes[-1]
            extra.update(
                last_fix_t_s=f.t_s,
                last_fix_dn_m=f.dn_m,
                last_fix_de_m=f.de_m,
                last_fix_quality=f.quality,
                last_fix_valid=f.valid,
            )
        extra.update(self._update_extra)
        extra.update(self._integrity_extra)
        # HPL: the Gaussian bound of P plus the last accepted fix's fault allowance (protection_level)
        pl.publish(extra, pl.gaussian_hpl(P[:2, :2], pl.filter_risk(self)) + self._fault_allowance_m, self)
        health = self.health.snapshot(self._consistency_warning, self._recovery.consistency)
        return Estimate(
            t_s=self.ins.t_s,
            lat_rad=float(st[0]),
            lon_rad=float(st[1]),
            h_m=float(st[2]),
            v_ned_mps=st[3:6].copy(),
            roll_rad=roll,
            pitch_rad=pitch,
            yaw_rad=yaw,
            covariance=P,
            health=health,
            extra=extra,
        )
