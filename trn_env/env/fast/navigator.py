"""The fast tier's navigator: an INS error process and a batch TERCOM fix with a Kalman filter, per aircraft.

The family the fast tier models is the project's "ins_tercom" (navigators.filters.ins_trn_ekf: INS + batch
TERCOM + error-state Kalman filter, seed 000 section 4.3) and its unaided "ins" (no fixes). Reduced to what
sets the horizontal error at the goal:

- INS error (estimate minus truth), north and east independently: position error p, velocity error v,
  acceleration error a = b_a + g0 (psi0 + b_g t) - c (accelerometer turn-on bias b_a, initial tilt psi0,
  tilt rate from the gyro bias b_g, drawn per episode from the IMU grade; c the filter's fed-back
  compensation), plus the heading error's share, psi_z x f (the horizontal specific force, the centripetal
  acceleration of a turn, rotated by the heading error psi_z = psi_z0 + b_gz t, which the filter does not
  estimate), plus the accelerometer's white noise (velocity random walk), plus the tilt the gyros'
  misalignment and scale factors build in turns (trn_env.env.fast.turns). Schuler feedback is left out
  (its 84 min period is long against an episode). The vertical channel is the barometer's: a constant
  height error per episode.
- GNSS while available (the scenario's outage start): position and velocity updates at 1 Hz with the
  navigator's sigmas, the position sigma floored at gnss_correlated_sigma_m (as the full navigator's).
- TERCOM (seed 000 eq 2, with the per-profile mean removed when the scenario's `remove_bias` is set): the
  profile of measured terrain heights (baro height minus radar height: true terrain + baro error + noise,
  1 Hz; the barometer's first-order lag tau reads h - tau dh/dt on a climb, as the full loop's lagged
  barometer does in its IRA heights, which removing the profile's mean leaves in) along the INS-indicated
  track over `fix_period_s`, correlated with the MAP over +-half_cells x cell_m in north and east, coarse
  to fine (the whole window at 50 m on every 4th profile point - a wider, recovery window at 100 m, then
  +-100 m at 50 m -, then +-40 m at 20 m and +-10 m at the cell size on every point); a best offset on the
  window's edge is a failed fix; otherwise it is the fix, z = INS - matched position at the profile's mean
  time (z = p - lag v), noise fix_sigma_m, chi-square gated (2 dof) against the filter's covariance, as the
  full navigator does (navigators.filters.ins_trn_ekf).
- Kalman filter over (p, v, a) per axis with one shared covariance (the axes see the same dynamics and
  measurement noise): F the constant-acceleration transition, process noise from the navigator's settings
  as the full navigator's filter takes them (accel_noise_mps2_rthz: velocity random walk;
  g0 x gyro_noise_rps_rthz: the random walk of a, through the tilt), feedback form (the estimated errors
  are removed from the INS after each update), and the full navigator's turn term on P22
  (trn_env.env.fast.turns).

Health, as the full navigator's (navigators.integrity.innovation_monitor, navigators.core.recovery): every
fix's NIS (accepted or gated; +inf for an edge fix) enters a test of the sum over the last
integrity_window fixes against its chi-square upper limit (probability integrity_alpha / 2 above it).
Entering "degraded" (`nav_ok` False) inflates the position variance by recovery_sigma_m^2 once and widens
the search to recovery_half_cells until the test is back in band. The fast tier never reports
"diverged".
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from trn_env.env.fast import fix_noise
from trn_env.env.fast import rng as frng
from trn_env.env.fast.state import (
    BA_E,
    BA_N,
    BARO,
    BG_E,
    BG_N,
    BG_Z,
    BI_A_E,
    BI_A_N,
    BI_G_E,
    BI_G_N,
    CA_E,
    CA_N,
    DEGRADED,
    EP_E,
    EP_N,
    EV_E,
    EV_N,
    HDG_MAX,
    HDG_NET,
    MAX_WINDOW,
    N_FIXES,
    N_NIS,
    N_PROF,
    NIS0,
    P00,
    P01,
    P02,
    P11,
    P12,
    P22,
    REJECTS,
    TILT_E,
    TILT_GM_E,
    TILT_GM_N,
    TILT_N,
    TURN_PSI_E,
    TURN_PSI_N,
    YAW0,
    T,
)
from trn_env.terrain import kernels

G0_MPS2 = 9.80665
COARSE_STEP_M = 50.0  # TERCOM's first search stage: grid step over the whole window
BI_STEP_S = 10  # bias instabilities advance every 10 s
COARSE_STRIDE = 4  # ... on every 4th profile point (1 Hz profile: 4 s apart)
COARSE_STEPS = 5  # ... in at most this many steps each way from the centre (wider windows: longer steps)
MODELLED_NAVIGATORS = ("ins", "ins_tercom")

# navigator parameter vector (float64), built by navigator_params()
(
    NP_TERCOM,
    NP_FIX_PERIOD,
    NP_HALF_WINDOW,
    NP_CELL,
    NP_FIX_SIGMA,
    NP_GATE,
    NP_REMOVE_BIAS,
    NP_PROFILE_NOISE,
    NP_Q_V,
    NP_Q_A,
    NP_GNSS_UNTIL,
    NP_GNSS_SIGMA,
    NP_UNHEALTHY,
    NP_MIN_SAMPLES,
    NP_COARSE_STEP,
    NP_COARSE_STRIDE,
    NP_QF_V,
    NP_BI_A,
    NP_TAU_A,
    NP_BI_G,
    NP_TAU_G,
    NP_SIG_BA_PRIOR,
    NP_RECOVERY_SIGMA,
    NP_RECOVERY_WINDOW,
    NP_SAMPLE_DT,
    NP_GNSS_SIGMA_V,
    NP_GNSS_FLOOR,
    NP_FIX_NOISE,  # 1: the batch fix covariance (fix_noise "batch"), 0: fix_sigma_m per axis ("fixed")
    NP_TERRAIN_SIGMA,  # the map's unresolved terrain (m) in the batch fix covariance
    NP_TURN_TILT2,  # the turn term's tilt variance per rad of excursion (rad^2/rad: m^2 TURN_REFERENCE_RAD)
    NP_TURN_HEAD2,  # ... its heading variance per rad (rad^2/rad: s^2 TURN_REFERENCE_RAD)
    NP_BARO_LAG,  # the baro lag the navigator leaves in (s): the profile reads the height tau earlier
    NP_BAND0,  # NP_BAND0 + k - 1: the innovation test's upper limit over k NIS values (2k dof)
) = range(33)
N_NAV_PARAMS = NP_BAND0 + MAX_WINDOW


def ins_tercom_default(name: str):
    """The full navigator's default of its setting `name` (navigators.filters.ins_trn_settings), for a
    scenario that does not set it."""
    from trn_env.navigators.filters.ins_trn_settings import InsTrnSettings

    return getattr(InsTrnSettings(), name)


def navigator_params(
    name: str,
    settings: dict,
    imu: dict,
    gnss_until_s: float,
    ira_noise_m: float,
    ira_rate_hz: float,
    imu_spec=None,
    sample_dt_s: float = 1.0,
    terrain_sigma_m: float = 0.0,
    baro_lag_s: float = 0.0,
) -> np.ndarray:
    """The kernel's parameter vector for navigator `name` ("ins" or "ins_tercom") with the scenario's
    navigator settings (navigators.filters.ins_trn_ekf's names and defaults), IMU grade (trn_env.sensors.imu
    fields), GNSS availability (s) and IRA noise (m) and rate (Hz): the 1 Hz profile sample is the mean of
    a second of IRA samples, so its noise is ira_noise_m / sqrt(ira_rate_hz); sample_dt_s the profile's
    sample interval (s); terrain_sigma_m the map's unresolved terrain (m: navigators.measurements.
    ira_map_noise.interpolation_sigma_m, used with fix_noise "batch" when terrain_model_sigma_m is "auto");
    baro_lag_s the barometer's lag the navigator leaves in its terrain heights (s: trn_env.sensors.baro's
    lag_tau_s less the navigator's baro_lag_s compensation, which a scenario sets to it).
    The innovation test's window (integrity_window) is at most MAX_WINDOW fixes."""
    if name not in MODELLED_NAVIGATORS:
        raise ValueError(
            f"navigator {name!r} is not modelled by the fast tier; it models: "
            f"{', '.join(MODELLED_NAVIGATORS)}"
        )
    p = np.zeros(N_NAV_PARAMS)
    p[NP_TERCOM] = 1.0 if name == "ins_tercom" else 0.0
    p[NP_FIX_PERIOD] = float(settings.get("fix_period_s", 40.0))
    p[NP_HALF_WINDOW] = float(settings.get("half_cells", 50)) * float(settings.get("cell_m", 5.0))
    p[NP_CELL] = float(settings.get("cell_m", 5.0))
    p[NP_FIX_SIGMA] = float(settings.get("fix_sigma_m", 10.0))
    fix_noise_model = settings.get("fix_noise", ins_tercom_default("fix_noise"))
    if fix_noise_model not in ("batch", "fixed"):
        raise ValueError(f"navigator.settings.fix_noise: 'batch' or 'fixed', got {fix_noise_model!r}")
    p[NP_FIX_NOISE] = 1.0 if fix_noise_model == "batch" else 0.0
    ts = settings.get("terrain_model_sigma_m", ins_tercom_default("terrain_model_sigma_m"))
    p[NP_TERRAIN_SIGMA] = float(terrain_sigma_m) if ts == "auto" else float(ts)
    p[NP_GATE] = float(settings.get("gate_chi2", 18.42))
    p[NP_REMOVE_BIAS] = 1.0 if settings.get("remove_bias", False) else 0.0
    p[NP_PROFILE_NOISE] = ira_noise_m / math.sqrt(max(ira_rate_hz, 1.0))
    p[NP_BARO_LAG] = float(baro_lag_s)
    # truth: the IMU's velocity random walk; the filter's process noise: the navigator's own settings, as
    # the full navigator's filter takes them (velocity random walk, and the angle random walk that drives its
    # tilt states, here g0 x that as the random walk of the acceleration error)
    p[NP_Q_V] = float(imu["accel_noise_density_mps2_rthz"]) ** 2
    q_acc = float(settings.get("accel_noise_mps2_rthz", 10e-6 * G0_MPS2)) ** 2
    q_gyr = float(settings.get("gyro_noise_rps_rthz", math.radians(0.005) / 60.0)) ** 2
    q_tilt = q_ba_walk = 0.0
    sig_ba = float(settings.get("accel_bias_mps2", 50e-6 * G0_MPS2))
    if imu_spec is not None:
        # a navigator that takes its error model from the IMU's specification (its apply_imu_spec,
        # navigators.filters.ins_trn_propagation): each figure a floor over the setting, the x / y gyro
        # biases as a tilt random walk matching them at EKF_MEMORY_S, the accelerometer bias instability's
        # Gauss-Markov drive as a random walk
        from trn_env.navigators.filters.ins_trn_propagation import EKF_MEMORY_S

        q_acc = max(q_acc, imu_spec.accel_noise_density_mps2_rthz**2)
        q_gyr = max(q_gyr, imu_spec.gyro_noise_density_rps_rthz**2)
        q_tilt = imu_spec.gyro_bias_sigma_rps**2 * EKF_MEMORY_S
        q_ba_walk = 2.0 * imu_spec.accel_bias_instability_mps2**2 / imu_spec.accel_bias_tau_s
        sig_ba = max(sig_ba, imu_spec.body_accel_sigma_mps2)
    if imu_spec is not None:
        # the turn terms (ins_trn_propagation.InsTrnPropagation.apply_imu_spec): per rad turned the gyro
        # misalignment (tilt) and scale factor (heading), as variances per rad of TURN_REFERENCE_RAD
        from trn_env.navigators.filters.ins_trn_propagation import TURN_REFERENCE_RAD

        p[NP_TURN_TILT2] = imu_spec.turn_tilt_sigma_rad(1.0) ** 2 * TURN_REFERENCE_RAD
        p[NP_TURN_HEAD2] = imu_spec.turn_heading_sigma_rad(1.0) ** 2 * TURN_REFERENCE_RAD
    p[NP_QF_V] = q_acc
    p[NP_Q_A] = G0_MPS2**2 * (q_gyr + q_tilt) + q_ba_walk
    p[NP_SIG_BA_PRIOR] = sig_ba
    p[NP_RECOVERY_SIGMA] = float(settings.get("recovery_sigma_m", 100.0))
    half = float(settings.get("half_cells", 50))
    p[NP_RECOVERY_WINDOW] = float(settings.get("recovery_half_cells") or 2 * half) / half
    p[NP_BI_A] = float(imu.get("accel_bias_instability_mps2", 0.0))
    p[NP_TAU_A] = float(imu.get("accel_bias_tau_s", 3600.0))
    p[NP_BI_G] = float(imu.get("gyro_bias_instability_rps", 0.0))
    p[NP_TAU_G] = float(imu.get("gyro_bias_tau_s", 3600.0))
    p[NP_GNSS_UNTIL] = float(gnss_until_s)
    p[NP_GNSS_SIGMA] = float(settings.get("gnss_sigma_h_m", 2.0))
    window = int(settings.get("integrity_window", 3))
    if not 1 <= window <= MAX_WINDOW:
        raise ValueError(
            f"navigator.settings.integrity_window: the fast tier models windows of 1 to {MAX_WINDOW} fixes, "
            f"got {window!r}"
        )
    p[NP_UNHEALTHY] = float(window)
    from scipy.stats import chi2

    alpha = float(settings.get("integrity_alpha", 0.01))
    for k in range(1, MAX_WINDOW + 1):
        p[NP_BAND0 + k - 1] = float(chi2.isf(0.5 * alpha, 2 * k))
    p[NP_SAMPLE_DT] = float(sample_dt_s)
    p[NP_GNSS_SIGMA_V] = float(settings.get("gnss_sigma_v_mps", 0.1))
    p[NP_GNSS_FLOOR] = float(settings.get("gnss_correlated_sigma_m", 1.5))
    p[NP_MIN_SAMPLES] = 5.0
    p[NP_COARSE_STEP] = COARSE_STEP_M
    p[NP_COARSE_STRIDE] = COARSE_STRIDE
    return p


