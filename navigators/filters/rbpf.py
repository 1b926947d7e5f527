"""IRA-aided Rao-Blackwellized (marginalized) particle filter of seed 002 (`rbpf`).

Structure (seed 002 sections II-III): a strapdown INS (navigators.inertial, 50 Hz error-model steps) and the
15-state INS error model of eqs 16-22 (navigators.inertial.error_model_15). The position error is the
particles' nonlinear part x^n (metres north, east, up: eq 17's dL, dlambda scaled by the radii); velocity
error, attitude error and the accelerometer and gyro bias errors (12 states) are each particle's Kalman
filter x^l, P (eqs 1-3). Every TRN epoch (1 Hz, Table 1):

- time update over the interval since the last epoch, eqs 5-8 and 13-15, with the error model's transition
  Phi multiplied up along the INS history and the process noise per epoch (Q^n, Q^l diagonal);
- IRA measurement update (rbpf_ira_update.py): each particle's predicted range (eq 23, the minimum over
  the zero-Doppler line of the INS velocity) and look angle (eq 26), the step-wise linearisation in
  velocity (eq 24) and attitude (eq 25) as its H (navigators.measurements.ira_seed002); weights by eq 9's
  predictive density, Kalman update eqs 10-12. The look angle is dropped (the range alone) where eqs 24-25
  do not describe the sample: a return on the look window's edge (its range rows by differences of eq 23),
  a closest point that can jump to another basin of the zero-Doppler line (by the velocity's tilt of the
  line, within ambiguity_gap_m for ambiguity_weight of the cloud, or by the map's height errors, above
  ambiguity_probability), a look-angle innovation beyond theta_gate_sigmas of the mixture's predictive
  spread on a converged cloud with status "ok" (the map's look-angle error is heavy-tailed), a look angle
  not linear in the velocity over the cloud's velocity spread (theta_linearity_sigmas), or one that would
  leave fewer than theta_collapse_ess * N effective particles on a converged cloud; and at every update
  with the opt-in look_angle = false (the look angle's information, as the map-noise model states it, is
  the one that makes the default mislead on as-published maps: docs/validation/integrity.md, section 6.7);
- progressive correction of that update (rbpf_progressive.py; Oudjane & Musso 2000, Musso, Oudjane & Le
  Gland 2001 sec. 12.5): a measurement sharper than the cloud can sample is applied in stages of noise
  R / lambda_i (shares summing to one, each the largest that keeps the conditional effective sample size
  above ess_threshold * N), the cloud resampled (by the ESS test) and regularised between them, so the whole
  measurement's information is used without collapsing the cloud onto a few ancestors. Tempering (R
  inflated by (spread / acquisition_spread_m)^2, RbpfIraUpdate._r_var_now) discards part of that
  information, so the published covariance is that of a filter which never had it. The default, "spread"
  (whenever the spread exceeds acquisition_spread_m) with the update in one stage, leaves a converged cloud
  on the tactical grade tempered by 2-20x and its covariance about twice its error's; the opt-in
  "acquisition" (before the hand-over, and while a recovery's re-spread cloud re-acquires) with
  progressive_correction makes it consistent there but lets the cloud narrow where a coarse map's errors
  exceed what the likelihood covers, and its protection levels then fail on DTED level 1 (both measured:
  docs/validation/navigators.md), so the defaults keep the spread tempering;
- map errors as measurement noise (ira_seed002.map_noise_variances): the map's error class (map_sigma_m,
  map_bias_sigma_m) and the terrain a coarse map cannot hold between its posts (terrain_model_sigma_m,
  "auto": from the map's spectrum; 0 when the map is the world), calibrated on the map's own error class
  (map_noise_model "calibrated": ira_seed002.map_noise_calibration) at the flight's height above it, to the
  octave of the sample's range (ira_seed002.calibration_height_m: the look angle's error falls with height
  faster than the flat-ground model's 1 / R). The map's bias, and its random error
  when correlated along the ground (map_correlation_length_m), are noise only while GNSS pins the height
  with the opt-in map_error_in_height: once it no longer does, the cloud's up coordinate carries them (no
  barometer: the up is the height above the map's terrain), widened by their variances and then walking
  with the correlated error's rate over the ground flown (`_map_release`), as the point-mass and particle
  filters' vertical offset does. On coarse maps with a tactical IMU it is more accurate than the default but
  misleads hazardously where the default does not, so the default keeps the map's errors as noise
  (measured: docs/validation/integrity.md, section 6.7);
- GNSS, while SensorFrames.gnss has valid fixes (rbpf_cloud.py): position moves the cloud onto the Kalman
  posterior of its moments (a square-root update), the velocity updates each particle's Kalman part;
- systematic resampling when the effective sample size falls below ess_threshold * N, the copies then moved
  by a Gaussian kernel of the cloud's position covariance at the optimal bandwidth, drawn towards the
  cloud's mean first so that its mean and covariance stay (regularisation "shrunk": Musso, Oudjane & Le
  Gland 2001's regularised filter with Liu & West 2001's shrinkage; navigators.core.resampling): with the
  position's small process noise (seed 002 sec. II-A) the copies of one ancestor otherwise stay stacked,
  and the next updates weigh a few distinct positions, whose spread falls faster than the posterior's (not
  while a recovery's re-spread cloud re-acquires: RbpfCloud._regularise);
- acquisition (our addition): the cloud starts with acquisition_particles and is resampled down to
  n_particles (Table 1's 1,000) once its horizontal spread is below acquisition_spread_m (regularised as a
  resampling), so the Kalman parts after the first sharp updates do not all descend from a few survivors;
- feedback: the weighted mean error is corrected into the INS (position, velocity, attitude, biases) and
  subtracted from every particle, so the error model stays linear about a good INS.

Estimate: the corrected INS; covariance: the mixture's 9 x 9 (position from the cloud, the rest from the
Kalman parts, cross terms included) at the last epoch, its down variance at least the height's error
variance where the map has a vertical error model (the IRA pins the height to the map, whose error stays
in it: height_error, fed by `_height_update`), and its horizontal block plus the share of the map's
horizontal shift the mean took on where map_horizontal_sigma_m is given (map_shift, from the mean's own
response to each IRA update: `_shift_response`; a GNSS fix takes the share into its prior and restarts
it). Estimate.extra after an IRA update: the fixed keys of
navigators.protocol (innovation and its covariance from the mixture's predictive moments, NIS with 2 dof,
log-likelihood log sum w p(y | particle), ESS before resampling).

Prior: initial.covariance (prior_from_initial, default); otherwise, and for the bias states always, the
settings. Defaults are seed 002 Table 1 (table1_covariance() states its initial distribution for an
Estimate). Table 1's u2 row lists five numbers for twelve states; we read them as (horizontal velocity,
vertical velocity, attitude, accelerometer bias, gyro bias); Table 1 gives no gyro bias prior (ours:
gyro_bias_sigma_rps). Two process-noise defaults depart from Table 1, vertical velocity (q_vel_mps[1]) and
horizontal position (q_pos_m[:2]): without a barometer the vertical velocity is seen only through the
range and the tilt of the zero-Doppler plane (eq 24), which moves the closest point along track by
R dv_d / V, so along-track position and vertical velocity trade in the measurement. In a scenario the
bias priors and the biases' process noise come from the IMU's specification (trn_env's build_navigator:
navigators.core.imu_spec, the turn-on bias and instability of the grade; the instability's Gauss-Markov
drive per epoch). No barometer (seed 002: IMU and IRA only): the INS vertical channel is free and the filter
estimates it. The measured history of these choices: docs/validation/navigators.md.

At run time it never raises: a NaN or invalid IRA sample is skipped, particles whose hypothesis has no
return (off the map) get zero weight; if every weight vanishes the cloud is re-initialised around the INS
with the prior spread; each is counted in Health (status "degraded") with an event.
Integrity (navigators.integrity.InnovationMonitor): each IRA update's NIS (2 dof; a sample every particle
rejects counts as infinite; capped as navigators.core.recovery.capped_nis) enters a window of integrity_window
updates; when the sum leaves its chi-square band (probability integrity_alpha) Health says "degraded" (ok
False) and the particles' positions are re-spread (resampled, then N(0, recovery_sigma_m^2) added
horizontally), both logged; a whole window still out of band after a re-spread re-spreads again, twice as
wide (up to 8 x); back in band the status is "acquiring" until the cloud's spread is below 30 m ("ok").
With recovery_reset_kalman (default) a re-spread also gives every particle's velocity-attitude block the
prior's covariance plus the cloud's mixture covariance (cross terms with the biases zeroed): the test says
the whole belief is overconfident.
Randomness: only from `rng` (the scenario's navigator stream), so one seed fixes a run bit for bit.
"""

