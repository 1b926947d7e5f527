"""IRA-aided Rao-Blackwellized (marginalized) particle filter of seed 002 (`rbpf`).

Structure (seed 002 sections II-III): a strapdown INS (navigators.inertial, 50 Hz error-model steps) and the
15-state INS error model of eqs 16-22 (navigators.inertial.error_model_15). The position error is the
particles' nonlinear part x^n (here in metres north, east, up: eq 17's dL, dlambda scaled by the radii);
velocity error, attitude error and the accelerometer and gyro bias errors (12 states) are each particle's
Kalman filter x^l, P (eqs 1-3). Every TRN epoch (1 Hz, Table 1):

- time update over the interval since the last epoch, eqs 5-8 and 13-15, with the error model's transition
  Phi multiplied up along the INS history and Table 1's process noise per epoch (Q^n, Q^l diagonal);
- IRA measurement update at the IRA sample of the epoch: each particle's predicted range (eq 23, the
  minimum over the zero-Doppler line of the INS velocity) and look angle (eq 26) from its position, and the
  step-wise linearisation in velocity (eq 24) and attitude (eq 25) as its H
  (navigators.measurements.ira_seed002); weights by eq 9's predictive density, Kalman update eqs 10-12;
- GNSS, while SensorFrames.gnss has valid fixes: position moves the cloud onto the Kalman posterior of its
  moments (a square-root update, _gnss_update: weighting 1,000 particles by a 2 m fix would keep about one),
  the velocity updates each particle's Kalman part; TRN carries on alone when GNSS is denied;
- map errors as measurement noise (ira_seed002.map_noise_variances): the map's error class (map_sigma_m,
  map_bias_sigma_m, from the scenario's map error model) and the terrain a coarse map cannot hold between
  its posts (terrain_model_sigma_m, "auto": from the map's spectrum; 0 when the map is the world), whose
  flat-ground range and look-angle variances are calibrated on the map's own error class
  (map_noise_model "calibrated": ira_seed002.map_noise_calibration, refinements of the map down to
  terrain_detail_spacing_m; the flat-ground model overstated them, NEES 1.71 on the default route's 3" map
  over 60 seeds, 1.89 calibrated with the look-angle gate below, README "RBPF");
- systematic resampling when the effective sample size falls below ess_threshold * N;
- acquisition (our addition): the cloud starts with acquisition_particles (5,000) and is resampled down to
  n_particles (Table 1's 1,000) once its horizontal spread is below acquisition_spread_m. 1,000 particles
  over Table 1's 50 x 50 x 20 m prior keep a few survivors after the first sharp updates, whose Kalman parts
  then carry one sampled position path's information about velocity and attitude (eq 6's L(z - F^n x^l)
  term): on the seed002 straight leg the attitude NEES was 30 and the velocity error 2-4 sigma; with
  5,000 during acquisition it is as with 5,000 throughout (3-D position 3.2 m against 5.6 m);
- IRA samples eqs 24-25 cannot describe (our additions): a return on the look window's edge
  (window_edge_margin_deg: the window's boundary ray, not the terrain's minimum, fixed the point; in a 45-deg
  bank 29 % of samples) updates on the range alone, its velocity and attitude rows by differences of eq 23
  (window_edge_range; False skips it); when a point of the zero-Doppler line 68 m or more across track from
  the closest one (another basin, or the far side of a flat minimum) lies within ambiguity_gap_m of its range
  for particles holding ambiguity_weight of the cloud, the closest point can jump (a few tenths of m/s of
  velocity error tilt the line enough) and theta with it by degrees, so the update uses the range alone
  (continuous across the jump); on the default route this was the cause of the overconfidence on long
  stretches (pooled NEES 4.0 -> 1.9 on seeds 0-2, rbpf_consistency.py). The same jump made by the map
  (its height errors close the runner-up's gap: _basin_jump_probability, above ambiguity_probability) uses
  the range alone too: on a coarse map these jumps (13 deg at 2 m gap) were the overconfident episodes of
  the default route. The range alone where the look angle's innovation exceeds theta_gate_sigmas (3) of the
  mixture's predictive spread on a converged cloud with status "ok" (the map's look-angle error is
  heavy-tailed; map_noise_calibration trims the same tail). The range alone too where theta is
  not linear in the velocity over the cloud's velocity spread (theta_linearity_sigmas, _theta_velocity_row),
  and where, on a converged cloud, the look angle would leave fewer than theta_collapse_ess * N effective
  particles (theta then varies with position faster than the cloud samples it: at wings level in a roll
  reversal on the seed002 flight it left 4 of 1,000, and every Kalman part one ancestor's);
- feedback: the weighted mean error is corrected into the INS (position, velocity, attitude, biases) and
  subtracted from every particle, so the error model stays linear about a good INS.

Estimate: the corrected INS; covariance: the mixture's 9 x 9 (position from the cloud, the rest from the
Kalman parts, cross terms included) at the last epoch. Estimate.extra after an IRA update: the fixed keys of
navigators.protocol (innovation and its covariance from the mixture's predictive moments, NIS with 2 dof,
log-likelihood log sum w p(y | particle), ESS before resampling).

Prior: initial.covariance (prior_from_initial, default), as the EKF, PMF and PF start; otherwise, and for the
bias states always, the settings. Defaults are seed 002 Table 1 (table1_covariance() states its initial
distribution for an Estimate): 1,000 particles, sigma_R 3.5 m, sigma_theta 0.1 deg, initial position sigma
(50, 50, 20) m, velocity (1/sqrt 2, 1/sqrt 2, 0.5) m/s, attitude 0.1 deg, accelerometer bias 1e-4 m/s^2;
process noise per epoch: position 0.5 m, velocity 1e-4 m/s, attitude 1e-6 rad, biases 1e-7. Table 1's u2
row lists five numbers for twelve states; we read them as (horizontal velocity, vertical velocity,
attitude, accelerometer bias, gyro bias). Table 1 gives no gyro bias prior; ours is gyro_bias_sigma_rps.
Two process-noise defaults depart from Table 1 (measured on the default King Air route, 40 seeds, README
"RBPF"): vertical velocity 1e-2 m/s per epoch (q_vel_mps[1]) and horizontal position 0.25 m (q_pos_m[:2]).
Without a barometer the vertical velocity is seen only through the range: the position the range pins
and, through eq 24, the tilt of the zero-Doppler plane, which moves the closest point along track by
R dv_d / V (1.8 m per 0.1 m/s at 1,500 m and 85 m/s), so along-track position and vertical velocity
trade in the measurement. At Table 1's 1e-4 the Kalman parts held the vertical velocity 6x tighter than
its error (squared normalised error 24-39 with map = world), and a run's vertical-velocity error came with
an along-track error under a too-small sigma (whole runs averaging horizontal NEES 7); at 1e-2 it is
1.3-2.0, the worst run averages 3.7 and the horizontal RMS is 3.3 -> 2.9 m (seeds 20-39). The horizontal
position's 0.5 m then left the filter conservative (NEES 1.4 of 2), and with the recovery of session 9
(below) 0.25 gives 2.02 (seeds 0-19; 0.35: 1.57, 0.20: 2.24, same alpha). Before it, below 0.3
runs averaging 5-16 returned: the fictitious position noise was covering for the false alarms' re-spreads,
not for the model. seed002's 240 m/s flight keeps its own 1.0 m (reproduce_seed002.FILTER_SETTINGS).
In a scenario both bias priors come from its IMU (uses_imu_spec: trn_env's build_navigator gives the
turn-on bias and bias instability of the IMU's grade; 50 ug and 0.005 deg/h for the navigation grade), and
so does the biases' process noise (the instability's Gauss-Markov drive per epoch: 0 for the navigation
grade, where Table 1's 1e-7 per epoch took the tilt's sigma from 50 to 125 urad in 300 s).
No barometer (seed 002: IMU and IRA only), so the INS vertical channel is free and the filter estimates it.

At run time it never raises: a NaN or invalid IRA sample is skipped, particles whose hypothesis has no
return (off the map) get zero weight; if every weight vanishes the cloud is re-initialised around the INS
with the prior spread; each is counted in Health (status "degraded") with an event.
Integrity (navigators.integrity.InnovationMonitor): each IRA update's NIS (2 dof; a sample every particle
rejects counts as infinite; capped as terrain_filter.capped_nis) enters a window of integrity_window
updates; when the sum leaves its chi-square band (probability integrity_alpha) Health says "degraded" (ok
False) and the particles' positions are re-spread (resampled, then N(0, recovery_sigma_m^2) added
horizontally), both logged; a whole window still out of band after a re-spread re-spreads again, twice as
wide (up to 8 x); back in band the status is "acquiring" until the cloud's spread is below 30 m ("ok").
With recovery_reset_kalman (default) a re-spread also gives every particle's velocity-attitude block the
prior's covariance plus the cloud's mixture covariance (cross terms with the biases zeroed): the test says
the whole belief is overconfident, and re-converging 1,000 particles from a wide spread keeps the Kalman
parts of a few ancestors, whose heading and velocity sigmas had fallen to 0.005 deg and 0.01 m/s against
errors of 0.1 deg and 0.1-0.3 m/s (seed 0, noise-free IMU, map = world). integrity_alpha is 1e-4 as for
the pmf and pf (session 9; was 0.01): at 0.01 the test raised about one false alarm per run on the default
route, and a 100 m re-spread of a cloud 3 m off was how the overconfident runs (averaging NEES 5-16)
began; a lost filter's NIS is far outside either band (a 120 m range bias flags at its first or second
sample, tests/test_nav_integrity_filters.py). A 30 m recovery_sigma_m did as well against the false alarms
but left 3 of 5 such faulted flights 145-160 m off (README "RBPF").
Randomness: only from `rng` (the scenario's navigator stream), so one seed fixes a run bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import trn_env.navigators.filters._rbpf_kernels as kern
from scipy.special import erfc as _erfc
from trn_env.navigators.core.settings import SettingsError
from trn_env.navigators.filters.rbpf_settings import CAPABILITIES, MAX_PARTICLES, RbpfSettings
from trn_env.navigators.filters.terrain_filter import capped_nis
from trn_env.navigators.frames import SensorFrames
from trn_env.navigators.inertial.error_model_15 import transition_over_history
from trn_env.navigators.inertial.strapdown import StrapdownIns, euler_from_C_bn, quat_to_dcm
from trn_env.navigators.integrity.innovation_monitor import InnovationMonitor
from trn_env.navigators.measurements import ira_seed002 as ira_model
from trn_env.navigators.protocol import (
    EXTRA_ESS,
    EXTRA_INNOVATION,
    EXTRA_INNOVATION_COV,
    EXTRA_LOG_LIKELIHOOD,
    EXTRA_MEASUREMENT_TIME,
    EXTRA_NIS,
    EXTRA_NIS_DOF,
    Estimate,
    Health,
)
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

OUTLIER_SIGMA = 10.0          # an IRA sample farther than this from every particle's prediction is rejected
REINIT_AFTER_REJECTS = 3      # consecutive rejections that re-initialise the cloud around the INS
_BYTES_PER_PARTICLE = 8 * (3 + 12 + 144) * 3


def table1_covariance() -> np.ndarray:
    """Seed 002 Table 1's initial distribution as a 9 x 9 covariance (NED position m, velocity m/s, attitude
    rad; diagonal): position (50, 50, 20) m, velocity (1/sqrt 2, 1/sqrt 2, 0.5) m/s, attitude 0.1 deg - the
    RBPF's init_* defaults, for an Estimate that states them (prior_from_initial)."""
    return np.diag(np.r_[50.0, 50.0, 20.0, 1 / math.sqrt(2), 1 / math.sqrt(2), 0.5,
                         np.radians([0.1, 0.1, 0.1])] ** 2)


