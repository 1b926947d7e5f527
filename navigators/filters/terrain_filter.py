"""What the point-mass and particle filters share: an INS they ride on, the measurement epochs, GNSS, Health.

`InsRiddenFilter` runs the strapdown INS (navigators.inertial.StrapdownIns, baro-slaved vertical channel)
over each frame and hands the filter, in time order, the terrain samples it selected at
`measurement_rate_hz` (IRA and/or radar altimeter) and the valid GNSS fixes, each with the INS state at the
sample's time. The filter's belief is over the INS errors (true minus INS for the horizontal position, INS
height minus true for the vertical), so the INS is never corrected and the belief needs no linearisation.
A subclass implements `_init_belief`, `_predict_to`, `_terrain_update`, `_gnss_update` and `_moments`.

Terrain measurement (navigators.measurements.terrain_models): the measured terrain height of a sample is
h_INS - p_d (IRA, seed 000 eq 2) or h_INS - range (radar altimeter, eq 1); its noise variance is the sensor's
(sigma_R^2 (p_d / R)^2 + (sigma_theta |p_h|)^2, or the altimeter's sigma^2) plus the map's error class
`map_sigma_m` (the scenario's map error model, filled in by trn_env's build_navigator) plus
`terrain_model_sigma_m` (terrain the map does not resolve between its posts, and interpolation). The
vertical offset (baro bias + the map's vertical bias, prior sigma sqrt(baro_bias_sigma_m^2 +
map_bias_sigma_m^2)) is estimated with the position, so a biased baro or map does not pull the fix.

What the published covariance adds to the belief's: the map's vertical error the published height keeps
(height_error) and the share of the map's horizontal shift the position took on (map_shift): terrain
samples pin both to the map, which the belief, relative to the map, cannot see.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.capture import CaptureGuard, anchor_from_cov9, free_ins_tilt_sigma_rad
from ..core.ins_gnss import InsGnssBlock, gnss_fixes, velocity_into_ins
from ..core.maps import MapRecord, load_map, map_record
from ..core.recovery import IntegrityRecovery, capped_nis  # noqa: F401 (re-exported)
from ..frames import SensorFrames
from ..inertial.strapdown import StrapdownIns, euler_from_C_bn, quat_to_dcm
from ..integrity import protection_level as pl
from ..integrity.innovation_monitor import InnovationMonitor
from ..measurements import ira, radar_altimeter
from ..measurements.baro import geometric_height_m
from ..measurements.ira import IRA_FORMULA_CODES
from ..measurements.sampling import terrain_samples
from ..measurements.terrain_models import radii_m
from ..protocol import Estimate, Health, update_extra
from ._ekf_kernels import yaw_total_variation
from .height_error import MAP_WALK_FACTORS, HeightError, map_walk_variance_per_m  # noqa: F401
from .map_shift import MapShiftShare
from .terrain_filter_settings import (
    TerrainFilterSettings,
)

G0 = 9.80665
MAX_RECOVERY_DOUBLINGS = 4   # consecutive re-spreads widen by 2x each, up to 2^3 x recovery_sigma_m
# a terrain sample is skipped when the belief puts more than this probability on hypotheses whose map has
# no height (a void of the DEM, or off it): those cannot be scored, and scoring the rest alone lets a chance
# match far from the truth take the belief (a 1 km void under the route moved the pmf 200 m)
MAX_MASS_WITHOUT_MAP = 0.5


class InsRiddenFilter(InsGnssBlock):
    """Base of the terrain filters (see the module docstring). Settings common to both (SI, 1 sigma):

    dem: the navigator's map (terrain.Dem or a name for terrain.load), required. aiding: "ira" (default),
    "radar_altimeter" or "both". measurement_rate_hz: terrain samples used per second (the sensors sample
    faster; every 1/rate s the next valid sample is taken; default 1 Hz, seed 002's TRN rate). ira_formula:
    "proposed" (seed 000 eqs 14-36, default: its closest point follows the attitude and the velocity) or
    "conventional" (eqs 9-13). ira_range_sigma_m, ira_look_angle_sigma_deg: the IRA's noise (seed 002
    Table 1). ra_sigma_m, ra_half_beam_deg, ra_cone_rings: the radar altimeter's noise, half beamwidth and
    the rings of its cone model (0: the axis ray only). map_sigma_m: the map's random vertical error (its
    accuracy class); map_bias_sigma_m: its vertical bias; terrain_model_sigma_m: terrain between the map's
    posts (default 2.5 m: the world's detail the map does not hold, with interpolation).
    vertical_noise_m_per_sqrt_s: random walk of the vertical offset b (default 0.3: the baro-slaved INS
    height's wander over the filters' memory, the same in every run over the same flight, which b must
    follow or a cross slope turns it into a cross-track error). map_interpolation: "bicubic" (default:
    Catmull-Rom, terrain.kernels.bicubic, a C1 surface through the posts) or "bilinear": how the IRA update
    reads the map between its posts (the two differ by an error that is the same in every run over the same
    ground, which the white terrain_model_sigma_m cannot describe). outlier_prob, outlier_width_m: the heavy
    tail of the likelihood. gnss_sigma_m, gnss_vertical_sigma_m, gnss_velocity_sigma_mps: GNSS fix noise.
    gnss_drift_sigma_m: the receiver's horizontal drift (a Gauss-Markov error far slower than the fixes, the
    same in every fix of a run): fixes that share it cannot average it away, so after each GNSS update the
    belief's north and east variances are widened to at least its square (`_gnss_drift_deficit`; the
    posterior of a position seen through N fixes x + d + w_k is sigma_d^2 + sigma_w^2 / N, never below
    sigma_d^2); 0 (default) treats fixes as independent. A scenario fills it from its GNSS sensor.
    map_correlation_length_m, map_correlation_function: the map's random vertical error correlated along
    the ground (a scenario fills them from its map error model; 0, default: white per sample). Correlated,
    that error is common to the samples within a correlation length, so it is not sample noise that
    averages away but a slowly wandering offset: the filter carries it in the vertical offset b (its prior
    gains map_sigma_m^2, the samples' noise loses it) and b walks with the variance rate
    `map_walk_variance_per_m` per metre flown, the smallest random walk whose variance over every distance
    covers the error's structure function 2 sigma^2 (1 - rho(d / L)) (Schmidt-style augmentation of a
    coloured measurement error into the state; a random walk in place of the Gauss-Markov reversion is the
    conservative side). The map's part of b (its bias, and the correlated error when modelled) is invisible
    to a GNSS height, which measures the INS height's error only: a GNSS update gains b through that part
    only and leaves the map's variance in b (`_gnss_offset_split`), so the map's offset is not taken as
    known when GNSS is lost.
    baro_bias_sigma_m: prior of the baro height's bias. converged_sigma_m: Health says "acquiring" while the
    horizontal 1-sigma is above it. Vertical channel: gravity_model, tau_baro_s, imu_samples,
    baro_geopotential as in navigators.filters.InsTrnNavigator; the INS height starts at the first baro
    height. The measurements behind the defaults: docs/validation/navigators.md ("Terrain filters: measured
    grounds of the defaults").

    Integrity (navigators.integrity.InnovationMonitor, default integrity_alpha 1e-4): every terrain update's
    NIS (an update every cell or particle rejects counts as infinite; each enters capped, see `capped_nis`)
    goes into a sliding window of integrity_window updates; when its sum leaves the chi-square band of
    probability integrity_alpha, Health says "degraded" (ok False) and the filter recovers (`_recover`: the
    belief is re-spread around its mean with recovery_sigma_m added to the horizontal 1-sigma, at least the
    initial spread), each step an event; if a whole window after a re-spread is still out of band it
    re-spreads again, twice as wide (up to 8 x recovery_sigma_m); back in band, the status follows the
    belief's spread again ("acquiring", then "ok").

    Capture (navigators.core.capture, with the IMU's specification): past the small-angle limit the
    published horizontal covariance adds the closest points' offset the free INS's attitude error makes
    (the INS the filter rides on is never corrected); beyond the capture range (a subclass'
    `_capture_range_m`) as well, the filter suspends its terrain updates (its belief kept), Health
    "degraded", and publishes its belief's covariance at the suspension plus the free INS error's growth
    since; a GNSS fix re-spreads the belief with that covariance and resumes. A published horizontal
    covariance is floored at `_capture_floor_m2` (never not positive definite).
    """

    _consistency_warning = ""  # set by a subclass' apply_imu_spec (navigators.core.imu_spec)
    name = "terrain_filter"
    integrity_risk = pl.DEFAULT_INTEGRITY_RISK   # per epoch, for the published HPL (registry sets it)
    map_horizontal_sigma_m = 0.0                 # the map's horizontal error in the HPL (registry sets it)
    # states besides the position whose means take part of the map's shift (map_shift: U), and which of
    # them are the published horizontal velocity's (north, east); none here, a subclass' own
    _MAP_SHIFT_CARRIED = 0
    _MAP_SHIFT_VELOCITY_ROWS: tuple[int, ...] = ()

    settings_class: type[TerrainFilterSettings] = TerrainFilterSettings

    def __init__(self, dem=None, settings: TerrainFilterSettings | None = None, name: str | None = None,
                 **overrides):
        s = self.settings = self.settings_class.build(settings, overrides)
        dem = load_map(dem, "the terrain filter")
        self.dem = dem
        s.copy_to(self, "aiding measurement_rate_hz ira_formula ira_range_sigma_m ra_sigma_m ra_cone_rings "
                        "map_sigma_m map_bias_sigma_m terrain_model_sigma_m map_interpolation outlier_prob "
                        "gnss_sigma_m gnss_vertical_sigma_m gnss_drift_sigma_m gnss_velocity_sigma_mps "
                        "baro_bias_sigma_m map_correlation_length_m map_correlation_function "
                        "converged_sigma_m baro_geopotential baro_lag_s recovery_sigma_m")
        self.ira_code = IRA_FORMULA_CODES[s.ira_formula]
        self.map_walk_var_per_m = map_walk_variance_per_m(s.map_sigma_m, s.map_correlation_length_m,
                                                          s.map_correlation_function)
        self.ira_look_angle_sigma_rad = math.radians(s.ira_look_angle_sigma_deg)
        self.ra_half_beam_rad = math.radians(s.ra_half_beam_deg)
        self.map_cubic = s.map_interpolation == "bicubic"
        self.log_outlier_density = -math.log(s.outlier_width_m)
        self.vertical_noise = s.vertical_noise_m_per_sqrt_s
        self.q_acc = s.accel_noise_mps2_rthz ** 2
        self.q_gyr = s.gyro_noise_rps_rthz ** 2
        self.ins = StrapdownIns(s.gravity_model, s.tau_baro_s, s.imu_samples)
        self.integrity = InnovationMonitor(s.integrity_window, s.integrity_alpha)
        self.recoveries = 0
        self._streak = 0
        self._since_recovery = 0
        self._init_cov9 = np.eye(9)
        if name is not None:
            self.name = str(name)
        self.grid = dem.grid
        self.health = Health(status="acquiring")
        self.extra: dict = {}
        self._t_next_meas = -np.inf
        self._height_initialised = False
        self._t_belief = np.nan
        # INS velocity / attitude error variances of the states a filter does not carry
        self._p_vel = np.zeros(3)
        self._p_att = np.zeros(3)
        self._p_vel0 = np.zeros(3)
        self._p_att0 = np.zeros(3)
        self._n_underflow = 0

    # -------------------------------------------------------------------------------------- protocol
    def reset(self, initial: Estimate) -> None:
        cov = np.asarray(initial.covariance, float)
        if cov.shape != (9, 9) or not np.all(np.isfinite(cov)):
            raise ValueError("initial.covariance must be a finite 9 x 9 matrix")
        self.ins.reset(initial.t_s, initial.lat_rad, initial.lon_rad, initial.h_m, initial.v_ned_mps,
                       initial.roll_rad, initial.pitch_rad, initial.yaw_rad)
        self.health = Health(status="acquiring")
        self.extra = {}
        self._t_next_meas = -np.inf
        self._height_initialised = False
        self._t_belief = float(initial.t_s)
        self._t_ins0 = float(initial.t_s)
        self._turn_pending = 0.0
        self._yaw_turn_prev = math.nan
        d = np.diag(cov)
        self._p_vel0 = d[3:6].copy()
        self._p_att0 = d[6:9].copy()
        self._p_vel = self._p_vel0.copy()
        self._p_att = self._p_att0.copy()
        self._n_underflow = 0
        self.integrity.reset()
        self.recoveries = 0
        self._recovery = IntegrityRecovery(self.integrity, self.recovery_sigma_m,
                                           max_doublings=MAX_RECOVERY_DOUBLINGS)
        self._init_cov9 = cov.copy()
        self._capture = CaptureGuard(self._capture_range_m(), self.name, self._capture_spec, geometry=True)
        anchor_from_cov9(self._capture, float(initial.t_s), cov)
        self._tilt0_var = 0.5 * float(d[6] + d[7])
        # the INS's error is independent of the map's shift
        self._map_shift = MapShiftShare(n_carried=self._MAP_SHIFT_CARRIED)
        self._init_belief(cov)

    def update(self, frames: SensorFrames) -> Estimate:
        self.health.events = []
        t_imu = self._imu_times(frames)
        if t_imu is None:
            return self.estimate().extrapolated(frames.t_end_s)
        hist = self._propagate_ins(frames, t_imu)
        events = self._events(frames, t_imu)
        row = 0
        for t_s, kind, payload, k in events:
            if self._tracks_turn:
                row = self._add_turn(hist, row, k + 1)
            st = hist[k]
            if not np.all(np.isfinite(st)):
                self.health.skip(t_s, "ins_invalid", "INS state not finite at a measurement")
                continue
            if self._capture_suspends(t_s, kind):
                continue
            self._predict_to(t_s, st)
            self._grow_ins_model(t_s)
            if kind == "gnss":
                self._gnss_update(t_s, st, payload)
                self._capture_anchor(t_s)
            else:
                self._terrain_sample(t_s, kind, payload, st)
        if self._tracks_turn:
            self._add_turn(hist, row, hist.shape[0])
        self._after_frame(float(t_imu[-1]))
        return self.estimate()

    # ------------------------------------------------------------------------------------ capture
    _capture_spec = None     # the IMU's specification (a subclass' apply_imu_spec sets it)
    _capture: CaptureGuard | None = None
    _tilt0_var = 0.0

    def _capture_range_m(self) -> float:
        """How far (m) the belief can cover (navigators.core.capture): a subclass' grid or re-spread."""
        raise NotImplementedError

    def _capture_floor_m2(self) -> float:
        """A variance (m^2) the horizontal covariance always holds per axis (a grid cell's, uniform)."""
        return 0.0

    def _capture_suspends(self, t_s: float, kind: str) -> bool:
        """navigators.core.capture's check before each measurement: True when a terrain sample is to be
        skipped (the filter is beyond capture, suspended: its belief kept as it stood, Health degraded). A
        GNSS fix ends a suspension: the belief is re-spread around its kept mean with the published
        covariance (`_recovery_cov9`), then updated by the fix."""
        g = self._capture
        self._t_capture = t_s
        if kind == "gnss":
            if g.suspended:
                self._t_belief = t_s
                self.health.events.append((float(t_s), "capture: a GNSS fix ends the suspension; "
                                           + self._recover(t_s)))
                g.anchor(t_s, 0.0, 0.0, 0.0)
            return False
        if g.skips(t_s, lambda: self._output_moments()[1][:2, :2], self.health):
            self._grow_ins_model(t_s)
            return True
        return False

    def _capture_anchor(self, t_s: float) -> None:
        """After a GNSS update: the free INS's growth restarts from the belief's position and velocity
        variances, the tilt the free INS's since the reset (a GNSS fix does not observe it here)."""
        g = self._capture
        if g.spec is None:
            return
        _, cov = self._moments()
        d = np.nan_to_num(np.diag(cov), nan=0.0)
        tilt = free_ins_tilt_sigma_rad(g.spec, t_s - self._t_ins0, self._tilt0_var)
        g.anchor(t_s, 0.5 * (d[0] + d[1]), 0.5 * (d[3] + d[4]), tilt * tilt)

    # ------------------------------------------------------------------------------------ internals
    _tracks_turn = False    # a subclass whose process noise grows with the angle turned sets it
    _turn_pending = 0.0
    _yaw_turn_prev = math.nan
    _t_ins0 = 0.0

    def _add_turn(self, hist: np.ndarray, a: int, b: int) -> int:
        """Add to the angle turned since the last prediction (`_take_turn`) the total variation of the INS
        yaw over the history rows a..b-1 (the integral of |yaw rate| at the IMU's rate,
        _ekf_kernels.yaw_total_variation); returns b."""
        if b > a:
            turn, self._yaw_turn_prev = yaw_total_variation(hist[a:b], self._yaw_turn_prev)
            self._turn_pending += turn
        return max(a, b)

    def _take_turn(self) -> float:
        """The angle (rad) the INS turned since the last call: the integral of |yaw rate| over the IMU
        samples, not the net yaw change between predictions (which drops the back-and-forth between them
        and so depends on the measurement rate)."""
        turn, self._turn_pending = self._turn_pending, 0.0
        return turn

    def _propagate_ins(self, frames: SensorFrames, t_imu: np.ndarray) -> np.ndarray:
        imu = frames.imu
        baro = frames.baro
        tb = hb = vb = None
        if baro is not None and baro.t_s.shape[0]:
            tb = np.asarray(baro.t_s, float)
            hb = np.asarray(baro.h_baro_m, float)
            vb = np.asarray(baro.valid, bool) & np.isfinite(hb)
            if self.baro_geopotential:
                hb = geometric_height_m(hb)
            v_down = float(self.ins.state[5])
            if self.baro_lag_s > 0.0 and math.isfinite(v_down):
                # a first-order lag reads a steady climb lag x its rate low; the INS's down velocity at the
                # frame's start stands for the frame's (navigators.filters._ekf_kernels.collect_ira)
                hb = hb - self.baro_lag_s * v_down
            nbad = int((~vb).sum())
            if nbad:
                self._count_skip(float(tb[0]), "baro_invalid", nbad, f"{nbad} baro samples invalid")
            if not self._height_initialised and vb.any():
                self.ins.state[2] = float(hb[np.argmax(vb)])
                self._height_initialised = True
        return self._strapdown(t_imu, imu.f_b_mps2, imu.omega_ib_b_rps, imu.valid, tb, hb, vb)

    def _events(self, frames: SensorFrames, t_imu: np.ndarray) -> list:
        """(t, kind, payload, index of the INS history row) of the frame's measurements, in time order."""
        n_imu = t_imu.shape[0]
        ev, self._t_next_meas, n_bad = terrain_samples(frames, self.aiding, self.measurement_rate_hz,
                                                       self._t_next_meas)
        if n_bad:
            self._count_skip(frames.t_start_s, "terrain_sample_invalid", n_bad,
                             f"{n_bad} altimeter samples invalid or without a return (skipped)")
        g = gnss_fixes(frames.gnss, need_height=True, need_velocity=False)
        for i in range(0 if g is None else g.n):
            ev.append((float(g.t_s[i]), "gnss", (float(g.lat_rad[i]), float(g.lon_rad[i]), float(g.h_m[i]),
                                                 g.v_ned_mps[i])))
        ev.sort(key=lambda e: e[0])
        out = []
        for t_s, kind, payload in ev:
            k = min(int(np.searchsorted(t_imu, t_s - 1e-9)), n_imu - 1)
            if t_s > t_imu[-1] + 1e-6 or t_s < t_imu[0] - 0.5:
                continue    # not covered by this frame's INS history
            out.append((t_s, kind, payload, k))
        return out

    def _terrain_sample(self, t_s: float, kind: str, payload, st: np.ndarray) -> None:
        rng_m, theta = payload
        if math.isfinite(rng_m):
            self._capture.range_m = float(rng_m)     # the closest points' lever (navigators.core.capture)
        if kind == "ira":
            var_sensor = None   # depends on the hypothesis' closest point: computed by the filter
        else:
            var_sensor = self.ra_sigma_m ** 2
        self._terrain_update(t_s, kind, rng_m, theta, st, var_sensor)

    def ira_variance(self, range_m: float, p_d_m, p_h_m) -> np.ndarray:
        """Measured terrain height variance (m^2) of an IRA sample whose closest point is at (p_h, p_d)."""
        return ira.variance(range_m, p_d_m, p_h_m, self.ira_range_sigma_m, self.ira_look_angle_sigma_rad,
                            self._map_white_sigma_m(), self.terrain_model_sigma_m)

    def ra_variance(self) -> float:
        return radar_altimeter.variance(self.ra_sigma_m, self._map_white_sigma_m(),
                                        self.terrain_model_sigma_m)

    def _map_white_sigma_m(self) -> float:
        """The map's random vertical error each terrain sample carries as its own noise: map_sigma_m, or 0
        when it is correlated along the ground (map_correlation_length_m > 0: the vertical offset carries it,
        see the class docstring)."""
        return 0.0 if self.map_walk_var_per_m > 0.0 else self.map_sigma_m

    def bias_prior_var(self) -> float:
        var = self.baro_bias_sigma_m ** 2 + self.map_bias_sigma_m ** 2
        if self.map_walk_var_per_m > 0.0:
            var += self.map_sigma_m ** 2        # the correlated map error is part of the vertical offset
        return var

    def _grow_offset(self, dt: float, st: np.ndarray | None) -> None:
        """The variance (m^2) the vertical offset b gains over dt s: its random walk, plus, with a correlated
        map error, the walk map_walk_var_per_m times the ground distance the INS flew (its horizontal speed
        times dt; see the class docstring). The height's error model (height_error) takes the first as the
        INS's; the map's decorrelates over the distance flown."""
        q = q_ins = self.vertical_noise ** 2 * dt
        distance_m = 0.0
        if self.map_walk_var_per_m > 0.0 and st is not None and math.isfinite(st[3] + st[4]):
            speed_mps = math.hypot(float(st[3]), float(st[4]))
            q += self.map_walk_var_per_m * speed_mps * dt
            distance_m = speed_mps * dt
        self.P_b += q
        self._height.step(q_ins, distance_m)

    def _start_height_error(self) -> None:
        """The published height's error model from the prior P_b (after `_init_belief` sets it)."""
        var_corr = self.map_sigma_m ** 2 if self.map_walk_var_per_m > 0.0 else 0.0
        self._height = HeightError.start(self.P_b, self.map_bias_sigma_m ** 2, var_corr,
                                         self.map_correlation_length_m, self.map_correlation_function)

    def _height_variance(self, var_down: float) -> float:
        """The published down variance: the belief's (the cells' or particles' spread of b plus P_b) with P_b
        replaced by the height's error variance where the map's error is modelled (height_error), never
        below the belief's (P_b already holds the map's part after a GNSS height)."""
        if not self._height.active:
            return var_down
        return var_down + max(self._height.var_e - self.P_b, 0.0)

    def _gnss_offset_split(self) -> tuple[float, float]:
        """(P_h, P_m): the vertical offset's variance split into the INS height's part, which a GNSS height
        sees, and the map's (its bias, and its correlated random error when modelled), which it does not:
        P_m = map_bias_sigma_m^2 (+ map_sigma_m^2), P_h = max(P_b - P_m, 0). A GNSS height updates b with
        the gain P_h / (P_h + r) and leaves P_b = P_h (1 - K) + P_m."""
        p_m = self.map_bias_sigma_m ** 2
        if self.map_walk_var_per_m > 0.0:
            p_m += self.map_sigma_m ** 2
        return max(self.P_b - p_m, 0.0), p_m

    def _grow_ins_model(self, t_s: float) -> None:
        dt = max(t_s - getattr(self, "_t_ins_model", t_s), 0.0)
        self._t_ins_model = t_s
        self._p_vel += self.q_acc * dt
        self._p_att += self.q_gyr * dt

    def _gnss_velocity_ins(self, v_gnss: np.ndarray, carried: tuple[int, ...]) -> None:
        """GNSS velocity into the INS velocity for the axes the filter does not carry
        (navigators.core.ins_gnss.velocity_into_ins)."""
        velocity_into_ins(self.ins.state, self._p_vel, v_gnss, self.gnss_velocity_sigma_mps ** 2, carried)

    def _set_update_extra(self, t_s: float, innovation, S, log_lik: float) -> None:
        innov = np.atleast_1d(np.asarray(innovation, float))
        S = np.atleast_2d(np.asarray(S, float))
        try:
            nis = float(innov @ np.linalg.solve(S, innov))
        except np.linalg.LinAlgError:
            nis = math.nan
        self.extra.update(update_extra(innov, S, nis, int(innov.shape[0]), float(log_lik), float(t_s)))
        self._integrity_test(t_s, nis, int(innov.shape[0]))

    def _integrity_test(self, t_s: float, nis: float, dof: int) -> None:
        """Feed the innovation test through the shared recovery policy (navigators.core.recovery); on a
        recovery re-spread the belief (`_recover`), logged."""
        decision = self._recovery.add(t_s, nis, dof)
        verdict = decision.verdict
        self.extra.update(verdict.extra())
        if verdict.changed:
            self.health.events.append((float(t_s), verdict.message))
        if verdict.degraded:
            self.health.ok, self.health.status = False, "degraded"
            if decision.recover:
                self.recoveries = self._recovery.recoveries
                self.health.events.append((float(t_s), "recovery: " + self._recover(t_s)))
        elif verdict.changed:
            self.health.ok, self.health.status = True, "acquiring"

    def _map_record(self, bilinear: bool = False) -> MapRecord:
        """The map and its interpolation as the kernels take it (navigators.core.maps.MapRecord): the
        map_interpolation setting's, or bilinear (the radar altimeter's cone model reads the map so)."""
        key = "_map_rec_bilinear" if bilinear else "_map_rec"
        rec = getattr(self, key, None)
        if rec is None:
            rec = map_record(self.grid, self.map_cubic and not bilinear)
            setattr(self, key, rec)
        return rec

    def _recovery_sigma_now_m(self) -> float:
        """recovery_sigma_m, doubled for each re-spread in a row that did not bring the test back in band."""
        return self._recovery.sigma_now_m

    def _recovery_cov9(self) -> tuple[np.ndarray, np.ndarray]:
        """(mean over [dn, de, b, dvn, dve, dpsi], 9 x 9 covariance) to re-spread the belief with: the
        horizontal block is the belief's plus recovery_sigma_m^2, at least the initial one."""
        mean, cov = self._moments()
        c9 = self._init_cov9.copy()
        ch = np.nan_to_num(cov[:2, :2]) + np.eye(2) * self._recovery_sigma_now_m() ** 2
        if self._capture is not None and self._capture.suspended:     # resuming at a GNSS fix
            ch = self._capture.published_covariance(self._t_capture)
        if np.trace(ch) > np.trace(c9[:2, :2]):
            c9[:2, :2] = ch
        return np.nan_to_num(mean), c9

    def _degrade(self, t_s: float, reason: str, message: str) -> None:
        self.health.skip(t_s, reason, message)
        self.health.status = "degraded"

    def _belief_without_map(self, t_s: float, kind: str, mass: float) -> bool:
        """Skip the terrain sample (True) when `mass`, the belief's probability on hypotheses whose map has
        no height, is above MAX_MASS_WITHOUT_MAP (counted in Health as 'belief_over_map_void')."""
        if mass <= MAX_MASS_WITHOUT_MAP:
            return False
        self.health.skip(t_s, "belief_over_map_void", f"{kind} update skipped: {mass:.0%} of the belief is "
                         "where the map has no height (a void, or off the map)")
        return True

    def _after_frame(self, t_end: float) -> None:
        """Health from the belief's spread (a degraded state lasts until the next good update)."""
        mean, cov = self._moments()
        sig_h = math.sqrt(max(cov[0, 0] + cov[1, 1], 0.0))
        if not (np.all(np.isfinite(mean[:3])) and math.isfinite(sig_h)):
            self.health.ok, self.health.status = False, "diverged"
        elif self.integrity.degraded or self._capture.suspended:
            self.health.ok, self.health.status = False, "degraded"
        elif self.health.status != "degraded":
            self.health.ok = True
            self.health.status = "ok" if sig_h <= self.converged_sigma_m * math.sqrt(2.0) else "acquiring"

    # ----------------------------------------------------------------------------------------- output
    def estimate(self) -> Estimate:
        """INS + the belief's mean offset; covariance: the belief's block and the INS error model's rest, the
        down variance the published height's error where the map's vertical error is modelled
        (height_error), the horizontal block plus the share of the map's horizontal shift the estimate took
        on where map_horizontal_sigma_m is given (map_shift)."""
        st = self.ins.state
        # mean over [dn, de, b, dvn, dve, dpsi]; cov_b 6 x 6 (NaN: not carried)
        mean, cov_b = self._output_moments()
        lat, lon, h = float(st[0]), float(st[1]), float(st[2])
        r_lat, r_lon = radii_m(lat, h)
        C = quat_to_dcm(st[6:10])
        roll, pitch, yaw = euler_from_C_bn(C)
        v = st[3:6].copy()
        P = np.zeros((9, 9))
        P[3:6, 3:6] = np.diag(self._p_vel)
        P[6:9, 6:9] = np.diag(self._p_att)
        # belief index -> Estimate index (down = INS height minus true height = b)
        idx = {0: 0, 1: 1, 2: 2, 3: 3, 4: 4, 5: 8}
        carried = [i for i in range(6) if np.isfinite(cov_b[i, i])]
        for i in carried:
            for j in carried:
                P[idx[i], idx[j]] = cov_b[i, j]
        if 2 in carried:
            P[2, 2] = self._height_variance(P[2, 2])
        suspended = self._capture.suspended   # beyond capture (navigators.core.capture)
        P = self._capture.publish(P, float(self.ins.t_s), self._capture_floor_m2())
        hpl_cov = P[:2, :2].copy()       # the protection level bounds the map's shift apart (pl.publish)
        sigma_shift = self._map_shift_sigma_m()
        if sigma_shift > 0.0:
            P[:2, :2] += self._map_shift.covariance(sigma_shift)
            rows = list(self._MAP_SHIFT_VELOCITY_ROWS)
            if rows and 3 in carried:       # the horizontal velocity's share (its error holds U_v s)
                c_ux, c_uu = self._map_shift.carried_covariances(sigma_shift)
                P[3:5, :2] += c_ux[rows]
                P[:2, 3:5] += c_ux[rows].T
                P[3:5, 3:5] += c_uu[np.ix_(rows, rows)]
        dn, de = (float(mean[0]), float(mean[1])) if np.all(np.isfinite(mean[:2])) else (0.0, 0.0)
        if np.isfinite(mean[3]):
            v[0] += mean[3]
            v[1] += mean[4]
        if np.isfinite(mean[5]):
            yaw = math.atan2(math.sin(yaw + mean[5]), math.cos(yaw + mean[5]))
        b = float(mean[2]) if np.isfinite(mean[2]) else 0.0
        health = self.health.snapshot(self._consistency_warning, self._recovery.consistency)
        gaussian = suspended or self._capture.geometry_variance_m2(float(self.ins.t_s)) > 0.0
        return Estimate(t_s=float(self.ins.t_s), lat_rad=lat + dn / r_lat, lon_rad=lon + de / r_lon,
                        h_m=h - b, v_ned_mps=v, roll_rad=roll, pitch_rad=pitch, yaw_rad=yaw, covariance=P,
                        health=health, extra=(pl.publish(dict(self.extra), pl.gaussian_hpl(
                            hpl_cov, pl.filter_risk(self)), self) if gaussian
                            else self._with_protection_level(dict(self.extra))))

    def _map_shift_sigma_m(self) -> float:
        """The map's horizontal error per axis (m; map_horizontal_sigma_m, 0 when not given): the published
        horizontal covariance carries the share of it the estimate took on (map_shift)."""
        return float(getattr(self, "map_horizontal_sigma_m", 0.0))

    def _shift_into_belief(self) -> np.ndarray | None:
        """Before a GNSS fix: the share of the map's shift the estimate took on, as the horizontal covariance
        (2 x 2, m^2) to widen the belief by, or None (none taken on, or not modelled). The fix sees the
        position relative to the Earth, whose error holds the share: fused against the belief alone (the
        error relative to the map) a fix some sigma_h away would be an outlier to it. The share becomes the
        belief's, so it restarts from 0 (map_shift)."""
        sigma = self._map_shift_sigma_m()
        if not sigma > 0.0 or not self._map_shift.any():
            return None
        q = self._map_shift.covariance(sigma)
        self._map_shift.reset()
        return q

    def _shift_prior(self) -> np.ndarray | None:
        """The belief's horizontal covariance (2 x 2, m^2) before an update, for map_shift; None when the
        map's shift is not modelled. The moments' cache is left as it was (the update's bits unchanged)."""
        if not self._map_shift_sigma_m() > 0.0:
            return None
        cache = self._moments_cache
        cov = self._moments()[1][:2, :2]
        self._moments_cache = cache
        return cov

    def _shift_after(self, prior: np.ndarray | None) -> None:
        """map_shift's step for a terrain sample whose update started from the horizontal covariance `prior`
        (`_shift_prior`; None: nothing to do). (A GNSS fix needs none: `_shift_into_belief` set the share to
        0 before it.)"""
        if prior is None:
            return
        cache = self._moments_cache
        post = self._moments()[1][:2, :2]
        self._moments_cache = cache
        self._map_shift.terrain(prior, post)

    def _with_protection_level(self, extra: dict) -> dict:
        """extra with the belief's HPL (navigators.integrity.protection_level: the mass radius of the points
        of `_pl_points` plus their pad) for the navigator's integrity_risk."""
        risk = pl.filter_risk(self)
        dn, de, w, pad = self._pl_points(risk)
        return pl.publish(extra, pl.particle_hpl(dn, de, w, risk, pad), self)

    # ------------------------------------------------------------------------------------ subclass API
    def _init_belief(self, cov9: np.ndarray) -> None:
        raise NotImplementedError

    def _predict_to(self, t_s: float, st: np.ndarray) -> None:
        raise NotImplementedError

    def _terrain_update(self, t_s, kind, range_m, theta_rad, st, var_sensor) -> None:
        raise NotImplementedError

    def _gnss_update(self, t_s, st, payload) -> None:
        raise NotImplementedError

    def _gnss_drift_deficit(self) -> np.ndarray:
        """(north, east) variance (m^2) the belief lacks after a GNSS update to cover the receiver's drift:
        max(0, gnss_drift_sigma_m^2 - its variance) per axis (see the class docstring)."""
        if not self.gnss_drift_sigma_m > 0.0:
            return np.zeros(2)
        _, cov = self._moments()
        var = np.nan_to_num(np.diag(cov)[:2], nan=0.0)
        return np.clip(self.gnss_drift_sigma_m ** 2 - var, 0.0, None)

    def _moments(self) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def _output_moments(self) -> tuple[np.ndarray, np.ndarray]:
        """The moments the Estimate reports (`_moments` unless the belief's coordinates differ from the INS
        error's)."""
        return self._moments()

    def _pl_points(self, risk: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """(north, east, weights, pad_m) of the belief's horizontal points for the protection level."""
        raise NotImplementedError

    def _recover(self, t_s: float) -> str:
        """Re-spread the belief after the innovation test failed; returns what was done (for the log)."""
        raise NotImplementedError
