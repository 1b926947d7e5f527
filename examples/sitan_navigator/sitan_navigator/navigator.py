"""SITAN-style terrain-aided navigation: an extended Kalman filter over the INS error state whose radar-
altimeter measurement is linearised on the map's local terrain slopes.

SITAN (Sandia Inertial Terrain-Aided Navigation; Hostetler & Andreas, "Nonlinear Kalman filtering
techniques for terrain-aided navigation", IEEE TAC 28(3), 1983) runs one Kalman filter on the INS errors and
feeds it each radar-altimeter range: the measurement is the clearance the INS position predicts on the map
minus the measured one, and its Jacobian with respect to the horizontal position error is the terrain
slope under the aircraft. Over terrain that is locally planar at the scale of the position uncertainty
the filter is linear and tracks the INS drift continuously (no batch, no grid); it is a tracking filter:
it needs an initial position within roughly the terrain's correlation length (GNSS before a denial gives
it), where a grid filter (pmf) or a particle filter would acquire from kilometres.

State (17; computed minus true, position in metres):

    0-2   position error north, east, up (m)
    3-5   velocity error north, east, down (m/s)
    6-8   attitude error eps (rad; C_computed = (I - [eps x]) C_true)
    9-11  accelerometer bias error (m/s^2, body)    12-14  gyro bias error (rad/s, body)
    15    barometric height bias (m): h_baro = h_true + b + noise
    16    terrain-clearance error (m): what the map and the cone model get wrong about the range over the
          last few hundred metres (unresolved terrain, map error), a first-order Gauss-Markov process
          (`clearance_sigma_m`, `clearance_tau_s`); without it the altimeter's many samples would be taken
          as independent and the height and position sigmas would shrink below the true errors

The INS is navigators.inertial.StrapdownIns (free vertical channel: the filter slaves it to the
barometer and the altimeter), its error dynamics navigators.inertial.error_model_15 (seed 002 eqs 16-22)
discretised along the INS history.

Measurements, each at its own sample time:

- radar altimeter: predicted range r(x) = the shortest return inside the beam cone around the body down
  axis from the INS position on the map (navigators.measurements.radar_altimeter.predict, as the
  pmf's model); H = dr/d(position) by central differences over +-d north, east and up, d = max(half a map
  post, the horizontal 1-sigma, capped at `slope_baseline_max_m`): SITAN's slope taken over the region
  the position is uncertain in (its "stochastic linearisation"), not a single post pair. Noise: the
  altimeter's (constant + fraction of range) plus the map's. A residual beyond `gate_sigmas` is rejected
  (counted in Health as "gated"): the linearisation does not hold there.
- barometer: z = h_ins - (h_baro - b_hat) = dh + (b_hat - b), correcting the height, vertical velocity and
  bias only (a consider update: a pressure altitude's scale error in a non-standard atmosphere must not
  reach the tilt and position through the cross-covariances).
- GNSS (while available): position (metres N, E, up) and velocity against the INS.

Health counts every skipped sample by reason: "imu_invalid", "ra_invalid" (NaN or no return),
"ra_off_map" (no map under the hypothesis), "gated", "gnss_invalid", "baro_invalid".
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np
from trn_env.navigators.core.capabilities import Capabilities
from trn_env.navigators.core.maps import map_record
from trn_env.navigators.frames import SensorFrames, imu_gap_s
from trn_env.navigators.inertial.error_model_15 import noise_input_matrix, transition_over_history
from trn_env.navigators.inertial.strapdown import StrapdownIns
from trn_env.navigators.measurements import radar_altimeter
from trn_env.navigators.protocol import Estimate, Health
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

N_STATE = 17
I_POS, I_VEL, I_ATT, I_BA, I_BG, I_BARO, I_CLR = 0, 3, 6, 9, 12, 15, 16
UG_MPS2 = 9.80665e-6


def _setting(default, unit: str, doc: str, **kw):
    return field(default=default, metadata={"unit": unit, "doc": doc}, **kw)


@dataclass(frozen=True)
class SitanSettings:
    """Settings of the SITAN navigator (SI, 1 sigma unless stated)."""

    measurement_rate_hz: float = _setting(5.0, "Hz",
                                          "radar-altimeter samples used per second (<= the sensor's)")
    error_model_rate_hz: float = _setting(25.0, "Hz", "rate the INS error transition is evaluated at")
    ra_noise_const_m: float = _setting(0.6, "m", "radar-altimeter noise, constant part")
    ra_noise_fraction: float = _setting(0.02, "-", "radar-altimeter noise, fraction of the range")
    ra_half_beam_deg: float = _setting(8.5, "deg", "half beamwidth of the altimeter's cone")
    ra_cone_rings: int = _setting(2, "-", "rings sampling the cone (0: nadir ray only)")
    map_sigma_m: float = _setting(3.0, "m", "white part of the map's height error")
    clearance_sigma_m: float = _setting(5.0, "m", "correlated terrain-clearance error (map, unresolved "
                                        "terrain): its 1 sigma")
    clearance_tau_s: float = _setting(10.0, "s", "correlation time of the terrain-clearance error")
    slope_baseline_max_m: float = _setting(300.0, "m", "largest half-baseline of the slope differences")
    gate_sigmas: float = _setting(4.0, "-", "altimeter residuals beyond this many sigmas are rejected")
    baro_noise_m: float = _setting(0.5, "m", "barometric height noise")
    baro_bias_sigma_m: float = _setting(10.0, "m", "prior of the barometric bias")
    baro_bias_walk_m_per_sqrt_s: float = _setting(0.02, "m/√s", "random walk of the barometric bias")
    gnss_sigma_m: float = _setting(2.0, "m", "GNSS horizontal position noise per axis")
    gnss_vertical_sigma_m: float = _setting(4.0, "m", "GNSS vertical position noise")
    gnss_velocity_sigma_mps: float = _setting(0.05, "m/s", "GNSS velocity noise per axis")
    accel_noise_mps2_rthz: float = _setting(10.0 * UG_MPS2, "m/s²/√Hz", "accelerometer white noise density")
    gyro_noise_rps_rthz: float = _setting(1.45e-6, "rad/s/√Hz", "gyro white noise density")
    accel_bias_sigma_mps2: float = _setting(50.0 * UG_MPS2, "m/s²", "accelerometer turn-on bias prior")
    gyro_bias_sigma_rps: float = _setting(2.4e-8, "rad/s", "gyro turn-on bias prior")
    position_walk_m_per_sqrt_s: float = _setting(0.3, "m/√s", "position process noise (unmodelled drift)")
    gravity_model: str = _setting("j2", "-", "INS gravity: 'j2' or 'somigliana'")
    imu_samples: str = _setting("interval", "-", "IMU samples as 'interval' means or 'instant' values")

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in ("gravity_model", "imu_samples"):
                allowed = ("j2", "somigliana") if f.name == "gravity_model" else ("interval", "instant")
                if v not in allowed:
                    raise ValueError(f"{f.name}: must be one of {allowed}, got {v!r}")
                continue
            if f.name == "ra_cone_rings":
                if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not 0 <= v <= 8:
                    raise ValueError(f"ra_cone_rings: must be an integer in [0, 8], got {v!r}")
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ValueError(f"{f.name}: must be a finite number >= 0, got {v!r}")
        for name in ("measurement_rate_hz", "error_model_rate_hz", "gate_sigmas", "ra_half_beam_deg",
                     "clearance_tau_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: must be > 0, got {getattr(self, name)!r}")
        if self.ra_half_beam_deg >= 60:
            raise ValueError(f"ra_half_beam_deg: must be < 60 deg, got {self.ra_half_beam_deg!r}")


class SitanNavigator:
    """SITAN-style radar-altimeter EKF over the INS error state (see the module docstring).

    Parameters
    ----------
    dem : terrain.Dem or str
        the navigator's terrain map (a name or path goes to terrain.load); required.
    **settings
        SitanSettings' fields.
    """

    name = "sitan"
    settings_class = SitanSettings
    # what trn-env reads before building it: the map as dem=, the scenario IMU's specification
    # (apply_imu_spec), the sensors it needs (a scenario without them is refused) and those it uses
    capabilities = Capabilities(
        needs_map=True, uses_imu_spec=True,
        required_sensors=(("imu", "SITAN corrects a strapdown INS"),
                          ("radar_altimeter", "SITAN's measurement is the radar altimeter's range over the "
                                              "map")),
        optional_sensors=("baro", "gnss"))

    def __init__(self, dem=None, **settings):
        if dem is None:
            raise ValueError("dem: the SITAN navigator needs the terrain map (dem=)")
        if isinstance(dem, str):
            from trn_env import terrain
            dem = terrain.load(dem)
        if not hasattr(dem, "grid"):
            raise ValueError(f"dem: expected a terrain.Dem, got {type(dem).__name__}")
        unknown = sorted(set(settings) - {f.name for f in fields(SitanSettings)})
        if unknown:
            raise ValueError(f"{unknown[0]}: unknown setting of the SITAN navigator")
        self.settings = SitanSettings(**settings)
        s = self.settings
        self.dem = dem
        self.grid = dem.grid
        self.post_m = 0.5 * min(dem.spacing_m)
        self.ins = StrapdownIns(s.gravity_model, tau_baro_s=None, imu_samples=s.imu_samples)
        self.dt_err = 1.0 / s.error_model_rate_hz
        self.dt_meas = 1.0 / s.measurement_rate_hz
        self.health = Health()
        self.x_P = np.eye(N_STATE)
        self._t_meas = -math.inf
        self._phi = np.eye(15)
        self._q_acc = np.zeros((N_STATE, N_STATE))
        self.epochs = 0
        self._baro_bias = 0.0
        self._clr = 0.0
        self._phi_clr = 1.0
        self.last_nis = math.nan
        # the INS error model's figures: the settings, raised by the scenario's IMU (apply_imu_spec)
        self._imu = {"accel_noise_mps2_rthz": s.accel_noise_mps2_rthz,
                     "gyro_noise_rps_rthz": s.gyro_noise_rps_rthz,
                     "accel_bias_sigma_mps2": s.accel_bias_sigma_mps2,
                     "gyro_bias_sigma_rps": s.gyro_bias_sigma_rps,
                     "accel_bias_walk": 0.0, "gyro_bias_walk": 0.0}

    def apply_imu_spec(self, spec) -> None:
        """Take the INS error model from the IMU's specification (navigators.core.imu_spec.ImuSpec; trn-env's
        scenario builder calls this with the scenario's IMU before `reset`): noise densities and bias priors
        (root sum square of turn-on bias and instability) raise the settings, never lower them; the bias
        instabilities drive the bias states as random walks of density 2 sigma^2 / tau."""
        imu = self._imu
        imu["accel_noise_mps2_rthz"] = max(imu["accel_noise_mps2_rthz"], spec.accel_noise_density_mps2_rthz)
        imu["gyro_noise_rps_rthz"] = max(imu["gyro_noise_rps_rthz"], spec.gyro_noise_density_rps_rthz)
        imu["accel_bias_sigma_mps2"] = max(imu["accel_bias_sigma_mps2"],
                                           math.hypot(spec.accel_bias_mps2, spec.accel_bias_instability_mps2))
        imu["gyro_bias_sigma_rps"] = max(imu["gyro_bias_sigma_rps"],
                                         math.hypot(spec.gyro_bias_rps, spec.gyro_bias_instability_rps))
        imu["accel_bias_walk"] = 2.0 * spec.accel_bias_instability_mps2 ** 2 / max(spec.accel_bias_tau_s, 1.0)
        imu["gyro_bias_walk"] = 2.0 * spec.gyro_bias_instability_rps ** 2 / max(spec.gyro_bias_tau_s, 1.0)

    @classmethod
    def required_sensors(cls) -> list[tuple[str, str]]:
        """(sensor name, why) of every sensor SITAN needs (its capabilities' required_sensors)."""
        return list(cls.capabilities.required_sensors)

    # ------------------------------------------------------------------ protocol
    def reset(self, initial: Estimate) -> None:
        s = self.settings
        self.ins.reset(initial.t_s, initial.lat_rad, initial.lon_rad, initial.h_m, initial.v_ned_mps,
                       initial.roll_rad, initial.pitch_rad, initial.yaw_rad)
        P = np.zeros((N_STATE, N_STATE))
        c = np.asarray(initial.covariance, float)[:9, :9]
        flip = np.diag([1.0, 1.0, -1.0, 1, 1, 1, 1, 1, 1])          # down -> up for the position
        P[:9, :9] = flip @ (0.5 * (c + c.T)) @ flip
        P[9:12, 9:12] = np.eye(3) * self._imu["accel_bias_sigma_mps2"] ** 2
        P[12:15, 12:15] = np.eye(3) * self._imu["gyro_bias_sigma_rps"] ** 2
        P[15, 15] = s.baro_bias_sigma_m ** 2
        P[16, 16] = s.clearance_sigma_m ** 2
        self.P = P
        self._clr = 0.0
        self._phi_clr = 1.0
        self.health = Health()
        self._t_meas = -math.inf
        self._phi = np.eye(15)
        self._q_acc = np.zeros((N_STATE, N_STATE))
        self._baro_bias = 0.0
        self.epochs = 0

    def update(self, frames: SensorFrames) -> Estimate:
        self.health.events = []
        imu = frames.imu
        t_end = float(frames.t_end_s)
        meas = self._measurements(frames)
        if imu is not None and imu.t_s.shape[0]:
            t = np.asarray(imu.t_s, float)
            gap_s = imu_gap_s(t, self.ins.t_s)
            if gap_s > 0.0:
                self.health.skip(float(t[0]), "imu_gap", f"{gap_s:.2f} s of IMU samples missing")
            keep = t > self.ins.t_s
            t, f_b, w_b, ok = t[keep], imu.f_b_mps2[keep], imu.omega_ib_b_rps[keep], imu.valid[keep]
            i0 = 0
            for tm, kind, data in meas:
                i1 = int(np.searchsorted(t, tm, side="right"))
                if i1 > i0:
                    self._propagate(t[i0:i1], f_b[i0:i1], w_b[i0:i1], ok[i0:i1])
                    i0 = i1
                if abs(tm - self.ins.t_s) <= 0.02:
                    self._predict()
                    getattr(self, f"_fuse_{kind}")(tm, data)
                else:
                    self.health.skip(tm, "no_imu", f"{kind} sample at {tm:.2f} s: no IMU sample near it")
            if i0 < t.shape[0]:
                self._propagate(t[i0:], f_b[i0:], w_b[i0:], ok[i0:])
        else:
            self.health.skip(t_end, "no_imu",
                             f"no IMU samples in the frame ({len(meas)} other samples unused)")
        self._predict()
        return self._estimate(max(t_end, self.ins.t_s) if math.isfinite(self.ins.t_s) else t_end)

    # ------------------------------------------------------------------ time update
    def _propagate(self, t, f_b, w_b, ok) -> None:
        bad0 = self.ins.bad_imu_samples
        hist = self.ins.propagate(t, f_b, w_b, ok)
        if self.ins.bad_imu_samples > bad0:
            self.health.skip(float(t[0]), "imu_invalid",
                             f"{self.ins.bad_imu_samples - bad0} IMU samples invalid (held previous)")
        n = t.shape[0]
        dt_imu = float(t[-1] - t[0]) / (n - 1) if n > 1 else self.dt_err
        stride = max(int(round(self.dt_err / max(dt_imu, 1e-6))), 1)
        rows = np.arange(0, n, stride)
        fb = np.where(np.isfinite(f_b), f_b, 0.0)
        dt = n * max(dt_imu, 1e-6) / rows.shape[0]
        good = np.all(np.isfinite(hist[rows]), axis=1)
        if good.all():
            phi = transition_over_history(hist[rows], fb[rows], self.ins.accel_bias_b, 0, rows.shape[0], dt,
                                          True)
            if np.all(np.isfinite(phi)):
                self._phi = phi @ self._phi
        s = self.settings
        G = noise_input_matrix(self.ins.C_bn)
        imu = self._imu
        q = np.array([imu["accel_noise_mps2_rthz"] ** 2] * 3 + [imu["gyro_noise_rps_rthz"] ** 2] * 3)
        span = n * max(dt_imu, 1e-6)
        self._q_acc[:15, :15] += (G * q) @ G.T * span
        self._q_acc[0, 0] += s.position_walk_m_per_sqrt_s ** 2 * span
        self._q_acc[1, 1] += s.position_walk_m_per_sqrt_s ** 2 * span
        self._q_acc[15, 15] += s.baro_bias_walk_m_per_sqrt_s ** 2 * span
        for i in range(3):                # bias instabilities as random walks (Gauss-Markov, span << tau)
            self._q_acc[9 + i, 9 + i] += imu["accel_bias_walk"] * span
            self._q_acc[12 + i, 12 + i] += imu["gyro_bias_walk"] * span
        decay = math.exp(-span / s.clearance_tau_s)
        self._phi_clr *= decay
        self._clr *= decay
        self._q_acc[16, 16] += s.clearance_sigma_m ** 2 * (1.0 - decay * decay)

    def _metric(self) -> np.ndarray:
        lat, h = self.ins.state[0], self.ins.state[2]
        return np.array([meridian_radius_m(lat) + h, (prime_vertical_radius_m(lat) + h) * math.cos(lat)])

    def _predict(self) -> None:
        """P <- Phi P Phi' + Q over the IMU samples since the last prediction (position in metres)."""
        T = np.ones(15)
        T[:2] = self._metric()
        phi = np.eye(N_STATE)
        phi[:15, :15] = self._phi * T[:, None] / T[None, :]
        phi[16, 16] = self._phi_clr
        self._phi_clr = 1.0
        P = phi @ self.P @ phi.T + self._q_acc
        self.P = 0.5 * (P + P.T)
        self._phi = np.eye(15)
        self._q_acc = np.zeros((N_STATE, N_STATE))

    # ------------------------------------------------------------------ measurements
    def _measurements(self, frames: SensorFrames) -> list[tuple[float, str, object]]:
        """(time, kind, data) of the samples to fuse in this interval, in time order."""
        out: list[tuple[float, str, object]] = []
        ra = frames.radar_altimeter
        if ra is not None:
            for t, r, v in zip(np.asarray(ra.t_s, float), np.asarray(ra.range_m, float),
                               np.asarray(ra.valid, bool), strict=True):
                if t < self._t_meas + self.dt_meas - 1e-9:
                    continue
                self._t_meas = t
                if not (v and math.isfinite(r) and r > 0):
                    self.health.skip(t, "ra_invalid", "radar altimeter: no return or invalid sample")
                    continue
                out.append((t, "ra", r))
        g = frames.gnss
        if g is not None:
            for j in range(g.t_s.shape[0]):
                row = (g.lat_rad[j], g.lon_rad[j], g.h_m[j], *np.asarray(g.v_ned_mps[j], float))
                if not (g.valid[j] and all(math.isfinite(x) for x in row)):
                    self.health.skip(float(g.t_s[j]), "gnss_invalid", "GNSS: invalid fix")
                    continue
                out.append((float(g.t_s[j]), "gnss", row))
        b = frames.baro
        if b is not None and b.t_s.shape[0]:
            ok = np.asarray(b.valid, bool) & np.isfinite(b.h_baro_m)
            if (~ok).any():
                self.health.skip(float(b.t_s[0]), "baro_invalid", f"{int((~ok).sum())} baro samples invalid")
            if ok.any():
                j = np.flatnonzero(ok)[-1]
                out.append((float(b.t_s[j]), "baro", float(b.h_baro_m[j])))
        out.sort(key=lambda m: m[0])
        return out

    def _kalman(self, z: np.ndarray, H: np.ndarray, R: np.ndarray, t: float, gate: float | None,
                states: list[int] | None = None) -> bool:
        """One EKF update (Joseph form); `states`: the only states it may correct (the others' gain rows are
        zero: a consider update that leaves them and their covariance as they were)."""
        S = H @ self.P @ H.T + R
        try:
            Sinv = np.linalg.inv(S)
        except np.linalg.LinAlgError:
            self.health.skip(t, "singular", "innovation covariance singular")
            return False
        nis = float(z @ Sinv @ z)
        if not math.isfinite(nis):
            self.health.skip(t, "non_finite", "non-finite innovation")
            return False
        if gate is not None and nis > gate ** 2 * len(z):
            self.health.skip(t, "gated", f"residual {z[0]:.1f} m beyond {gate:g} sigma")
            return False
        K = self.P @ H.T @ Sinv
        if states is not None:
            mask = np.zeros(N_STATE, bool)
            mask[states] = True
            K[~mask] = 0.0
        dx = K @ z
        IKH = np.eye(N_STATE) - K @ H
        P = IKH @ self.P @ IKH.T + K @ R @ K.T               # Joseph form
        self.P = 0.5 * (P + P.T)
        self._feedback(dx)
        self.last_nis = nis
        return True

    def _feedback(self, dx: np.ndarray) -> None:
        """Correct the INS by the estimated errors (the error state returns to zero)."""
        self.ins.correct(np.array([dx[0], dx[1], -dx[2]]), dx[3:6], dx[6:9])
        self.ins.accel_bias_b -= dx[9:12]
        self.ins.gyro_bias_b -= dx[12:15]
        self._baro_bias -= dx[15]
        self._clr -= dx[16]

    def _fuse_ra(self, t: float, r_meas: float) -> None:
        s = self.settings
        sig_h = math.sqrt(max(0.5 * (self.P[0, 0] + self.P[1, 1]), 0.0))
        d = min(max(self.post_m, sig_h), s.slope_baseline_max_m)
        dn = np.array([0.0, d, -d, 0.0, 0.0, 0.0, 0.0])
        de = np.array([0.0, 0.0, 0.0, d, -d, 0.0, 0.0])
        dz = 2.0
        dh = np.array([0.0, 0.0, 0.0, 0.0, 0.0, dz, -dz])
        st = self.ins.state
        r_lat, r_lon = self._metric()
        out = np.empty(7)
        radar_altimeter.predict(map_record(self.grid, cubic=False), st[0], st[1], r_lat, r_lon, st[2], dn, de,
                                dh, self.ins.C_bn, np.zeros(1), math.radians(s.ra_half_beam_deg),
                                int(s.ra_cone_rings), 8, out)
        if not np.all(np.isfinite(out)):
            self.health.skip(t, "ra_off_map", "radar altimeter: no map return under the INS position")
            return
        # error = computed - true: the prediction at the computed position minus its value at the truth is
        # dr/dp . dx, so H = dr/dp (p = north, east, up; dh above is a drop of the antenna: minus up)
        H = np.zeros((1, N_STATE))
        H[0, 0] = (out[1] - out[2]) / (2 * d)
        H[0, 1] = (out[3] - out[4]) / (2 * d)
        H[0, 2] = -(out[5] - out[6]) / (2 * dz)
        H[0, 16] = 1.0                    # state 16 = estimated - true clearance error
        sig_r = s.ra_noise_const_m + s.ra_noise_fraction * r_meas
        R = np.array([[sig_r ** 2 + s.map_sigma_m ** 2]])
        self.epochs += 1
        self._kalman(np.array([out[0] + self._clr - r_meas]), H, R, t, s.gate_sigmas)

    def _fuse_baro(self, t: float, h_baro: float) -> None:
        H = np.zeros((1, N_STATE))
        H[0, 2] = 1.0
        H[0, 15] = 1.0                    # state 15 = estimated - true bias: z = dh + (b_hat - b)
        z = np.array([self.ins.state[2] - (h_baro - self._baro_bias)])
        # the height channel only: a pressure altitude's scale error in a non-standard atmosphere would
        # otherwise leak through the cross-covariances into tilt, accelerometer bias and position
        self._kalman(z, H, np.array([[self.settings.baro_noise_m ** 2]]), t, None,
                     [I_POS + 2, I_VEL + 2, I_BARO])

    def _fuse_gnss(self, t: float, row) -> None:
        s = self.settings
        lat, lon, h, vn, ve, vd = row
        st = self.ins.state
        r_lat, r_lon = self._metric()
        z = np.array([(st[0] - lat) * r_lat, (st[1] - lon) * r_lon, st[2] - h,
                      st[3] - vn, st[4] - ve, st[5] - vd])
        H = np.zeros((6, N_STATE))
        H[:6, :6] = np.eye(6)
        R = np.diag([s.gnss_sigma_m ** 2] * 2 + [s.gnss_vertical_sigma_m ** 2]
                    + [s.gnss_velocity_sigma_mps ** 2] * 3)
        self._kalman(z, H, R, t, None)

    # ------------------------------------------------------------------ output
    def _estimate(self, t_s: float) -> Estimate:
        st = self.ins.state
        dt = t_s - self.ins.t_s if math.isfinite(self.ins.t_s) else 0.0
        r_lat, r_lon = self._metric()
        v = st[3:6].copy()
        roll, pitch, yaw = self.ins.euler_rad
        flip = np.diag([1.0, 1.0, -1.0, 1, 1, 1, 1, 1, 1])
        cov = flip @ self.P[:9, :9] @ flip
        ok = bool(np.all(np.isfinite(st)) and np.all(np.isfinite(cov)))
        if not ok:
            self.health.ok, self.health.status = False, "diverged"
        return Estimate(float(t_s), float(st[0] + v[0] * dt / r_lat), float(st[1] + v[1] * dt / r_lon),
                        float(st[2] - v[2] * dt), v, roll, pitch, yaw, cov, self.health,
                        {"nis": self.last_nis, "nis_dof": 1, "sitan_epochs": self.epochs,
                         "baro_bias_m": float(self._baro_bias)})
