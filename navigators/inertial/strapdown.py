"""Strapdown inertial navigation in the local NED frame on WGS84.

Mechanisation (numba, one call per chunk of IMU samples, at the IMU rate):

- attitude: quaternion q_bn (body FRD -> NED), rotation-vector update with the trapezoidal body rate and a
  coning term (w0 x w1) dt^2 / 12, and the navigation-frame rotation (Earth rate + transport rate);
- velocity: v_dot = C_bn f_b - (2 w_ie^n + w_en^n) x v + g^n, specific force integrated by the trapezoid
  of C_bn f_b over the step, Coriolis and gravity at the predicted mid-step state;
- position: geodetic latitude/longitude/height from the mid-step velocity and radii of curvature;
- vertical channel damped by a third-order barometric loop (gains 3/tau, 3/tau^2, 1/tau^3: a triple pole
  at -1/tau) on the last barometric height;
- gravity: "somigliana" (WGS84 normal gravity with the height correction, Groves 2nd ed. eqs 2.134/2.139)
  or "j2" (J2 gravitation + centrifugal, the model JSBSim uses by default: FGInertia gtWGS84, with its GM,
  J2 and semi-major axis) - the difference is a few micro-g horizontally at altitude, which matters when
  the INS must follow a JSBSim truth to 1 m over 10 minutes.

IMU samples are rates (rad/s) and specific forces (m/s^2) at instants t_k; the step from t_{k-1} to t_k
uses both end samples ("instant"), or sample k alone as the mean over the step ("interval").

Following a JSBSim truth. JSBSim 1.3 integrates its attitude quaternion with a rectangular Euler step and
normalises it (simulation/integrator/position/rotational = 1), so per step its body turns by
2 atan(|w| dt / 2) about the reported inertial rate w, not by |w| dt. Gravity (J2 at JSBSim's ECEF
position matches accelerations/gravity-ft_sec2 to 1e-14 m/s^2; "j2" here, from geodetic lat/h, agrees to
1e-10), Earth rate
(7.292115e-5 rad/s, from JSBSim's ECI - ECEF velocity) and its translational integrators (Adams-Bashforth
2/3: second-order differences only) leave centimetres; the attitude shortfall (|w| dt)^3 / 12 per step
(~5e-7 rad of tilt per roll manoeuvre at 100 Hz) leaves ~1 m in 10 min. This mechanisation stays exact
(the right thing for a real gyro); a perfect gyro of the JSBSim body reports the rotation the body
actually makes, w 2 atan(|w| dt / 2) / (|w| dt) (tests/test_nav_ins_jsbsim.py: 0.017 m in 10 min).

Invalid samples (valid False or non-finite) are replaced by the previous good one
and counted.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...terrain.geodesy import OMEGA_EARTH_RPS, WGS84_A_M, WGS84_E2, WGS84_F

GRAVITY_MODELS = {"somigliana": 0, "j2": 1}

# JSBSim FGInertia constants (ft units converted): GM = 14.0764417572e15 ft^3/s^2, J2 = 1.08262982e-3,
# a = 20925646.32546 ft.
_FT = 0.3048
JSBSIM_GM = 14.0764417572e15 * _FT**3
JSBSIM_J2 = 1.08262982e-3
JSBSIM_A_M = 20925646.32546 * _FT
GM_WGS84 = 3.986004418e14

# state vector layout used by the kernels
I_LAT, I_LON, I_H, I_VN, I_VE, I_VD, I_Q0 = 0, 1, 2, 3, 4, 5, 6
N_STATE = 10


@njit(cache=True)
def gravity_ned(lat: float, h: float, model: int) -> np.ndarray:
    """Gravity (gravitation + centrifugal) in NED at geodetic latitude lat (rad), height h (m)."""
    g = np.zeros(3)
    sl = np.sin(lat)
    cl = np.cos(lat)
    if model == 0:
        # Somigliana normal gravity on the ellipsoid (Groves eq 2.134)
        g0 = 9.7803253359 * (1.0 + 0.001931853 * sl * sl) / np.sqrt(1.0 - WGS84_E2 * sl * sl)
        m = OMEGA_EARTH_RPS**2 * WGS84_A_M**2 * WGS84_A_M * (1.0 - WGS84_F) / GM_WGS84
        # height correction (Groves eq 2.139)
        g[2] = g0 * (
            1.0
            - 2.0 / WGS84_A_M * (1.0 + WGS84_F + m - 2.0 * WGS84_F * sl * sl) * h
            + 3.0 * h * h / WGS84_A_M**2
        )
        g[0] = -8.08e-9 * h * np.sin(2.0 * lat)
        return g
    # J2 gravitation in ECEF (JSBSim FGInertia::GetGravityJ2) + centrifugal, rotated to NED
    r_e = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * sl * sl)
    x = (r_e + h) * cl
    z = (r_e * (1.0 - WGS84_E2) + h) * sl  # meridian plane: lon = 0 without loss of generality
    r = np.sqrt(x * x + z * z)
    s_gc = z / r
    adivr = JSBSIM_A_M / r
    pre = 1.5 * JSBSIM_J2 * adivr * adivr
    gm_r2 = JSBSIM_GM / (r * r)
    gx = -gm_r2 * (1.0 + pre * (1.0 - 5.0 * s_gc * s_gc)) * x / r + OMEGA_EARTH_RPS**2 * x
    gz = -gm_r2 * (1.0 + pre * (3.0 - 5.0 * s_gc * s_gc)) * z / r
    # NED axes at lon = 0: N = (-sl, 0, cl), D = (-cl, 0, -sl) in (x, y, z)
    g[0] = -sl * gx + cl * gz
    g[2] = -cl * gx - sl * gz
    return g


@njit(cache=True)
def _qmul(a, b):
    return np.array(
        [
            a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
            a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
        ]
    )


@njit(cache=True)
def _rotvec_q(v):
    a = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    q = np.empty(4)
    if a < 1e-12:
        q[0] = 1.0
        q[1] = 0.5 * v[0]
        q[2] = 0.5 * v[1]
        q[3] = 0.5 * v[2]
        return q
    s = np.sin(0.5 * a) / a
    q[0] = np.cos(0.5 * a)
    q[1] = s * v[0]
    q[2] = s * v[1]
    q[3] = s * v[2]
    return q


@njit(cache=True)
def quat_to_dcm(q):
    """Quaternion [w, x, y, z] (body -> NED) to C_bn."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    c = np.empty((3, 3))
    c[0, 0] = w * w + x * x - y * y - z * z
    c[0, 1] = 2.0 * (x * y - w * z)
    c[0, 2] = 2.0 * (x * z + w * y)
    c[1, 0] = 2.0 * (x * y + w * z)
    c[1, 1] = w * w - x * x + y * y - z * z
    c[1, 2] = 2.0 * (y * z - w * x)
    c[2, 0] = 2.0 * (x * z - w * y)
    c[2, 1] = 2.0 * (y * z + w * x)
    c[2, 2] = w * w - x * x - y * y + z * z
    return c


