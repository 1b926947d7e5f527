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
fix, z = -(correction) = INS - matched position (north, east), noise (10 m)^2 (Table 2), chi-square gated.
"Velocity-error estimates fed back to compensate the TRN inputs": the estimated errors and biases are fed
back into the INS at every fix, so the next batch is collected with the compensated INS.

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

import numpy as np
import trn_env.navigators.filters._ekf_kernels as kern
from filterpy.kalman import KalmanFilter
from trn_env.navigators.filters.ins_trn_settings import (
    INS_CAPABILITIES,
    InsTrnSettings,
)
from trn_env.navigators.frames import SensorFrames
from trn_env.navigators.inertial.strapdown import GRAVITY_MODELS, StrapdownIns, quat_to_dcm
from trn_env.navigators.integrity.innovation_monitor import InnovationMonitor
from trn_env.navigators.measurements.ira_closest_point import closest_point_ned
from trn_env.navigators.protocol import (
    EXTRA_INNOVATION,
    EXTRA_INNOVATION_COV,
    EXTRA_LOG_LIKELIHOOD,
    EXTRA_MEASUREMENT_TIME,
    EXTRA_NIS,
    EXTRA_NIS_DOF,
    Estimate,
    Health,
)
from trn_env.navigators.tercom.mad import TercomBatch, TercomFix, correlate
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

G0 = 9.80665
N_ERR = 13
_GNSS_STATES = (0, 1, 3, 4, 5)      # north, east position; NED velocity
R0_GEOPOTENTIAL_M = 6356766.0  # US Standard Atmosphere 1976 Earth radius for geopotential height
_EMPTY = np.zeros(0)
_EMPTY_BOOL = np.zeros(0, np.bool_)


def _is_pd(P: np.ndarray) -> bool:
    if not np.all(np.isfinite(P)):
        return False
    try:
        np.linalg.cholesky(0.5 * (P + P.T))
        return True
    except np.linalg.LinAlgError:
        return False


