"""Point-mass filter (`pmf`): a grid over the INS's horizontal position error, riding on the INS.

Belief: log-densities on an n x n grid of north/east offsets (true minus INS position, m) centred at
(centre_n, centre_e) with spacing d (m), and in every cell the Gaussian of the vertical offset b (INS height
minus true: the baro's and the map's vertical bias) given that cell - its mean per cell, its variance
shared (the measurements are the same for all cells, so the Kalman gain is): a Rao-Blackwellised vertical
channel instead of a third grid axis, so a baro or map bias does not pull the horizontal fix and costs
nothing per cell but one multiply-add.

- The INS's horizontal velocity error model u = (v, t, b, eps) (true minus INS; m/s, m/s^2, rad): the
  velocity offset v, the acceleration of the initial tilt t (g times the tilt, constant in NED), the
  accelerometer bias b (constant in the body frame, so R b in NED turns with the heading, R the INS's
  body-to-NED matrix's horizontal block) and the heading error eps (INS yaw minus true yaw, which turns
  every velocity change the INS integrates: v gains eps (dv_e, -dv_n)), and the INS's down specific-force
  error beta (u[BETA]: through the baro loop's transients it tilts every IRA closest point's geometry and
  moves the vertical offset, `_vertical_velocity_shift`); a Gaussian (mean, covariance, and its covariance
  with the grid's position and vertical offset) outside the grid. Its process noise and
  b's prior come from the IMU's specification (apply_imu_spec, navigators.core.imu_spec): the tilt
  acceleration's growth from the horizontal gyro biases, the heading's from the z gyro bias, the
  accelerometer instability's drive on b, beta's prior the vertical specific-force error, and per rad
  turned (the integral of |yaw rate| over the IMU samples) the gyro misalignment and scale factor; the
  velocity's random walk is a floor (velocity_noise_mps_per_sqrt_s; the measurements that chose this
  model: docs/validation/navigators.md). Priors: v, t and eps from the initial
  estimate's velocity, roll/pitch and yaw variances, b from accel_bias_sigma_mps2. A terrain or GNSS
  update leaves p(u | dn, de, b) unchanged, so u follows the grid's posterior moments by the Gaussian
  regression (`_velocity_from_position`, exact for a Gaussian belief: tests/test_terrain_filter_linear.py
  against a 10-state Kalman filter).
- Prediction: the grid rides on the INS and moves by the mean of v dt + (t + R b) dt^2 / 2 (its cells are
  offsets: an exact shift), plus process noise - the rest of the position growth,
  2 sym(B C_ux) + B C_uu B' + q dt with B = [I dt, I dt^2 / 2, R dt^2 / 2, 0] - as a separable
  convolution whose kernel
  has exactly the accumulated variance (a three-tap kernel [p, 1 - 2p, p], p = q / (2 d^2), while the noise
  is below the spacing, a normalised sampled Gaussian above it; in the spirit of the Lagrangian grid
  filters), applied before every measurement update. The per-cell vertical offsets move with their mass: a
  cell's new mean is the mean of its sources' means, and the spread of those means goes into the shared
  variance (_pmf_kernels.convolve_separable).
- Terrain update: one IRA (or radar-altimeter) sample: its closest point p (seed 000 eqs 14-36) from the
  INS attitude and velocity with the heading and horizontal velocity corrected by the means of u's heading
  and velocity offsets (`_reference_offsets`; shared by all cells: the PMF does not carry attitude or
  velocity hypotheses, but the INS it rides on is free, and the zero-Doppler geometry turns with its
  velocity's direction: a cross-track velocity error dv moves the closest point along track by its
  cross-track offset times dv / V; the vertical velocity's error tilts it along track: the grid carries
  the position the samples read, y = x + D beta, and the output x), one map lookup per cell, the
  heavy-tailed likelihood (measurements.robust_ll_one) with variance S = P_b + sensor + map noise and the
  per-cell bias update, fused in one numba pass over the cells (_pmf_kernels.ira_update_pass; the radar
  altimeter goes through measurements.radar_altimeter).
- GNSS: the fix's position likelihood on the grid, its height into the vertical offset, its horizontal
  velocity into the velocity offset (its vertical velocity into the INS).
- Re-gridding after an update, from the posterior's spread: the half-span follows span_sigmas times its
  largest standard deviation (spacing within [spacing_min_m, spacing_max_m], at most halved or doubled at
  a time), the centre follows the mean once it is n/8 cells away; log-densities and biases are
  interpolated (bilinear) onto the new grid. So the grid starts wide, shrinks as it converges and grows
  again where the terrain is flat.

Outputs: mean and covariance of the grid (position block, + d^2/12 per axis for the cells' width), the
vertical from the bias, the horizontal velocity from the velocity offset (the tilt, bias and heading
offsets are not in the Estimate: the yaw is the INS's), the rest from the INS error
model (terrain_filter); Estimate.extra:
the fixed update keys (navigators.protocol) and "multimodality" (density of the second-highest local
maximum of the grid over the highest: 0 for one mode, 1 for two equal ones) and "pmf_modes" (local maxima
above 1 % of the peak), "pmf_spacing_m", "pmf_grid_n".

Default IRA model: "proposed" (seed 000's); the comparison with "conventional": docs/validation/navigators.md.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.capture import capture_spec
from ..core.imu_spec import (
    G0_MPS2,
    ImuSpec,
    equivalent_walk_density,
    rss,
    vertical_offset_walk_density,
)
from ..core.measured_consistency import grade_warning
from ..inertial.strapdown import quat_to_dcm
from ..integrity import protection_level as pl
from ..measurements import gnss as gnss_model
from ..measurements import ira, radar_altimeter
from ..measurements.terrain_models import radii_m
from . import _pmf_kernels as kern
from .pmf_grid import LOG_FLOOR, PmfGrid
from .terrain_filter import InsRiddenFilter
from .terrain_filter_settings import PMF_CAPABILITIES, PmfSettings

G0 = 9.80665
PMF_MEMORY_S = 240.0        # the memory over which carried-as-constant error rates are matched (imu_spec)
TURN_REFERENCE_RAD = 0.5 * math.pi  # a turn of this angle builds the whole scale-factor / misalignment error
N_U = 8                     # u = (dvn, dve, tilt acceleration n, e, accelerometer bias x, y, heading error,
#                             vertical specific-force error)
BETA = 7                    # index in u of the vertical specific-force error
VD_STEP_MPS = 0.05          # vertical velocity step of the closest point's finite difference (m/s)


def baro_loop_velocity_response_s(t_s: float, tau_s: float | None) -> float:
    """Down-velocity error (m/s) of a baro-damped INS vertical channel (triple pole at -1 / tau, gains
    3 / tau, 3 / tau^2, 1 / tau^3: navigators.inertial.strapdown) per m/s^2 of a constant down specific-force
    error present since t = 0: the height error is h(s) = -a / (s + 1 / tau)^3 and the velocity the loop
    integrates is -(s + 3 / tau) h (its height takes the direct correction 3 / tau (h - h_baro)), so
    v(t) = a (t + t^2 / tau) exp(-t / tau), a transient peaking at t = 1.618 tau at 0.840 a tau that the
    loop's bias integrator then removes. 0 before t = 0 and without a loop."""
    if tau_s is None or not t_s > 0.0:
        return 0.0
    return float((t_s + t_s * t_s / tau_s) * math.exp(-t_s / tau_s))