from __future__ import annotations

import math

import numpy as np

from ...terrain.geodesy import meridian_radius_m, prime_vertical_radius_m
from ..core.capture import capture_spec, rbpf_capture_guard, rbpf_capture_skips
from ..core.imu_spec import ImuSpec, TurnAngle
from ..core.ins_gnss import InsGnssBlock, gnss_fixes
from ..core.maps import load_map
from ..core.measured_consistency import grade_warning
from ..core.recovery import IntegrityRecovery
from ..core.settings import SettingsError
from ..frames import SensorFrames
from ..inertial.error_model_15 import transition_over_history
from ..inertial.strapdown import StrapdownIns, euler_from_C_bn, quat_to_dcm
from ..integrity import protection_level as pl
from ..integrity.innovation_monitor import InnovationMonitor
from ..measurements import ira_seed002 as ira_model
from ..measurements.sampling import ira_epochs
from ..protocol import (
    Estimate,
    Health,
)
from . import _rbpf_kernels as kern
from . import rbpf_progressive as prog
from ._ekf_kernels import yaw_total_variation
from .height_error import HeightError, map_walk_variance_per_m
from .map_shift import MapShiftShare
from .rbpf_cloud import RbpfCloud
from .rbpf_ira_update import RbpfIraUpdate
from .rbpf_settings import CAPABILITIES, MAX_PARTICLES, RbpfSettings, table1_covariance

