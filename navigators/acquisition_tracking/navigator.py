"""AcqTrackNavigator: the GPS-inspired acquisition-and-tracking TRN behind the Navigator protocol (seed 001).

Each new transect sample (one per sample_period_s) is one epoch:

    GNSS at the sample   -> the sample's position is the fix; the references b_v, b_psi and the wind are
                            calibrated from the GNSS velocity ("gnss" lock state); no terrain work.
    transect filling     -> dead reckoning on the aiding ("acquiring").
    acquisition due      -> serial search (acquisition.py) around the dead-reckoned transect start; a
                            distinct minimum starts tracking, none retries with the next transect.
    tracking             -> aided: start-point loops along and across the track at the (slow) references,
                            then speed 1st, speed 2nd, heading 1st, heading 2nd early-late loops
                            (tracking.py; unaided the start-point loops come last), then integrity
                            (integrity.py): in lock with V-shapes, SNR >= 5 dB and no false lock; the
                            fit's transect centroid is the position fix, weighed by a 2-state Kalman filter
                            against the dead-reckoned centroid (an NIS above fix_gate_nis is a false lock);
                            the references take reference_gain of the loops' change; "ok". Out of lock the
                            references are kept and the status is "degraded"; lost_after_epochs such epochs
                            in a row -> "lost", which asks for a new acquisition when the dead-reckoned
                            sigma exceeds acquire_above_sigma_m (below it the loops re-lock).

Position: the replica's newest sample (the start point, which follows from the filtered centroid and the
references, + the aided speed and track), dead-reckoned with the output velocity to the frame's end. The
transect's start for the next epoch is its second sample.

Health.status state machine (documented in Health): acquiring -> ok <-> degraded -> lost -> acquiring ...;
each transition's reason is an event. In lock, each epoch's NIS (the centroid fix minus its prediction,
north/east m, against S = P_pred + R, 2 dof) also feeds an InnovationMonitor (integrity_window epochs, band
probability integrity_alpha); while its sum is above the band a tracking epoch is "degraded" instead of
"ok" (its recovery is the re-acquisition the lock detection already asks for). Overlapping transects share
N - 1 samples, so successive NIS values are correlated.

Covariance (north, east): the centroid filter's Pc grows per epoch by the references' sigma over one sample
(T sigma_v along, V T sigma_psi across) plus the aiding's random walk (aiding_walk_m_per_sqrt_s^2 T), and in
lock is updated by the fix with R = fix_sigma_scale^2 (pi/2) sigma_res^2 / (the replica's squared map slopes
along / across) + a map post^2 / 12, its gain counting fix_overlap (N / 2) epochs per fix. The output is Pc
plus dead reckoning from the centroid to the newest sample; out of lock it grows linearly on the aiding's
sigmas. Vertical: the barometer's bias.

reference_frame "ne" (the default): the aiding of every transect sample is corrected by one north/east
velocity bias e_ne (_aid_arrays; an INS's velocity error, or the wind with air data), the loops run around
b = 0, and the centroid filter has four states (centroid north/east, e_ne north/east): the fix updates
both, e_ne walks by aiding_bias_walk_mps_per_sqrt_s, the output is the centroid plus the lever to the
newest sample, and out of lock the dead-reckoned sigma grows on e_ne's. replica_model "return": each
sample's measured height and map point come from the ray of its predicted shortest return (beam.py;
_return_height), and the loops get the samples' offsets.

Estimate.extra, besides the fixed protocol keys (innovation = the centroid fix minus its prediction, north
and east in m, its covariance S, NIS with 2 dof, measurement time):
    lock_state          "gnss" | "filling" | "acquiring" | "tracking" | "out_of_lock" | "lost"
    snr_db              terrain SNR of the prompt profile (dB; NaN before the first epoch)
    tracked_speed_mps   output (moving-averaged) ground speed
    tracked_track_deg   output ground track (deg, clockwise from north)
    speed_spacing_mps   first-stage speed spacing in use (the adaptivity block's choice)
    heading_spacing_deg first-stage heading spacing in use
    v_shape             both SCF and HCF V-shaped at the last epoch
    false_lock          '' or the reason of a false-lock detection
    loop_iterations     iterations of [speed 1st, speed 2nd, heading 1st, heading 2nd]
    wind_ne_mps         the wind estimate (north, east)
    acquisitions        number of serial searches run (their wall time: attributes acquisition_s, _total_s;
                        not in the estimate, which one seed fixes bit for bit)
"""

from __future__ import annotations

import math
import time

import numpy as np
from trn_env.navigators.acquisition_tracking import acquisition, beam, filter_kernels, loop_kernel, tracking
from trn_env.navigators.acquisition_tracking.aiding import (
    WindEstimator,
    air_vector_sum,
    coordinated_turn_roll_rad,
    ground_vector,
    lsq_rate,
    sample_at,
    speed_track,
    wrap_rad,
)
from trn_env.navigators.acquisition_tracking.correlation import (
    COSTS,
    INTERPOLATIONS,
    replica_heights,
    replica_offsets,
)
from trn_env.navigators.acquisition_tracking.integrity import (
    OutputAverage,
    a_priori_sigma_m,
    false_lock,
    terrain_snr_db,
)
from trn_env.navigators.acquisition_tracking.profile import (
    Sample,
    Transect,
    geometric_height_m,
    plumb_height_m,
)
from trn_env.navigators.acquisition_tracking.settings import CAPABILITIES, AcqTrackConfig
from trn_env.navigators.frames import SensorFrames
from trn_env.navigators.integrity.innovation_monitor import InnovationMonitor
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
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

_TAIL_S = 3.0  # seconds of each sensor's samples carried into the next frame (sample look-ups)
_TURN_RATE_WINDOW_S = 3.0  # compass heading rate for the coordinated-turn roll: LSQ slope over 3 s
_MAD_VARIANCE_FACTOR = math.pi / 2.0


# closed forms of the 2 x 2 (north, east) covariance algebra: np.linalg on a 2 x 2 costs more in its Python
# call than the arithmetic (once per epoch per operation, it was a visible part of an epoch)
def _rot_diag(psi: float, a: float, b: float) -> np.ndarray:
    """G diag(a, b) G^T, G the rotation from (along, across) track psi (rad) to (north, east)."""
    c, s = math.cos(psi), math.sin(psi)
    cs = c * s * (a - b)
    return np.array([[c * c * a + s * s * b, cs], [cs, s * s * a + c * c * b]])


def _det2(m: np.ndarray) -> float:
    return float(m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0])


def _inv2(m: np.ndarray) -> np.ndarray:
    det = _det2(m)
    if det == 0.0:  # as np.linalg: singular raises, NaN propagates
        raise np.linalg.LinAlgError("singular 2 x 2 matrix")
    return np.array([[m[1, 1], -m[0, 1]], [-m[1, 0], m[0, 0]]]) / det


def _quad2(x: np.ndarray, m: np.ndarray) -> float:
    """x^T m^-1 x of a 2-vector and a 2 x 2 matrix."""
    a, b, c, d = float(m[0, 0]), float(m[0, 1]), float(m[1, 0]), float(m[1, 1])
    det = a * d - b * c
    if det == 0.0:  # as np.linalg: singular raises, NaN propagates
        raise np.linalg.LinAlgError("singular 2 x 2 matrix")
    x0, x1 = float(x[0]), float(x[1])
    return (x0 * (d * x0 - b * x1) + x1 * (a * x1 - c * x0)) / det


def _median(x: np.ndarray) -> float:
    """np.median of a 1-D array without NaN by a sort (the same value: the middle element, or the mean of the
    two middle ones as (a + b) / 2); np.median's Python layers cost more than the sort of N samples."""
    x = np.sort(x)
    m = x.size // 2
    return float(x[m]) if x.size % 2 else float((x[m - 1] + x[m]) / 2.0)


def _mean(x: np.ndarray) -> float:
    """np.mean of a 1-D array as it computes it (sum / count) without its Python layers."""
    return float(x.sum()) / x.size


def _nanmean(x: np.ndarray) -> float:
    """np.nanmean of a 1-D array (NaN when it has no finite value), without its Python layers when no
    element is NaN (then it is sum / count, as np.nanmean computes it)."""
    nan = np.isnan(x)
    if not nan.any():
        return float(x.sum()) / x.size
    if nan.all():
        return math.nan
    return float(np.where(nan, 0.0, x).sum()) / int(x.size - nan.sum())


class _Offsets:
    """The transect's beam offsets (north, east m) as the rows of a buffer, oldest first, with a bounded
    deque's semantics (when full the oldest drops out); rows() is a view (callers copy what they keep)."""

    def __init__(self, n: int):
        self._rows = np.zeros((n, 2))
        self._n = 0

    def __len__(self) -> int:
        return self._n

    def append(self, offset) -> None:
        if self._n == self._rows.shape[0]:
            self._rows[:-1] = self._rows[1:]
        else:
            self._n += 1
        self._rows[self._n - 1] = offset

    def rows(self) -> np.ndarray:
        return self._rows[: self._n]