def tercom_table_rows(nav: np.ndarray) -> int:
    """Candidates per axis of the widest TERCOM search stage (tercom_offset's tables): the coarse stage's
    2 COARSE_STEPS + 1 (at most), or the fine stages' 5."""
    return max(2 * COARSE_STEPS + 1, 5)


@njit(cache=True)
def ins_step(X, i, dt, noise_n, noise_e, f_n, f_e):
    """Propagate aircraft i's INS error (truth) by dt seconds; noise_n, noise_e are the step's velocity
    random-walk increments (m/s) from the white accelerometer noise, drawn by the caller; f_n, f_e the
    horizontal specific force (m/s^2) the heading error rotates."""
    t = X[i, T]
    # the turns' tilt (psi, turn_truth_step) in this function's signs: the north acceleration error is
    # g0 psi_e, the east one -g0 psi_n
    yaw = X[i, YAW0] + X[i, BG_Z] * t
    a_n = (
        X[i, BA_N]
        + X[i, BI_A_N]
        + G0_MPS2 * (X[i, TILT_N] + X[i, BG_N] * t + X[i, TILT_GM_N] + X[i, TURN_PSI_E])
        - X[i, CA_N]
        - yaw * f_e
    )
    a_e = (
        X[i, BA_E]
        + X[i, BI_A_E]
        + G0_MPS2 * (X[i, TILT_E] + X[i, BG_E] * t + X[i, TILT_GM_E] - X[i, TURN_PSI_N])
        - X[i, CA_E]
        + yaw * f_n
    )
    X[i, EP_N] += X[i, EV_N] * dt + 0.5 * a_n * dt * dt
    X[i, EP_E] += X[i, EV_E] * dt + 0.5 * a_e * dt * dt
    X[i, EV_N] += a_n * dt + noise_n
    X[i, EV_E] += a_e * dt + noise_e
    X[i, TILT_GM_N] += X[i, BI_G_N] * dt
    X[i, TILT_GM_E] += X[i, BI_G_E] * dt