@njit(cache=True)
def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@njit(cache=True)
def _mv(C, v):
    """C @ v for a 3 x 3 matrix and a 3-vector (numba's @ calls BLAS: slow at 3 x 3)."""
    return np.array(
        [
            C[0, 0] * v[0] + C[0, 1] * v[1] + C[0, 2] * v[2],
            C[1, 0] * v[0] + C[1, 1] * v[1] + C[1, 2] * v[2],
            C[2, 0] * v[0] + C[2, 1] * v[1] + C[2, 2] * v[2],
        ]
    )


@njit(cache=True)
def _rates(lat, h, vn, ve):
    """Earth rate and transport rate in NED, and the radii R_N + h, R_E + h."""
    sl = np.sin(lat)
    w = 1.0 - WGS84_E2 * sl * sl
    rn = WGS84_A_M * (1.0 - WGS84_E2) / (w * np.sqrt(w)) + h
    re = WGS84_A_M / np.sqrt(w) + h
    w_ie = np.array([OMEGA_EARTH_RPS * np.cos(lat), 0.0, -OMEGA_EARTH_RPS * sl])
    w_en = np.array([ve / re, -vn / rn, -ve * np.tan(lat) / re])
    return w_ie, w_en, rn, re


@njit(cache=True)
def propagate_chunk(ins, imu, baro, mech, out):
    """Advance the INS over IMU samples t_imu[k] (k = 0..n-1). Records (numba tuples):

    ins = (state, prev_imu, baro_state), updated in place: state (10,) lat, lon, h, vn, ve, vd, q_bn (w, x,
    y, z); prev_imu (7,) t, f_b (3), w_b (3) of the previous sample (after a reset: the reset time with NaN
    samples, so the first sample's step starts at the state's own time; t NaN as well: no time yet, the
    first sample only sets it); baro_state (3,) last baro time, last baro height (NaN: none), vertical
    accel correction.
    imu = (t_imu, f_b, w_b, imu_ok) the samples; baro = (t_baro, h_baro, baro_ok) the baro samples.
    mech = (accel_bias_b, gyro_bias_b (3,) subtracted from the samples, tau_baro_s the baro loop's time
    constant, gravity_model, interval_samples: True if each sample is the mean over the step ending at its
    time (JSBSim's f_b)).
    out (n, 10): state after each sample. Returns the number of replaced (invalid) IMU samples.
    """
    state, prev_imu, baro_state = ins
    t_imu, f_b, w_b, imu_ok = imu
    t_baro, h_baro, baro_ok = baro
    accel_bias_b, gyro_bias_b, tau_baro_s, gravity_model, interval_samples = mech
    n = t_imu.shape[0]
    nb = t_baro.shape[0]
    jb = 0
    bad = 0
    k1 = 3.0 / tau_baro_s
    k2 = 3.0 / tau_baro_s**2
    k3 = 1.0 / tau_baro_s**3
    for k in range(n):
        f1 = f_b[k] - accel_bias_b
        w1 = w_b[k] - gyro_bias_b
        ok = imu_ok[k]
        for i in range(3):
            if not (np.isfinite(f1[i]) and np.isfinite(w1[i])):
                ok = False
        if not ok:
            bad += 1
            if np.isnan(prev_imu[1]):   # no good sample yet to hold
                for j in range(N_STATE):
                    out[k, j] = state[j]
                continue
            f1 = prev_imu[1:4].copy()
            w1 = prev_imu[4:7].copy()
        # newest baro sample at or before this time
        while jb < nb and t_baro[jb] <= t_imu[k]:
            if baro_ok[jb] and np.isfinite(h_baro[jb]):
                baro_state[0] = t_baro[jb]
                baro_state[1] = h_baro[jb]
            jb += 1
        if np.isnan(prev_imu[0]):
            prev_imu[0] = t_imu[k]
            for i in range(3):  # element loops, not slice assignments: those compile a shape-error path
                prev_imu[1 + i] = f1[i]
                prev_imu[4 + i] = w1[i]
            for j in range(N_STATE):
                out[k, j] = state[j]
            continue
        dt = t_imu[k] - prev_imu[0]
        if dt <= 0.0:
            if np.isnan(prev_imu[1]):   # a first sample at the reset time: the left end of the next step
                for i in range(3):
                    prev_imu[1 + i] = f1[i]
                    prev_imu[4 + i] = w1[i]
            for j in range(N_STATE):
                out[k, j] = state[j]
            continue
        if interval_samples or np.isnan(prev_imu[1]):
            # sample k is the mean over (t_{k-1}, t_k] ("interval"), or the first step after the reset time
            # has no left-end sample ("instant"): use sample k alone for the step
            f0 = f1
            w0 = w1
        else:  # instantaneous samples: trapezoid of the two ends
            f0 = prev_imu[1:4]
            w0 = prev_imu[4:7]
        lat, lon, h = state[0], state[1], state[2]
        v0 = state[3:6].copy()
        q = state[6:10].copy()
        # ---- predicted mid-step position and velocity (for Earth/transport rate, Coriolis, gravity)
        w_ie, w_en, rn, re = _rates(lat, h, v0[0], v0[1])
        g = gravity_ned(lat, h, gravity_model)
        C0 = quat_to_dcm(q)
        Cf0 = _mv(C0, f0)
        a0 = Cf0 + g - _cross(2.0 * w_ie + w_en, v0)
        v_mid = v0 + 0.5 * dt * a0
        lat_m = lat + 0.5 * dt * v_mid[0] / rn
        h_m = h - 0.5 * dt * v_mid[2]
        w_ie, w_en, rn, re = _rates(lat_m, h_m, v_mid[0], v_mid[1])
        # ---- attitude: body rotation vector with coning, navigation-frame rotation
        phi = 0.5 * (w0 + w1) * dt + _cross(w0, w1) * (dt * dt / 12.0)
        zeta = (w_ie + w_en) * dt
        q1 = _qmul(_qmul(_rotvec_q(-zeta), q), _rotvec_q(phi))
        q1 /= np.sqrt(q1[0] ** 2 + q1[1] ** 2 + q1[2] ** 2 + q1[3] ** 2)
        C1 = quat_to_dcm(q1)
        # ---- velocity
        g = gravity_ned(lat_m, h_m, gravity_model)
        dv_sf = 0.5 * dt * (Cf0 + _mv(C1, f1))
        v1 = v0 + dv_sf + dt * (g - _cross(2.0 * w_ie + w_en, v_mid))
        # ---- vertical channel: third-order baro loop (down-positive velocity)
        if np.isfinite(baro_state[1]):
            e = h - baro_state[1]
            v1[2] += dt * (k2 * e + baro_state[2])
            baro_state[2] += dt * k3 * e
            h_corr = -k1 * e
        else:
            h_corr = 0.0
        v_avg = 0.5 * (v0 + v1)
        # ---- position
        state[0] = lat + dt * v_avg[0] / rn
        state[1] = lon + dt * v_avg[1] / (re * np.cos(lat_m))
        state[2] = h + dt * (-v_avg[2] + h_corr)
        for i in range(3):
            state[3 + i] = v1[i]
            prev_imu[1 + i] = f1[i]
            prev_imu[4 + i] = w1[i]
        for i in range(4):
            state[6 + i] = q1[i]
        prev_imu[0] = t_imu[k]
        for j in range(N_STATE):
            out[k, j] = state[j]
    return bad