class _Tail:
    """A sensor's recent samples (t, columns..., valid), carried across frames: the samples within _TAIL_S
    of the newest, kept in buffers that a frame's samples are written into (t, v, ok are views of them)."""

    def __init__(self, n_cols: int):
        self._t = np.zeros(64)
        self._v = np.zeros((64, n_cols))
        self._ok = np.zeros(64, bool)
        self._lo = self._hi = 0
        self._views()

    def _views(self) -> None:
        lo, hi = self._lo, self._hi
        self.t, self.v, self.ok = self._t[lo:hi], self._v[lo:hi], self._ok[lo:hi]

    def extend(self, t, cols, ok) -> None:
        t = np.asarray(t, float)
        n = t.size
        if n == 0:
            return
        live = self._hi - self._lo
        if self._hi + n > self._t.size:  # move the live samples to the front, growing the buffers if needed
            cap = max(self._t.size, 2 * (live + n))
            bt, bv, bo = np.zeros(cap), np.zeros((cap, self._v.shape[1])), np.zeros(cap, bool)
            bt[:live], bv[:live], bo[:live] = self.t, self.v, self.ok
            self._t, self._v, self._ok = bt, bv, bo
            self._lo, self._hi = 0, live
        hi = self._hi
        self._t[hi : hi + n] = t
        if isinstance(cols, np.ndarray):  # (n_cols, n) at once
            self._v[hi : hi + n] = cols.T
        else:
            for j, c in enumerate(cols):
                self._v[hi : hi + n, j] = c
        self._ok[hi : hi + n] = ok
        self._hi = hi + n
        # sensor times increase: the samples within _TAIL_S of the newest are a suffix
        self._lo += int(self._t[self._lo : self._hi].searchsorted(t[-1] - _TAIL_S, side="left"))
        self._views()

    def rate(self, t_s: float, col: int, window_s: float) -> float:
        """Least-squares slope (per s) of column col over the valid samples in [t_s - window_s, t_s]."""
        return float(lsq_rate(self.t, np.ascontiguousarray(self.v[:, col]), self.ok, t_s, window_s))

    def row(self, t_s: float, max_gap_s: float) -> tuple[np.ndarray | None, bool]:
        """(all columns of the newest valid sample at or before t_s within max_gap_s, found)."""
        if self.t.size == 0:
            return None, False
        k = int(self.t.searchsorted(t_s + 1e-9, side="right")) - 1
        while k >= 0 and not self.ok[k]:
            k -= 1
        if k < 0 or t_s - self.t[k] > max_gap_s:
            return None, False
        return self.v[k], True

    def at(self, t_query, col: int, max_gap_s: float):
        return sample_at(
            np.atleast_1d(np.asarray(t_query, float)), self.t, self.v[:, col], self.ok, max_gap_s
        )