@njit(cache=True)
def bias_instability_step(X, i, dt, nav, w0, w1, w2, w3):
    """Advance aircraft i's bias instabilities (first-order Gauss-Markov, exact over dt seconds, with the
    IMU grade's std and correlation time) by dt; w0..w3 standard normals."""
    fa = math.exp(-dt / nav[NP_TAU_A])
    fg = math.exp(-dt / nav[NP_TAU_G])
    sa = nav[NP_BI_A] * math.sqrt(1.0 - fa * fa)
    sg = nav[NP_BI_G] * math.sqrt(1.0 - fg * fg)
    X[i, BI_A_N] = fa * X[i, BI_A_N] + sa * w0
    X[i, BI_A_E] = fa * X[i, BI_A_E] + sa * w1
    X[i, BI_G_N] = fg * X[i, BI_G_N] + sg * w2
    X[i, BI_G_E] = fg * X[i, BI_G_E] + sg * w3


@njit(cache=True)
def covariance_step(X, i, dt, q_v, q_a):
    """P <- F P F^T + Q for F = [[1, dt, dt^2/2], [0, 1, dt], [0, 0, 1]] (symmetric, stored in 6 columns)."""
    p00, p01, p02, p11, p12, p22 = X[i, P00], X[i, P01], X[i, P02], X[i, P11], X[i, P12], X[i, P22]
    h = 0.5 * dt * dt
    # A = F P
    a00 = p00 + dt * p01 + h * p02
    a01 = p01 + dt * p11 + h * p12
    a02 = p02 + dt * p12 + h * p22
    a11 = p11 + dt * p12
    a12 = p12 + dt * p22
    a10 = p01 + dt * p02
    a20 = p02
    a21 = p12
    # F P F^T
    X[i, P00] = a00 + dt * a01 + h * a02 + q_v * dt**3 / 3.0
    X[i, P01] = a10 + dt * a11 + h * a12 + q_v * dt * dt / 2.0
    X[i, P02] = a20 + dt * a21 + h * p22
    X[i, P11] = a11 + dt * a12 + q_v * dt
    X[i, P12] = a21 + dt * p22
    X[i, P22] = p22 + q_a * dt