_BYTES_PER_PARTICLE = 8 * (3 + 12 + 144) * 3
TURN_REFERENCE_RAD = 0.5 * math.pi  # a turn of this angle builds the whole scale-factor / misalignment error
# attitude-error memory of the small-angle check (imu_spec.consistency_warning): the time the gyro biases
# build attitude error before the look angle has observed them (acquisition on the default route ~100 s)
RBPF_MEMORY_S = 120.0


class RaoBlackwellizedPF(RbpfIraUpdate, RbpfCloud, InsGnssBlock):
    """Seed 002's IRA-aided RBPF; see the module docstring. Settings (SI, 1 sigma):

    dem: the navigator's map (terrain.Dem or a name for terrain.load), required. rng: numpy Generator
    (None: default_rng(0)). n_particles; ess_threshold in (0, 1]; trn_rate_hz; error_model_rate_hz (the
    error model's step, 50 Hz); range_sigma_m, look_angle_sigma_deg; half_window_deg, max_range_m (the IRA's
    look window, as the sensor's); search_step_m ("auto" or m: eq 23's coarse-scan step along the
    zero-Doppler line, ira_seed002.search_step_for: 45 m, finer on maps with posts under 72 m);
    window_edge_margin_deg (an IRA sample whose look angle lies within this of
    the window's edge is not an interior minimum, which eqs 24-25 describe), window_edge_range (True: such a
    sample updates on its range, rows by differences, _edge_range_row; False: skipped);
    theta_linearity_sigmas (the range alone when theta's departure from its velocity row over the cloud's
    velocity spread exceeds this many look-angle sigmas; 0: off), theta_collapse_ess in [0, 1) (the range
    alone when the look angle would leave fewer effective particles than this fraction of a converged cloud;
    0: off); theta_gate_sigmas (the range alone when the look angle's innovation exceeds this many sigmas
    of the mixture's predictive spread; 0: off); init_pos_sigma_m (N, E, up),
    init_vel_sigma_mps, init_att_sigma_deg,
    accel_bias_sigma_mps2, gyro_bias_sigma_rps; map_sigma_m, map_bias_sigma_m (the map's random and bias
    vertical error, m), terrain_model_sigma_m ("auto" or m: the map's interpolation error),
    map_noise_model ("calibrated" | "flat_ground", see ira_seed002.map_noise_variances),
    terrain_detail_spacing_m ("auto": the map's smaller post spacing / 3, or m: the finest terrain the
    calibration assumes below the posts; the scenario passes its world's refinement spacing), see
    _r_var_now; acquisition_spread_m (see _r_var_now); q_pos_m (3), q_vel_mps (horizontal, vertical),
    q_att_rad, q_accel_bias_mps2, q_gyro_bias_rps (per TRN epoch); gnss_pos_sigma_m (white, horizontal,
    vertical), gnss_pos_bias_sigma_m (the receiver's drift: a floor on the fused position),
    gnss_vel_sigma_mps;
    acquisition_particles (0: off; see the module docstring); theta_velocity_rows (add the look angle's
    sensitivity to velocity, left out of eq 23, by central differences at the cloud's mean, see
    _theta_velocity_row); ambiguity_gap_m, ambiguity_weight (range-only updates, module docstring);
    ambiguity_probability in [0, 1] (the range alone when the map's errors would move the closest point to
    another basin with more than this probability, _basin_jump_probability; 0.05); prior_from_initial (the
    cloud's and Kalman parts' prior from reset's initial.covariance, _set_prior; False: the init_* settings);
    imu_samples ("interval" | "instant"); gravity_gradient (error model, see
    error_model_15); integrity_window, integrity_alpha, recovery_sigma_m, recovery_reset_kalman (the
    innovation test and its recovery, see the module docstring); turn_angle ("excursion" | "total": the
    angle the turn terms of apply_imu_spec run in, _epoch_ql_var); regularisation ("shrunk" | "gaussian" |
    "none": the resampled copies' kernel, module docstring and RbpfCloud._regularise); tempering ("none" |
    "acquisition" | "spread": when _r_var_now inflates the IRA variances), progressive_correction (the IRA
    update in stages, rbpf_progressive).
    """

    capabilities = CAPABILITIES
    settings_class = RbpfSettings            # what `trn-env navigators` lists as its settings
    integrity_risk = pl.DEFAULT_INTEGRITY_RISK   # per epoch, for the published HPL (registry sets it)
    map_horizontal_sigma_m = 0.0                 # the map's horizontal error in the HPL (registry sets it)

    def __init__(self, dem=None, rng: np.random.Generator | None = None, settings: RbpfSettings | None = None,
                 name: str = "rbpf", **overrides):
        s = self.settings = RbpfSettings.build(settings, overrides)
        dem = load_map(dem, "the RBPF")
        if rng is not None and not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator or None, got {type(rng).__name__}")
        self.name = name
        self.dem = dem
        self.rng = rng if rng is not None else np.random.default_rng(0)
        s.copy_to(self, "n_particles ess_threshold map_sigma_m map_bias_sigma_m map_correlation_length_m "
                        "map_correlation_function map_noise_model "
                        "window_edge_range theta_velocity_rows ambiguity_gap_m ambiguity_weight "
                        "ambiguity_probability prior_from_initial theta_linearity_sigmas theta_collapse_ess "
                        "theta_gate_sigmas max_range_m gravity_gradient acquisition_spread_m "
                        "recovery_sigma_m recovery_reset_kalman turn_angle regularisation tempering "
                        "progressive_correction map_error_in_height look_angle")
        self.n_acquisition = max(s.acquisition_particles, self.n_particles)
        self.n = self.n_particles          # the cloud's current size
        self.trn_period_s = 1.0 / s.trn_rate_hz
        self.dt_err = 1.0 / s.error_model_rate_hz
        # the sensor's own noise; the map's errors are added per epoch (_r_var_now, map_noise_variances)
        self.r_var = np.array([s.range_sigma_m ** 2, math.radians(s.look_angle_sigma_deg) ** 2])
        # the map's vertical error (its error class, as the scenario's map error model states it) and the
        # terrain the map cannot hold between its posts (interpolation error): measurement noise the filter
        # knows about (ira_seed002.map_noise_variances)
        self.terrain_model_sigma_m = (ira_model.interpolation_sigma_m(dem)
                                      if s.terrain_model_sigma_m == "auto" else s.terrain_model_sigma_m)
        detail = s.terrain_detail_spacing_m
        self.terrain_detail_spacing_m = float(min(dem.spacing_m)) / 3.0 if detail == "auto" else detail
        # the calibration refines a <= 16 km square of the map to this spacing: finer than the posts, and
        # not so fine that the refinement's memory (~40 bytes per post) runs away
        if not 5.0 <= self.terrain_detail_spacing_m < min(dem.spacing_m):
            raise SettingsError([("terrain_detail_spacing_m", f"must lie in [5, {min(dem.spacing_m):.1f}) m "
                                  f"(finer than the map's posts), got {s.terrain_detail_spacing_m!r}")])
        self._terrain_factors: dict = {}   # map_noise_calibration's per height, computed when first used
        self.half_window_rad = math.radians(s.half_window_deg)
        self.edge_margin_rad = math.radians(s.window_edge_margin_deg)
        self.search_step_m = (ira_model.search_step_for(dem) if s.search_step_m == "auto"
                              else s.search_step_m)
        self.init_pos_sigma = np.array(s.init_pos_sigma_m)
        sv = np.array(s.init_vel_sigma_mps)
        sa = np.radians(np.array(s.init_att_sigma_deg))
        self.P0_settings = np.diag(np.r_[sv, sa, [s.accel_bias_sigma_mps2] * 3,
                                         [s.gyro_bias_sigma_rps] * 3] ** 2)
        self.P0 = self.P0_settings.copy()
        self.init_pos_sigma_settings = self.init_pos_sigma.copy()
        self.qn_var = np.array(s.q_pos_m) ** 2
        qv = s.q_vel_mps
        self.ql_var = np.r_[qv[0], qv[0], qv[1], [s.q_att_rad] * 3, [s.q_accel_bias_mps2] * 3,
                            [s.q_gyro_bias_rps] * 3] ** 2
        gp = s.gnss_pos_sigma_m
        self.gnss_pos_var = np.array([gp[0], gp[0], gp[1]]) ** 2
        gb = s.gnss_pos_bias_sigma_m
        self.gnss_bias_var = np.array([gb[0], gb[0], gb[1]]) ** 2
        self.gnss_vel_var = np.full(3, s.gnss_vel_sigma_mps) ** 2
        self.ins = StrapdownIns("j2", tau_baro_s=None, imu_samples=s.imu_samples)
        self.integrity = InnovationMonitor(s.integrity_window, s.integrity_alpha)
        self.recoveries = 0
        # log N at OUTLIER_SIGMA for the inflated-at-most-100x variances (2 dof): the rejection floor
        self.health = Health()
        self._reset_done = False

    # ------------------------------------------------------------------ IMU specification
    _turn_att_var = np.zeros(3)  # attitude variance per rad turned (n, e: gyro misalignment; d: scale factor)
    _yaw_prev = math.nan
    _turn_pending = 0.0          # integral of |yaw rate| since the last epoch (rad)

    def apply_imu_spec(self, spec: ImuSpec) -> None:
        """The Kalman parts' process noise and accelerometer-bias prior from the IMU's specification
        (navigators.core.imu_spec), each a floor over the setting: per TRN epoch T the velocity noise the
        velocity random walk N_a sqrt(T) and the attitude noise the angle random walk N_g sqrt(T) (Q of white
        specific-force and rate noise over T, Titterton & Weston 2004 sec. 12.6; seed 002 Table 1 gives
        these per epoch), the x / y accelerometer-bias prior the body-fixed horizontal specific-force error
        (bias, instability and misalignment x g: in level flight the misalignment reads gravity as a
        constant body-frame bias), and per rad turned the gyro misalignment (tilt) and scale factor (heading)
        over TURN_REFERENCE_RAD (the angle: _epoch_ql_var). The bias priors and drives themselves arrive as
        settings (trn_env's imu_bias_settings). Its 15-state model is a small-angle one (eqs 16-22): a
        grade whose gyro biases build more than imu_spec.SMALL_ANGLE_LIMIT_RAD over RBPF_MEMORY_S sets the
        Health warning."""
        root_t = math.sqrt(self.trn_period_s)
        q = np.sqrt(self.ql_var)
        q[0:3] = np.maximum(q[0:3], spec.accel_noise_density_mps2_rthz * root_t)
        q[3:6] = np.maximum(q[3:6], spec.gyro_noise_density_rps_rthz * root_t)
        self.ql_var = q ** 2
        for i in (6, 7):
            self.P0_settings[i, i] = max(self.P0_settings[i, i], spec.body_accel_sigma_mps2 ** 2)
        tilt2, heading2 = spec.turn_tilt_sigma_rad(1.0) ** 2, spec.turn_heading_sigma_rad(1.0) ** 2
        self._turn_att_var = np.array([tilt2, tilt2, heading2]) * TURN_REFERENCE_RAD
        self._consistency_warning = grade_warning(spec, RBPF_MEMORY_S, self.name, capture=True)
        self._capture_spec = capture_spec(spec, RBPF_MEMORY_S, self.name)  # navigators.core.capture

    def _epoch_ql_var(self) -> np.ndarray:
        """The Kalman parts' process noise over this epoch: ql_var plus the attitude variance the INS's turn
        builds (apply_imu_spec), per rad of the angle turn_angle names: "excursion" (default), the growth of
        the net heading change since the reset (navigators.core.imu_spec.TurnAngle), as the heading's
        back-and-forth on a straight leg undoes its own misalignment and scale-factor error; "total", the
        integral of |yaw rate| over the IMU samples since the last epoch (`_propagate`: it does not depend
        on the rate)."""
        turn, self._turn_pending = self._turn_pending, 0.0
        if not self._turn_att_var.any():
            return self.ql_var
        if self.turn_angle == "excursion":
            C = quat_to_dcm(self.ins.state[6:10])
            turn = self._turn_angle.advance(math.atan2(C[1, 0], C[0, 0]))
        if turn == 0.0:
            return self.ql_var
        ql = self.ql_var.copy()
        ql[3:6] += self._turn_att_var * turn
        return ql

    # ------------------------------------------------------------------ protocol
    def reset(self, initial: Estimate) -> None:
        self._yaw_prev = math.nan
        self._turn_pending = 0.0
        self._turn_angle = TurnAngle(self.turn_angle)
        self._reacquiring = False
        self.ins.reset(initial.t_s, initial.lat_rad, initial.lon_rad, initial.h_m, initial.v_ned_mps,
                       initial.roll_rad, initial.pitch_rad, initial.yaw_rad)
        self._set_prior(initial)
        self._init_cloud()
        self.health = Health(status="acquiring", ok=True)
        self.integrity.reset()
        self.recoveries = 0
        self._recovery = IntegrityRecovery(self.integrity, self.recovery_sigma_m)
        self._integrity_extra: dict = {}
        self._t_next = float(initial.t_s) + self.trn_period_s
        self._t_gnss_next = float(initial.t_s)
        self._Phi = np.eye(15)
        self._pl_B = None          # eq 5's position rows of B at the last time update (_mixture_hpl)
        self._last_row = None          # INS row and specific force carried into the next chunk
        self._extra: dict = {}
        self._cov9 = self._covariance9()
        self._map_shift = MapShiftShare()   # the INS's error is independent of the map's shift (map_shift)
        # the published height's error with the map's (height_error): the cloud's prior height spread is the
        # INS's; the map's random error counts as correlated only with a correlation length
        var_corr = self.map_sigma_m ** 2 if self.map_correlation_length_m > 0.0 else 0.0
        self._height = HeightError(float(self._cov9[2, 2]), 0.0, 0.0, self.map_bias_sigma_m ** 2, var_corr,
                                   self.map_correlation_length_m, self.map_correlation_function)
        self._height_t = float(initial.t_s)
        # the map's vertical errors in the cloud's up coordinate once GNSS no longer pins it (_map_release)
        self._map_walk_var_per_m = map_walk_variance_per_m(self.map_sigma_m, self.map_correlation_length_m,
                                                           self.map_correlation_function)
        self._map_released = False
        self._map_walk_t = float(initial.t_s)
        self._t_fix_last = -math.inf
        self._fix_interval_s = self.trn_period_s
        self._n_rejected = 0
        self._last_range_m = -1.0
        self.epochs = 0
        self.resamples = 0
        self._capture = rbpf_capture_guard(self, initial)    # navigators.core.capture
        self._reset_done = True

    def update(self, frames: SensorFrames) -> Estimate:
        if not self._reset_done:
            raise RuntimeError("RaoBlackwellizedPF.update before reset")
        self.health.events = []
        t = self._imu_times(frames)
        if t is None:
            return self.estimate().extrapolated(frames.t_end_s)
        imu = frames.imu
        f_b = np.asarray(imu.f_b_mps2, float)
        w_b = np.asarray(imu.omega_ib_b_rps, float)
        ok = np.asarray(imu.valid, bool)
        epochs = self._epochs_in(frames, t)
        a = 0
        n = t.shape[0]
        for t_ep, y_ira, gnss in epochs:
            b = int(np.searchsorted(t, t_ep, side="right"))
            if b > a:
                self._propagate(t[a:b], f_b[a:b], w_b[a:b], ok[a:b])
                a = b
            self._epoch(t_ep, y_ira, gnss)
        if a < n:
            self._propagate(t[a:], f_b[a:], w_b[a:], ok[a:])
        return self.estimate()

    # ------------------------------------------------------------------ internals
    def _epochs_in(self, frames: SensorFrames, t: np.ndarray) -> list:
        """(time, (R, theta) or None, gnss tuple or None) of the TRN epochs falling in this frame: the
        first valid IRA sample at or after each due time (GNSS: the fix nearest it, while available;
        navigators.measurements.sampling.ira_epochs)."""
        gnss = gnss_fixes(frames.gnss, need_height=True, need_velocity=True)   # (navigators.core.ins_gnss)
        out, self._t_next, n_bad = ira_epochs(frames.ira, gnss, float(t[-1]), self._t_next, self.trn_period_s)
        if n_bad:
            self.health.skip(float(frames.ira.t_s[0]), "ira_invalid", f"{n_bad} IRA samples invalid or NaN")
            self.health.skipped["ira_invalid"] += n_bad - 1
        return out

    def _propagate(self, t, f_b, w_b, ok) -> None:
        hist = self._strapdown(t, f_b, w_b, ok)      # (navigators.core.ins_gnss)
        if self._turn_att_var.any():
            turn, self._yaw_prev = yaw_total_variation(hist, self._yaw_prev)
            self._turn_pending += turn
        # error-model transition over this stretch at the error model's rate (eq 16 discretised)
        dt_imu = (float(t[-1] - t[0]) / (t.shape[0] - 1)) if t.shape[0] > 1 else self.dt_err
        stride = max(int(round(self.dt_err / max(dt_imu, 1e-6))), 1)
        fb = np.where(np.isfinite(f_b), f_b, 0.0)
        rows = np.arange(0, t.shape[0], stride)
        if rows.shape[0]:
            dt = t.shape[0] * dt_imu / rows.shape[0]     # the stretch's n IMU intervals over the rows
            Phi = transition_over_history(hist[rows], fb[rows], self.ins.accel_bias_b, 0, rows.shape[0], dt,
                                          self.gravity_gradient)
            if np.all(np.isfinite(Phi)):
                self._Phi = Phi @ self._Phi

    def _metric_scale(self) -> np.ndarray:
        lat, h = self.ins.state[0], self.ins.state[2]
        return np.array([meridian_radius_m(lat) + h, (prime_vertical_radius_m(lat) + h) * math.cos(lat), 1.0])

    def _ins_at(self, te: float):
        """INS position at te (the last INS sample time may trail te by < 1 IMU step: dead-reckoned)."""
        st = self.ins.state
        dt = te - self.ins.t_s
        sc = self._metric_scale()
        v = st[3:6]
        return (st[0] + v[0] * dt / sc[0], st[1] + v[1] * dt / sc[1], st[2] - v[2] * dt, v.copy(),
                quat_to_dcm(st[6:10]))

    def _epoch(self, te: float, y_ira, gnss) -> None:
        # beyond capture (navigators.core.capture): the epoch skipped
        if rbpf_capture_skips(self, te, gnss,
                              lambda: kern.moments(self.xn, self.xl, self.P, self._weights())[1]):
            return
        self.epochs += 1
        q_map = self._map_release(te, gnss)
        # ---- time update (eqs 5-8, 13-15) in metric position units
        T = np.ones(15)
        T[:3] = self._metric_scale()
        Phi = self._Phi * T[:, None] / T[None, :]
        self._Phi = np.eye(15)
        w = self.rng.standard_normal((self.n, 3))
        self._pl_B = Phi[:2, 3:].copy()     # position rows of eq 5's B, for the HPL's mixture (estimate)
        qn_var = self.qn_var if q_map == 0.0 else self.qn_var + np.array([0.0, 0.0, q_map])
        nbad = kern.time_update(self.xn, self.xl, self.P, np.ascontiguousarray(Phi), qn_var,
                                self._epoch_ql_var(), w)
        if nbad:
            self.health.skip(te, "time_update_not_pd", f"{nbad} particles: N not positive definite")
        up_var = self._height_step(te, q_map) if self._height.active else 0.0
        logw_prev = self.logw.copy()
        updated = False
        ll = np.empty(self.n)
        lat, lon, h, v, C = self._ins_at(te)
        sc = self._metric_scale()
        if y_ira is not None:
            self._gnss_now = gnss is not None
            self._share_left = 1.0
            updated = self._ira_update(te, y_ira, lat, lon, h, v, C, sc, logw_prev, ll)
            stage = 1
            # progressive correction (rbpf_progressive): the rest of the measurement's information in further
            # stages, the cloud resampled and regularised before each when its ESS is below the threshold
            while updated and self._share_left > 0.0:
                if stage >= prog.MAX_STAGES:
                    sk = self.health.skipped
                    sk["ira_progressive_cap"] = sk.get("ira_progressive_cap", 0) + 1
                    break
                self._normalise_resample(te, logw_prev)
                ll = np.empty(self.n)
                self._ira_update(te, y_ira, lat, lon, h, v, C, sc, self.logw.copy(), ll, stage)
                stage += 1
            if updated and self._height.active:
                up_var = self._height_update(up_var, self._height.terrain)
        if gnss is not None:
            if ll.shape[0] != self.n:       # the IRA update re-initialised the cloud (another size)
                ll = np.empty(self.n)
            self._gnss_update(te, gnss, lat, lon, h, v, sc, ll)
            updated = True
            if self._height.active:
                self._height_update(up_var, self._height.gnss)
        if updated:
            self._normalise_resample(te, logw_prev)
            self._handover()
        self._feedback()
        self._cov9 = self._covariance9()
        if self.integrity.degraded:
            self.health.status, self.health.ok = "degraded", False
        elif updated and self.health.status == "acquiring":
            sig = math.sqrt(max(self._cov9[0, 0] + self._cov9[1, 1], 0.0))
            if sig < 30.0:
                self.health.status = "ok"
                self._reacquiring = False

    def _up_var(self) -> float:
        return float(kern.moments(self.xn, self.xl, self.P, self._weights())[1][2, 2])

    def _map_release(self, te: float, gnss) -> float:
        """Up variance (m^2) the map's vertical errors add to the cloud at this epoch's time update. While
        GNSS pins the height they are measurement noise (_r_var_now). Once no fix has come for 1.5 fix
        intervals (at least one epoch), the up coordinate carries them instead, as the point-mass and particle
        filters' vertical offset does (terrain_filter): the terrain samples then see the INS height's
        error plus the map's bias and correlated error, a slowly wandering offset that successive samples
        share and cannot average away (taken as white noise, a correlated error is counted once per sample:
        the cloud narrows onto the map's error; tempered instead, the filter discards the terrain's shape
        along with it). At the release the up is widened by the bias's and the correlated error's variances
        (the map's offset there is unknown to a height GNSS pinned); afterwards it walks with the correlated
        error's variance rate over the ground flown (height_error.map_walk_variance_per_m, Schmidt-style
        augmentation of a coloured measurement error). 0 without a map error model or without
        map_error_in_height (the default: the map's random error stays noise throughout, its bias while a
        fix is at hand)."""
        if not self.map_error_in_height:
            return 0.0
        if gnss is not None:
            t_fix = float(gnss[0])
            if math.isfinite(self._t_fix_last) and t_fix > self._t_fix_last:
                self._fix_interval_s = t_fix - self._t_fix_last
            self._t_fix_last = t_fix
            self._map_released = False
            self._map_walk_t = te
            return 0.0
        var_corr = self.map_sigma_m ** 2 if self.map_correlation_length_m > 0.0 else 0.0
        var_release = self.map_bias_sigma_m ** 2 + var_corr
        if not var_release > 0.0:
            return 0.0
        q = 0.0
        if self._map_released:
            st = self.ins.state
            speed = math.hypot(float(st[3]), float(st[4])) if np.all(np.isfinite(st[3:5])) else 0.0
            q = self._map_walk_var_per_m * speed * max(te - self._map_walk_t, 0.0)
        elif te - self._t_fix_last > max(1.5 * self._fix_interval_s, self.trn_period_s):
            self._map_released = True
            q = var_release
        self._map_walk_t = te
        return q

    def _height_step(self, te: float, q_map: float = 0.0) -> float:
        """The height's error model over the time update (height_error): the cloud's height spread grown
        about the INS (less q_map, the map's share the up coordinate took on: _map_release), the map's
        correlated error decorrelated over the ground flown. Returns the spread."""
        up_var = self._up_var()
        self._height.widen(up_var - float(self._cov9[2, 2]) - q_map)
        st = self.ins.state
        speed = math.hypot(float(st[3]), float(st[4])) if np.all(np.isfinite(st[3:5])) else 0.0
        self._height.step(0.0, speed * max(te - self._height_t, 0.0))
        self._height_t = te
        return up_var

    def _height_update(self, up_var_before: float, update) -> float:
        """An update that narrowed the cloud's height spread from up_var_before to the current one, as the
        scalar Kalman update that narrows it so: gain K = 1 - after / before, noise r = before * after /
        (before - after) (height_error: a terrain sample moves the height's error by -K times the map's, a
        GNSS height does not). Returns the spread after."""
        after = self._up_var()
        if 0.0 < after < up_var_before:
            update(1.0 - after / up_var_before, up_var_before * after / (up_var_before - after))
        elif after > up_var_before:
            self._height.widen(after - up_var_before)
        return after

    def _covariance9(self) -> np.ndarray:
        w = self._weights()
        _, C15 = kern.moments(self.xn, self.xl, self.P, w)
        C = C15[:9, :9].copy()
        s = np.ones(9)
        s[2] = -1.0           # up -> down
        return C * s[:, None] * s[None, :]

    # ------------------------------------------------------------------ output
    def estimate(self) -> Estimate:
        st = self.ins.state
        roll, pitch, yaw = euler_from_C_bn(quat_to_dcm(st[6:10]))
        if not np.all(np.isfinite(st)):
            self.health.ok, self.health.status = False, "diverged"
        extra = dict(self._extra)
        extra.update(self._integrity_extra)
        sig_ba = np.sqrt(np.einsum("k,kii->i", self._weights(), self.P[:, 6:9, 6:9]))
        extra.update(accel_bias_b_mps2=self.ins.accel_bias_b.copy(),
                     gyro_bias_b_rps=self.ins.gyro_bias_b.copy(),
                     accel_bias_sigma_mps2=sig_ba,
                     position_spread_m=np.sqrt(np.clip(np.diag(self._cov9)[:3], 0, None)))
        if self._capture.suspended:
            pl.publish(extra, pl.gaussian_hpl(self._capture.published_covariance(float(self.ins.t_s)),
                                              pl.filter_risk(self)), self)
        else:
            pl.publish(extra, self._mixture_hpl(pl.filter_risk(self)), self)
        health = self.health.snapshot(self._consistency_warning, self._recovery.consistency)
        cov9 = self._cov9
        if self._height.active and self._height.var_e > cov9[2, 2]:    # the height keeps the map's error
            cov9 = cov9.copy()
            cov9[2, 2] = self._height.var_e
        if self.map_horizontal_sigma_m > 0.0:     # and the position the share of its shift (map_shift)
            cov9 = cov9.copy()
            cov9[:2, :2] += self._map_shift.covariance(self.map_horizontal_sigma_m)
        return Estimate(t_s=self.ins.t_s, lat_rad=float(st[0]), lon_rad=float(st[1]), h_m=float(st[2]),
                        v_ned_mps=st[3:6].copy(), roll_rad=roll, pitch_rad=pitch, yaw_rad=yaw,
                        covariance=self._capture.publish(cov9, float(self.ins.t_s)), health=health,
                        extra=extra)


__all__ = ["MAX_PARTICLES", "RaoBlackwellizedPF", "table1_covariance"]
