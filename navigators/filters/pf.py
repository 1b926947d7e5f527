"""Particle filter (`pf`): bootstrap / SIR over the INS error state, riding on the INS.

Particle state (M particles, contiguous arrays): horizontal position offset dn, de (true minus INS, m),
horizontal velocity offset dv (m/s) and heading offset dpsi (rad), and the vertical offset b (INS height
minus true: baro and map bias, m) Rao-Blackwellised as in the PMF: each particle carries b's mean, the
variance P_b is shared (the measurements are the same for all particles, so is the gain), and each terrain
sample's likelihood has variance S + P_b. Sampled, b took most of each update's weight spread (it is
measured by every sample), so the cloud degenerated faster. The INS itself is never corrected; the estimate
is INS + the weighted mean.

- Propagation (navigators.filters._pf_kernels.propagate_particles): the INS error dynamics between
  measurement epochs - position from velocity, velocity from the heading error turning the specific force
  and the Schuler term on the position error built since the INS's alignment (not the initial error,
  which the alignment's tilt cancels) - plus process noise drawn from the filter's Generator; its
  densities come from the IMU's specification (apply_imu_spec, navigators.core.imu_spec): with
  velocity_noise_model "imu_spec" (default) the velocity's noise is the effect on the velocity the cloud
  holds of the acceleration error the particles do not carry (`_velocity_step_var`); with "walk" that error
  enters as an equivalent velocity random walk, a floor over the tuned setting.
- Terrain update: each particle's IRA closest point from its own heading and velocity (seed 000 eqs 14-36,
  or eqs 9-13 with ira_formula="conventional"; navigators.measurements.ira.closest_points), one map lookup
  per particle, the heavy-tailed mixture likelihood (one bad return cannot kill the cloud); radar
  altimeter: the shortest in-cone return under the particle's heading (measurements.radar_altimeter.
  predict). Log-weights, normalised by their maximum; log p(z | past) by logsumexp.
- Acquisition (opt-in, acquisition_particles): from each reset the cloud holds acquisition_particles and
  is resampled down to n_particles once its horizontal spread is below acquisition_spread_m (`_handover`),
  as the rbpf's; a recovery's re-spread keeps the cloud's current size.
- Resampling: systematic (navigators.core.resampling) when the effective sample size falls below
  ess_threshold * M, then a kernel jitter against sample impoverishment at Gordon et al.'s (1993) roughening
  scale (roughening * M^(-1/d) times the cloud's span, d = 6) but with Liu & West's (2001) shrinkage, so the
  jitter keeps the cloud's mean and covariance (`_regularise`); Gordon's jitter adds its variance at each
  resampling, a process noise the INS error does not have.
- GNSS: the horizontal position and velocity by an ensemble Kalman update of the particles
  (velocity_noise_model "imu_spec", default: `_gnss_ensemble_update`) or by their likelihoods ("walk");
  the height's likelihood on the particles' vertical offsets; the vertical velocity into the INS.
- Robustness: a NaN sample is skipped; when every particle's likelihood underflows (possible only with
  outlier_prob = 0, or a cloud entirely off the map) the update is skipped and Health says "degraded";
  ten in a row re-draw the cloud around its mean with the initial spread.

Estimate.extra: the fixed update keys of navigators.protocol, including "ess" (before resampling), and
"pf_resampled" (resamplings so far). Randomness: `rng` (numpy Generator; trn_env passes the scenario's
`navigator` stream), so a scenario seed fixes the run bit for bit; rng=None uses default_rng(0).
Nothing is kept per step: the cloud is a fixed set of arrays of M rows.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.capture import CAPTURE_SIGMAS, capture_spec
from ..core.imu_spec import (
    G0_MPS2,
    ImuSpec,
    equivalent_ramp_walk_density,
    equivalent_walk_density,
    rss,
    vertical_offset_walk_density,
)
from ..core.measured_consistency import grade_warning
from ..core.resampling import systematic_kernel
from ..inertial.strapdown import quat_to_dcm
from ..measurements import gnss as gnss_model
from ..measurements import ira, radar_altimeter
from ..measurements.terrain_models import radii_m
from ..protocol import EXTRA_ESS
from ._pf_kernels import propagate_particles
from .terrain_filter import MAX_RECOVERY_DOUBLINGS, InsRiddenFilter
from .terrain_filter_settings import PF_CAPABILITIES, PfSettings

PF_MEMORY_S = 120.0  # memory over which the error sources the particles do not carry are matched
N_STATE = 6


def _erfinv_approx(y: float) -> float:
    """erfinv(y) for y in (0, 1) (scipy-free: Newton on math.erf from Winitzki's approximation)."""
    a = 0.147
    ln = math.log(1.0 - y * y)
    t = 2.0 / (math.pi * a) + 0.5 * ln
    x = math.copysign(math.sqrt(math.sqrt(t * t - ln / a) - t), y)
    for _ in range(3):
        x -= (math.erf(x) - y) / (2.0 / math.sqrt(math.pi) * math.exp(-x * x))
    return x


class ParticleFilter(InsRiddenFilter):
    """SIR particle filter over the INS error state (see the module docstring).

    Settings (besides InsRiddenFilter's): n_particles (default 10,000), ess_threshold (in (0, 1]: resample
    when ESS < ess_threshold * n_particles), roughening (>= 0, Gordon's K setting the jitter's scale, see
    the module docstring; default 0.1: smaller leaves the cloud impoverished), position_noise_m_per_sqrt_s
    (default 0.1, a floor as the PMF's), velocity_noise_mps_per_sqrt_s (default 0.02: the particles'
    velocity offsets need the diversity, learnt only through the weights and resampling),
    velocity_noise_model ("imu_spec", default: `_velocity_step_var`, GNSS by `_gnss_ensemble_update`; or
    "walk": the random walk, the specification's equivalent walk as a floor),
    heading_noise_rad_per_sqrt_s (process noise), acquisition_particles and acquisition_spread_m (a larger
    cloud from each reset until it has converged: `_handover`; 0, off, by default), max_memory_mb, rng. The
    measurements behind the defaults:
    docs/validation/navigators.md ("Terrain filters: measured grounds of the defaults").
    """

    name = "pf"

    settings_class = PfSettings
    capabilities = PF_CAPABILITIES

    def __init__(self, dem=None, rng: np.random.Generator | None = None, settings: PfSettings | None = None,
                 name: str | None = None, **overrides):
        if rng is not None and not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator or None, got {type(rng).__name__}")
        super().__init__(dem=dem, settings=settings, name=name, **overrides)
        s = self.settings
        s.copy_to(self, "ess_threshold roughening")
        self.s_pos = s.position_noise_m_per_sqrt_s
        self.s_vel = s.velocity_noise_mps_per_sqrt_s
        self.s_psi = s.heading_noise_rad_per_sqrt_s
        self._imu_spec: ImuSpec | None = None
        self._spec_velocity = s.velocity_noise_model == "imu_spec"
        self._accel_model: tuple[float, float, float, float] | None = None  # set by reset ("imu_spec")
        self._t_ins0_s = 0.0
        self._t_fix_s: float | None = None   # the last GNSS velocity fix ("imu_spec", `_velocity_step_var`)
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.n_particles = s.n_particles
        # a reset starts with the acquisition's cloud (_handover ends it); off: n_particles throughout
        self.n_acquisition = max(s.acquisition_particles, s.n_particles)
        self.acquisition_spread_m = s.acquisition_spread_m
        self._allocate(s.n_particles)
        self._init_cov = np.eye(9)
        self._moments_cache = None
        self.n_resampled = 0
        self._v_prev = None

    def _allocate(self, M: int) -> None:
        """Particle arrays and scratch for a cloud of M particles."""
        self.M = M
        self.dn = np.zeros(M)
        self.de = np.zeros(M)
        self.b = np.zeros(M)
        self.dv = np.zeros((M, 2))
        self.dpsi = np.zeros(M)
        # the part of (dn, de) the INS built since its alignment, which the Schuler term acts on
        # (_pf_kernels.propagate_particles): 0 at a reset, carried through resampling, not jittered
        self.sn = np.zeros(M)
        self.se = np.zeros(M)
        self.logw = np.zeros(M)
        self._P = np.empty((M, 3))
        self._hmap = np.empty(M)
        self._ll = np.empty(M)
        self._idx = np.empty(M, np.int64)
        self._moments_cache = None

    # ------------------------------------------------------------------------------------ belief
    def apply_imu_spec(self, spec: ImuSpec) -> None:
        """Take the error model from the IMU's specification (navigators.core.imu_spec). The particles carry
        position, velocity and heading offsets, not the acceleration error. velocity_noise_model "walk":
        the acceleration errors enter as an equivalent velocity random walk matching them at
        PF_MEMORY_S, a floor over the tuned setting - the body-fixed specific-force error (accelerometer
        bias, instability, misalignment x g) and a 90 deg turn's gyro misalignment (g x tilt) as constant
        accelerations, the tilt the horizontal gyro biases build as a ramp (g sigma_bg t:
        equivalent_ramp_walk_density), with the velocity random walk. "imu_spec" (default): the velocity's
        noise is that error's effect on the velocity the cloud holds (`_velocity_step_var`, the initial
        tilt x g added to the constant part). The heading's random walk matches the z gyro bias and a 90 deg
        turn's scale factor at PF_MEMORY_S, with the angle random walk, as a floor over the tuned setting."""
        self._imu_spec = spec
        if not self._spec_velocity:
            a = rss(spec.body_accel_sigma_mps2, G0_MPS2 * spec.turn_tilt_sigma_rad(0.5 * math.pi))
            tilt = equivalent_ramp_walk_density(spec.tilt_accel_rate_sigma_mps3, PF_MEMORY_S)
            self.s_vel = max(self.s_vel, rss(equivalent_walk_density(a, PF_MEMORY_S), tilt,
                                             spec.accel_noise_density_mps2_rthz))
        r_psi = rss(spec.gyro_bias_sigma_rps, spec.turn_heading_sigma_rad(0.5 * math.pi) / PF_MEMORY_S)
        self.s_psi = max(self.s_psi, rss(equivalent_walk_density(r_psi, PF_MEMORY_S),
                                         spec.gyro_noise_density_rps_rthz))
        # the vertical offset's walk: the tuned baro-height wander and the IMU's baro-loop transient (rss)
        q_v = vertical_offset_walk_density(spec, self.ins.tau_baro_s)
        self.vertical_noise = rss(self.vertical_noise, q_v)
        self._consistency_warning = grade_warning(spec, PF_MEMORY_S, self.name, capture=True)
        self._capture_spec = capture_spec(spec, PF_MEMORY_S, self.name)

    def _capture_range_m(self) -> float:
        """CAPTURE_SIGMAS times the widest re-spread of the recovery policy (navigators.core.capture)."""
        return CAPTURE_SIGMAS * self.recovery_sigma_m * 2.0 ** (MAX_RECOVERY_DOUBLINGS - 1)

    def reset(self, initial) -> None:
        if self.M != self.n_acquisition:
            self._allocate(self.n_acquisition)
        super().reset(initial)
        self._t_ins0_s = float(initial.t_s)
        self._t_fix_s = None
        spec = self._imu_spec
        if spec is None or not self._spec_velocity:
            self._accel_model = None
            return
        tilt0 = math.sqrt(max(0.5 * float(self._p_att0[0] + self._p_att0[1]), 0.0))   # initial tilt (rad)
        a = rss(spec.body_accel_sigma_mps2, G0_MPS2 * spec.turn_tilt_sigma_rad(0.5 * math.pi),
                G0_MPS2 * tilt0)
        v0 = max(0.5 * float(self._p_vel0[0] + self._p_vel0[1]), 0.0)                  # initial velocity
        self._accel_model = (spec.accel_noise_density_mps2_rthz ** 2, a * a,
                             spec.tilt_accel_rate_sigma_mps3 ** 2, v0)

    def _velocity_step_var(self, t_s: float, dt: float) -> float:
        """Variance (m^2/s^2 per axis) the particles' velocity offsets gain over dt ending at t_s.

        Without the IMU's specification: velocity_noise_mps_per_sqrt_s^2 dt. With it: the acceleration
        error the particles do not carry, a(t) = a0 + j t (a0 ~ sigma_a, a constant; j = g sigma_bg, the
        gyro-bias tilt's ramp; t since the reset; variance sigma_acc^2 = sigma_a^2 + sigma_j^2 t^2), moves the
        velocity error by a dt per step, correlated with the velocity error v it built: the step adds
        2 rho sigma_v sigma_acc dt + sigma_acc^2 dt^2 + N^2 dt, sigma_v the cloud's velocity sigma (the larger
        axis). rho is the correlation of v and a in the free INS, which starts with an independent v0
        (sigma_v0, the initial velocity's): cov = sigma_a^2 t + sigma_j^2 t^3 / 2, var v = sigma_v0^2 + N^2 t
        + sigma_a^2 t^2 + sigma_j^2 t^4 / 4. An unobserved velocity (sigma_v the free INS's) thus grows
        exactly as the free INS's velocity error (Titterton & Weston 2004, sec. 12.3, without Schuler's
        bound), and a velocity the terrain has told apart gains less, with its smaller sigma. A random walk
        of fixed density (the equivalent walk at one memory) cannot do both: fitted at a memory it is too
        small for an unobserved velocity and too large for an observed one. The growth scales with the
        cloud's own spread, so that spread must be the posterior's: a GNSS fix enters by the ensemble
        update (`_gnss_ensemble_update`), not by resampling on its sharp likelihood, which left a few
        particles' spread, and a GNSS velocity fix restarts the free INS there (its posterior velocity
        variance as v0, t_f the fix): cov = sigma_a^2 tau + sigma_j^2 t (t_f tau + tau^2 / 2), var v = v0^2 +
        N^2 tau + sigma_a^2 tau^2 + sigma_j^2 (t_f tau + tau^2 / 2)^2, tau = t - t_f (the ramp's acceleration
        j t keeps its time since the reset)."""
        model = self._accel_model
        if model is None:
            return self.s_vel * self.s_vel * dt
        n2, a2, j2, v02 = model
        t = max(t_s - self._t_ins0_s, 0.0)
        w = self._weights()
        d = self.dv - w @ self.dv
        sigma_v = math.sqrt(max(float(np.max(w @ (d * d))), 0.0))
        acc2 = a2 + j2 * t * t
        if self._t_fix_s is None:
            cov_free = a2 * t + 0.5 * j2 * t ** 3
            var_free = v02 + n2 * t + a2 * t * t + 0.25 * j2 * t ** 4
        else:     # since the last GNSS velocity fix at tf (v02 its posterior): the same free INS from there
            tf = max(self._t_fix_s - self._t_ins0_s, 0.0)
            tau = max(t - tf, 0.0)
            ramp = tf * tau + 0.5 * tau * tau
            cov_free = a2 * tau + j2 * t * ramp
            var_free = v02 + n2 * tau + a2 * tau * tau + j2 * ramp * ramp
        rho = min(cov_free / math.sqrt(var_free * acc2), 1.0) if var_free * acc2 > 0.0 else 0.0
        return n2 * dt + 2.0 * rho * sigma_v * math.sqrt(acc2) * dt + acc2 * dt * dt

    def _init_belief(self, cov9: np.ndarray, mean=None) -> None:
        self._init_cov = np.array(cov9, float)
        M = self.M
        z = self.rng.standard_normal((M, N_STATE))
        c = np.zeros((N_STATE, N_STATE))
        c[:2, :2] = cov9[:2, :2]
        c[2, 2] = self.bias_prior_var()
        c[3:5, 3:5] = cov9[3:5, 3:5]
        c[5, 5] = cov9[8, 8]
        w, V = np.linalg.eigh(0.5 * (c + c.T))
        x = z @ (V * np.sqrt(np.clip(w, 0.0, None))).T
        if mean is not None:
            x += mean
        self.dn[:] = x[:, 0]
        self.de[:] = x[:, 1]
        # the vertical offset is Rao-Blackwellised: each particle carries its mean, the variance P_b is
        # shared (the measurements are the same for all particles, so is the Kalman gain), as in the PMF
        self.b[:] = 0.0 if mean is None else float(mean[2])
        self.P_b = float(c[2, 2])
        self._start_height_error()
        self.dv[:] = x[:, 3:5]
        self.dpsi[:] = x[:, 5]
        if mean is None:        # a reset: the INS is aligned now
            self.sn[:] = 0.0
            self.se[:] = 0.0
        else:                   # a re-draw: the INS keeps its alignment, each particle the cloud's mean drift
            w = self._weights()
            self.sn = np.full(M, float(w @ self.sn))
            self.se = np.full(M, float(w @ self.se))
        self.logw[:] = 0.0
        self._moments_cache = None
        self._n_underflow = 0
        self._v_prev = None

    def _predict_to(self, t_s: float, st: np.ndarray | None = None) -> None:
        dt = t_s - self._t_belief
        if st is not None:
            v = np.array(st[3:5], float)
            f_n = f_e = 0.0
            if self._v_prev is not None and dt > 1e-6:
                f_n, f_e = (v - self._v_prev) / dt   # horizontal specific force ~ INS acceleration
            self._v_prev = v
        else:
            f_n = f_e = 0.0
        if dt <= 0.0:
            return
        lat = float(st[0]) if st is not None else 0.6
        g_over_r = 9.81 / float(radii_m(lat, 0.0)[0])
        z = self.rng.standard_normal((self.M, N_STATE))
        s_vel = float(self.s_vel)
        if self._accel_model is not None:      # velocity_noise_model "imu_spec"
            s_vel = math.sqrt(self._velocity_step_var(t_s, dt) / dt)
        propagate_particles((self.dn, self.de, self.b, self.dv, self.dpsi, self.sn, self.se), dt,
                            (float(f_n), float(f_e), g_over_r),
                            (float(self.s_pos), s_vel, float(self.s_psi), 0.0), z)
        self._grow_offset(dt, st)
        self._t_belief = t_s
        self._moments_cache = None

    def _weights(self) -> np.ndarray:
        w = np.exp(self.logw - self.logw.max())
        return w / w.sum()

    def _pl_points(self, risk: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """The particles' horizontal errors and weights (no pad)."""
        return self.dn, self.de, self._weights(), 0.0

    def _apply_loglik_b(self, t_s: float, ll: np.ndarray, what: str, gam_resid: np.ndarray, gam: np.ndarray,
                        S: float) -> tuple[float, float] | None:
        """`_apply_loglik` of a measurement of the vertical offset (variance S including P_b): each
        particle's offset mean moves by its Kalman gain P_b / S times its residual, weighted by the
        probability gam that the sample is an inlier there (an outlier does not drag it), and P_b shrinks
        by the posterior mean of gam (as the PMF's cells)."""
        gain = self.P_b / S
        b_new = self.b + gain * gam_resid
        g_mean = None
        new = self.logw + ll
        if np.isfinite(new.max()):
            w = np.exp(new - new.max())
            g_mean = float(w @ gam / w.sum())
        out = self._apply_loglik(t_s, ll, what, b_new)
        if out is not None and g_mean is not None:
            self._height.terrain(g_mean * gain, S - self.P_b)
            self.P_b *= (1.0 - g_mean * gain)
        return out

    def _apply_loglik(self, t_s: float, ll: np.ndarray, what: str,
                      b_new: np.ndarray | None = None) -> tuple[float, float] | None:
        """logw += ll, ESS, resampling; (log p(z | past), ESS before resampling) or None if skipped.
        b_new: the particles' vertical offset means after this measurement (set before resampling)."""
        new = self.logw + ll
        mx = new.max()
        if not np.isfinite(mx):
            self._n_underflow += 1
            self._degrade(t_s, "likelihood_underflow", f"{what}: every particle's likelihood underflowed "
                          f"(update skipped, {self._n_underflow} in a row)")
            if self._n_underflow >= 10:
                mean, _ = self._moments()
                self._init_belief(self._init_cov, np.nan_to_num(mean))
                self._degrade(t_s, "reinitialised", "particles re-drawn around the mean after repeated "
                              "underflows")
            return None
        w0 = self._weights()
        lm = ll.max()
        log_lik = float(lm + np.log(np.sum(w0 * np.exp(ll - lm))))
        if b_new is not None:
            self.b = np.ascontiguousarray(b_new)
        self.logw = new - mx
        w = np.exp(self.logw)
        w /= w.sum()
        ess = float(1.0 / np.sum(w * w))
        self._n_underflow = 0
        self._moments_cache = None
        if ess < self.ess_threshold * self.M:
            self._resample(w)
        return log_lik, ess

    def _resample(self, w: np.ndarray) -> None:
        systematic_kernel(w, float(self.rng.random()), self._idx)
        i = self._idx
        self.dn = self.dn[i]
        self.de = self.de[i]
        self.b = self.b[i]
        self.dv = np.ascontiguousarray(self.dv[i])
        self.dpsi = self.dpsi[i]
        self.sn = self.sn[i]
        self.se = self.se[i]
        self.logw[:] = 0.0
        self.n_resampled += 1
        if self.roughening > 0.0:
            self._regularise()
        self._moments_cache = None

    def _regularise(self) -> None:
        """Kernel jitter against impoverishment that keeps the cloud's mean and covariance (Liu & West
        2001's shrinkage): x <- a x + (1 - a) mean + h N(0, Sigma), a = sqrt(1 - h^2), Sigma the resampled
        cloud's covariance. h is Gordon et al.'s roughening scale for this cloud, roughening M^(-1/d) times
        a Gaussian cloud's span in sigmas (~7.8 at M = 10,000). Gordon's own jitter adds that variance on top
        (h^2 Sigma at every resampling, ~3 % at the defaults): a process noise the INS error does not have,
        which leaves the reported covariance larger than the error."""
        M = self.M
        X = np.stack([self.dn, self.de, self.b, self.dv[:, 0], self.dv[:, 1], self.dpsi], axis=1)
        mean = X.mean(axis=0)
        D = X - mean
        cov = D.T @ D / M
        span_sigmas = 2.0 * math.sqrt(2.0) * _erfinv_approx(1.0 - 1.0 / M)
        h = min(self.roughening * M ** (-1.0 / N_STATE) * span_sigmas, 0.5)
        a = math.sqrt(1.0 - h * h)
        w, V = np.linalg.eigh(0.5 * (cov + cov.T))
        L = V * np.sqrt(np.clip(w, 0.0, None))
        z = self.rng.standard_normal((M, N_STATE))
        X = a * X + (1.0 - a) * mean + h * (z @ L.T)
        self.dn = np.ascontiguousarray(X[:, 0])
        self.de = np.ascontiguousarray(X[:, 1])
        self.b = np.ascontiguousarray(X[:, 2])
        self.dv = np.ascontiguousarray(X[:, 3:5])
        self.dpsi = np.ascontiguousarray(X[:, 5])

    # ------------------------------------------------------------------------------------ updates
    def _terrain_update(self, t_s, kind, range_m, theta_rad, st, var_sensor) -> None:
        prior = self._shift_prior()
        self._terrain_update_cloud(t_s, kind, range_m, theta_rad, st)
        self._shift_after(prior)
        self._handover()

    def _handover(self) -> None:
        """The acquisition over: once the acquisition's cloud (acquisition_particles) has a horizontal spread
        below acquisition_spread_m it is resampled (systematic, by weight) down to n_particles and
        regularised as after any resampling. A 1 km prior collapsing onto ~10 m leaves a cloud of n particles
        few distinct ancestors, whose velocities are then a few draws of the prior's; the larger cloud keeps
        enough of them through the collapse, and the tracking after it needs only n."""
        if self.M <= self.n_particles:
            return
        w = self._weights()
        d_n = self.dn - w @ self.dn
        d_e = self.de - w @ self.de
        if not math.sqrt(max(float(w @ (d_n * d_n + d_e * d_e)), 0.0)) < self.acquisition_spread_m:
            return
        n, m = self.n_particles, self.M
        cw = np.cumsum(w)
        u = (float(self.rng.random()) + np.arange(n)) / n
        i = np.minimum(np.searchsorted(cw, u * cw[-1], side="left"), m - 1)
        kept = (self.dn[i], self.de[i], self.b[i], self.dv[i], self.dpsi[i], self.sn[i], self.se[i])
        self._allocate(n)
        self.dn, self.de, self.b, self.dpsi, self.sn, self.se = (np.ascontiguousarray(x) for x in (
            kept[0], kept[1], kept[2], kept[4], kept[5], kept[6]))
        self.dv = np.ascontiguousarray(kept[3])
        self.n_resampled += 1
        if self.roughening > 0.0:
            self._regularise()
        self._moments_cache = None

    def _terrain_update_cloud(self, t_s, kind, range_m, theta_rad, st) -> None:
        lat, lon, h = float(st[0]), float(st[1]), float(st[2])
        r_lat, r_lon = radii_m(lat, h)
        C = quat_to_dcm(st[6:10])
        M = self.M
        if kind == "ira":
            nb = ira.closest_points(range_m, theta_rad, C, np.ascontiguousarray(st[3:6]), self.dpsi, self.dv,
                                  self.ira_code, self._P)
            if nb == M:
                self.health.skip(t_s, "ira_geometry", "IRA sample with no closest-point solution")
                return
            P = self._P
            pn = np.ascontiguousarray(P[:, 0])
            pe = np.ascontiguousarray(P[:, 1])
            n_nan = ira.predict(self._map_record(), lat, lon, r_lat, r_lon, self.dn, self.de, pn, pe,
                                self._hmap)
            resid = (h - self.b - P[:, 2]) - self._hmap        # seed 000 eq 2 under each particle
            # one variance for the cloud, at its mean closest point: the particles' points differ by metres
            # at ranges of km, which changes sigma_R (p_d / R) and sigma_theta |p_h| by < 1e-3 relative
            k0 = int(np.argmax(self.logw))
            p0 = P[k0] if np.all(np.isfinite(P[k0])) else np.nanmean(P, axis=0)
            var = np.array([float(self.ira_variance(range_m, p0[2], math.hypot(p0[0], p0[1]))) + self.P_b])
        else:
            n_nan = radar_altimeter.predict(self._map_record(bilinear=True), lat, lon, r_lat, r_lon, h,
                                            self.dn, self.de, self.b, C, self.dpsi, self.ra_half_beam_rad,
                                            self.ra_cone_rings, 12, self._hmap)
            resid = self._hmap - range_m      # predicted minus measured range = measured - predicted height
            var = np.array([self.ra_variance() + self.P_b])
        if n_nan == M:
            self._degrade(t_s, "cloud_off_map", f"{kind} update skipped: every particle is off the map")
            return
        if n_nan and self._belief_without_map(t_s, kind, float(self._weights()[~np.isfinite(resid)].sum())):
            return
        ira.likelihood(resid, np.ascontiguousarray(var), self.outlier_prob, self.log_outlier_density,
                       self._ll)  # (the terrain sensors' shared likelihood: radar_altimeter.likelihood too)
        w0 = self._weights()
        ok = np.isfinite(resid)
        wm = w0[ok].sum()
        innov = float(np.sum(w0[ok] * resid[ok]) / wm)
        var_b = np.broadcast_to(var, resid.shape)
        S = float(np.sum(w0[ok] * ((resid[ok] - innov) ** 2 + var_b[ok])) / wm)
        S_b = float(var[0])
        with np.errstate(invalid="ignore", over="ignore"):
            gauss = (math.log1p(-self.outlier_prob)
                     - 0.5 * (resid * resid / S_b + math.log(S_b) + math.log(2 * math.pi)))
            gam = np.where(ok, np.exp(np.minimum(gauss - self._ll, 0.0)), 0.0)
        out = self._apply_loglik_b(t_s, self._ll, f"{kind} update", gam * np.where(ok, resid, 0.0), gam, S_b)
        if out is None:
            self._integrity_test(t_s, math.inf, 1)
            return
        log_lik, ess = out
        self._set_update_extra(t_s, [innov], [[S]], log_lik)
        self.extra[EXTRA_ESS] = ess
        self.extra["pf_resampled"] = self.n_resampled
        if n_nan:
            self._count_skip(t_s, "particles_off_map", n_nan,
                             f"{n_nan} particles off the map (outlier density only)")
        if self.health.status == "degraded" and not self.integrity.degraded:
            self.health.status = "acquiring"

    def _gnss_update(self, t_s, st, payload) -> None:
        widen = self._shift_into_belief()      # the map shift's share, spread into the cloud (terrain_filter)
        if widen is not None:
            self.dn += math.sqrt(widen[0, 0]) * self.rng.standard_normal(self.M)
            self.de += math.sqrt(widen[1, 1]) * self.rng.standard_normal(self.M)
            self._moments_cache = None
        lat, lon, h, v = payload
        gn, ge = gnss_model.predict(st, lat, lon)
        sv2 = self.gnss_vertical_sigma_m ** 2
        z_b = float(st[2]) - h            # INS minus GNSS height = b + noise
        p_h, p_m = self._gnss_offset_split()    # the map's part of b is not seen by GNSS (terrain_filter)
        S_b = sv2 + (p_h if p_m > 0.0 else self.P_b)
        K_b = (p_h if p_m > 0.0 else self.P_b) / S_b
        has_v = bool(np.all(np.isfinite(v)))
        if self._accel_model is not None:     # "imu_spec": the ensemble update (its docstring)
            ll = np.zeros(self.M)
            self._gnss_ensemble_update(gn, ge, (float(v[0] - st[3]), float(v[1] - st[4])) if has_v else None,
                                       t_s)
        else:
            ll = gnss_model.likelihood(gn, ge, self.dn, self.de, self.gnss_sigma_m)
        ll -= 0.5 * (z_b - self.b) ** 2 / S_b
        if has_v:
            if self._accel_model is None:
                r2 = self.gnss_velocity_sigma_mps ** 2
                ll -= 0.5 * ((v[0] - st[3] - self.dv[:, 0]) ** 2 + (v[1] - st[4] - self.dv[:, 1]) ** 2) / r2
            self._gnss_velocity_ins(v, carried=(0, 1))
        out = self._apply_loglik(t_s, ll, "GNSS update", self.b + K_b * (z_b - self.b))
        if out is not None:
            self.P_b = p_h * (1.0 - K_b) + p_m if p_m > 0.0 else self.P_b * (1.0 - K_b)
            self._height.gnss(K_b, sv2)
            deficit = self._gnss_drift_deficit()       # the receiver drift the fixes share (terrain_filter)
            if deficit.max() > 0.0:
                self.dn += math.sqrt(deficit[0]) * self.rng.standard_normal(self.M)
                self.de += math.sqrt(deficit[1]) * self.rng.standard_normal(self.M)
                self._moments_cache = None
        if out is not None and self.health.status == "degraded" and not self.integrity.degraded:
            self.health.status = "acquiring"

    def _gnss_ensemble_update(self, gn: float, ge: float, dv_obs: tuple[float, float] | None,
                              t_s: float) -> None:
        """velocity_noise_model "imu_spec": the GNSS fix's horizontal position (gn, ge: the fix minus the
        INS, m) and velocity offset (m/s, or None) by an ensemble Kalman update of the particles (Evensen
        2003, perturbed observations) over position, velocity and heading, with the cloud's weighted
        covariance; the weights stay. The fix is linear in these states with Gaussian noise, so for a
        Gaussian cloud this is the Bayes update, and every particle moves by the gain instead of being kept
        or dropped: reweighting a 30 m cloud by a 2 m fix keeps a handful of particles, whose velocity spread
        is then a few particles' jitter and whose mean velocity is theirs - the fixes' velocity is lost, and
        this model, which grows the velocity's spread from the cloud's own (`_velocity_step_var`), would not
        restore it. A velocity fix restarts the free INS's correlation of the velocity error with the
        acceleration error (rho): from the fix on, the velocity error grows from the fix's posterior as the
        free INS's grows from its initial error."""
        X = np.column_stack([self.dn, self.de, self.dv[:, 0], self.dv[:, 1], self.dpsi])
        obs = [0, 1]
        z = [gn, ge]
        r = [self.gnss_sigma_m ** 2] * 2
        if dv_obs is not None:
            obs += [2, 3]
            z += list(dv_obs)
            r += [self.gnss_velocity_sigma_mps ** 2] * 2
        w = self._weights()
        D = X - w @ X
        P_xh = (D * w[:, None]).T @ D[:, obs]
        K = np.linalg.solve(P_xh[obs] + np.diag(r), P_xh.T).T
        innov = np.asarray(z) + self.rng.standard_normal((self.M, len(obs))) * np.sqrt(r) - X[:, obs]
        X += innov @ K.T
        self.dn = np.ascontiguousarray(X[:, 0])
        self.de = np.ascontiguousarray(X[:, 1])
        self.dv = np.ascontiguousarray(X[:, 2:4])
        self.dpsi = np.ascontiguousarray(X[:, 4])
        self._moments_cache = None
        if dv_obs is not None and self._accel_model is not None:
            d = self.dv - w @ self.dv
            n2, a2, j2, _ = self._accel_model
            self._accel_model = (n2, a2, j2, float(np.max(w @ (d * d))))
            self._t_fix_s = float(t_s)

    def _recover(self, t_s: float) -> str:
        """The cloud re-drawn around its mean with the widened horizontal covariance (initial otherwise)."""
        mean, c9 = self._recovery_cov9()
        init = self._init_cov
        self._init_belief(c9, mean)
        self._init_cov = init          # the underflow re-initialisation keeps the initial spread
        return (f"{self.M} particles re-drawn around the mean, horizontal 1-sigma "
                f"{math.sqrt(0.5 * np.trace(c9[:2, :2])):.0f} m")

    # ------------------------------------------------------------------------------------ output
    def _moments(self) -> tuple[np.ndarray, np.ndarray]:
        if self._moments_cache is None:
            w = self._weights()
            X = np.stack([self.dn, self.de, self.b, self.dv[:, 0], self.dv[:, 1], self.dpsi])
            mean = X @ w
            D = X - mean[:, None]
            cov = (D * w) @ D.T
            cov[2, 2] += self.P_b
            self._moments_cache = (mean, cov)
        mean, cov = self._moments_cache
        return mean.copy(), cov.copy()