@njit(cache=True)
def measurement_update(X, i, z_n, z_e, h0, h1, r_var):
    """Kalman update of aircraft i with a horizontal measurement z = h0 p + h1 v + noise per axis (m; north
    and east share the covariance), noise variance r_var. Feedback form: the estimated errors are removed
    from the INS."""
    p00, p01, p02, p11, p12, p22 = X[i, P00], X[i, P01], X[i, P02], X[i, P11], X[i, P12], X[i, P22]
    c0 = h0 * p00 + h1 * p01  # P H^T
    c1 = h0 * p01 + h1 * p11
    c2 = h0 * p02 + h1 * p12
    s = h0 * c0 + h1 * c1 + r_var
    k0 = c0 / s
    k1 = c1 / s
    k2 = c2 / s
    X[i, EP_N] -= k0 * z_n
    X[i, EP_E] -= k0 * z_e
    X[i, EV_N] -= k1 * z_n
    X[i, EV_E] -= k1 * z_e
    X[i, CA_N] += k2 * z_n
    X[i, CA_E] += k2 * z_e
    X[i, P00] = p00 - k0 * c0
    X[i, P01] = p01 - k0 * c1
    X[i, P02] = p02 - k0 * c2
    X[i, P11] = p11 - k1 * c1
    X[i, P12] = p12 - k1 * c2
    X[i, P22] = p22 - k2 * c2