class AcqTrackNavigator:
    """Acquisition-and-tracking TRN (seed 001); settings are AcqTrackConfig's fields (see settings.py).

    dem: the navigator's map (terrain.Dem, or a name/path for terrain.load). `required_sensors()` lists the
    sensors its settings need (the scenario check refuses a scenario without them before the flight).
    """

    capabilities = CAPABILITIES

    def __init__(self, dem=None, settings: AcqTrackConfig | None = None, name: str = "acq_track",
                 **overrides):
        self.config = self.settings = cfg = AcqTrackConfig.build(settings, overrides)
        self.integrity = InnovationMonitor(cfg.integrity_window, cfg.integrity_alpha)
        if dem is None:
            raise ValueError("dem: the navigator's terrain map is required")
        if isinstance(dem, str):
            from trn_env import terrain

            dem = terrain.load(dem)
        self.dem = dem
        self.name = name
        self._grid = dem.grid
        self._footprint = None
        self._return_model = cfg.replica_model == "return"
        if cfg.replica_model == "footprint":
            from trn_env.navigators.acquisition_tracking.footprint import FootprintMaps

            self._footprint = FootprintMaps(dem, cfg.beamwidth_deg)
        sn, se = dem.spacing_m
        self.map_resolution_m = float(0.5 * (sn + se))
        self.sigma_floor_m = float(cfg.position_sigma_floor_m or 0.5 * self.map_resolution_m)
        self._cost = COSTS[cfg.correlation]
        self._interp = INTERPOLATIONS[cfg.interpolation]
        self._disc = tracking.DISCRIMINATORS[cfg.discriminator]
        self._n_min = max(3, int(math.ceil(cfg.min_valid_fraction * cfg.transect_samples)))
        self._fix_overlap = float(
            cfg.fix_overlap if cfg.fix_overlap is not None else 0.5 * cfg.transect_samples
        )
        walk = cfg.aiding_walk_m_per_sqrt_s
        self._walk2 = float(walk) ** 2
        self._speed_set = np.array(cfg.speed_spacings_mps)
        self._heading_set = np.radians(np.array(cfg.heading_spacings_deg))
        self._position_set = np.array(cfg.position_spacings_cells) * self.map_resolution_m
        # the loops' spacing sets widest first, and the start-point loops' reach (m), fixed by the settings
        self._speed_desc = np.sort(self._speed_set)[::-1].copy()
        self._heading_desc = np.sort(self._heading_set)[::-1].copy()
        self._position_desc = np.sort(self._position_set)[::-1].copy()
        self._position_reach = float(
            max(cfg.scf_offset_cells * self.map_resolution_m, float(self._position_set.max()))
        )
        # loop_kernel.track_loops' settings (fixed by the config) and its preallocated outputs
        f_r = cfg.scf_offset_cells * self.map_resolution_m
        self._loop_args = (
            self._cost, bool(cfg.remove_bias), self._interp, self._n_min, bool(cfg.aiding),
            bool(cfg.position_loops), cfg.loop_order == "speed_first",
        )  # fmt: skip
        self._loop_settings = (
            int(cfg.scf_points), float(cfg.symmetry_ratio_max), int(cfg.break_iteration), self._disc,
            loop_kernel.MITIGATIONS[cfg.bias_mitigation], float(f_r), float(cfg.sample_period_s),
            max(f_r / (cfg.transect_samples * cfg.sample_period_s), float(self._speed_set.max())),
            self._speed_desc, float(cfg.speed_threshold_mps), float(cfg.speed_narrow_spacing_mps),
            float(cfg.speed_narrow_threshold_mps), self._heading_desc,
            math.radians(cfg.heading_threshold_deg), math.radians(cfg.heading_narrow_spacing_deg),
            math.radians(cfg.heading_narrow_threshold_deg),
            self._position_reach, self._position_desc, float(cfg.position_threshold_m),
            float(cfg.position_narrow_spacing_cells * self.map_resolution_m),
            float(cfg.position_narrow_threshold_m),
        )  # fmt: skip
        self._loop_out = (np.zeros(4, np.int64), np.zeros(4, bool), np.zeros(4, bool), np.zeros((4, 6)))
        self.wind = WindEstimator(cfg.wind_gain)
        self.average = OutputAverage(
            cfg.average_length,
            cfg.output_average_speed_tol_mps,
            math.radians(cfg.output_average_heading_tol_deg),
        )
        self.transect = Transect(cfg.transect_samples)
        self._ne_frame = bool(cfg.aiding and cfg.reference_frame == "ne")
        self._bias_sigma0 = float(cfg.aiding_speed_sigma_mps)
        self._bias_walk2 = float(cfg.aiding_bias_walk_mps_per_sqrt_s) ** 2
        self.ins = None
        if cfg.aiding and cfg.aiding_source == "ins":
            from trn_env.navigators.inertial.strapdown import StrapdownIns

            self.ins = StrapdownIns("j2", 30.0, "interval")
        # estimate()'s covariance entries that are constant (baro bias, vertical speed, attitude)
        self._C0 = np.zeros((9, 9))
        self._C0[2, 2] = cfg.baro_bias_sigma_m**2 + 4.0
        self._C0[5, 5] = 1.0
        self._C0[6, 6] = self._C0[7, 7] = math.radians(3.0) ** 2
        self._C0[8, 8] = math.radians(cfg.aiding_heading_sigma_deg) ** 2
        self.health = Health(status="acquiring")
        self._reset_state()

    # ------------------------------------------------------------------ requirements
    def required_sensors(self) -> list[tuple[str, str]]:
        """(sensor name, why) of every sensor these settings need."""
        return list(self.config.sensor_needs().required.items())

    def required_duration_s(self) -> float:
        """Flight time one full transect takes (s): a scenario shorter than this gives no transect."""
        return self.config.transect_duration_s

    # ------------------------------------------------------------------ protocol
    def _reset_state(self) -> None:
        self.lock_state = "filling"
        self.b_v = 0.0
        self.b_psi = 0.0
        self.b_mean = (0.0, 0.0)
        self.e_ne = np.zeros(2)  # reference_frame "ne": the aiding's north/east velocity bias (m/s)
        self.e_mean = np.zeros(2)
        self._gnss_epochs = 0
        self._aid_key = None
        self.p0 = (math.nan, math.nan)
        self.pos = (math.nan, math.nan)
        self.t_pos = math.nan
        self.P = np.eye(2) * 1e4
        self.Pc = self.P.copy()
        self.X = np.zeros((4, 4))  # reference_frame "ne": covariance of (centroid n, e m; e_ne n, e m/s)
        self.X[:2, :2] = self.Pc
        self.X[2:, 2:] = np.eye(2) * self._bias_sigma0**2
        self.sigma_v = self.config.aiding_speed_sigma_mps
        self.sigma_psi = math.radians(self.config.aiding_heading_sigma_deg)
        self.out_speed = 0.0
        self.out_track = 0.0
        self.h_m = math.nan
        self.roll = 0.0
        self.pitch = 0.0
        self.yaw = 0.0
        self.snr_db = math.nan
        self.v_shape = False
        self.false_lock = ""
        self.iterations = [0, 0, 0, 0]
        self.spacing = (float(self._speed_set.max()), float(self._heading_set.max()))
        self.bad_epochs = 0
        self.pull_in = 0
        self.need_acquisition = False
        self.acq_wait = 0
        self.acq_failures = 0
        self._deferred = False
        self._anchored = False
        self.acquisitions = 0
        self.acquisition_s = math.nan
        self.acquisition_total_s = 0.0
        self.last_innovation = None
        self.integrity.reset()
        self._integrity_extra: dict = {}
        self.t_epoch = math.nan
        self.next_k = None
        self._tails = {
            k: _Tail(n) for k, n in (("baro", 1), ("air", 2), ("hdg", 1), ("gnss", 5), ("ins", 5))
        }
        self.transect.clear()
        self._offs = _Offsets(self.config.transect_samples)  # beam offsets (north, east m)
        self._pending_offset = (0.0, 0.0)
        self._beam_rot = None
        self._beam_cache = None
        self.average.reset()
        self.wind.reset()

    def reset(self, initial: Estimate) -> None:
        self._reset_state()
        cfg = self.config
        v = np.asarray(initial.v_ned_mps, float)
        speed, track = speed_track(v[:2])
        self.t0 = float(initial.t_s)
        self.pos = (float(initial.lat_rad), float(initial.lon_rad))
        self.t_pos = float(initial.t_s)
        self.h_m = float(initial.h_m)
        self.yaw = float(initial.yaw_rad)
        cov = np.asarray(initial.covariance, float)
        if cov.shape != (9, 9) or not np.all(np.isfinite(cov)):
            raise ValueError("initial.covariance must be a finite 9 x 9 matrix")
        self.P = 0.5 * (cov[:2, :2] + cov[:2, :2].T)
        self.Pc = self.P.copy()
        self._set_centroid_cov(self.Pc)
        # the velocity bias' prior: the aiding's sigma, or the initial velocity's if larger
        v_cov = 0.5 * (cov[3:5, 3:5] + cov[3:5, 3:5].T)
        self.X[2:, 2:] = np.maximum(np.eye(2) * self._bias_sigma0**2, v_cov)
        self.out_speed, self.out_track = speed, track
        self._v0 = (speed, track)
        if not cfg.aiding:
            self.b_v, self.b_psi = speed, track
        if self.ins is not None:
            self.ins.reset(
                initial.t_s,
                initial.lat_rad,
                initial.lon_rad,
                initial.h_m,
                v,
                initial.roll_rad,
                initial.pitch_rad,
                initial.yaw_rad,
            )
        self.health = Health(status="acquiring")
        self.next_k = int(math.ceil(float(initial.t_s) / cfg.sample_period_s - 1e-9))

    def update(self, frames: SensorFrames) -> Estimate:
        self.health.events = []
        try:
            self._ingest(frames)
            self._samples(frames)
        except (FloatingPointError, ZeroDivisionError, np.linalg.LinAlgError) as exc:
            self.health.skip(frames.t_end_s, "numerical", f"acq_track: epoch skipped ({exc})")
        return self.estimate(frames.t_end_s)

    # ------------------------------------------------------------------ sensor intake
    def _ingest(self, frames: SensorFrames) -> None:
        tl = self._tails
        if frames.baro is not None:
            hb = np.asarray(frames.baro.h_baro_m, float)
            if self.config.baro_geopotential:
                hb = geometric_height_m(hb)
            tl["baro"].extend(frames.baro.t_s, [hb], frames.baro.valid)
        # the radar altimeter is read from the frame itself (_add_sample): no tail
        # air data and compass enter only the air-data aiding (_add_sample, _air_vector): not kept otherwise
        air_aiding = self.config.aiding and self.config.aiding_source == "air_data"
        if air_aiding and frames.air_data is not None:
            ad = frames.air_data
            n_ad = ad.t_s.size
            beta = np.asarray(ad.beta_rad, float) if self.config.air_vector_sideslip else np.zeros(n_ad)
            tl["air"].extend(ad.t_s, [ad.tas_mps, beta], ad.valid & np.isfinite(beta))
        hd = frames.heading
        if air_aiding and hd is not None and hd.t_s.size:
            h = np.asarray(hd.heading_rad, float)
            ok = hd.valid & np.isfinite(h)
            if ok.any():  # continuous heading across frames (for the turn rate)
                h = h.copy()
                prev = tl["hdg"].v[-1, 0] if tl["hdg"].t.size else h[ok][0]
                hu = np.unwrap(np.concatenate([[prev], h[ok]]))[1:]
                h[ok] = hu
            tl["hdg"].extend(hd.t_s, [h], ok)
        g = frames.gnss
        if g is not None and g.t_s.size:
            tl["gnss"].extend(
                g.t_s, [g.lat_rad, g.lon_rad, g.h_m, g.v_ned_mps[:, 0], g.v_ned_mps[:, 1]], g.valid
            )
        if self.ins is not None and frames.imu is not None and frames.imu.t_s.size:
            if g is not None and g.t_s.size and g.valid.any():  # GNSS resets the INS position and velocity
                j = int(np.nonzero(g.valid)[0][-1])
                if abs(float(g.t_s[j]) - self.ins.t_s) < 1.0:
                    self.ins.state[0:3] = (g.lat_rad[j], g.lon_rad[j], g.h_m[j])
                    self.ins.state[3:6] = g.v_ned_mps[j]
            b = frames.baro
            hist = self.ins.propagate(
                frames.imu.t_s,
                frames.imu.f_b_mps2,
                frames.imu.omega_ib_b_rps,
                frames.imu.valid,
                None if b is None else b.t_s,
                None if b is None else b.h_baro_m,
                None if b is None else b.valid,
            )
            step = max(1, hist.shape[0] // 50)  # attitude at <= 50 points per frame is plenty at 1 s
            # (v_n, v_e, roll, pitch, yaw, finite) of every step-th row in one call (filter_kernels.ins_rows)
            rows = np.empty(((hist.shape[0] + step - 1) // step, 6))
            filter_kernels.ins_rows(hist, step, rows)
            tl["ins"].extend(frames.imu.t_s[::step], rows[:, :5].T, rows[:, 5] != 0.0)

    def _samples(self, frames: SensorFrames) -> None:
        cfg = self.config
        T = cfg.sample_period_s
        if self.next_k is None:
            self.next_k = int(math.ceil(frames.t_start_s / T - 1e-9))
        ra = frames.radar_altimeter
        if ra is None:
            self.health.skip(frames.t_start_s, "no_radar_altimeter", "acq_track: no radar-altimeter frame")
        while self.next_k * T < frames.t_end_s - 1e-9:
            t_k = self.next_k * T
            self.next_k += 1
            self._add_sample(t_k, ra)

    def _add_sample(self, t_k: float, ra) -> None:
        cfg = self.config
        tl = self._tails
        T = cfg.sample_period_s
        r_m = math.nan
        if ra is not None and ra.t_s.size:
            j = int(np.searchsorted(ra.t_s, t_k - 1e-6))
            if j < ra.t_s.size and ra.t_s[j] < t_k + 0.5 * T:
                r_m = float(ra.range_m[j]) if bool(ra.valid[j]) else math.nan
        hb, okb = tl["baro"].row(t_k, 0.5)
        h_baro = float(hb[0]) if okb else math.nan
        if math.isfinite(h_baro):
            self.h_m = h_baro
        # aiding values at the sample
        tas = hdg = math.nan
        roll = pitch = 0.0
        yaw = self.yaw
        m_v = m_psi = 0.0
        if cfg.aiding and cfg.aiding_source == "air_data":
            a, oka = tl["air"].row(t_k, 1.0)
            h, okh = tl["hdg"].row(t_k, 1.5 * T)
            tas = float(a[0]) if oka else math.nan
            hdg = float(wrap_rad(h[0])) if okh else math.nan
            if oka and okh:
                self.yaw = hdg
                tas, hdg = self._air_vector(t_k)
            rate = tl["hdg"].rate(t_k, 0, _TURN_RATE_WINDOW_S)
            if math.isfinite(rate) and math.isfinite(tas):
                roll = coordinated_turn_roll_rad(tas, rate)
            if not (math.isfinite(tas) and math.isfinite(hdg)):
                self.health.skip(t_k, "aiding_missing", "acq_track: air data or compass missing; aiding held")
                last = self.transect.samples[-1] if len(self.transect) else None
                m_v, m_psi = (last.m_v, last.m_psi) if last is not None else self._v0
            else:
                # "ne": the air vector itself, the wind is e_ne; else the wind estimator's prediction
                m_v, m_psi = (
                    self.wind.predict(tas, hdg) if cfg.wind_estimation and not self._ne_frame else (tas, hdg)
                )
        elif cfg.aiding:
            row, found = tl["ins"].row(t_k, 0.5)
            if found and np.all(np.isfinite(row[:4])):
                vn, ve, roll, pitch = (float(x) for x in row[:4])
                yaw = float(row[4]) if math.isfinite(row[4]) else yaw
                m_v, m_psi = speed_track(np.array([vn, ve]))
            else:
                self.health.skip(t_k, "aiding_missing", "acq_track: INS velocity missing; aiding held")
                last = self.transect.samples[-1] if len(self.transect) else None
                m_v, m_psi = (last.m_v, last.m_psi) if last is not None else self._v0
        self.roll, self.pitch = roll, pitch
        # measured terrain height; a no-return / NaN / missing baro drops out
        valid = math.isfinite(r_m) and math.isfinite(h_baro)
        if not math.isfinite(r_m):
            self.health.skip(
                t_k,
                "radar_no_return",
                f"acq_track: no radar-altimeter return at {t_k:.1f} s (sample drops out of the transect)",
            )
        elif not math.isfinite(h_baro):
            self.health.skip(
                t_k,
                "baro_missing",
                f"acq_track: no barometric height at {t_k:.1f} s (sample drops out of the transect)",
            )
        agl = float(plumb_height_m(r_m, roll, pitch, cfg.beamwidth_deg)) if cfg.roll_compensation else r_m
        d = h_baro - agl if valid else math.nan
        self._pending_offset = (0.0, 0.0)
        if valid and self._return_model:  # the ray of the predicted shortest return (beam.py)
            if cfg.aiding and cfg.aiding_source == "air_data" and math.isfinite(hdg):
                yaw = hdg
            d, self._pending_offset = self._return_height(t_k, r_m, h_baro, m_v, m_psi, roll, pitch, yaw, d)
        # GNSS at the sample
        g, have_gnss = tl["gnss"].row(t_k, 0.6)
        have_gnss = bool(have_gnss and np.all(np.isfinite(g)))
        glat, glon = (float(g[0]), float(g[1])) if have_gnss else (math.nan, math.nan)
        gv = (float(g[3]), float(g[4])) if have_gnss else (math.nan, math.nan)
        s = Sample(t_k, d, bool(valid), r_m, float(m_v), float(m_psi), tas, hdg, glat, glon, gv, roll)
        self._epoch(s, have_gnss)

    def _return_height(self, t_k, r_m, h_baro, m_v, m_psi, roll, pitch, yaw, d_fallback):
        """(measured terrain height m, beam offset (north, east) m) of a range r_m by the predicted return's
        ray (beam.py) at the dead-reckoned position of t_k; the fallback height and no offset when there is
        no position yet or the prediction has no return."""
        cfg = self.config
        lat, lon = self.pos
        if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(yaw)):
            return d_fallback, (0.0, 0.0)
        r_n, r_e = self._radii(lat, h_baro)
        if math.isfinite(self.t_pos) and cfg.aiding:  # one step of dead reckoning on this sample's aiding
            v_ne = ground_vector(m_v, m_psi) + (self.e_ne if self._ne_frame else 0.0)
            v, psi = speed_track(v_ne)
            v_ne = ground_vector(v + self.b_v, psi + self.b_psi)
            dtp = t_k - self.t_pos
            lat, lon = lat + v_ne[0] * dtp / r_n, lon + v_ne[1] * dtp / r_e
        if not cfg.roll_compensation:
            roll = pitch = 0.0
        ray = beam.predicted_ray(self.dem, lat, lon, h_baro, roll, pitch, yaw, cfg.beamwidth_deg, r_n, r_e)
        if ray is None:
            return d_fallback, (0.0, 0.0)
        theta, u_n, u_e = ray
        rho = r_m * math.sin(theta)
        return h_baro - r_m * math.cos(theta), (rho * u_n, rho * u_e)

    def _beam_arrays(self, b_psi: float) -> tuple[np.ndarray, np.ndarray]:
        """The transect's beam offsets (m) in the replica frame of heading reference b_psi."""
        n = len(self.transect)
        if not self._return_model or len(self._offs) != n:
            z = np.zeros(n)
            return z, z
        key = (self.transect.samples.version, b_psi)
        if self._beam_cache is not None and self._beam_cache[0] == key:
            return self._beam_cache[1]
        o = self._offs.rows()
        out = beam.rotate_offsets(o[:, 0], o[:, 1], -b_psi)
        self._beam_cache = (key, out)
        return out

    def _air_vector(self, t_k: float) -> tuple[float, float]:
        """(speed, direction) of the air vector over the sample interval (t_k - T, t_k]: the mean of
        tas (cos, sin)(heading + sideslip) over the air-data samples in it (settings aiding_interval_mean,
        air_vector_sideslip). The displacement between two samples is the integral of the velocity over the
        interval, and the mean also averages the gusts the ground track does not follow; the sideslip turns
        the compass heading into the air vector's direction (in a gust the aircraft weathercocks)."""
        cfg = self.config
        air, hdg = self._tails["air"], self._tails["hdg"]
        lo = t_k - cfg.sample_period_s if cfg.aiding_interval_mean else t_k - 1e-6
        sn, se, m = air_vector_sum(
            air.t, np.ascontiguousarray(air.v[:, 0]), np.ascontiguousarray(air.v[:, 1]), air.ok, hdg.t,
            np.ascontiguousarray(hdg.v[:, 0]), hdg.ok, lo, t_k, 1.5 * cfg.sample_period_s,
        )  # fmt: skip
        if m == 0:  # no air-data sample in the interval: the newest one (found by the caller)
            row, _ = air.row(t_k, 1.0)
            hr, _ = hdg.row(t_k, 1.5 * cfg.sample_period_s)
            return float(row[0]), float(wrap_rad(hr[0] + row[1]))
        return speed_track(np.array([sn / m, se / m]))

    # ------------------------------------------------------------------ epochs
    def _radii(self, lat: float, h: float) -> tuple[float, float]:
        key = (lat, h)
        if getattr(self, "_radii_key", None) == key:  # an epoch asks several times for the same start
            return self._radii_val
        h = h if math.isfinite(h) else 0.0
        r = float(meridian_radius_m(lat)) + h, (float(prime_vertical_radius_m(lat)) + h) * math.cos(lat)
        self._radii_key, self._radii_val = key, r
        return r

    def _offsets(self, dt, m_v, m_psi, b_v, b_psi, lat, radii=None):
        """Replica offsets (rad) from the start at latitude lat; radii: its (r_n, r_e) when known."""
        r_n, r_e = self._radii(lat, self.h_m) if radii is None else radii
        dla = np.empty(dt.size)
        dlo = np.empty(dt.size)
        replica_offsets(dt, m_v, m_psi, b_v, b_psi, r_n, r_e, dla, dlo)
        return dla, dlo

    def _set_status(self, t: float, status: str, reason: str) -> None:
        if status != self.health.status:
            self.health.events.append((t, f"acq_track: {self.health.status} -> {status}: {reason}"))
            self.health.status = status
        self.health.ok = status in ("ok", "degraded") or (
            status == "acquiring" and self._sigma_h() < self.config.acquire_above_sigma_m
        )

    def _sigma_h(self) -> float:
        return math.sqrt(max(self.P[0, 0] + self.P[1, 1], 0.0))

    def _epoch(self, s: Sample, have_gnss: bool) -> None:
        cfg = self.config
        tr = self.transect
        prev = tr.samples[-1] if len(tr) else None
        # the start point for this epoch: drop the oldest sample when full
        if tr.full:
            _, _, _, dt, m_v, m_psi, _ = self._aid_arrays()
            dla, dlo = self._offsets(dt, m_v, m_psi, self.b_v, self.b_psi, self.p0[0])
            self.p0 = (self.p0[0] + dla[1], self.p0[1] + dlo[1])
        tr.append(s)
        self._offs.append(self._pending_offset)
        if len(tr) == 1:
            lat, lon = self.pos
            if prev is None and math.isfinite(self.t_pos):  # dead-reckon the reset position to t_k
                dtp = s.t_s - self.t_pos
                v = ground_vector(self._aided_speed(s), self._aided_track(s))
                r_n, r_e = self._radii(lat, self.h_m)
                lat, lon = lat + v[0] * dtp / r_n, lon + v[1] * dtp / r_e
            self.p0 = (lat, lon)
        if have_gnss:
            self._gnss_epoch(s)
            return
        self._propagate_cov(s)
        if not tr.full:
            self._set_lock("filling", s.t_s, "acquiring", "transect filling")
            self._finish(s)
            return
        # a transect placed by GNSS goes straight to tracking; otherwise a large sigma asks for a search
        # a serial search only when the dead-reckoned start is too uncertain for the loops' pull-in range:
        # after a loss of lock with a small sigma the loops re-lock from the dead-reckoned state (the
        # integrity checks decide), so a low-SNR stretch does not leave the tracker searching to the end
        acq_due = (
            self.need_acquisition or (self.lock_state in ("filling", "acquiring") and not self._anchored)
        ) and self._sigma_h() > cfg.acquire_above_sigma_m
        if acq_due:
            if self.acq_wait > 0:
                self.acq_wait -= 1
                self._finish(s)
                return
            snr_pred = self._predicted_snr()
            if not snr_pred >= cfg.snr_min_db:  # integrity prediction: no search over flat terrain
                if not self._deferred:
                    self.health.events.append(
                        (
                            s.t_s,
                            f"acq_track: predicted terrain SNR {snr_pred:.1f} dB < "
                            f"{cfg.snr_min_db:g} dB: acquisition deferred",
                        )
                    )
                self._deferred = True
                self.snr_db = snr_pred
                self._set_lock(
                    self.lock_state if self.lock_state == "lost" else "acquiring",
                    s.t_s,
                    "lost" if self.need_acquisition else "acquiring",
                    f"predicted terrain SNR {snr_pred:.1f} dB < {cfg.snr_min_db:g} dB: acquisition deferred",
                )
                self._finish(s)
                return
            self._deferred = False
            if not self._acquire(s):
                # retry with the next transect, backing off to every 4th after repeated failures
                self.acq_failures += 1
                self.acq_wait = (cfg.transect_samples - 1) * min(2 ** (self.acq_failures - 1), 4)
                self._finish(s)
                return
        self._track(s)
        self._finish(s)

    def _corrected(self, s: Sample) -> tuple[float, float]:
        """The sample's aiding (speed, track) corrected by e_ne (reference_frame "ne"), else as measured."""
        if not self._ne_frame:
            return s.m_v, s.m_psi
        # speed_track(ground_vector(m_v, m_psi) + e_ne) in plain floats (the same operations)
        e_n, e_e = self.e_ne.tolist()
        vn = s.m_v * math.cos(s.m_psi) + e_n
        ve = s.m_v * math.sin(s.m_psi) + e_e
        return math.hypot(vn, ve), math.atan2(ve, vn)

    def _aided_speed(self, s: Sample) -> float:
        return self._corrected(s)[0] + self.b_v

    def _aided_track(self, s: Sample) -> float:
        return self._corrected(s)[1] + self.b_psi

    def _set_lock(self, lock: str, t: float, status: str, reason: str) -> None:
        self.lock_state = lock
        self._set_status(t, status, reason)

    def _gnss_epoch(self, s: Sample) -> None:
        cfg = self.config
        g_speed, g_track = speed_track(np.array(s.gnss_v_ne))
        if (
            cfg.aiding
            and cfg.aiding_source == "air_data"
            and cfg.wind_estimation
            and math.isfinite(s.tas_mps)
        ):
            self.wind.update(np.array(s.gnss_v_ne), s.tas_mps, s.heading_rad, gain=max(cfg.wind_gain, 0.2))
        if math.isfinite(g_speed) and g_speed > 1.0 and self._ne_frame:
            # the triangle GNSS velocity - aiding vector (the wind with air data); the first one sets it
            k = 0.2 if self._gnss_epochs else 1.0
            self.e_ne = self.e_ne + k * (np.array(s.gnss_v_ne) - ground_vector(s.m_v, s.m_psi) - self.e_ne)
            self.e_mean = self.e_ne.copy()
            self._gnss_epochs += 1
        elif math.isfinite(g_speed) and g_speed > 1.0:
            k = 0.2
            self.b_v += k * (g_speed - s.m_v - self.b_v)
            self.b_psi += k * float(wrap_rad(g_track - s.m_psi - self.b_psi))
            self.b_mean = (self.b_v, self.b_psi)
        # the transect's start from this sample's fix back along the references (its first sample may have
        # had no fix, e.g. before the first GNSS epoch, and kept the initial estimate's error)
        _, _, _, dt, m_v, m_psi, _ = self._aid_arrays()
        dla, dlo = self._offsets(dt, m_v, m_psi, self.b_v, self.b_psi, s.gnss_lat)
        self.p0 = (s.gnss_lat - dla[-1], s.gnss_lon - dlo[-1])
        self.pos = (s.gnss_lat, s.gnss_lon)
        self.t_pos = s.t_s
        self.P = np.eye(2) * cfg.gnss_sigma_m**2
        self.Pc = self.P.copy()
        # e_ne's sigma after the GNSS triangles: the aiding's per-sample noise through the gain-0.2 low-pass
        # (steady-state variance k / (2 - k) of the noise's); an INS is reset by GNSS, air data carries gusts
        self._set_centroid_cov(self.Pc, bias_sigma_mps=cfg.aiding_speed_sigma_mps * math.sqrt(0.2 / 1.8))
        self.sigma_v = 0.1
        self.sigma_psi = math.radians(0.2)
        self.bad_epochs = 0
        self.need_acquisition = False
        self.out_speed, self.out_track = self.average.push(g_speed, g_track)
        self._anchored = True
        self._set_lock("gnss", s.t_s, "ok", "GNSS available")

    def _propagate_cov(self, s: Sample) -> None:
        cfg = self.config
        T = cfg.sample_period_s
        cv, cp = self._corrected(s)  # _aided_speed / _aided_track in one
        v = max(cv + self.b_v, 0.0)
        psi = cp + self.b_psi
        if self.lock_state == "tracking":
            sv, sp = self.sigma_v, self.sigma_psi
        elif cfg.aiding:
            sv, sp = cfg.aiding_speed_sigma_mps, math.radians(cfg.aiding_heading_sigma_deg)
        else:
            sv, sp = cfg.unaided_speed_sigma_mps, math.radians(cfg.unaided_heading_sigma_deg)
        walk = self._walk2 * T
        P = self.P
        if self._ne_frame:  # the centroid moves one sample on the aiding + e_ne; e_ne's error walks
            X = self.X
            filter_kernels.ne_predict(X, T, walk, self._bias_walk2 * T)
            self.Pc = X[:2, :2].copy()
            if self.lock_state == "tracking":  # the output: the centroid + the lever to the newest sample
                self.P = self._ne_output_cov(0.5 * cfg.transect_duration_s)
            else:  # out of lock the output is dead-reckoned from the last in-lock newest sample
                self.P = P + _rot_diag(psi, walk, walk) + self._ne_growth(P, T)
            return
        # the aiding's errors are biases over a transect: sigma grows linearly, sqrt(P) + T sigma_v per epoch
        c, sn = math.cos(psi), math.sin(psi)
        p01 = float(P[0, 1] + P[1, 0])
        p_al = c * c * P[0, 0] + c * sn * p01 + sn * sn * P[1, 1]  # (G^T P G) diagonal
        p_cr = sn * sn * P[0, 0] - c * sn * p01 + c * c * P[1, 1]
        s_al, s_cr = math.sqrt(max(p_al, 0.0)), math.sqrt(max(p_cr, 0.0))
        d_al, d_cr = T * sv, v * T * sp
        self.P = P + _rot_diag(psi, 2.0 * s_al * d_al + d_al**2 + walk, 2.0 * s_cr * d_cr + d_cr**2 + walk)
        # the transect centroid's filter: one sample of dead reckoning on the references and the aiding
        self.Pc = self.Pc + _rot_diag(psi, d_al**2 + walk, d_cr**2 + walk)

    def _aid_arrays(self):
        """The transect's arrays with the aiding per sample corrected by the north/east bias e_ne
        (reference_frame "ne"; cached until the samples or e_ne change), else transect.arrays()."""
        arr = self.transect.arrays()
        if not self._ne_frame:
            return arr
        key = (arr, float(self.e_ne[0]), float(self.e_ne[1]))
        if self._aid_key is not None and self._aid_key[0] is arr and self._aid_key[1:3] == key[1:]:
            return self._aid_key[3]
        t, d, valid, dt, m_v, m_psi, rng = arr
        v_c, psi_c = np.empty(m_v.size), np.empty(m_v.size)
        filter_kernels.corrected_aiding(m_v, m_psi, key[1], key[2], v_c, psi_c)
        out = (t, d, valid, dt, v_c, psi_c, rng)
        self._aid_key = (arr, key[1], key[2], out)
        return out

    def _set_centroid_cov(self, Pc: np.ndarray, bias_sigma_mps: float | None = None) -> None:
        """Centroid covariance (reference_frame "ne"); the velocity bias' block kept (or set to
        bias_sigma_mps), their correlation cleared."""
        self.X[:2, :2] = Pc
        self.X[:2, 2:] = 0.0
        self.X[2:, :2] = 0.0
        if bias_sigma_mps is not None:
            self.X[2:, 2:] = np.eye(2) * bias_sigma_mps**2

    def _ne_output_cov(self, lever_s: float) -> np.ndarray:
        """Covariance (north, east m^2) of the point lever_s seconds of dead reckoning past the centroid."""
        X = self.X.tolist()  # plain floats: numpy on 2 x 2 blocks costs more in its calls than the sums
        L2, w = lever_s**2, self._walk2 * lever_s
        p = [
            [X[i][j] + lever_s * (X[i][j + 2] + X[i + 2][j]) + L2 * X[i + 2][j + 2] + (w if i == j else 0.0)
             for j in (0, 1)]
            for i in (0, 1)
        ]  # fmt: skip
        return np.array(p)

    def _ne_growth(self, P: np.ndarray, T: float) -> np.ndarray:
        """One step's growth of a dead-reckoned point's covariance P on the velocity bias' sigma: sigma
        grows linearly by T sigma_e (the bias is constant over the step; bounds the correlation)."""
        Xe = self.X[2:, 2:]
        s_p = math.sqrt(max(P[0, 0] + P[1, 1], 0.0))
        s_e = math.sqrt(max(Xe[0, 0] + Xe[1, 1], 0.0))
        if s_e <= 0:
            return np.zeros((2, 2))
        return (2.0 * s_p * T / s_e + T * T) * Xe

    @staticmethod
    def _ne_change(b_v: float, b_psi: float, m_v: np.ndarray, m_psi: np.ndarray) -> np.ndarray:
        """North/east velocity change (m/s) equivalent to references (b_v, b_psi) on top of the aiding
        (m_v, m_psi): the mean over the samples of (m_v + b_v) u(m_psi + b_psi) - m_v u(m_psi)."""
        return np.array(filter_kernels.ne_change(b_v, b_psi, m_v, m_psi))

    def _fold_references(self, b_v: float, b_psi: float, m_v: np.ndarray, m_psi: np.ndarray) -> None:
        """reference_frame "ne": move the loops' speed / track references (b_v, b_psi on top of the
        corrected aiding m_v, m_psi) into the north/east bias e_ne and zero them: the least-squares constant
        velocity vector of b_v along and v b_psi across each sample's track."""
        self.e_ne = self.e_ne + self._ne_change(b_v, b_psi, m_v, m_psi)
        self.b_v = self.b_psi = 0.0

    def _arrays(self):
        t, d, valid, dt, m_v, m_psi, rng = self._aid_arrays()
        r_n, r_e = self._radii(self.p0[0], self.h_m)
        return t, d, valid, dt, m_v, m_psi, rng, r_n, r_e

    def _track_grid(self, rng: np.ndarray):
        """The map grid the loops correlate with: the plain map, or its footprint dilation at the transect's
        median range (replica_model)."""
        if self._footprint is None:
            return self._grid
        key = getattr(self, "_track_grid_key", None)
        if key is not None and key[0] is rng:  # the same transect (its arrays are cached): the same grid
            return key[1]
        ok = np.isfinite(rng)
        grid = self._footprint.grid(_median(rng[ok]) if ok.any() else math.nan)
        self._track_grid_key = (rng, grid)
        return grid

    def _predicted_snr(self) -> float:
        """Terrain SNR (dB) of the map along the dead-reckoned transect against the a-priori noise alone."""
        cfg = self.config
        t, d, valid, dt, m_v, m_psi, rng, r_n, r_e = self._arrays()
        heights, lat0, lon0, dlat, dlon = self._grid
        n = dt.size
        h_p = np.empty(n)
        replica_heights(
            heights,
            lat0,
            lon0,
            dlat,
            dlon,
            self.p0[0],
            self.p0[1],
            dt,
            m_v,
            m_psi,
            self.b_v,
            self.b_psi,
            r_n,
            r_e,
            self._interp,
            np.empty(n),
            np.empty(n),
            h_p,
        )
        ok = valid & np.isfinite(h_p)
        if ok.sum() < self._n_min:
            return -math.inf
        r_mean = _nanmean(rng)
        sig0 = a_priori_sigma_m(r_mean, cfg.ra_noise_const_m, cfg.ra_noise_fraction, cfg.map_sigma_m)
        var_h = float(np.var(h_p[ok]))
        return 10.0 * math.log10(var_h / sig0**2) if var_h > 0 else -math.inf

    def _acquire(self, s: Sample) -> bool:
        cfg = self.config
        t, d, valid, dt, m_v, m_psi, rng, r_n, r_e = self._arrays()
        sig = self._sigma_h()
        half = min(max(cfg.acquisition_position_half_m, 3.0 * sig), 2.0 * cfg.acquisition_position_half_m)
        w0 = time.perf_counter()
        res = acquisition.serial_search(
            self._grid,
            self.p0[0],
            self.p0[1],
            dt,
            m_v,
            m_psi,
            self.b_v,
            self.b_psi,
            r_n,
            r_e,
            d,
            valid,
            position_half_m=half,
            position_bin_m=cfg.acquisition_position_bin_m,
            speed_half_mps=cfg.acquisition_speed_half_mps,
            speed_bin_mps=cfg.acquisition_speed_bin_mps,
            heading_half_rad=math.radians(cfg.acquisition_heading_half_deg),
            heading_bin_rad=math.radians(cfg.acquisition_heading_bin_deg),
            cost=self._cost,
            remove_bias=cfg.remove_bias,
            interp=self._interp,
            n_min=self._n_min,
            distinct_ratio=cfg.acquisition_distinct_ratio,
            exclusion_m=cfg.acquisition_exclusion_m,
        )
        self.acquisition_s = time.perf_counter() - w0
        self.acquisition_total_s += self.acquisition_s
        self.acquisitions += 1
        if not res.distinct:
            self.health.events.append(
                (
                    s.t_s,
                    f"acq_track: acquisition failed: {res.reason} "
                    f"({res.n_hypotheses} cells)",
                )
            )
            self._set_lock(
                "acquiring",
                s.t_s,
                "lost" if self.need_acquisition else "acquiring",
                f"acquisition: {res.reason}; retry with the next transect",
            )
            return False
        if self._ne_frame:  # the acquired velocity against the filter's velocity bias: a false acquisition
            # (a side minimum over weak terrain) moves it far beyond its sigma; R: one bin as 1 sigma
            dv_ne = self._ne_change(res.b_v - self.b_v, res.b_psi_rad - self.b_psi, m_v, m_psi)
            psi_c = _mean(m_psi)
            v_c = max(_mean(m_v), 1.0)
            R_acq = _rot_diag(
                psi_c,
                cfg.acquisition_speed_bin_mps**2,
                (v_c * math.radians(cfg.acquisition_heading_bin_deg)) ** 2,
            )
            nis_v = _quad2(dv_ne, self.X[2:, 2:] + R_acq)
            e_acq = self.e_ne + dv_ne
            if nis_v > cfg.fix_gate_nis or math.hypot(e_acq[0], e_acq[1]) > cfg.max_speed_bias_mps:
                self.health.events.append(
                    (
                        s.t_s,
                        f"acq_track: acquisition rejected: its velocity change {math.hypot(*dv_ne):.1f} m/s "
                        f"has NIS {nis_v:.1f} (gate {cfg.fix_gate_nis:g}) against the velocity bias' sigma, "
                        f"bias {math.hypot(*e_acq):.1f} m/s (limit {cfg.max_speed_bias_mps:g})",
                    )
                )
                self._set_lock(
                    "acquiring",
                    s.t_s,
                    "lost" if self.need_acquisition else "acquiring",
                    "acquisition: implausible velocity; retry with the next transect",
                )
                return False
        self.p0 = (self.p0[0] + res.dn_m / r_n, self.p0[1] + res.de_m / r_e)
        self.b_v, self.b_psi = res.b_v, res.b_psi_rad
        if self._ne_frame:  # the acquired speed / track references as the north/east bias
            self._fold_references(res.b_v, res.b_psi_rad, m_v, m_psi)
        b = cfg.acquisition_position_bin_m
        self.P = np.eye(2) * (b * b + self.sigma_floor_m**2)
        self.Pc = self.P.copy()
        self._set_centroid_cov(self.Pc)
        self.need_acquisition = False
        self.acq_failures = 0
        self.bad_epochs = 0
        self.pull_in = cfg.transect_samples
        self.health.events.append(
            (
                s.t_s,
                f"acq_track: acquired dn={res.dn_m:+.0f} m de={res.de_m:+.0f} m "
                f"b_v={res.b_v:+.2f} m/s b_psi={math.degrees(res.b_psi_rad):+.2f} deg "
                f"({res.n_hypotheses} cells)",
            )
        )
        self.lock_state = "tracking"
        return True

    def _track(self, s: Sample) -> None:
        cfg = self.config
        arrays = self._arrays()
        t, d, valid, dt, m_v, m_psi, rng, r_n, r_e = arrays
        n_valid = int(valid.sum())
        if n_valid < self._n_min:
            self.health.skip(
                s.t_s,
                "transect_too_few_samples",
                f"acq_track: {n_valid} valid samples of {valid.size}; loops skipped",
            )
            self._out_of_lock(s, "too few valid samples")
            return
        b_v0, b_psi0 = self.b_v, self.b_psi
        o_n, o_e = self._beam_arrays(b_psi0)
        # Aided: start-point loops first, at the (slow) references: the whole-replica shift is the position
        # fix, and the speed and heading loops then stretch and turn the shifted replica. Unaided the speed
        # and heading are the loops' own fast estimates, so they go first and the shift follows them. All of
        # it (adaptivity blocks, both stages, bias mitigation) and the prompt's map heights in one numba call.
        heights, lat0, lon0, dlat, dlon = self._track_grid(rng)
        h_p = np.empty(dt.size)
        its, locks, ran, shp = self._loop_out
        b_v, b_psi, lat_p, lon_p, sp_v, sp_psi = loop_kernel.track_loops(
            heights, lat0, lon0, dlat, dlon, self.p0[0], self.p0[1], dt, m_v, m_psi, b_v0, b_psi0, r_n, r_e,
            d, valid, *self._loop_args, _mean(m_v), _mean(m_psi), *self._loop_settings,
            its, locks, ran, shp, h_p, o_n, o_e,
        )  # fmt: skip
        p_s = (lat_p, lon_p)
        # the kernel's small outputs as Python lists: per-element numpy indexing costs more than tolist
        self.iterations = its.tolist()
        self.spacing = (sp_v, sp_psi)
        shp_rows = shp.tolist()
        self.v_shape = all(row[0] != 0.0 for row, r in zip(shp_rows, ran.tolist(), strict=True) if r)
        shapes = {k: tracking.VShape(bool(shp_rows[k][0]), *shp_rows[k][1:]) for k in (0, 1)}
        locks = locks.tolist()
        r_mean = _nanmean(rng)
        sig0 = a_priori_sigma_m(r_mean, cfg.ra_noise_const_m, cfg.ra_noise_fraction, cfg.map_sigma_m)
        self.snr_db, res_sigma = terrain_snr_db(h_p, d, valid, sig0, cfg.remove_bias)
        fl_v, fl_psi = b_v, b_psi
        if self._ne_frame:  # the plausible bias is the north/east vector's length (the loops' part on top)
            e_try = self.e_ne + self._ne_change(b_v, b_psi, m_v, m_psi)
            fl_v, fl_psi = float(math.hypot(e_try[0], e_try[1])), 0.0
        self.false_lock = false_lock(
            res_sigma,
            sig0,
            cfg.false_lock_sigma_factor,
            fl_v,
            fl_psi,
            cfg.aiding,
            cfg.max_speed_bias_mps,
            math.radians(cfg.max_heading_bias_deg),
        )
        reasons = []
        converged = bool(locks[0] and locks[1])
        if not self.v_shape:
            reasons.append("no V-shape around the correlation minimum")
        if not self.snr_db >= cfg.snr_min_db:
            reasons.append(f"terrain SNR {self.snr_db:.1f} dB < {cfg.snr_min_db:g} dB")
        if self.false_lock:
            reasons.append(f"false lock: {self.false_lock}")
        self.t_epoch = s.t_s
        if reasons:
            self._out_of_lock(s, "; ".join(reasons))
            return
        innov = np.array([b_v - b_v0, float(wrap_rad(b_psi - b_psi0))])
        # The fit pins the transect's centroid best: shift and stretch are uncorrelated about it, while its
        # far end carries the loops' speed / heading noise times half a transect. So the centroid the fit
        # found is the correlation's position fix; a 2-state Kalman filter (north, east of the centroid)
        # weighs it against the dead-reckoned centroid, the references move only part of the way
        # (reference_gain: the aided reference is a slow bias), and the start point follows from both, so the
        # fix is fed back into the start point and the output.
        c = self._centroid_index(valid)
        dla_f, dlo_f = self._offsets(dt, m_v, m_psi, b_v, b_psi, self.p0[0], (r_n, r_e))
        dla_p, dlo_p = self._offsets(dt, m_v, m_psi, b_v0, b_psi0, self.p0[0], (r_n, r_e))
        r_ne = np.array(
            [
                (p_s[0] - self.p0[0] + dla_f[c] - dla_p[c]) * r_n,
                (p_s[1] - self.p0[1] + dlo_f[c] - dlo_p[c]) * r_e,
            ]
        )
        # the fix's covariance: the terrain information along / across the track at the fit
        psi = self._aided_track(s)
        i_al, i_cr = beam.information_at(
            heights, lat0, lon0, dlat, dlon, p_s[0], p_s[1], dt, m_v, m_psi, b_v, b_psi, r_n, r_e, o_n, o_e,
            valid, psi,
        )
        sig_res = max(res_sigma if math.isfinite(res_sigma) else 0.0, sig0)
        k2 = cfg.fix_sigma_scale**2 * _MAD_VARIANCE_FACTOR * sig_res**2
        q_map = self.map_resolution_m**2 / 12.0  # the map's quantisation of the fix
        R = _rot_diag(psi, k2 / max(i_al, 1e-12) + q_map, k2 / max(i_cr, 1e-12) + q_map)
        S = self.Pc + R
        nis = _quad2(r_ne, S)
        if nis > cfg.fix_gate_nis:  # innovation gate: a fix this far from the prediction is a false lock
            self.last_innovation = (s.t_s, r_ne, S)
            self._out_of_lock(s, f"fix innovation NIS {nis:.1f} > gate {cfg.fix_gate_nis:g}")
            return
        # consecutive transects share N - 1 samples: each epoch's fix brings 1/overlap of new information
        if self._ne_frame:  # the 4-state filter: the fix corrects the centroid and the velocity bias
            Ro = self._fix_overlap * R
            X_new, dx = np.empty((4, 4)), np.empty(4)
            if not filter_kernels.ne_fix_gain(self.X, Ro, float(r_ne[0]), float(r_ne[1]), X_new, dx):
                raise np.linalg.LinAlgError("singular 2 x 2 matrix")
            e_new = self.e_ne + dx[2:]
            if math.hypot(e_new[0], e_new[1]) > cfg.max_speed_bias_mps:  # beyond the plausible bias
                self.last_innovation = (s.t_s, r_ne, S)
                lim = cfg.max_speed_bias_mps
                self._out_of_lock(s, f"false lock: velocity bias {math.hypot(*e_new):.1f} m/s beyond {lim:g}")
                return
            self.X = X_new
            dc = dx[:2]
            self.Pc = self.X[:2, :2].copy()
        else:
            K = self.Pc @ _inv2(self.Pc + self._fix_overlap * R)
            IK = np.eye(2) - K
            self.Pc = IK @ self.Pc @ IK.T + self._fix_overlap * (K @ R @ K.T)
            dc = K @ r_ne
        c_new = (self.p0[0] + dla_p[c] + dc[0] / r_n, self.p0[1] + dlo_p[c] + dc[1] / r_e)
        g = 1.0
        if cfg.aiding:  # the aided reference is a slow bias: move it part of the way (reference_gain), but
            # take the loops' values whole for a transect after an acquisition (pull-in: its bins are coarse)
            g = 1.0 if self.pull_in > 0 else cfg.reference_gain
            b_v, b_psi = b_v0 + g * innov[0], b_psi0 + g * innov[1]
        self.pull_in = max(self.pull_in - 1, 0)
        self.b_v, self.b_psi = b_v, b_psi
        if self._ne_frame:  # the fix's velocity part moves e_ne; the start point follows below
            self.e_ne = self.e_ne + dx[2:]
            self.b_v = self.b_psi = 0.0
            _, _, _, dt, m_v, m_psi, _ = self._aid_arrays()
            b_v = b_psi = 0.0
        dla_n, dlo_n = self._offsets(dt, m_v, m_psi, b_v, b_psi, self.p0[0], (r_n, r_e))
        self.p0 = (c_new[0] - dla_n[c], c_new[1] - dlo_n[c])
        # loop sigmas: the V's slopes against the cost noise (sigma sqrt((1 - 2/pi)/N), MAD of Gaussians)
        n_ok = max(n_valid, 1)
        cost_noise = sig0 * math.sqrt((1.0 - 2.0 / math.pi) / n_ok)
        mv_mean = _mean(m_v)  # the (corrected) aiding speed over the transect, used twice below
        if self._ne_frame:  # the references' sigma is e_ne's, along / across the track
            (xe00, xe01), (_, xe11) = self.X[2:, 2:].tolist()
            c_, s_ = math.cos(psi), math.sin(psi)
            s_al = c_ * c_ * xe00 + 2 * c_ * s_ * xe01 + s_ * s_ * xe11
            s_cr = s_ * s_ * xe00 - 2 * c_ * s_ * xe01 + c_ * c_ * xe11
            v_ref = max(mv_mean, 1.0)
            sv = [math.sqrt(max(s_al, 0.0)), math.sqrt(max(s_cr, 0.0)) / v_ref]
        else:
            sv = [
                self._loop_sigma(shapes[0], cost_noise, cfg.speed_narrow_spacing_mps),
                self._loop_sigma(shapes[1], cost_noise, math.radians(cfg.heading_narrow_spacing_deg)),
            ]
            if g < 1.0:  # the references are an exponential average of the loops' values (gain g)
                sv = [x * math.sqrt(g / (2.0 - g)) for x in sv]
        self.sigma_v, self.sigma_psi = sv
        self.last_innovation = (s.t_s, r_ne, S)
        verdict = self.integrity.add(s.t_s, nis, 2)
        self._integrity_extra = verdict.extra()
        if verdict.changed:
            self.health.events.append((s.t_s, f"acq_track: {verdict.message}"))
        self.bad_epochs = 0
        k = 1.0 / max(cfg.transect_samples, 1)  # the references' running mean over about a transect
        self.e_mean = self.e_mean + k * (self.e_ne - self.e_mean)
        self.b_mean = (
            self.b_mean[0] + k * (b_v - self.b_mean[0]),
            self.b_mean[1] + k * (b_psi - self.b_mean[1]),
        )
        # the newest sample's covariance: the centroid's, plus dead reckoning over the rest of the transect
        lever_s = float(t[-1] - t[c])
        v_mean = max(mv_mean + b_v, 1.0)
        walk = self._walk2 * lever_s
        if self._ne_frame:
            self.P = self._ne_output_cov(lever_s)
        else:
            self.P = self.Pc + _rot_diag(
                psi, (lever_s * sv[0]) ** 2 + walk, (v_mean * lever_s * sv[1]) ** 2 + walk
            )
        if converged and self.integrity.degraded:  # in lock, but the references jump: flagged
            self._set_lock("tracking", s.t_s, "degraded", "in lock, innovation test above its band")
        elif converged:
            self._set_lock("tracking", s.t_s, "ok", "in lock")
        else:  # the V is there but a loop hit the 101-iteration break: estimate kept, flagged
            self._set_lock("tracking", s.t_s, "degraded", "a loop did not converge (101-iteration break)")

    @staticmethod
    def _centroid_index(valid: np.ndarray) -> int:
        """The sample nearest the mean index of the valid samples (the fit's pivot)."""
        idx = np.nonzero(valid)[0]
        return int(round(_mean(idx))) if idx.size else (valid.size - 1) // 2

    @staticmethod
    def _loop_sigma(shape, cost_noise: float, narrow: float) -> float:
        slope = min(abs(shape.slope_left), abs(shape.slope_right))
        res = cost_noise / slope if slope > 0 else np.inf
        return float(math.sqrt(min(res, 10.0 * narrow) ** 2 + (narrow / math.sqrt(12.0)) ** 2))

    def _out_of_lock(self, s: Sample, reason: str) -> None:
        cfg = self.config
        self.bad_epochs += 1
        self.sigma_v = cfg.aiding_speed_sigma_mps if cfg.aiding else cfg.unaided_speed_sigma_mps
        self.sigma_psi = math.radians(
            cfg.aiding_heading_sigma_deg if cfg.aiding else cfg.unaided_heading_sigma_deg
        )
        if self.bad_epochs >= cfg.lost_after_epochs:
            if cfg.aiding and self.lock_state != "lost":
                # dead-reckon on the aiding with the references' running mean over the lock: they carry the
                # sensor biases and the wind's data bias the loops learned (zeroing them drops that)
                lim_v, lim_p = cfg.max_speed_bias_mps, math.radians(cfg.max_heading_bias_deg)
                self.b_v = float(np.clip(self.b_mean[0], -lim_v, lim_v))
                self.b_psi = float(np.clip(self.b_mean[1], -lim_p, lim_p))
                if self._ne_frame:  # the filter's e_ne is kept (it is not a loop value)
                    self.b_v = self.b_psi = 0.0
            self.need_acquisition = True
            self._anchored = False
            self._set_lock("lost", s.t_s, "lost", f"out of lock {self.bad_epochs} epochs: {reason}")
        else:
            self._set_lock("out_of_lock", s.t_s, "degraded", reason)

    def _finish(self, s: Sample) -> None:
        """Newest position from the replica; output speed/track through the moving average."""
        _, _, _, dt, m_v, m_psi, _ = self._aid_arrays()
        dla, dlo = self._offsets(dt, m_v, m_psi, self.b_v, self.b_psi, self.p0[0])
        self.pos = (self.p0[0] + dla[-1], self.p0[1] + dlo[-1])
        self.t_pos = s.t_s
        cv, cp = self._corrected(s)
        v, psi = cv + self.b_v, cp + self.b_psi  # _aided_speed, _aided_track
        if self.lock_state == "tracking":
            if self.config.aiding:  # average the references: the aiding carries ramps without lag
                ref_v, ref_psi = self.b_v, self.b_psi
                if self._ne_frame:  # the NE bias as the newest sample's speed / track reference
                    ref_v, ref_psi = cv - s.m_v + self.b_v, float(wrap_rad(cp - s.m_psi)) + self.b_psi
                ab_v, ab_psi = self.average.push(ref_v, ref_psi)
                self.out_speed, self.out_track = s.m_v + ab_v, float(wrap_rad(s.m_psi + ab_psi))
            else:
                self.out_speed, self.out_track = self.average.push(v, psi)
            if (
                self.config.aiding
                and self.config.aiding_source == "air_data"
                and self.config.wind_estimation
                and not self._ne_frame
                and math.isfinite(s.tas_mps)
            ):
                self.wind.update(ground_vector(v, psi), s.tas_mps, s.heading_rad)
                # the references keep the ground vector the loops found (the wind took over part of it)
                m_v2, m_psi2 = self.wind.predict(s.tas_mps, s.heading_rad)
                self.b_v += s.m_v - m_v2
                self.b_psi += float(wrap_rad(s.m_psi - m_psi2))
                tr = self.transect.samples
                tr[-1] = Sample(
                    s.t_s,
                    s.d_m,
                    s.valid,
                    s.range_m,
                    m_v2,
                    m_psi2,
                    s.tas_mps,
                    s.heading_rad,
                    s.gnss_lat,
                    s.gnss_lon,
                    s.gnss_v_ne,
                    s.roll_rad,
                )
        else:
            self.average.reset()
            self.out_speed, self.out_track = v, float(wrap_rad(psi))

    # ------------------------------------------------------------------ output
    def estimate(self, t_s: float | None = None) -> Estimate:
        t = float(self.t_pos if t_s is None else t_s)
        lat, lon = self.pos
        v_ne = ground_vector(self.out_speed, self.out_track)
        dtp = t - self.t_pos if math.isfinite(self.t_pos) else 0.0
        if math.isfinite(lat) and dtp != 0.0:
            r_n, r_e = self._radii(lat, self.h_m)
            lat, lon = lat + v_ne[0] * dtp / r_n, lon + v_ne[1] * dtp / r_e
        C = self._C0.copy()  # the constant diagonal entries (vertical, attitude) set in the constructor
        P = self.P
        if dtp > 0:  # the extrapolation's own growth (aiding-grade)
            P = P + _rot_diag(
                self.out_track, (dtp * self.sigma_v) ** 2, (self.out_speed * dtp * self.sigma_psi) ** 2
            )
        C[:2, :2] = P
        C[3:5, 3:5] = _rot_diag(self.out_track, self.sigma_v**2, (self.out_speed * self.sigma_psi) ** 2)
        extra = {
            "lock_state": self.lock_state,
            "snr_db": float(self.snr_db),
            "tracked_speed_mps": float(self.out_speed),
            "tracked_track_deg": float(math.degrees(self.out_track)),
            "speed_spacing_mps": float(self.spacing[0]),
            "heading_spacing_deg": float(math.degrees(self.spacing[1])),
            "v_shape": bool(self.v_shape),
            "false_lock": self.false_lock,
            "loop_iterations": list(self.iterations),
            "wind_ne_mps": self.e_ne.copy()
            if self._ne_frame and self.config.aiding_source == "air_data"
            else self.wind.w_ne.copy(),
            "acquisitions": int(self.acquisitions),
        }
        if self.last_innovation is not None:
            te, innov, S = self.last_innovation
            nis = _quad2(innov, S)
            extra.update(
                {
                    EXTRA_INNOVATION: innov.copy(),
                    EXTRA_INNOVATION_COV: S.copy(),
                    EXTRA_NIS: nis,
                    EXTRA_NIS_DOF: 2,
                    EXTRA_MEASUREMENT_TIME: float(te),
                    EXTRA_LOG_LIKELIHOOD: float(-0.5 * (nis + math.log((2 * math.pi) ** 2 * _det2(S)))),
                }
            )
        extra.update(self._integrity_extra)
        h = Health(
            ok=self.health.ok,
            status=self.health.status,
            skipped=dict(self.health.skipped),
            events=list(self.health.events),
        )
        return Estimate(
            t_s=t,
            lat_rad=float(lat),
            lon_rad=float(lon),
            h_m=float(self.h_m),
            v_ned_mps=np.array([v_ne[0], v_ne[1], 0.0]),
            roll_rad=float(self.roll),
            pitch_rad=float(self.pitch),
            yaw_rad=float(self.yaw),
            covariance=C,
            health=h,
            extra=extra,
        )