def euler_from_C_bn(C: np.ndarray) -> tuple[float, float, float]:
    """3-2-1 Euler angles (roll, pitch, yaw; rad) of a body FRD -> NED matrix."""
    return (
        float(np.arctan2(C[2, 1], C[2, 2])),
        float(-np.arcsin(np.clip(C[2, 0], -1.0, 1.0))),
        float(np.arctan2(C[1, 0], C[0, 0])),
    )


def quat_from_C_bn(C: np.ndarray) -> np.ndarray:
    """Quaternion [w, x, y, z] of C_bn (Shepperd's method)."""
    tr = np.trace(C)
    cands = [tr, C[0, 0], C[1, 1], C[2, 2]]
    i = int(np.argmax(cands))
    if i == 0:
        w = 0.5 * np.sqrt(1.0 + tr)
        q = [w, (C[2, 1] - C[1, 2]) / (4 * w), (C[0, 2] - C[2, 0]) / (4 * w), (C[1, 0] - C[0, 1]) / (4 * w)]
    elif i == 1:
        x = 0.5 * np.sqrt(1.0 + 2 * C[0, 0] - tr)
        q = [(C[2, 1] - C[1, 2]) / (4 * x), x, (C[0, 1] + C[1, 0]) / (4 * x), (C[0, 2] + C[2, 0]) / (4 * x)]
    elif i == 2:
        y = 0.5 * np.sqrt(1.0 + 2 * C[1, 1] - tr)
        q = [(C[0, 2] - C[2, 0]) / (4 * y), (C[0, 1] + C[1, 0]) / (4 * y), y, (C[1, 2] + C[2, 1]) / (4 * y)]
    else:
        z = 0.5 * np.sqrt(1.0 + 2 * C[2, 2] - tr)
        q = [(C[1, 0] - C[0, 1]) / (4 * z), (C[0, 2] + C[2, 0]) / (4 * z), (C[1, 2] + C[2, 1]) / (4 * z), z]
    q = np.array(q)
    return q / np.linalg.norm(q) * (1.0 if q[0] >= 0 else -1.0)