@njit(cache=True)
def position_update(X, i, z_n, z_e, r_var, gate_chi2):
    """Kalman update of aircraft i with a horizontal position-error measurement z = INS - reference (m),
    noise variance r_var, chi-square gate (2 dof; <= 0: no gate). Returns True when accepted."""
    s = X[i, P00] + r_var
    if gate_chi2 > 0.0 and (z_n * z_n + z_e * z_e) / s > gate_chi2:
        return False
    measurement_update(X, i, z_n, z_e, 1.0, 0.0, r_var)
    return True


@njit(cache=True)
def gnss_update(X, i, z_n, z_e, zv_n, zv_e, nav):
    """GNSS update of aircraft i (as the full navigator's, navigators.filters.ins_trn_gnss): position
    z = INS - GNSS (m) with gnss_sigma_h_m, velocity zv (m/s) with gnss_sigma_v_mps, then the position
    sigma held at or above gnss_correlated_sigma_m (congruence D P D: the receiver's slowly wandering error
    that white 1 Hz updates would average away)."""
    s_h = nav[NP_GNSS_SIGMA]
    s_v = nav[NP_GNSS_SIGMA_V]
    measurement_update(X, i, z_n, z_e, 1.0, 0.0, s_h * s_h)
    measurement_update(X, i, zv_n, zv_e, 0.0, 1.0, s_v * s_v)
    floor = nav[NP_GNSS_FLOOR]
    if X[i, P00] < floor * floor:
        d = floor / math.sqrt(max(X[i, P00], 1e-30))
        X[i, P00] = floor * floor
        X[i, P01] *= d
        X[i, P02] *= d