class InsTrnNavigator:
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
    Speed: a frame with no fix due inside it and no GNSS fix runs as one numba call
    (_ekf_kernels.fused_segment); set the attribute `fused = False` for the step-by-step path (the same
    numbers, to round-off).
    """

    capabilities = INS_CAPABILITIES

    def __init__(self, dem=None, settings: InsTrnSettings | None = None, name: str | None = None,
                 **overrides):
        s = self.settings = InsTrnSettings.build(settings, overrides)
        aiding = s.aiding
        if name is not None and not (isinstance(name, str) and name):
            raise ValueError(f"name must be a non-empty string, got {name!r}")
        if dem is not None and not isinstance(dem, str) and not hasattr(dem, "grid"):
            raise ValueError(f"dem must be a terrain.Dem or a DEM name or file path, got {dem!r}")
        if aiding is not None:
            if dem is None:
                raise ValueError("dem: the navigator's terrain map is required when aiding is set")
            if isinstance(dem, str):
                from trn_env import terrain

                try:
                    dem = terrain.load(dem)
                except (OSError, ValueError) as exc:
                    raise ValueError(f"dem: cannot load the navigator's map {dem!r}: {exc}") from exc
        self.name = name or ("ins" if aiding is None else "ins_tercom")
        self.aiding = aiding
        self.dem = dem
        self.formula = s.formula
        self.fix_period_s = s.fix_period_s
        self.half_cells = s.half_cells
        self.cell_m = s.cell_m
        self.fix_sigma_m = s.fix_sigma_m
        self.dt_ekf = 1.0 / s.ekf_rate_hz
        self.ins = StrapdownIns(s.gravity_model, s.tau_baro_s, s.imu_samples)
        self.sig_ba = s.accel_bias_mps2
        self.q_acc = s.accel_noise_mps2_rthz ** 2
        self.sig_bg = s.gyro_bias_rps
        self.q_gyr = s.gyro_noise_rps_rthz ** 2
        self.ira_decimation = s.ira_decimation
        self.gate_chi2 = s.gate_chi2
        self.min_samples = s.min_samples
        self.dp_min_m = s.dp_min_m
        self.dp_reference_formula = s.dp_reference_formula
        self.baro_geopotential = s.baro_geopotential
        self.remove_bias = s.remove_bias
        self.init_height_from_baro = s.init_height_from_baro
        self.baro_bias_sigma_m = s.baro_bias_sigma_m
        self.use_gnss = s.use_gnss
        self.gnss_sigma_h_m = s.gnss_sigma_h_m
        self.gnss_sigma_v_mps = s.gnss_sigma_v_mps
        self.gnss_correlated_sigma_m = s.gnss_correlated_sigma_m
        self.gnss_gate_chi2 = s.gnss_gate_chi2
        self.gnss_timeout_s = s.gnss_timeout_s
        self._t_gnss = -math.inf        # time of the last GNSS fix used
        self._gnss_up = False           # GNSS fixes arriving (loss reported once gnss_timeout_s passes)
        self._height_initialised = False
        self.integrity = InnovationMonitor(s.integrity_window, s.integrity_alpha)
        self._integrity_extra: dict = {}
        self.recovery_half_cells = s.recovery_half_cells
        self.nominal_half_cells = self.half_cells
        self.recovery_sigma_m = s.recovery_sigma_m
        self._update_extra: dict = {}
        self.kf = KalmanFilter(dim_x=N_ERR, dim_z=2)
        self.health = Health()
        # the fix's MAD surface is summed while the batch fills (tercom.MadAccumulator), not all at the fix
        self.batch = TercomBatch(None if aiding is None or dem is None else
                                 (self.half_cells, self.cell_m, self.remove_bias, self.dem))
        self.fixes: list[TercomFix] = []
        self._t_ekf = np.nan
        self._t_batch0 = np.nan
        self._last_f_b = np.array([0.0, 0.0, -G0])
        self._Q = None
        self._rows = np.empty((0, 6))
        self._baro_cache = None
        self._hist = np.empty((0, 10))
        self._bbuf = np.empty(0)
        self._vbuf = np.empty(0, np.bool_)
        self.fused = True  # False: the step-by-step path (same numbers; kept for tests and fixes)

    # ------------------------------------------------------------------ protocol
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
        if not _is_pd(cov):
            # a perfectly known start (zero sigmas) is positive semi-definite: floor its eigenvalues so the
            # filter's algebra stays defined; a negative eigenvalue is an error
            w, V = np.linalg.eigh(0.5 * (cov + cov.T))
            if w.min() < -1e-9 * max(1.0, float(np.abs(w).max())):
                raise ValueError("initial.covariance must be positive semi-definite (it has a negative "
                                 f"eigenvalue {w.min():.3g})")
            cov = (V * np.maximum(w, 1e-10)) @ V.T
        P[:9, :9] = cov
        P[9:12, 9:12] = np.eye(3) * self.sig_ba**2
        P[12, 12] = self.sig_bg**2
        self.kf.x = np.zeros((N_ERR, 1))
        self.kf.P = P
        self._P_good = P.copy()
        self.health = Health(status="free_inertial" if self.aiding is None else "acquiring")
        self.batch.clear()
        self.fixes = []
        self.integrity.reset()
        self._integrity_extra = {}
        self._set_search(self.nominal_half_cells)
        self._update_extra = {}
        self._t_ekf = float(initial.t_s)
        self._t_batch0 = float(initial.t_s)
        self._height_initialised = False
        self._t_gnss = -math.inf
        self._gnss_up = False

    def update(self, frames: SensorFrames) -> Estimate:
        self.health.events = []
        self._baro_cache = None
        imu = frames.imu
        if imu is None or imu.t_s.size == 0:
            self.health.skip(frames.t_end_s, "no_imu", "no IMU samples in the frame")
            return self.estimate()
        t = np.asarray(imu.t_s, float)
        n = t.size
        gnss = self._gnss_fixes(frames)
        if gnss is None:
            self._gnss_check_loss(float(t[-1]))
            if self._fused_ok(frames, t):
                self._fused_segment(frames, t)
                return self.estimate()
        t_g = gnss[0] if gnss is not None else _EMPTY
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
                g += 1
            a = b
        return self.estimate()

    # ------------------------------------------------------------------ GNSS
    def _gnss_fixes(self, frames: SensorFrames):
        """(t, lat, lon, v_ned) of the frame's valid GNSS fixes in time order, or None."""
        gf = frames.gnss
        if not self.use_gnss or gf is None or gf.t_s.shape[0] == 0:
            return None
        v = np.asarray(gf.v_ned_mps, float).reshape(-1, 3)
        ok = (np.asarray(gf.valid, bool) & np.isfinite(gf.t_s) & np.isfinite(gf.lat_rad)
              & np.isfinite(gf.lon_rad) & np.all(np.isfinite(v), axis=1))
        nbad = int(ok.shape[0] - ok.sum())
        if nbad:
            self._count_skip(float(frames.t_start_s), "gnss_invalid", nbad, f"{nbad} GNSS fixes invalid")
        if not ok.any():
            return None
        order = np.argsort(gf.t_s[ok], kind="stable")
        return (np.asarray(gf.t_s, float)[ok][order], np.asarray(gf.lat_rad, float)[ok][order],
                np.asarray(gf.lon_rad, float)[ok][order], v[ok][order])

    def _gnss_check_loss(self, t_now: float) -> None:
        if self._gnss_up and t_now - self._t_gnss > self.gnss_timeout_s:
            self._gnss_up = False
            on = "the INS and TRN" if self.aiding is not None else "the INS alone"
            self.health.events.append(
                (self._t_gnss, f"GNSS lost: no valid fix after t = {self._t_gnss:.2f} s (navigating on "
                               f"{on})"))
            if self.aiding is None:
                self.health.status = "free_inertial"

    def _gnss_update(self, gnss, i: int) -> None:
        """Loosely coupled GNSS update with fix i (module docstring)."""
        t_g, lat_g, lon_g, v_g = gnss[0][i], gnss[1][i], gnss[2][i], gnss[3][i]
        st = self.ins.state
        lat, lon, h = float(st[0]), float(st[1]), float(st[2])
        z = np.empty((5, 1))
        z[0, 0] = (lat - lat_g) * (meridian_radius_m(lat) + h)     # INS minus GNSS, north (m)
        z[1, 0] = (lon - lon_g) * (prime_vertical_radius_m(lat) + h) * math.cos(lat)
        z[2:, 0] = st[3:6] - v_g
        H = np.zeros((5, N_ERR))
        for r, c in enumerate(_GNSS_STATES):
            H[r, c] = 1.0
        Rm = np.diag([self.gnss_sigma_h_m**2] * 2 + [self.gnss_sigma_v_mps**2] * 3)
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
            d = np.ones(N_ERR)
            for k in (0, 1):
                if 0.0 < P[k, k] < floor2:
                    d[k] = math.sqrt(floor2 / P[k, k])
            P = self.kf.P = P * d[:, None] * d[None, :]
        if not (_is_pd(P) and np.all(np.isfinite(dx))):
            self.kf.x, self.kf.P = saved
            self._count_skip(t_g, "covariance_not_pd", 1,
                             "GNSS fix skipped: covariance not positive definite")
            return
        self.ins.correct(dx[0:3], dx[3:6], dx[6:9])
        self.ins.accel_bias_b += dx[9:12]
        self.ins.gyro_bias_b[2] += dx[12]
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
            ins.state, ins.prev_imu, ins.baro_state, t, imu.f_b_mps2, imu.omega_ib_b_rps, imu.valid,
            tb, hb_raw, vb_raw, self.baro_geopotential, self._vbuf[:nb], self._bbuf[:nb],
            ins.accel_bias_b, ins.gyro_bias_b, tau, GRAVITY_MODELS[ins.gravity_model],
            ins.imu_samples == "interval", self._hist[:n], P, self._Q, self._last_f_b, float(self._t_ekf),
            self.dt_ekf, collect, ts, rng_m, theta, iv, self.ira_decimation,
            kern.FORMULA_CODES.get(self.formula, 1), self._rows)
        t0 = float(t[0])
        if n_baro_bad:
            self._count_skip(t0, "baro_invalid", n_baro_bad, "baro samples invalid")
        ins.bad_imu_samples += int(bad)
        ins.t_s = float(t[-1])
        if bad:
            self._count_skip(t0, "imu_invalid", bad, "IMU samples invalid (held previous)")
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
        if n_ret:
            self._count_skip(t0, "altimeter_no_return", n_ret,
                             f"{n_ret} altimeter samples without a valid return")
        if n_nan:
            self._count_skip(t0, "ira_geometry", n_nan, "IRA samples with no closest-point solution")
        if m:
            self.batch.add_rows(self._rows[:m].copy())

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
        bad0 = self.ins.bad_imu_samples
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
        hist = self.ins.propagate(t_seg, f_seg, w_seg, ok_seg, tb, hb, vb)
        nbad = self.ins.bad_imu_samples - bad0
        if nbad:
            self._count_skip(float(imu.t_s[a]), "imu_invalid", nbad, "IMU samples invalid (held previous)")
        kern.last_good_row(ok_seg, f_seg, self._last_f_b)
        self._predict_to(float(t_seg[-1]), t_seg, f_seg, hist)
        if self.aiding is not None:
            self._collect(frames, t_seg, hist)

    def _process_noise(self, dt: float) -> np.ndarray:
        Q = np.zeros((N_ERR, N_ERR))
        Q[3:6, 3:6] = np.eye(3) * self.q_acc * dt
        Q[6:9, 6:9] = np.eye(3) * self.q_gyr * dt
        Q[9:12, 9:12] = np.eye(3) * (0.01 * self.sig_ba) ** 2 * dt / 3600.0
        Q[12, 12] = (0.01 * self.sig_bg) ** 2 * dt / 3600.0
        Q[2, 2] = 0.01 * dt  # baro noise entering through the loop
        return Q

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
            float(t_imu[0]), float(t_imu[-1]), t_imu, hist, ts, src.range_m, src.look_angle_rad, src.valid,
            self.ira_decimation, tb, hb, have_baro, self.baro_geopotential, kern.FORMULA_CODES[self.formula],
            self._rows)
        t0 = float(t_imu[0])
        if n_bad:
            self._count_skip(t0, "altimeter_no_return", n_bad,
                             f"{n_bad} altimeter samples without a valid return")
        if n_nan:
            self._count_skip(t0, "ira_geometry", n_nan, "IRA samples with no closest-point solution")
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
                    h_ref = R0_GEOPOTENTIAL_M * h_ref / (R0_GEOPOTENTIAL_M - h_ref)
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

    def _fix(self, t_s: float) -> None:
        s = self.batch.samples
        acc = self.batch.accumulator
        self.batch.clear()
        nxt = self._t_batch0 + self.fix_period_s
        self._t_batch0 = nxt if t_s - nxt < self.fix_period_s else t_s
        if s.shape[0] < self.min_samples:
            self._count_skip(t_s, "tercom_too_few_samples", 1, f"TERCOM batch with {s.shape[0]} samples")
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
        if not fix.valid:
            self._count_skip(t_s, f"tercom_{fix.reason}", 1, f"TERCOM fix rejected: {fix.reason}")
            if fix.reason == "edge":      # the best match lies beyond the search window: a failed test
                self._integrity_test(t_s, math.inf, 2)
            return
        z = -np.array([[fix.dn_m], [fix.de_m]])  # INS minus matched position
        H = np.zeros((2, N_ERR))
        H[0, 0] = H[1, 1] = 1.0
        Rm = np.eye(2) * self.fix_sigma_m**2
        S = H @ self.kf.P @ H.T + Rm
        d2 = float((z.T @ np.linalg.solve(S, z))[0, 0])
        gated = not np.isfinite(d2) or d2 > self.gate_chi2
        self._record_innovation(t_s, z, S, d2)
        if gated:
            self._count_skip(t_s, "tercom_gated", 1, f"TERCOM fix failed the chi-square gate ({d2:.1f})")
            return
        saved = copy.deepcopy((self.kf.x, self.kf.P))
        self.kf.update(z, R=Rm, H=H)
        dx = self.kf.x.ravel()
        if not (_is_pd(self.kf.P) and np.all(np.isfinite(dx))):
            self.kf.x, self.kf.P = saved
            self._count_skip(t_s, "covariance_not_pd", 1, "fix skipped: covariance not positive definite")
            return
        self.ins.correct(dx[0:3], dx[3:6], dx[6:9])
        self.ins.accel_bias_b += dx[9:12]
        self.ins.gyro_bias_b[2] += dx[12]
        self.kf.x[:] = 0.0
        if not self.integrity.degraded:
            self.health.ok, self.health.status = True, "ok"
        self.health.events.append(
            (t_s, f"TERCOM fix dn={fix.dn_m:.1f} m de={fix.de_m:.1f} m q={fix.quality:.2f}")
        )

    def _set_search(self, half_cells: int) -> None:
        """TERCOM search half-width (cells) of the batches started from now on."""
        self.half_cells = int(half_cells)
        if self.batch.accumulate is not None:
            self.batch.accumulate = (self.half_cells, self.cell_m, self.remove_bias, self.dem)

    def _record_innovation(self, t_s: float, z: np.ndarray, S: np.ndarray, d2: float) -> None:
        """The fix's innovation under the protocol's EXTRA_* keys; the innovation test and its recovery."""
        sign, logdet = np.linalg.slogdet(2.0 * np.pi * S)
        self._update_extra = {
            EXTRA_INNOVATION: z.ravel().copy(),
            EXTRA_INNOVATION_COV: S.copy(),
            EXTRA_NIS: d2,
            EXTRA_NIS_DOF: 2,
            EXTRA_LOG_LIKELIHOOD: float(-0.5 * (d2 + logdet)) if sign > 0 else float("nan"),
            EXTRA_MEASUREMENT_TIME: float(t_s),
        }
        self._integrity_test(t_s, d2, 2)

    def _integrity_test(self, t_s: float, nis: float, dof: int) -> None:
        """Feed the innovation test; on entering "degraded" recover (covariance inflation, wider search)."""
        verdict = self.integrity.add(t_s, nis, dof)
        self._integrity_extra = verdict.extra()
        if not verdict.changed:
            return
        self.health.events.append((t_s, verdict.message))
        if verdict.degraded:
            self.health.ok, self.health.status = False, "degraded"
            P = self.kf.P
            P[0, 0] += self.recovery_sigma_m**2
            P[1, 1] += self.recovery_sigma_m**2
            self._P_good[:] = P
            self._set_search(self.recovery_half_cells)
            self.health.events.append((t_s, f"recovery: horizontal covariance inflated by "
                                            f"({self.recovery_sigma_m:.0f} m)^2, TERCOM search widened to "
                                            f"+-{self.half_cells} cells"))
        else:
            self.health.ok, self.health.status = True, "ok"
            self._set_search(self.nominal_half_cells)
            self.health.events.append(
                (t_s, f"recovery ended: TERCOM search back to +-{self.half_cells} cells"))

    def _count_skip(self, t_s: float, reason: str, n: int, message: str) -> None:
        self.health.skipped[reason] = self.health.skipped.get(reason, 0) + int(n)
        self.health.events.append((float(t_s), message))

    # ------------------------------------------------------------------ output
    def estimate(self) -> Estimate:
        st = self.ins.state
        roll, pitch, yaw = kern.euler_from_quat(st[6:10])
        P = self.kf.P[:9, :9].copy()
        P[2, 2] += self.baro_bias_sigma_m**2
        sig_h = math.sqrt(max(P[0, 0] + P[1, 1], 0.0))
        if not math.isfinite(float(st.sum())):
            self.health.ok, self.health.status = False, "diverged"
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
        health = Health(
            ok=self.health.ok,
            status=self.health.status,
            skipped=dict(self.health.skipped),
            events=list(self.health.events),
        )
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


def initial_covariance(
    sigma_ne_m: float = 30.0,
    sigma_d_m: float = 15.0,
    sigma_v_mps: float = 0.1,
    sigma_tilt_rad: float = 0.05e-3,
    sigma_yaw_rad: float = 1e-3,
) -> np.ndarray:
    """9 x 9 initial covariance; defaults are seed 000 Table 2's initial errors."""
    return np.diag(
        [sigma_ne_m**2, sigma_ne_m**2, sigma_d_m**2]
        + [sigma_v_mps**2] * 3
        + [sigma_tilt_rad**2, sigma_tilt_rad**2, sigma_yaw_rad**2]
    )