def baro_loop_height_response_s2(t_s: float, tau_s: float | None) -> float:
    """Height error (INS minus true, m) of the same loop per m/s^2 of the down specific-force error
    (baro_loop_velocity_response_s): -t^2 exp(-t / tau) / 2, a transient of -0.27 tau^2 at t = 2 tau
    (navigators.core.imu_spec.ImuSpec.baro_loop_height_rate_sigma_mps)."""
    if tau_s is None or not t_s > 0.0:
        return 0.0
    return float(-0.5 * t_s * t_s * math.exp(-t_s / tau_s))


class PointMassFilter(PmfGrid, InsRiddenFilter):
    """Point-mass filter over the INS horizontal position error (see the module docstring).

    Settings (besides InsRiddenFilter's): grid_size n (cells per side, default 200), spacing_min_m,
    spacing_max_m (bounds of the cell spacing), span_sigmas (grid half-span in posterior sigmas),
    position_noise_m_per_sqrt_s (process noise: horizontal position random walk of the INS error, default
    0.1: a floor, not a model of the drift - the velocity and acceleration offsets carry that),
    velocity_noise_mps_per_sqrt_s (random walk of the velocity offset, default 0.001: the white part of
    the INS velocity error's increments), accel_bias_sigma_mps2 (1 sigma per body axis
    of the accelerometers' turn-on bias, default 50 ug: the scenario IMU's navigation grade, seed 000
    Table 2; the tilt and heading errors' priors come from the initial estimate), max_memory_mb
    (refuses a grid larger than that), measurement_rate_hz (terrain samples per second). The measurements
    behind the defaults: docs/validation/navigators.md ("Terrain filters: measured grounds of the defaults").
    """

    name = "pmf"

    settings_class = PmfSettings
    capabilities = PMF_CAPABILITIES

    _MAP_SHIFT_CARRIED = N_U             # u's means take part of the map's shift (map_shift)
    _MAP_SHIFT_VELOCITY_ROWS = (0, 1)    # u's velocity offset (dvn, dve): the published velocity's

    def __init__(self, dem=None, settings: PmfSettings | None = None, name: str | None = None, **overrides):
        super().__init__(dem=dem, settings=settings, name=name, **overrides)
        s = self.settings
        s.copy_to(self, "spacing_min_m spacing_max_m span_sigmas")
        self.position_noise = s.position_noise_m_per_sqrt_s
        self.velocity_noise = s.velocity_noise_mps_per_sqrt_s
        self.accel_bias_sigma = s.accel_bias_sigma_mps2
        self.n = s.grid_size
        self._ira_p = np.empty((1, 3))
        self._zero1 = np.zeros(1)
        self._zero12 = np.zeros((1, 2))
        self._moments_cache = None
        self._out = np.empty(14)
        self._lg = math.log1p(-self.outlier_prob)
        self._le = (math.log(self.outlier_prob) + self.log_outlier_density if self.outlier_prob > 0
                    else -np.inf)

    # ------------------------------------------------------------------------------------ IMU specification
    _imu_noise: tuple = ()  # q tilt acceleration, q accel bias, q heading, per-rad-turned tilt, heading
    _beta_sigma = 0.0       # prior of the vertical specific-force error (m/s^2; 0: not modelled)

    def apply_imu_spec(self, spec: ImuSpec) -> None:
        """Take the error model of u = (v, t, b, eps) from the IMU's specification (navigators.core.imu_spec),
        each figure a floor over the tuned setting: b's prior the body-fixed horizontal specific-force error
        (bias, instability, misalignment x g), v's random walk the velocity random walk; and as process noise
        the accelerometer instability's drive on b (2 sigma^2 / tau), the tilt acceleration's growth from the
        horizontal gyro biases (g sigma_bg) and the heading's from the z gyro bias as random walks matching
        them at PMF_MEMORY_S, and per rad turned the gyro misalignment (g x tilt on t) and scale factor (eps)
        over TURN_REFERENCE_RAD."""
        self.accel_bias_sigma = max(self.accel_bias_sigma, spec.body_accel_sigma_mps2)
        self.velocity_noise = max(self.velocity_noise, spec.accel_noise_density_mps2_rthz)
        self._tracks_turn = True
        self._beta_sigma = spec.vertical_accel_sigma_mps2 if self.ins.tau_baro_s is not None else 0.0
        self._imu_noise = (
            equivalent_walk_density(spec.tilt_accel_rate_sigma_mps3, PMF_MEMORY_S) ** 2,
            2.0 * spec.accel_bias_instability_mps2**2 / spec.accel_bias_tau_s,
            equivalent_walk_density(spec.gyro_bias_sigma_rps, PMF_MEMORY_S) ** 2,
            (G0_MPS2 * spec.turn_tilt_sigma_rad(1.0)) ** 2 * TURN_REFERENCE_RAD,
            spec.turn_heading_sigma_rad(1.0) ** 2 * TURN_REFERENCE_RAD,
        )
        # the vertical offset's walk: the tuned baro-height wander and the IMU's baro-loop transient (rss;
        # beta carries the transient, the walk stays a floor where its linear model does not hold)
        q_v = vertical_offset_walk_density(spec, self.ins.tau_baro_s)
        self.vertical_noise = rss(self.vertical_noise, q_v)
        self._consistency_warning = grade_warning(spec, PMF_MEMORY_S, self.name, capture=True)
        self._capture_spec = capture_spec(spec, PMF_MEMORY_S, self.name)

    def _capture_range_m(self) -> float:
        """The grid's half-span at its largest spacing (navigators.core.capture)."""
        return 0.5 * (self.n - 1) * self.spacing_max_m

    def _capture_floor_m2(self) -> float:
        """A cell's uniform width, d^2 / 12 per axis."""
        return self.spacing ** 2 / 12.0

    # ------------------------------------------------------------------------------------ belief

    def _u_prior_cov(self, cov9: np.ndarray) -> np.ndarray:
        """Prior covariance of u = (dvn, dve, tilt acceleration n, e, accelerometer bias x, y, heading
        error): the velocity block of cov9; g^2 times its mean roll/pitch variance; accel_bias_sigma^2;
        its yaw variance."""
        c = np.zeros((N_U, N_U))
        c[:2, :2] = np.array(cov9[3:5, 3:5], float)
        c[2, 2] = c[3, 3] = G0 ** 2 * 0.5 * (float(cov9[6, 6]) + float(cov9[7, 7]))
        c[4, 4] = c[5, 5] = self.accel_bias_sigma ** 2
        c[6, 6] = float(cov9[8, 8])
        c[BETA, BETA] = self._beta_sigma ** 2
        return c

    def _init_belief(self, cov9: np.ndarray, mean_ne=(0.0, 0.0), velocity=None) -> None:
        """The grid from cov9's horizontal block around mean_ne; the velocity and acceleration offsets'
        Gaussian u from cov9 and acceleration_sigma_mps2 (zero mean), or `velocity` = (mean (4,),
        covariance (4, 4)) kept from before (a re-spread)."""
        # C_uz: covariance of u (see _u_prior_cov) with z = (dn, de, b)
        self.C_uz = np.zeros((N_U, 3))
        if velocity is None:
            self._v_ins_prev = None
            self._D = np.zeros(2)        # the grid's shift per unit of the vertical specific-force error
            self._J = np.zeros(2)        # the closest point's horizontal shift per m/s of down velocity
            self._eta = 0.0              # the vertical offset's shift per unit of it
            self.u_mean = np.zeros(N_U)
            self.C_uu = self._u_prior_cov(cov9)
            self.C_uz[:2, :2] = np.array(cov9[3:5, 0:2], float)
        else:
            self.u_mean = np.array(velocity[0], float)
            self.C_uu = np.array(velocity[1], float)
        P = np.array(cov9[:2, :2], float)
        sig = math.sqrt(max(np.linalg.eigvalsh(P).max(), 1e-6))
        d = min(max(2.0 * self.span_sigmas * sig / (self.n - 1), self.spacing_min_m), self.spacing_max_m)
        self._set_geometry(mean_ne[0], mean_ne[1], d)
        try:
            Pi = np.linalg.inv(P + np.eye(2) * 1e-6)
        except np.linalg.LinAlgError:
            Pi = np.eye(2) / sig**2
        x = self.dn_flat - mean_ne[0]
        y = self.de_flat - mean_ne[1]
        lw = -0.5 * (Pi[0, 0] * x * x + 2 * Pi[0, 1] * x * y + Pi[1, 1] * y * y)
        self.logw = lw - lw.max()
        self.bias = np.zeros(self.n * self.n)
        self._work = np.empty((6, self.n * self.n))
        self.P_b = self.bias_prior_var()
        self._start_height_error()
        self._q_pending = np.zeros((2, 2))
        self._moments_cache = None
        self._n_underflow = 0

    def _predict_to(self, t_s: float, st: np.ndarray | None = None) -> None:
        """The INS horizontal error model over dt (u = (v, t, b, eps), see the module docstring): with
        a = t + R b the acceleration offset (R: the INS's body-to-NED matrix's horizontal block),
        x' = x + v dt + a dt^2 / 2 + w, v' = v + a dt + eps J + random walk, J = (dv_e, -dv_n) the INS
        velocity change over the step (a heading error eps = INS yaw - true yaw turns it); t, b, eps
        constant. The grid moves by the mean of x' - x (its cells are offsets: exact), the rest of the
        position growth, 2 sym(B C_ux) + B C_uu B' + q dt, is pending process noise."""
        dt = t_s - self._t_belief
        if dt > 0.0:
            R = np.eye(2)
            J = np.zeros(2)
            if st is not None and np.all(np.isfinite(st[3:10])):
                R = quat_to_dcm(st[6:10])[:2, :2]
                v_ins = np.array(st[3:5], float)
                if self._v_ins_prev is not None:
                    J = np.array([v_ins[1] - self._v_ins_prev[1], self._v_ins_prev[0] - v_ins[0]])
                self._v_ins_prev = v_ins
            B = np.zeros((2, N_U))
            B[:, 0:2] = np.eye(2) * dt
            B[:, 2:4] = np.eye(2) * (0.5 * dt * dt)
            B[:, 4:6] = R * (0.5 * dt * dt)
            F = np.eye(N_U)
            F[0:2, 2:4] = np.eye(2) * dt
            F[0:2, 4:6] = R * dt
            F[0:2, 6] = J
            self._map_shift.predict(B, F)   # the shift's share in u reaches the position (map_shift)
            shift = B @ self.u_mean
            if shift[0] != 0.0 or shift[1] != 0.0:
                self._set_geometry(self.centre_n + shift[0], self.centre_e + shift[1], self.spacing)
            C_ux = self.C_uz[:, :2]
            BC = B @ C_ux
            self._q_pending += BC + BC.T + B @ self.C_uu @ B.T + np.eye(2) * self.position_noise ** 2 * dt
            C_uz = self.C_uz.copy()
            C_uz[:, :2] = C_ux + self.C_uu @ B.T
            self.C_uz = F @ C_uz
            self.u_mean = F @ self.u_mean
            C_uu = F @ self.C_uu @ F.T
            C_uu[0, 0] += self.velocity_noise ** 2 * dt
            C_uu[1, 1] += self.velocity_noise ** 2 * dt
            if self._imu_noise:  # the IMU specification's sources (apply_imu_spec)
                turn = self._take_turn()   # integral of |yaw rate| since the last prediction (terrain_filter)
                q_t, q_b, q_eps, turn_t2, turn_h2 = self._imu_noise
                C_uu[2, 2] += q_t * dt + turn_t2 * turn
                C_uu[3, 3] += q_t * dt + turn_t2 * turn
                C_uu[4, 4] += q_b * dt
                C_uu[5, 5] += q_b * dt
                C_uu[6, 6] += q_eps * dt + turn_h2 * turn
            self.C_uu = 0.5 * (C_uu + C_uu.T)
            self._grow_offset(dt, st)
            self._t_belief = t_s
            self._moments_cache = None
            self._vertical_velocity_shift(t_s)

    def _vertical_velocity_shift(self, t_s: float) -> None:
        """Carry the vertical specific-force error beta = u[BETA] (down, m/s^2) into the grid and the vertical
        offset through the baro loop's transients.

        The baro-damped INS's down velocity is off by beta psi(t) and its height by beta eta(t)
        (baro_loop_velocity_response_s, baro_loop_height_response_s2; t since the INS's start).
        (1) The zero-Doppler plane is normal to the velocity (seed 000 eqs 9-12: its along-track axis s1
        tilts with the flight-path angle), so every IRA closest point computed from the INS velocity sits
        off by -J psi beta horizontally (J the closest point's horizontal derivative in the down velocity,
        `_J`, from the last sample): the samples read the map at y = x + D beta, D = -J psi, not at the INS
        error x. The grid carries y: as psi or J change, y moves by dD beta, a linear step like the velocity
        offsets' (mean dD E[beta], pending noise dD C_bb dD' + 2 sym(dD C_by), C_uy += C_ub dD'), and the
        output removes D beta again (`_output_moments`).
        (2) The vertical offset b (INS height minus true) moves by d_eta beta likewise (the cells' means by
        d_eta E[beta], P_b by d_eta^2 C_bb + 2 d_eta C_b,beta, C_ub += C_u,beta d_eta), which makes beta
        observable through the terrain's height.
        beta's prior is the IMU's vertical specific-force error (apply_imu_spec); 0 without a
        specification (then nothing moves)."""
        if not self._beta_sigma > 0.0:
            return
        t_rel = t_s - self._t_ins0
        D = -self._J * baro_loop_velocity_response_s(t_rel, self.ins.tau_baro_s)
        eta = baro_loop_height_response_s2(t_rel, self.ins.tau_baro_s)
        dD = D - self._D
        d_eta = eta - self._eta
        self._D, self._eta = D, eta
        m = float(self.u_mean[BETA])
        c_bb = float(self.C_uu[BETA, BETA])
        if not math.isfinite(m):
            return
        if np.all(np.isfinite(dD)) and np.any(dD):
            if m != 0.0:
                self._set_geometry(self.centre_n + dD[0] * m, self.centre_e + dD[1] * m, self.spacing)
            BC = np.outer(dD, self.C_uz[BETA, :2])
            self._q_pending += BC + BC.T + np.outer(dD, dD) * c_bb
            self.C_uz[:, :2] += np.outer(self.C_uu[:, BETA], dD)
        if d_eta != 0.0 and math.isfinite(d_eta):
            self.bias += d_eta * m
            p_b = self.P_b
            self.P_b = max(self.P_b + d_eta * d_eta * c_bb + 2.0 * d_eta * float(self.C_uz[BETA, 2]), 1e-9)
            self._height.widen(self.P_b - p_b)
            self.C_uz[:, 2] += self.C_uu[:, BETA] * d_eta
        self._moments_cache = None

    def _output_moments(self) -> tuple[np.ndarray, np.ndarray]:
        """The grid's moments with the closest points' vertical-velocity shift removed
        (`_vertical_velocity_shift`): x = y - D beta, mean - D E[beta], covariance
        + D C_bb D' - 2 sym(D C_by), its covariance with the velocity offset - C_vb D'."""
        mean, cov = self._moments()
        D = self._D
        if not np.any(D):
            return mean, cov
        mean, cov = mean.copy(), cov.copy()
        mean[:2] -= D * self.u_mean[BETA]
        X = np.outer(D, self.C_uz[BETA, :2])
        cov[:2, :2] += np.outer(D, D) * self.C_uu[BETA, BETA] - X - X.T
        cov[3:5, 0:2] -= np.outer(self.C_uu[:2, BETA], D)
        cov[0:2, 3:5] = cov[3:5, 0:2].T
        return mean, cov

    def _pl_points(self, risk: float):
        """The grid's points (pmf_grid) moved by -D E[beta], the pad widened by D C_bb D'
        (`_output_moments`)."""
        dn, de, w, pad = super()._pl_points(risk)
        D = self._D
        if not np.any(D):
            return dn, de, w, pad
        m = float(self.u_mean[BETA])
        q = self._q_pending + np.outer(D, D) * self.C_uu[BETA, BETA]
        pad = 0.5 * math.sqrt(2.0) * self.spacing + pl.gaussian_hpl(q, risk)
        return dn - D[0] * m, de - D[1] * m, w, pad

    def _velocity_from_position(self, prior: tuple, post: tuple) -> np.ndarray | None:
        """The velocity and acceleration offsets u after an update of the grid (terrain or GNSS position and
        height): p(u | z), z = (dn, de, b), is the prior's Gaussian regression u = u_mean + G (z - z_mean),
        G = C_uz C_zz^-1, which a measurement of z alone leaves unchanged, so the grid's posterior moments
        carry it over: u_mean += G (z+ - z-), C_uu += G (C_zz+ - C_zz-) G', C_uz = G C_zz+ (exact for a
        Gaussian z). Returns G (N_U x 3; None: moments not finite, u left as it was)."""
        (m0, c0), (m1, c1) = prior, post
        if not (np.all(np.isfinite(c0)) and np.all(np.isfinite(c1))):
            return None
        try:
            G = np.linalg.solve(c0, self.C_uz.T).T
        except np.linalg.LinAlgError:
            return None
        self.u_mean = self.u_mean + G @ (m1 - m0)
        C_uu = self.C_uu + G @ (c1 - c0) @ G.T
        self.C_uu = 0.5 * (C_uu + C_uu.T)
        self.C_uz = G @ c1
        self._moments_cache = None
        return G

    def _reference_offsets(self) -> tuple[np.ndarray, np.ndarray]:
        """(heading turn (1,), velocity offset (1, 2)) of the IRA closest point's geometry: the INS's
        heading and velocity corrected by the velocity-heading Gaussian's means (true heading = INS yaw -
        eps, true velocity = INS + v)."""
        dpsi, dv = self._zero1, self._zero12
        if np.all(np.isfinite(self.u_mean)):
            dpsi = np.array([-self.u_mean[6]])
            dv = self.u_mean[None, :2].copy()
        return dpsi, dv

    # ------------------------------------------------------------------------------------ updates
    def _terrain_update(self, t_s, kind, range_m, theta_rad, st, var_sensor) -> None:
        lat, lon, h = float(st[0]), float(st[1]), float(st[2])
        r_lat, r_lon = radii_m(lat, h)
        m = self.n * self.n
        C = quat_to_dcm(st[6:10])
        if kind == "ira":
            dpsi, dv_ne = self._reference_offsets()
            v_ned = np.ascontiguousarray(st[3:6], dtype=float)
            nb = ira.closest_points(range_m, theta_rad, C, v_ned, dpsi, dv_ne, self.ira_code, self._ira_p)
            if nb:
                self.health.skip(t_s, "ira_geometry", "IRA sample with no closest-point solution")
                return
            p = self._ira_p[0]
            if self._beta_sigma > 0.0:   # the closest point's derivative in the down velocity
                v_ned = v_ned.copy()
                v_ned[2] += VD_STEP_MPS
                p2 = np.full((1, 3), np.nan)
                ira.closest_points(range_m, theta_rad, C, v_ned, dpsi, dv_ne, self.ira_code, p2)
                J = (p2[0, :2] - p[:2]) / VD_STEP_MPS
                # the tilt moves the point by at most about R / V_h per m/s: a larger step is a change of
                # the closest point's branch, not its derivative (the previous J kept)
                j_max = 2.0 * range_m / max(math.hypot(v_ned[0], v_ned[1]), 1.0)
                if np.all(np.isfinite(J)) and math.hypot(J[0], J[1]) <= j_max:
                    self._J = J
                self._vertical_velocity_shift(t_s)
        elif self._beta_sigma > 0.0:     # the altimeter's range does not depend on the velocity
            self._J = np.zeros(2)
            self._vertical_velocity_shift(t_s)
        self._apply_process_noise()
        prior = self._position_moments()
        if kind == "ira":
            h_meas = h - p[2]          # seed 000 eq 2
            S = self.P_b + float(self.ira_variance(range_m, p[2], math.hypot(p[0], p[1])))
            saved = (self.logw.copy(), self.bias.copy())
            o = self._out
            kern.ira_update_pass(self._map_record(), (lat, lon, r_lat, r_lon),
                                 (self.dn_flat, self.de_flat, self.logw, self.bias),
                                 (float(p[0]), float(p[1]), h_meas, S, self.P_b / S),
                                 (self._lg, self._le, LOG_FLOOR), self._work[0], o)
            n_nan = int(o[3])
            if n_nan == m or not np.isfinite(o[4]) or self._belief_without_map(t_s, "IRA", float(o[13])):
                self.logw, self.bias = saved
                if n_nan == m:
                    self._degrade(t_s, "grid_off_map", "IRA update skipped: the whole grid is off the map")
                elif not np.isfinite(o[4]):
                    self._underflow(t_s, "IRA update")
                    self._integrity_test(t_s, math.inf, 1)
                return
            self._n_underflow = 0
            log_lik, pred_mean, pred_var = float(o[0]), float(o[1]), float(o[2])
            c = np.array([[o[7], o[8]], [o[8], o[9]]]) + np.eye(2) * self.spacing ** 2 / 12.0
            self._height.terrain(float(o[12]) * self.P_b / S, S - self.P_b)
            self.P_b *= (1.0 - float(o[12]) * self.P_b / S)   # as much as the sample is believed an inlier
            self._moments_cache = (float(o[5]), float(o[6]), c, float(o[10]), self.P_b + float(o[11]))
        else:
            var = self.ra_variance()
            rng_pred = np.empty(m)
            n_nan = radar_altimeter.predict(self._map_record(bilinear=True), lat, lon, r_lat, r_lon, h,
                                            self.dn_flat, self.de_flat, self.bias, C, self._zero1,
                                            self.ra_half_beam_rad, self.ra_cone_rings, 12, rng_pred)
            if n_nan == m:
                self._degrade(t_s, "grid_off_map", "altimeter update skipped: the whole grid is off the map")
                return
            if n_nan and self._belief_without_map(t_s, "altimeter",
                                                  float(self._weights()[~np.isfinite(rng_pred)].sum())):
                return
            h_meas = h - range_m       # seed 000 eq 1: terrain height below the aircraft
            pred = h - rng_pred        # terrain height that hypothesis predicts (bias included)
            resid = h_meas - pred
            S = self.P_b + var
            ll = np.empty(m)
            radar_altimeter.likelihood(resid, np.array([S]), self.outlier_prob, self.log_outlier_density, ll)
            pred_mean, pred_var = kern.predicted_moments(self.logw, pred)
            with np.errstate(invalid="ignore", over="ignore"):
                gauss = self._lg - 0.5 * (resid * resid / S + math.log(S) + math.log(2 * math.pi))
                gam = np.where(np.isfinite(resid), np.exp(np.minimum(gauss - ll, 0.0)), 0.0)
            log_lik = self._apply_loglik(t_s, ll, "altimeter update")
            if log_lik is None:
                self._integrity_test(t_s, math.inf, 1)
                return
            kern.bias_update(self.bias, gam * resid, self.P_b / S)
            g_mean = float(self._weights() @ gam)
            self._height.terrain(g_mean * self.P_b / S, var)
            self.P_b *= (1.0 - g_mean * self.P_b / S)
            self._moments_cache = None
        post = self._position_moments()
        G = self._velocity_from_position(prior, post)
        self._map_shift.terrain(prior[1], post[1], None if G is None else G[:, :2])
        self._set_update_extra(t_s, [h_meas - pred_mean], [[pred_var + S]], log_lik)
        if n_nan:
            self.health.skip(t_s, "cells_off_map", f"{n_nan} grid cells off the map (outlier density only)")
        if self.health.status == "degraded" and not self.integrity.degraded:
            self.health.status = "acquiring"
        self._regrid()

    def _gnss_update(self, t_s, st, payload) -> None:
        lat, lon, h, v = payload
        sigma_shift = self._map_shift_sigma_m()
        carried = self._map_shift.carried_covariances(sigma_shift) if sigma_shift > 0.0 else None
        widen = self._shift_into_belief()      # the map shift's share, convolved in with the process noise
        if widen is not None:
            self._q_pending = self._q_pending + widen
            c_ux, c_uu = carried               # and u's share: [A; U] sigma_h^2 [A; U]' (map_shift)
            self.C_uz = self.C_uz.copy()
            self.C_uz[:, :2] += c_ux
            self.C_uu = self.C_uu + c_uu
        self._apply_process_noise()
        prior = self._position_moments()
        gn, ge = gnss_model.predict(st, lat, lon)
        s2 = self.gnss_sigma_m ** 2
        sh = self._D * self.u_mean[BETA]     # the fix sees x = y - D beta (_vertical_velocity_shift)
        ll = (gnss_model.likelihood(gn, ge, self.dn_flat - sh[0], self.de_flat - sh[1], self.gnss_sigma_m)
              - math.log(2 * math.pi * s2))
        if self._apply_loglik(t_s, ll, "GNSS update") is None:
            return
        z_b = float(st[2]) - h      # INS minus GNSS height = b + noise
        p_h, p_m = self._gnss_offset_split()    # the map's part of b is not seen by GNSS (terrain_filter)
        if p_m > 0.0:
            K = p_h / (p_h + self.gnss_vertical_sigma_m ** 2)
            self.bias += K * (z_b - self.bias)
            self.P_b = p_h * (1.0 - K) + p_m
            self._height.gnss(K, self.gnss_vertical_sigma_m ** 2)
        else:
            S = self.P_b + self.gnss_vertical_sigma_m ** 2
            K = self.P_b / S
            self.bias += K * (z_b - self.bias)
            self.P_b *= (1.0 - K)
        self._moments_cache = None
        self._velocity_from_position(prior, self._position_moments())
        self._gnss_velocity(st, v)
        self._gnss_velocity_ins(v, carried=(0, 1))
        # the receiver drift the fixes share: convolved in with the next process noise (terrain_filter)
        self._q_pending = self._q_pending + np.diag(self._gnss_drift_deficit())
        if self.health.status == "degraded" and not self.integrity.degraded:
            self.health.status = "acquiring"
        self._regrid()

    def _gnss_velocity(self, st: np.ndarray, v_gnss: np.ndarray) -> None:
        """GNSS horizontal velocity into the velocity (and through it the acceleration) offset (Kalman
        update, z = v_GNSS - v_INS = H u + noise, H = [I 0]); its position part moves the grid by
        C_xv S^-1 (z - v_mean) (the grid's spread is not narrowed by it: conservative, C_xv S^-1 C_vx is
        at most centimetres^2 next to the GNSS position fix's)."""
        if not np.all(np.isfinite(v_gnss[:2])):
            return
        z = np.asarray(v_gnss[:2], float) - np.asarray(st[3:5], float)
        C_uv = self.C_uu[:, :2]
        S = C_uv[:2] + np.eye(2) * self.gnss_velocity_sigma_mps ** 2
        r = np.linalg.solve(S, z - self.u_mean[:2])
        dx = self.C_uz[:2, :2].T @ r
        self.u_mean = self.u_mean + C_uv @ r
        K = C_uv @ np.linalg.inv(S)
        self.C_uz = self.C_uz - K @ self.C_uz[:2]
        C_uu = self.C_uu - K @ C_uv.T
        self.C_uu = 0.5 * (C_uu + C_uu.T)
        if np.all(np.isfinite(dx)):
            self._set_geometry(self.centre_n + dx[0], self.centre_e + dx[1], self.spacing)
        self._moments_cache = None

    def _recover(self, t_s: float) -> str:
        """The grid re-spread around its mean (spacing from the widened spread; the vertical offset kept)."""
        mean, c9 = self._recovery_cov9()
        # the velocity offset learnt from the data the test rejected is suspect too: its spread widened by
        # the initial one (the mean kept)
        self._init_belief(c9, (float(mean[0]), float(mean[1])),
                          velocity=(self.u_mean, self.C_uu + self._u_prior_cov(self._init_cov9)))
        self.bias[:] = mean[2]
        return (f"grid re-spread around its mean, 1-sigma {math.sqrt(0.5 * np.trace(c9[:2, :2])):.0f} m, "
                f"spacing {self.spacing:.1f} m")