@njit(cache=True)
def integrity_add(X, i, nav, nis):
    """Add a TERCOM fix's NIS (2 dof; +inf for a failed fix) to aircraft i's innovation test (the sum over the
    last integrity_window fixes against its chi-square upper limit, navigators.integrity.innovation_monitor)
    and recover as the full navigator does (navigators.core.recovery, once per entry): entering "degraded"
    inflates the position variance by recovery_sigma_m^2 and widens the search (tercom_fix) until the test
    is back in band."""
    w = int(nav[NP_UNHEALTHY])
    k = int(X[i, N_NIS])
    X[i, NIS0 + k % w] = nis
    X[i, N_NIS] = k + 1
    m = min(k + 1, w)
    stat = 0.0
    for j in range(m):
        stat += X[i, NIS0 + j]
    degraded = stat > nav[NP_BAND0 + m - 1]
    if degraded and X[i, DEGRADED] < 0.5:
        X[i, P00] += nav[NP_RECOVERY_SIGMA] ** 2
    X[i, DEGRADED] = 1.0 if degraded else 0.0


@njit(cache=True)
def _axis_table(f, n, stride, offsets, n_off, size, cell_idx, frac):
    """Grid cell and fraction of every used profile point (f: fractional indices along one map axis, every
    stride-th of n) shifted by each of n_off offsets (cells): cell_idx[o, kk], frac[o, kk]; -1 where the
    point falls off the grid (kernels.bilinear_at_index's bounds)."""
    for o in range(n_off):
        kk = 0
        for k in range(0, n, stride):
            x = f[k] + offsets[o]
            if not (x >= -kernels._EDGE and x <= size - 1 + kernels._EDGE):
                cell_idx[o, kk] = -1.0
            else:
                c = min(max(int(x), 0), size - 2)
                cell_idx[o, kk] = c
                frac[o, kk] = x - c
            kk += 1


@njit(cache=True)
def _candidate_mad(meas, n, stride, heights, ii, uu, jj, vv, remove_bias, diff):
    """Mean absolute difference (mean-removed when remove_bias) of the profile's used points against the
    map at the cells and fractions (ii, uu) x (jj, vv) of one shifted candidate (kernels.bilinear_cell
    and its void retry); +inf when a point falls off the map or on a void."""
    s = 0.0
    m_used = 0
    for k in range(0, n, stride):
        if ii[m_used] < 0.0 or jj[m_used] < 0.0:
            return np.inf
        i = int(ii[m_used])
        j = int(jj[m_used])
        u = uu[m_used]
        v = vv[m_used]
        m = kernels.bilinear_cell(heights, i, j, u, v)[0]
        if m != m:
            m = kernels._edge_retry(heights, i, j, u, v)
            if m != m:
                return np.inf
        d = meas[k] - m
        diff[m_used] = d
        s += d
        m_used += 1
    mean = s / m_used if remove_bias else 0.0
    mad = 0.0
    for k in range(m_used):
        mad += abs(diff[k] - mean)
    return mad / m_used