class RaoBlackwellizedPF:
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
    innovation test and its recovery, see the module docstring).
    """

    capabilities = CAPABILITIES

    def __init__(self, dem=None, rng: np.random.Generator | None = None, settings: RbpfSettings | None = None,
                 name: str = "rbpf", **overrides):
        s = self.settings = RbpfSettings.build(settings, overrides)
        if dem is None:
            raise ValueError("dem: the RBPF needs the navigator's terrain map")
        if isinstance(dem, str):
            from trn_env import terrain

            dem = terrain.load(dem)
        if not hasattr(dem, "grid"):
            raise ValueError(f"dem must be a terrain.Dem or a map name, got {type(dem).__name__}")
        if rng is not None and not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator or None, got {type(rng).__name__}")
        self.name = name
        self.dem = dem
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.n_particles = s.n_particles
        self.n_acquisition = max(s.acquisition_particles, self.n_particles)
        self.n = self.n_particles          # the cloud's current size
        self.ess_threshold = s.ess_threshold
        self.trn_period_s = 1.0 / s.trn_rate_hz
        self.dt_err = 1.0 / s.error_model_rate_hz
        # the sensor's own noise; the map's errors are added per epoch (_r_var_now, map_noise_variances)
        self.r_var = np.array([s.range_sigma_m ** 2, math.radians(s.look_angle_sigma_deg) ** 2])
        # the map's vertical error (its error class, as the scenario's map error model states it) and the
        # terrain the map cannot hold between its posts (interpolation error): measurement noise the filter
        # knows about (ira_seed002.map_noise_variances)
        self.map_sigma_m = s.map_sigma_m
        self.map_bias_sigma_m = s.map_bias_sigma_m
        self.terrain_model_sigma_m = (ira_model.interpolation_sigma_m(dem)
                                      if s.terrain_model_sigma_m == "auto" else s.terrain_model_sigma_m)
        self.map_noise_model = s.map_noise_model
        detail = s.terrain_detail_spacing_m
        self.terrain_detail_spacing_m = float(min(dem.spacing_m)) / 3.0 if detail == "auto" else detail
        # the calibration refines a <= 16 km square of the map to this spacing: finer than the posts, and
        # not so fine that the refinement's memory (~40 bytes per post) runs away
        if not 5.0 <= self.terrain_detail_spacing_m < min(dem.spacing_m):
            raise SettingsError([("terrain_detail_spacing_m", f"must lie in [5, {min(dem.spacing_m):.1f}) m "
                                  f"(finer than the map's posts), got {s.terrain_detail_spacing_m!r}")])
        self._terrain_factors = None       # map_noise_calibration's, computed at the first IRA update
        self.half_window_rad = math.radians(s.half_window_deg)
        self.edge_margin_rad = math.radians(s.window_edge_margin_deg)
        self.window_edge_range = s.window_edge_range
        self.theta_velocity_rows = s.theta_velocity_rows
        self.ambiguity_gap_m = s.ambiguity_gap_m
        self.ambiguity_weight = s.ambiguity_weight
        self.ambiguity_probability = s.ambiguity_probability
        self.prior_from_initial = s.prior_from_initial
        self.theta_linearity_sigmas = s.theta_linearity_sigmas
        self.theta_collapse_ess = s.theta_collapse_ess
        self.theta_gate_sigmas = s.theta_gate_sigmas
        self.max_range_m = s.max_range_m
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
        self.gravity_gradient = s.gravity_gradient
        self.acquisition_spread_m = s.acquisition_spread_m
        self.ins = StrapdownIns("j2", tau_baro_s=None, imu_samples=s.imu_samples)
        self.integrity = InnovationMonitor(s.integrity_window, s.integrity_alpha)
        self.recovery_sigma_m = s.recovery_sigma_m
        self.recoveries = 0
        self.recovery_reset_kalman = s.recovery_reset_kalman
        # log N at OUTLIER_SIGMA for the inflated-at-most-100x variances (2 dof): the rejection floor
        self.health = Health()
        self._reset_done = False

    # ------------------------------------------------------------------ protocol
    def reset(self, initial: Estimate) -> None:
        self.ins.reset(initial.t_s, initial.lat_rad, initial.lon_rad, initial.h_m, initial.v_ned_mps,
                       initial.roll_rad, initial.pitch_rad, initial.yaw_rad)
        self._set_prior(initial)
        self._init_cloud()
        self.health = Health(status="acquiring", ok=True)
        self.integrity.reset()
        self.recoveries = self._streak = self._since_recovery = 0
        self._integrity_extra: dict = {}
        self._t_next = float(initial.t_s) + self.trn_period_s
        self._t_gnss_next = float(initial.t_s)
        self._Phi = np.eye(15)
        self._last_row = None          # INS row and specific force carried into the next chunk
        self._extra: dict = {}
        self._cov9 = self._covariance9()
        self._n_rejected = 0
        self._last_range_m = -1.0
        self.epochs = 0
        self.resamples = 0
        self._reset_done = True

    def _set_prior(self, initial: Estimate) -> None:
        """The cloud's and the Kalman parts' initial spread. prior_from_initial (default) and a 9 x 9
        initial.covariance (NED position m, velocity m/s, attitude rad, as every navigator's reset reads it):
        position sigmas from its diagonal (floored at 0.1 m), P0's velocity-attitude block from it (cross
        terms kept), the bias priors from the settings - as the EKF, PMF and PF start. Otherwise (or without
        a covariance) Table 1's priors, the init_* settings. On the default route the scenario's initial
        errors are 0.05 mrad of tilt and 0.1 m/s, against Table 1's 1.75 mrad and 0.71 m/s: starting from
        Table 1 there leaves the filter's velocity and attitude sigmas several times its errors."""
        self.init_pos_sigma = self.init_pos_sigma_settings.copy()
        self.P0 = self.P0_settings.copy()
        cov = getattr(initial, "covariance", None)
        if not self.prior_from_initial or cov is None:
            return
        c = np.asarray(cov, float)
        if c.shape != (9, 9):
            raise ValueError(f"initial.covariance must be 9 x 9 (position, velocity, attitude),"
                             f" not {c.shape}")
        if not np.all(np.isfinite(c)):
            raise ValueError("initial.covariance must be finite (prior_from_initial)")
        if not np.allclose(c, c.T, rtol=1e-9, atol=1e-12):
            raise ValueError("initial.covariance must be symmetric (prior_from_initial)")
        w_min = float(np.linalg.eigvalsh(c).min())
        if w_min < -1e-9 * max(1.0, float(np.abs(c).max())):
            raise ValueError("initial.covariance must be positive semi-definite (it has a negative "
                             f"eigenvalue {w_min:.3g})")
        d = np.diag(c)
        if np.any(np.sqrt(d[6:9]) > 0.1):
            raise ValueError("initial.covariance (a scenario's initial_errors.attitude_mrad): attitude sigma "
                             "above 0.1 rad (100 mrad), outside the error model's small-angle range "
                             "(prior_from_initial; set prior_from_initial=false and init_att_sigma_deg "
                             "instead)")
        self.init_pos_sigma = np.maximum(np.sqrt(d[:3]), 0.1)
        blk = c[3:9, 3:9].copy()
        blk[np.diag_indices(6)] = np.maximum(np.diag(blk), 1e-12)
        P0 = self.P0_settings.copy()
        P0[:6, :6] = blk          # the Kalman parts' velocity and attitude are NED, as initial's
        self.P0 = P0

    def _init_cloud(self) -> None:
        n = self.n = self.n_acquisition
        self.xn = self.rng.standard_normal((n, 3)) * self.init_pos_sigma
        self.xl = np.zeros((n, 12))
        self.P = np.broadcast_to(self.P0, (n, 12, 12)).copy()
        self.logw = np.full(n, -math.log(n))

    def update(self, frames: SensorFrames) -> Estimate:
        if not self._reset_done:
            raise RuntimeError("RaoBlackwellizedPF.update before reset")
        self.health.events = []
        imu = frames.imu
        if imu is None or imu.t_s.shape[0] == 0:
            self.health.skip(frames.t_end_s, "no_imu", "no IMU samples in the frame")
            return self.estimate()
        t = np.asarray(imu.t_s, float)
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
        first valid IRA sample at or after each due time (GNSS: the fix nearest it, while available)."""
        out = []
        ira = frames.ira
        t_last = float(t[-1])
        gn = frames.gnss
        if gn is not None and gn.t_s.shape[0]:
            gv = (np.asarray(gn.valid, bool) & np.all(np.isfinite(gn.v_ned_mps), axis=1)
                  & np.isfinite(gn.lat_rad))
        else:
            gv = None
        if ira is not None and ira.t_s.shape[0]:
            ts = np.asarray(ira.t_s, float)
            good = np.asarray(ira.valid, bool) & np.isfinite(ira.range_m) & np.isfinite(ira.look_angle_rad)
            n_bad = int((~good).sum())
            if n_bad:
                self.health.skip(float(ts[0]), "ira_invalid", f"{n_bad} IRA samples invalid or NaN")
                self.health.skipped["ira_invalid"] += n_bad - 1
            i = 0
            while True:
                i = int(np.searchsorted(ts, self._t_next - 1e-9, side="left"))
                while i < ts.shape[0] and not good[i]:
                    i += 1
                if i >= ts.shape[0] or ts[i] > t_last + 1e-9:
                    break
                te = float(ts[i])
                g = self._gnss_at(gn, gv, te)
                out.append((te, (float(ira.range_m[i]), float(ira.look_angle_rad[i])), g))
                self._t_next = te + self.trn_period_s
        if not out and gv is not None and gv.any():  # no usable IRA sample: GNSS epochs alone
            ts = np.asarray(gn.t_s, float)
            for i in np.flatnonzero(gv):
                te = float(ts[i])
                if te + 1e-9 >= self._t_next and te <= t_last + 1e-9:
                    out.append((te, None, self._gnss_at(gn, gv, te)))
                    self._t_next = te + self.trn_period_s
        return out

    @staticmethod
    def _gnss_at(gn, gv, te):
        if gv is None or not gv.any():
            return None
        ts = np.asarray(gn.t_s, float)
        idx = np.flatnonzero(gv)
        j = idx[np.argmin(np.abs(ts[idx] - te))]
        if abs(ts[j] - te) > 0.5:
            return None
        return (float(ts[j]), float(gn.lat_rad[j]), float(gn.lon_rad[j]), float(gn.h_m[j]),
                np.asarray(gn.v_ned_mps[j], float).copy())

    def _propagate(self, t, f_b, w_b, ok) -> None:
        bad0 = self.ins.bad_imu_samples
        hist = self.ins.propagate(t, f_b, w_b, ok)
        if self.ins.bad_imu_samples > bad0:
            self.health.skip(float(t[0]), "imu_invalid",
                             f"{self.ins.bad_imu_samples - bad0} IMU samples invalid (held previous)")
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
        self.epochs += 1
        # ---- time update (eqs 5-8, 13-15) in metric position units
        T = np.ones(15)
        T[:3] = self._metric_scale()
        Phi = self._Phi * T[:, None] / T[None, :]
        self._Phi = np.eye(15)
        w = self.rng.standard_normal((self.n, 3))
        nbad = kern.time_update(self.xn, self.xl, self.P, np.ascontiguousarray(Phi), self.qn_var, self.ql_var,
                                w)
        if nbad:
            self.health.skip(te, "time_update_not_pd", f"{nbad} particles: N not positive definite")
        logw_prev = self.logw.copy()
        updated = False
        ll = np.empty(self.n)
        lat, lon, h, v, C = self._ins_at(te)
        sc = self._metric_scale()
        if y_ira is not None:
            self._gnss_now = gnss is not None
            updated = self._ira_update(te, y_ira, lat, lon, h, v, C, sc, logw_prev, ll)
        if gnss is not None:
            self._gnss_update(te, gnss, lat, lon, h, v, sc, ll)
            updated = True
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

    def _ira_update(self, te, y_ira, lat, lon, h, v, C, sc, logw_prev, ll) -> bool:
        edge = abs(y_ira[1]) > self.half_window_rad - self.edge_margin_rad
        if edge and not self.window_edge_range:
            # the return sits on the look window's edge: the window, not the terrain's minimum, fixed the
            # point, so its range depends on roll and its look angle is the window's - eqs 24-25 (an
            # interior minimum on the zero-Doppler line) do not describe it
            sk = self.health.skipped
            sk["ira_window_edge"] = sk.get("ira_window_edge", 0) + 1
            return False
        lat_i = lat - self.xn[:, 0] / sc[0]
        lon_i = lon - self.xn[:, 1] / sc[1]
        h_i = h - self.xn[:, 2]
        out = self._predict(lat_i, lon_i, h_i, v, C)
        Hs = np.zeros((self.n, 2, 6))
        ira_model.measurement_rows(out, v, C, Hs)
        theta_curv = 0.0
        if edge:
            # on the window's edge (see window_edge_range): the range alone, its velocity and attitude rows
            # by differences, as eqs 24-25 describe an interior minimum only
            Hs[:, 0, :] = self._edge_range_row(out, lat_i, lon_i, h_i, v, C)
        elif self.theta_velocity_rows:
            Hs[:, 1, :3], theta_curv = self._theta_velocity_row(out, lat_i, lon_i, h_i, v, C)
        H = np.zeros((self.n, 2, 12))
        H[:, :, :6] = Hs
        ok = out[:, ira_model.OUT_VALID] > 0.5
        if not ok.any():
            self.health.skip(te, "ira_no_hypothesis",
                             "IRA update skipped: no particle has a return (off map?)")
            self.health.status, self.health.ok = "degraded", True
            self._integrity_test(te, math.inf, 2)
            return False
        # a point of the zero-Doppler line more than 1.5 scan steps (68 m) across track from the closest
        # one, in another basin or on the far side of a flat minimum, within ambiguity_gap_m of its range:
        # the closest point can jump there (a velocity error of a few tenths of m/s tilts the line enough),
        # and theta with it by degrees - what eqs 24-25 cannot linearise (the range, a minimum, stays
        # continuous). When such particles carry ambiguity_weight of the cloud, the range alone.
        wq = np.exp(self.logw - np.max(self.logw))
        wq = np.where(ok, wq, 0.0)
        gap = out[:, ira_model.OUT_R2] - out[:, ira_model.OUT_R]
        near = ok & np.isfinite(gap) & (gap < self.ambiguity_gap_m)
        dims = 1 if float(wq[near].sum()) > self.ambiguity_weight * float(wq.sum()) else 2
        # the same jump made by the map: its height errors move the two minima's ranges independently, so
        # the map's closest point lies in the runner-up's basin where the world's does not with probability
        # Phi(-gap / (sqrt 2 sigma_h)); above ambiguity_probability, the range alone
        if dims == 2 and self._basin_jump_probability(gap, ok, wq) > self.ambiguity_probability:
            dims = 1
        wp = np.exp(logw_prev - logw_prev.max())
        wp = np.where(ok, wp, 0.0)
        wp /= wp.sum()
        # the look angle's variance as this update uses it (tempered while acquiring): the yardstick of
        # the theta-velocity row's linearity (_theta_velocity_row)
        theta_var = self._r_var_now(float(np.sum(wp * np.where(ok, out[:, ira_model.OUT_R], 0.0))))[1]
        sk = self.health.skipped
        if edge:
            dims = 1
            sk["ira_window_edge"] = sk.get("ira_window_edge", 0) + 1
        elif dims == 1:
            sk["ira_theta_ambiguous"] = sk.get("ira_theta_ambiguous", 0) + 1
        elif self.theta_linearity_sigmas > 0.0 and not theta_curv < self.theta_linearity_sigmas * math.sqrt(
                theta_var):
            dims = 1
            sk["ira_theta_nonlinear"] = sk.get("ira_theta_nonlinear", 0) + 1
        H_full = H
        saved = (self.xl.copy(), self.P.copy(), self.logw.copy())
        # the collapse guard below is for a converged cloud (no acquisition tempering): while acquiring, a
        # look angle that selects a few particles is the bootstrap's normal work
        converged = math.sqrt(max(self._cov9[0, 0] + self._cov9[1, 1], 0.0)) <= self.acquisition_spread_m
        # the look-angle gate only on a converged cloud the innovation test trusts: a lost or re-acquiring
        # one needs exactly the large innovations a gate would reject (after a 120 m range bias, gated at
        # 3 sigma throughout, the cloud stayed 930 m off)
        gate = self.theta_gate_sigmas > 0.0 and converged and self.health.status == "ok"
        while True:
            y = np.array(y_ira)[:dims]
            pred = np.stack([out[:, ira_model.OUT_R], out[:, ira_model.OUT_THETA]], axis=1)[:, :dims]
            H = np.ascontiguousarray(H_full[:, :dims, :])
            e = np.where(ok[:, None], y[None, :] - pred, 0.0)
            # innovation moments of the mixture (before the update): the fixed Estimate.extra keys
            pred_ok = np.ascontiguousarray(np.where(ok[:, None], pred, 0.0))
            self._last_range_m = float(np.sum(wp * pred_ok[:, 0]))
            r_var = np.ascontiguousarray(self._r_var_now(self._last_range_m)[:dims])
            ybar, S = kern.predictive_moments(H, self.xl, self.P, r_var, pred_ok, ok, wp)
            nu = y - ybar
            if dims == 2 and gate and not nu[1] ** 2 <= self.theta_gate_sigmas ** 2 * S[1, 1]:
                # a look angle beyond the gate of the mixture's predictive spread: the map's error at the
                # closest point is heavy-tailed (kurtosis 17 at random states on the 3" map, 1 % of the
                # samples beyond 3 sigma holding a quarter of the variance), which a Gaussian update would
                # read as position and attitude; the range alone (map_noise_calibration trims the same)
                dims = 1
                sk["ira_theta_gated"] = sk.get("ira_theta_gated", 0) + 1
                continue
            n_bad = kern.linear_update(self.xl, self.P, H, e, r_var, self.logw, ok, ll)
            if (dims == 1 or self.theta_collapse_ess <= 0.0 or not converged
                    or self._ess(self.logw) >= self.theta_collapse_ess * self.n):
                break
            # the look angle alone would leave (nearly) one particle: theta is then a function of position
            # sharper than the cloud can sample (a flat minimum, or the closest point at a bilinear cell's
            # kink, where it jumps): its information cannot be represented, and taking it collapses every
            # Kalman part onto one ancestor's. The range alone instead.
            self.xl, self.P, self.logw = (a.copy() for a in saved)
            dims = 1
            sk["ira_theta_collapse"] = sk.get("ira_theta_collapse", 0) + 1
        fin_ll = ll[np.isfinite(ll)]
        # log N at OUTLIER_SIGMA for the variances inflated at most 100x: the rejection floor
        ll_floor = (-0.5 * OUTLIER_SIGMA**2 - 0.5 * math.log(float(np.prod(r_var)) * 100.0 ** dims)
                    - 0.5 * dims * math.log(2 * math.pi))
        # no particle within OUTLIER_SIGMA of the measurement: in linear weights every one underflows
        if fin_ll.size == 0 or fin_ll.max() < ll_floor:
            self.xl, self.P, self.logw = saved
            self._n_rejected += 1
            if self._n_rejected >= REINIT_AFTER_REJECTS:
                self.health.skip(te, "weights_underflow",
                                 f"{self._n_rejected} IRA samples unexplained by every particle: "
                                 "cloud re-initialised")
                self._init_cloud()
                self._n_rejected = 0
            else:
                self.health.skip(te, "ira_outlier", "IRA sample unexplained by every particle: skipped")
            self.health.status, self.health.ok = "degraded", True
            self._integrity_test(te, math.inf, dims)
            return False
        self._n_rejected = 0
        if n_bad:
            sk = self.health.skipped
            sk["ira_particle_no_return"] = sk.get("ira_particle_no_return", 0) + n_bad
        m = np.max(logw_prev)
        lse_prev = m + math.log(np.sum(np.exp(logw_prev - m)))
        fin = np.isfinite(self.logw)
        if fin.any():
            mm = np.max(self.logw[fin])
            lse = mm + math.log(np.sum(np.exp(self.logw[fin] - mm)))
        else:
            lse = -np.inf
        try:
            nis = float(nu @ np.linalg.solve(S, nu))
        except np.linalg.LinAlgError:
            nis = float("nan")
        self._extra = {EXTRA_INNOVATION: nu, EXTRA_INNOVATION_COV: S, EXTRA_NIS: nis, EXTRA_NIS_DOF: dims,
                       EXTRA_LOG_LIKELIHOOD: float(lse - lse_prev), EXTRA_MEASUREMENT_TIME: te}
        self._integrity_test(te, nis, dims)
        return True

    def _predict(self, lat, lon, h, v, C) -> np.ndarray:
        """eqs 23-26 on the map for hypotheses (lat, lon rad, h m): ira_seed002.predict_ira with the sensor's
        look window and this filter's coarse-scan step (search_step_m)."""
        return ira_model.predict_ira(self.dem, lat, lon, h, v, C, self.half_window_rad, self.max_range_m,
                                     ds_m=self.search_step_m)

    def _edge_range_row(self, out, lat_i, lon_i, h_i, v, C) -> np.ndarray:
        """Range sensitivity (1 x 6: dv_ned m/s, eps_ned rad) of a return on the look window's edge, where the
        window's boundary ray, not the terrain's minimum, fixes the point: eq 24's envelope argument does
        not hold there (the range moves with the ray, so with roll), so central differences of eq 23 (the
        exact constrained search) at the cloud's weighted-mean position, shared by the particles. Errors
        computed minus true: R_true = R(v - dv, (I + [eps x]) C), so H_v = -dR/dv, H_eps = +dR/deps."""
        ok = out[:, ira_model.OUT_VALID] > 0.5
        w = np.where(ok, np.exp(self.logw - np.max(self.logw)), 0.0)
        row = np.zeros(6)
        if not w.sum() > 0:
            return row
        w /= w.sum()
        la, lo, hh = (np.array([float(w @ np.where(ok, x, 0.0))]) for x in (lat_i, lon_i, h_i))
        dv, de = 0.2, 2e-3     # de: eq 23's search resolves ~5 mm; R is smooth in the ray angle

        def rng_at(vv, CC):
            r = self._predict(la, lo, hh, vv, CC)
            return r[0, ira_model.OUT_R] if r[0, ira_model.OUT_VALID] > 0.5 else math.nan

        for j in range(3):
            d = np.zeros(3)
            d[j] = dv
            row[j] = -(rng_at(v + d, C) - rng_at(v - d, C)) / (2 * dv)
            e = np.zeros(3)
            e[j] = de
            Ep = np.array([[0.0, -e[2], e[1]], [e[2], 0.0, -e[0]], [-e[1], e[0], 0.0]])
            row[3 + j] = (rng_at(v, (np.eye(3) + Ep) @ C) - rng_at(v, (np.eye(3) - Ep) @ C)) / (2 * de)
        return np.where(np.isfinite(row), row, 0.0)

    def _theta_velocity_row(self, out, lat_i, lon_i, h_i, v, C) -> tuple[np.ndarray, float]:
        """Look-angle sensitivity to the velocity error (1 x 3, rad per m/s), which eq 23's look-angle row
        leaves out: a velocity error tilts and turns the zero-Doppler line (the shift eq 24 applies to the
        range), and the closest point moves along the terrain, so theta moves too (on the seed002 flight
        ~0.1 deg per m/s of vertical velocity, up to 0.5). Central differences of eqs 23/26 (the exact
        search) at the cloud's weighted-mean position, shared by the particles; H = -dtheta/dv (errors
        computed minus true, as eq 24's range row).

        Also how far theta departs from that line over the cloud's velocity spread: the second difference's
        term, 0.5 sum_j |theta''_jj| sigma_vj^2 (rad; inf when a perturbed search has no return), which
        _ira_update compares with theta_linearity_sigmas look-angle sigmas (a flat minimum, or a closest
        point at a bilinear cell's kink, jumps under a small tilt of the line; a Kalman update through this
        row would then read the jump as velocity information)."""
        ok = out[:, ira_model.OUT_VALID] > 0.5
        w = np.where(ok, np.exp(self.logw - np.max(self.logw)), 0.0)
        if not w.sum() > 0:
            return np.zeros(3), math.inf
        w /= w.sum()
        la, lo, hh = (np.array([float(w @ np.where(ok, x, 0.0))]) for x in (lat_i, lon_i, h_i))
        row = np.zeros(3)
        dv = 0.2
        c = self._predict(la, lo, hh, v, C)
        linear = bool(c[0, ira_model.OUT_VALID] > 0.5)
        sig_v2 = np.clip(np.diag(self._cov9)[3:6], 0.0, None)
        curv = 0.0
        for j in range(3):
            d = np.zeros(3)
            d[j] = dv
            a = self._predict(la, lo, hh, v + d, C)
            b = self._predict(la, lo, hh, v - d, C)
            if a[0, ira_model.OUT_VALID] > 0.5 and b[0, ira_model.OUT_VALID] > 0.5:
                ta, tb = a[0, ira_model.OUT_THETA], b[0, ira_model.OUT_THETA]
                row[j] = -(ta - tb) / (2 * dv)
                if linear:
                    curv += 0.5 * abs(ta - 2.0 * c[0, ira_model.OUT_THETA] + tb) / dv**2 * sig_v2[j]
            else:
                linear = False
        return row, (curv if linear else math.inf)

    def _basin_jump_probability(self, gap: np.ndarray, ok: np.ndarray, w: np.ndarray) -> float:
        """Probability, weighted over the cloud, that the map's closest point on the zero-Doppler line lies
        in another basin than the world's: per particle, the map's height errors (sigma_h = hypot(map_sigma_m,
        terrain_model_sigma_m), independent between two basins 68 m or more apart, each seen near the
        vertical so a height error is a range error) change the runner-up's range margin gap by
        N(0, 2 sigma_h^2), which closes it with probability Phi(-gap / (sqrt 2 sigma_h)) =
        erfc(gap / (2 sigma_h)) / 2. Such a jump moves theta by degrees (13 deg at t = 399 s on the
        default route's seed 0, map gap 2.0 m), which eqs 25-26 would read as attitude and position. 0 for a
        map that is the world (sigma_h = 0) or when no particle has a runner-up (gap inf)."""
        sigma_h = math.hypot(self.map_sigma_m, self.terrain_model_sigma_m)
        if not sigma_h > 0.0:
            return 0.0
        use = ok & np.isfinite(gap)
        tot = float(w[ok].sum())
        if not tot > 0.0 or not use.any():
            return 0.0
        p = 0.5 * _erfc(np.maximum(gap[use], 0.0) / (2.0 * sigma_h))
        return float(np.sum(w[use] * p)) / tot

    @staticmethod
    def _ess(logw: np.ndarray) -> float:
        fin = np.isfinite(logw)
        if not fin.any():
            return 0.0
        w = np.exp(logw[fin] - np.max(logw[fin]))
        return float(w.sum() ** 2 / np.sum(w * w))

    def _integrity_test(self, te: float, nis: float, dof: int) -> None:
        """Feed the innovation test; on entering "degraded" re-spread the particles' positions (logged)."""
        verdict = self.integrity.add(te, capped_nis(self.integrity, nis, dof), dof)
        self._integrity_extra = verdict.extra()
        if verdict.changed:
            self.health.events.append((float(te), verdict.message))
        if verdict.degraded:
            self.health.status, self.health.ok = "degraded", False
            self._since_recovery += 1
            # again, twice as wide, when a whole window after the last re-spread is still out of band
            if verdict.changed or self._since_recovery >= self.integrity.window:
                self._since_recovery = 0
                self._streak = min(self._streak + 1, 4)
                self.recoveries += 1
                self._respread(te)
        elif verdict.changed:
            self._streak = 0
            self.health.status, self.health.ok = "acquiring", True

    def _respread(self, te: float) -> None:
        """Resample by weight, then N(0, recovery_sigma_m^2) on every particle's horizontal position."""
        w = self._weights()
        idx = kern.systematic_resample(w, float(self.rng.random()))
        self.xn, self.xl, self.P = kern.gather(self.xn, self.xl, self.P, idx)
        sig = self.recovery_sigma_m * 2.0 ** (self._streak - 1)
        self.xn[:, :2] += self.rng.standard_normal((self.n, 2)) * sig
        if self.recovery_reset_kalman:
            # the Kalman parts' velocity and attitude share the position's failed test: back to the prior
            # spread (plus the cloud's), so the cloud re-converges without inheriting their overconfidence
            c = kern.moments(self.xn, self.xl, self.P, np.full(self.n, 1.0 / self.n))[1][3:9, 3:9]
            blk = c + self.P0[:6, :6]
            self.P[:, :6, :6] = blk
            self.P[:, :6, 6:] = 0.0
            self.P[:, 6:, :6] = 0.0
        self.logw = np.full(self.n, -math.log(self.n))
        self._cov9 = self._covariance9()
        self.health.events.append((float(te), f"recovery: {self.n} particles re-spread, horizontal 1-sigma "
                                               f"+{sig:.0f} m"))

    def terrain_factors(self) -> tuple[float, float]:
        """(range, look angle) factors on the flat-ground map-noise variances of terrain_model_sigma_m:
        ira_seed002.map_noise_calibration on this map ("calibrated", ~2 s once per map and process) or
        (1, 1) ("flat_ground", or nothing unresolved: terrain_model_sigma_m 0)."""
        if self._terrain_factors is None:
            self._terrain_factors = (1.0, 1.0)
            if self.map_noise_model == "calibrated" and self.terrain_model_sigma_m > 0.0:
                self._terrain_factors = ira_model.map_noise_calibration(
                    self.dem, self.terrain_detail_spacing_m,
                    ambiguity_probability=self.ambiguity_probability, gate_sigmas=self.theta_gate_sigmas,
                    theta_sensor_var=float(self.r_var[1]))
        return self._terrain_factors

    def _r_var_now(self, range_m: float) -> np.ndarray:
        """IRA measurement variances (range m^2, look angle rad^2) at a slant range range_m: the sensor's,
        plus the map's errors (ira_seed002.map_noise_variances: map_sigma_m, terrain_model_sigma_m, and
        map_bias_sigma_m while GNSS pins the height, which then cannot absorb a map bias). While the
        cloud's horizontal spread exceeds acquisition_spread_m they are inflated by
        (spread / acquisition_spread_m)^2 (at most 100x): tempering against the collapse of 1,000 particles
        spread over 50 m onto a 3.5 m likelihood, where the survivors' Kalman parts absorb their position's
        look-angle mismatch as attitude error (our addition; 0 disables it)."""
        bias = self.map_bias_sigma_m if getattr(self, "_gnss_now", False) else 0.0
        r = self.r_var + ira_model.map_noise_variances(math.hypot(self.map_sigma_m, bias),
                                                       self.terrain_model_sigma_m, range_m,
                                                       self.terrain_factors())
        if self.acquisition_spread_m <= 0.0:
            return r
        spread = math.sqrt(max(self._cov9[0, 0] + self._cov9[1, 1], 0.0))
        f = min(max((spread / self.acquisition_spread_m) ** 2, 1.0), 100.0)
        return r * f

    def _gnss_update(self, te, gnss, lat, lon, h, v, sc, ll) -> None:
        """GNSS position: a linear-Gaussian measurement of x^n. Weighting the cloud by it cannot represent a
        2 m fix on a 50 m cloud (about one particle in 1,000 lies in the posterior's 1-sigma box), so the
        cloud is moved instead: the weighted mean m and covariance Pc are fused with the fix by a Kalman
        update (m', P') and every particle is mapped x -> m' + L' L^-1 (x - m) (L, L' Cholesky factors of Pc,
        P'), keeping its weight: the weighted cloud then has exactly the posterior's first two moments, its
        shape otherwise kept (an ensemble square-root update). The receiver's error has a white part
        (gnss_pos_sigma_m) and a slowly drifting one (gnss_pos_bias_sigma_m, constant over a fix's
        neighbours): the update uses their sum and P' is kept above the drift's variance, so ten fixes do not
        claim to beat the receiver's own bias. GNSS velocity: each particle's Kalman update (eqs 9-12)."""
        _, glat, glon, gh, gv = gnss
        y = np.array([(lat - glat) * sc[0], (lon - glon) * sc[1], h - gh])
        self._gnss_cloud_update(y)
        H = np.zeros((self.n, 3, 12))
        H[:, 0, 0] = H[:, 1, 1] = H[:, 2, 2] = 1.0
        e = np.broadcast_to(v - gv, (self.n, 3)).copy()
        kern.linear_update(self.xl, self.P, H, e, self.gnss_vel_var, self.logw, np.ones(self.n, bool), ll)

    def _gnss_cloud_update(self, y: np.ndarray) -> None:
        w = self._weights()
        m = w @ self.xn
        d = self.xn - m
        Pc = (d * w[:, None]).T @ d
        Rg = np.diag(self.gnss_pos_var + self.gnss_bias_var)
        try:
            L = np.linalg.cholesky(Pc + 1e-9 * np.eye(3))
            K = Pc @ np.linalg.inv(Pc + Rg)
        except np.linalg.LinAlgError:
            return
        m_new = m + K @ (y - m)
        P_new = (np.eye(3) - K) @ Pc
        P_new = 0.5 * (P_new + P_new.T)
        # the receiver's drift is common to consecutive fixes: no position better than it
        # (never wider than the cloud before the fix)
        floor = np.sqrt(np.minimum(self.gnss_bias_var, np.diag(Pc)))
        sd = np.sqrt(np.clip(np.diag(P_new), 1e-12, None))
        f = np.maximum(floor / sd, 1.0)
        P_new = P_new * f[:, None] * f[None, :]
        try:
            L_new = np.linalg.cholesky(P_new + 1e-9 * np.eye(3))
        except np.linalg.LinAlgError:
            return
        A = L_new @ np.linalg.inv(L)
        self.xn = m_new + d @ A.T

    def _normalise_resample(self, te, logw_prev) -> None:
        fin = np.isfinite(self.logw)
        if not fin.any():
            self.health.skip(te, "weights_underflow", "all particle weights vanished: cloud re-initialised")
            self.health.status, self.health.ok = "degraded", True
            self._init_cloud()
            self.xn += 0.0
            self._extra[EXTRA_ESS] = 0.0
            return
        m = np.max(self.logw[fin])
        w = np.where(fin, np.exp(self.logw - m), 0.0)
        w /= w.sum()
        ess = 1.0 / float(np.sum(w * w))
        self._extra[EXTRA_ESS] = ess
        if ess < self.ess_threshold * self.n:
            idx = kern.systematic_resample(w, float(self.rng.random()))
            self.xn, self.xl, self.P = kern.gather(self.xn, self.xl, self.P, idx)
            self.logw = np.full(self.n, -math.log(self.n))
            self.resamples += 1
        else:
            self.logw = np.log(np.where(w > 0, w, 1e-300))

    def _handover(self) -> None:
        """Acquisition over: the cloud of acquisition_particles is resampled (systematic, by weight) down to
        n_particles once its horizontal spread is below acquisition_spread_m (see the class docstring)."""
        if self.n <= self.n_particles:
            return
        c = kern.moments(self.xn, self.xl, self.P, self._weights())[1]
        if math.sqrt(max(c[0, 0] + c[1, 1], 0.0)) >= max(self.acquisition_spread_m, 1e-9):
            return
        cw = np.cumsum(self._weights())
        u = (float(self.rng.random()) + np.arange(self.n_particles)) / self.n_particles
        idx = np.minimum(np.searchsorted(cw, u * cw[-1], side="left"), self.n - 1).astype(np.int64)
        self.xn, self.xl, self.P = kern.gather(self.xn, self.xl, self.P, idx)
        self.n = self.n_particles
        self.logw = np.full(self.n, -math.log(self.n))

    def _weights(self) -> np.ndarray:
        m = np.max(self.logw)
        w = np.exp(self.logw - m)
        return w / w.sum()

    def _feedback(self) -> None:
        """Correct the INS by the weighted mean error and subtract it from the particles (an exact change of
        the linearisation point of the error model)."""
        w = self._weights()
        mu, _ = kern.moments(self.xn, self.xl, self.P, w)
        if not np.all(np.isfinite(mu)):
            return
        self.ins.correct(np.array([mu[0], mu[1], -mu[2]]), mu[3:6], mu[6:9])
        self.ins.accel_bias_b -= mu[9:12]
        self.ins.gyro_bias_b -= mu[12:15]
        kern.shift(self.xn, self.xl, mu)

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
        health = Health(ok=self.health.ok, status=self.health.status, skipped=dict(self.health.skipped),
                        events=list(self.health.events))
        return Estimate(t_s=self.ins.t_s, lat_rad=float(st[0]), lon_rad=float(st[1]), h_m=float(st[2]),
                        v_ned_mps=st[3:6].copy(), roll_rad=roll, pitch_rad=pitch, yaw_rad=yaw,
                        covariance=self._cov9.copy(), health=health, extra=extra)


__all__ = ["MAX_PARTICLES", "RaoBlackwellizedPF", "table1_covariance"]