class StrapdownIns:
    """Strapdown INS state and chunked propagation (see module docstring).

    gravity_model: "somigliana" | "j2"; tau_baro_s: baro loop time constant (None: undamped vertical channel);
    imu_samples: "instant" (samples at instants, trapezoid between them) or "interval" (each sample is the
    mean over the step ending at its time stamp, like a delta-v / delta-theta sample).
    The accelerometer and gyro bias estimates (body, m/s^2 and rad/s) are subtracted from every sample;
    an error-state filter sets them.
    """

    def __init__(
        self, gravity_model: str = "j2", tau_baro_s: float | None = 30.0, imu_samples: str = "instant"
    ):
        if gravity_model not in GRAVITY_MODELS:
            raise ValueError(f"gravity_model must be one of {list(GRAVITY_MODELS)}, got {gravity_model!r}")
        if tau_baro_s is not None and not tau_baro_s > 0:
            raise ValueError(f"tau_baro_s must be positive, got {tau_baro_s}")
        if imu_samples not in ("instant", "interval"):
            raise ValueError(f"imu_samples must be 'instant' or 'interval', got {imu_samples!r}")
        self.imu_samples = imu_samples
        self.gravity_model = gravity_model
        self.tau_baro_s = tau_baro_s
        self.state = np.full(N_STATE, np.nan)
        self.prev_imu = np.full(7, np.nan)
        self.baro_state = np.array([np.nan, np.nan, 0.0])
        self.accel_bias_b = np.zeros(3)
        self.gyro_bias_b = np.zeros(3)
        self.t_s = np.nan
        self.bad_imu_samples = 0

    def reset(
        self,
        t_s: float,
        lat_rad: float,
        lon_rad: float,
        h_m: float,
        v_ned_mps,
        roll_rad: float,
        pitch_rad: float,
        yaw_rad: float,
    ) -> None:
        from ...terrain.geodesy import euler_to_C_bn

        self.state = np.empty(N_STATE)
        self.state[:3] = (lat_rad, lon_rad, h_m)
        self.state[3:6] = np.asarray(v_ned_mps, float)
        self.state[6:] = quat_from_C_bn(euler_to_C_bn(roll_rad, pitch_rad, yaw_rad))
        # the state is at t_s: the first IMU sample's step runs from t_s (an "interval" sample at t_s + dt is
        # the mean over (t_s, t_s + dt]); starting the clock at the first sample instead lagged the INS by
        # one IMU interval (0.8 m along track at 80 m/s and 100 Hz, the same in every run)
        self.prev_imu[:] = np.nan
        self.prev_imu[0] = float(t_s)
        self.baro_state[:] = (np.nan, np.nan, 0.0)
        self.accel_bias_b[:] = 0.0
        self.gyro_bias_b[:] = 0.0
        self.t_s = float(t_s)
        self.bad_imu_samples = 0

    def propagate(
        self, t_imu, f_b_mps2, omega_ib_b_rps, imu_valid=None, t_baro=None, h_baro_m=None, baro_valid=None
    ) -> np.ndarray:
        """Advance over IMU samples; returns the (n, 10) state history [lat, lon, h, v_ned, q_bn]."""
        t_imu = np.ascontiguousarray(t_imu, dtype=float)
        n = t_imu.shape[0]
        ok = np.ones(n, bool) if imu_valid is None else np.ascontiguousarray(imu_valid, dtype=bool)
        if t_baro is None or self.tau_baro_s is None:
            t_baro, h_baro_m, baro_valid = np.zeros(0), np.zeros(0), np.zeros(0, bool)
        else:
            t_baro = np.ascontiguousarray(t_baro, float)
            h_baro_m = np.ascontiguousarray(h_baro_m, float)
            baro_valid = (
                np.ones(len(t_baro), bool) if baro_valid is None else np.ascontiguousarray(baro_valid, bool)
            )
        out = np.empty((n, N_STATE))
        tau = 1e30 if self.tau_baro_s is None else float(self.tau_baro_s)
        bad = propagate_chunk(
            (self.state, self.prev_imu, self.baro_state),
            (t_imu, np.ascontiguousarray(f_b_mps2, float), np.ascontiguousarray(omega_ib_b_rps, float), ok),
            (t_baro, h_baro_m, baro_valid),
            (self.accel_bias_b, self.gyro_bias_b, tau, GRAVITY_MODELS[self.gravity_model],
             self.imu_samples == "interval"),
            out,
        )
        self.bad_imu_samples += int(bad)
        if n:
            self.t_s = float(t_imu[-1])
        return out

    # ---- accessors and corrections (used by error-state filters)
    @property
    def C_bn(self) -> np.ndarray:
        return quat_to_dcm(self.state[6:10])

    @property
    def euler_rad(self) -> tuple[float, float, float]:
        return euler_from_C_bn(self.C_bn)

    def correct(self, d_ned_m=None, dv_ned_mps=None, dpsi_ned_rad=None) -> None:
        """Subtract estimated errors: position error (m, NED), velocity error (m/s), attitude error (rad,
        small rotation of the computed navigation frame: C_true = (I + [psi x]) C_computed)."""
        from ...terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

        lat, h = self.state[0], self.state[2]
        if d_ned_m is not None:
            dn, de, dd = d_ned_m
            self.state[0] -= dn / (meridian_radius_m(lat) + h)
            self.state[1] -= de / ((prime_vertical_radius_m(lat) + h) * np.cos(lat))
            self.state[2] += dd
        if dv_ned_mps is not None:
            self.state[3:6] -= np.asarray(dv_ned_mps, float)
        if dpsi_ned_rad is not None:
            p = np.asarray(dpsi_ned_rad, float)
            # computed C = (I - [psi x]) C_true  ->  C_true = rot(psi) C_computed
            q = _qmul(_rotvec_q(p), self.state[6:10])
            self.state[6:10] = q / np.linalg.norm(q)