@njit(cache=True)
def tercom_offset(profile, n, rec, half_window_m, cell_m, remove_bias, m_per_rad, work, coarse):
    """Best north/east offset (m) of the profile (measured terrain heights `meas` at the INS-indicated
    positions plat, plon; n points) against the map over +-half_window_m, coarse to fine: the whole window
    in coarse_step_m steps (a window wider than COARSE_STEPS of them: in COARSE_STEPS longer steps, then
    +-one of those in coarse_step_m steps around the best) on every coarse_stride-th profile point, then
    +-40 m in 20 m steps and +-10 m in cell_m steps around the best on every point. Each stage's
    candidates form a north x east lattice, so the map cell and fraction of every point under every north
    and every east shift are tabulated once (_axis_table) and a candidate's bilinear look-ups only read
    them.

    Records (numba tuples): profile = (meas, plat, plon); rec = the map (terrain.kernels.MapRecord,
    bilinear); m_per_rad = (m_per_rad_lat, m_per_rad_lon) (m/rad at the profile); work = (scratch (3, >= n)
    work rows, tables (4, >= candidates per axis, >= points used) work tables); coarse = (coarse_step_m,
    coarse_stride). Returns (dn, de, mad)."""
    meas, plat, plon = profile
    heights, lat0, lon0, dlat, dlon, _ = rec
    m_per_rad_lat, m_per_rad_lon = m_per_rad
    scratch, tables = work
    coarse_step_m, coarse_stride = coarse
    diff = scratch[0]
    fi = scratch[1]
    fj = scratch[2]
    for k in range(n):  # the profile's points as fractional map indices, once per fix
        fi[k] = (plat[k] - lat0) / dlat
        fj[k] = (plon[k] - lon0) / dlon
    cells_per_m_n = 1.0 / (m_per_rad_lat * dlat)
    cells_per_m_e = 1.0 / (m_per_rad_lon * dlon)
    n_lat, n_lon = heights.shape
    max_off = tables.shape[1]
    off_n = np.empty(max_off)
    off_e = np.empty(max_off)
    val_n = np.empty(max_off)
    val_e = np.empty(max_off)
    best_n = 0.0
    best_e = 0.0
    best = np.inf
    # the coarse stage spans the window in at most COARSE_STEPS steps each way; a wider window (recovery's)
    # gets a middle stage at coarse_step_m around the coarse best
    step0 = max(coarse_step_m, half_window_m / COARSE_STEPS)
    steps = (step0, coarse_step_m, 20.0, cell_m)
    spans = (half_window_m, step0, 40.0, 10.0)
    strides = (coarse_stride, coarse_stride, 1, 1)
    for stage in range(4):
        if stage == 1 and step0 <= coarse_step_m + 1e-9:
            continue
        step = steps[stage]
        stride = strides[stage]
        span = min(spans[stage], half_window_m)
        k = min(int(span / step + 1e-9), (max_off - 1) // 2)
        na = 0
        nb = 0
        for a in range(-k, k + 1):
            on = best_n + a * step
            if abs(on) <= half_window_m + 1e-9:
                val_n[na] = on
                off_n[na] = on * cells_per_m_n
                na += 1
            oe = best_e + a * step
            if abs(oe) <= half_window_m + 1e-9:
                val_e[nb] = oe
                off_e[nb] = oe * cells_per_m_e
                nb += 1
        _axis_table(fi, n, stride, off_n, na, n_lat, tables[0], tables[1])
        _axis_table(fj, n, stride, off_e, nb, n_lon, tables[2], tables[3])
        best = np.inf  # each stage compares its candidates on its own points
        cn = best_n
        ce = best_e
        for a in range(na):
            for b in range(nb):
                mad = _candidate_mad(
                    meas, n, stride, heights, tables[0, a], tables[1, a], tables[2, b], tables[3, b],
                    remove_bias, diff,
                )
                if mad < best:
                    best = mad
                    cn = val_n[a]
                    ce = val_e[b]
        best_n = cn
        best_e = ce
    return best_n, best_e, best


@njit(cache=True)
def tercom_fix(X, i, prof, rec, nav, m_per_rad, work):
    """Aircraft i's TERCOM fix from its profile (row i of prof = (measured heights, latitudes, longitudes)),
    fused by the Kalman filter; the profile is then restarted. rec, m_per_rad: as tercom_offset's; work =
    aircraft i's (diff, tables) scratch. Returns True when the fix was accepted."""
    prof_meas, prof_lat, prof_lon = prof
    n = int(X[i, N_PROF])
    X[i, N_PROF] = 0.0
    if n < nav[NP_MIN_SAMPLES]:
        return False
    half_m = nav[NP_HALF_WINDOW] * (nav[NP_RECOVERY_WINDOW] if X[i, DEGRADED] > 0.5 else 1.0)
    dn, de, mad = tercom_offset(
        (prof_meas[i], prof_lat[i], prof_lon[i]), n, rec, half_m, nav[NP_CELL], nav[NP_REMOVE_BIAS] > 0.5,
        m_per_rad, work, (nav[NP_COARSE_STEP], int(nav[NP_COARSE_STRIDE])),
    )
    if not math.isfinite(mad):
        return False
    X[i, N_FIXES] += 1.0
    ok = False
    if abs(dn) >= half_m - 1e-6 or abs(de) >= half_m - 1e-6:
        # the best match on the search window's edge (the true offset may lie outside): a failed fix
        nis = np.inf
    else:
        # the map matches where the INS path is shifted by (dn, de): truth = INS + offset, z = INS - matched;
        # the rigid shift is the INS error at the batch's mean sample time, lag before the fix:
        # z = p - lag v (the full navigator's H)
        lag = 0.5 * (n - 1) * nav[NP_SAMPLE_DT]
        s_p = X[i, P00] - 2.0 * lag * X[i, P01] + lag * lag * X[i, P11]
        if nav[NP_FIX_NOISE] > 0.5:
            # the batch's covariance (fix_noise.lad_fix_covariance); the gate takes it whole, the update (one
            # covariance shared by the axes) its mean per-axis variance
            c_nn, c_ne, c_ee = fix_noise.lad_fix_covariance(
                (prof_meas[i], prof_lat[i], prof_lon[i]), n, rec, dn, de, m_per_rad, nav[NP_CELL],
                nav[NP_REMOVE_BIAS] > 0.5, nav[NP_TERRAIN_SIGMA], work[0],
            )
            s_nn = s_p + c_nn
            s_ee = s_p + c_ee
            nis = (s_ee * dn * dn - 2.0 * c_ne * dn * de + s_nn * de * de) / (s_nn * s_ee - c_ne * c_ne)
            r_var = 0.5 * (c_nn + c_ee)
        else:
            r_var = nav[NP_FIX_SIGMA] ** 2
            nis = (dn * dn + de * de) / (s_p + r_var)
        if nis <= nav[NP_GATE]:
            measurement_update(X, i, -dn, -de, 1.0, -lag, r_var)
            ok = True
    X[i, REJECTS] = 0.0 if ok else X[i, REJECTS] + 1.0
    integrity_add(X, i, nav, nis)
    return ok


@njit(cache=True)
def draw_initial_errors(X, i, state, sig):
    """Episode draws of aircraft i's navigation errors and inertial error sources, and the filter's prior;
    sig = (sig_pos m, sig_vel m/s, sig_tilt rad, ba m/s^2, bg rad/s, baro_sigma m, sig_yaw rad,
    sig_ba_prior m/s^2) (reset.IP_*). The draws are taken in the order of `drawn` (one normal each)."""
    sig_pos, sig_vel, sig_tilt, ba, bg, baro_sigma, sig_yaw, sig_ba_prior = sig
    drawn = (EP_N, EP_E, EV_N, EV_E, TILT_N, TILT_E, BA_N, BA_E, BG_N, BG_E, BARO, YAW0, BG_Z)
    scale = (sig_pos, sig_pos, sig_vel, sig_vel, sig_tilt, sig_tilt, ba, ba, bg, bg, baro_sigma, sig_yaw, bg)
    for k in range(len(drawn)):
        X[i, drawn[k]] = scale[k] * frng.normal(state, i)
    for c in (BI_A_N, BI_A_E, BI_G_N, BI_G_E, TILT_GM_N, TILT_GM_E, CA_N, CA_E, P01, P02, P12, N_PROF,
              REJECTS, N_FIXES, N_NIS, DEGRADED):
        X[i, c] = 0.0
    X[i, P00] = sig_pos * sig_pos
    X[i, P11] = sig_vel * sig_vel
    X[i, P22] = sig_ba_prior * sig_ba_prior + (G0_MPS2 * sig_tilt) ** 2
    X[i, HDG_NET] = 0.0
    X[i, HDG_MAX] = 0.0
    for j in range(MAX_WINDOW):
        X[i, NIS0 + j] = 0.0
