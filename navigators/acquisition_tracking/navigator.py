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
along / across) + a map post^2 / 12, its gain counting fix_overlap epochs per fix (N with the INS as aiding:
consecutive fixes share N - 1 of N samples; N / 2 with air data; settings.py). The output is Pc
plus dead reckoning from the centroid to the newest sample; out of lock it grows linearly on the aiding's
sigmas. Vertical: the barometer's bias.

reference_frame "ne" (the default): the aiding of every transect sample is corrected by one north/east
velocity bias e_ne (_aid_arrays; an INS's velocity error, or the wind with air data), the loops run around
b = 0, and the centroid filter has four states (centroid north/east, e_ne north/east): the fix updates
both, e_ne walks by aiding_bias_walk_mps_per_sqrt_s (with the INS as aiding and the IMU's specification,
apply_imu_spec: from the initial velocity covariance as the free INS's velocity error grows), the output is
the centroid plus the lever to the newest sample, and out of lock the dead-reckoned sigma grows on e_ne's
(with the IMU's specification the 4-state filter's own propagation, e_ne's variance growing as the free INS's
velocity error: ins_error.py). replica_model "return": each sample's measured height and map point come
from the ray of its predicted shortest return (beam.py; _return_height), and the loops get the samples'
offsets.

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

import numpy as np

from ..core.maps import load_map
from ..frames import SensorFrames, frame_defects
from ..integrity import protection_level as pl
from ..integrity.consistency_check import ConsistencyCheck
from ..integrity.innovation_monitor import InnovationMonitor
from ..protocol import Estimate, Health, update_extra
from . import loop_kernel, tracking
from .acquire_step import AcquisitionStep
from .aiding import (
    WindEstimator,
    ground_vector,
    speed_track,
)
from .buffers import (
    _det2,
    _Offsets,
    _quad2,
    _rot_diag,
    _Tail,
)
from .centroid_filter import CentroidFilter
from .correlation import (
    COSTS,
)
from .intake import SensorIntake
from .integrity import (
    OutputAverage,
)
from .profile import (
    Sample,
    Transect,
)
from .settings import CAPABILITIES, AcqTrackConfig
from .tracking_step import TrackingStep

# the sensors whose NaN-but-valid samples and gaps update() counts in its Health
_DEFECT_SENSORS = ("radar_altimeter", "baro", "air_data", "heading", "imu")   # GNSS outages are no defect


class AcqTrackNavigator(SensorIntake, CentroidFilter, AcquisitionStep, TrackingStep):
    """Acquisition-and-tracking TRN (seed 001); settings are AcqTrackConfig's fields (see settings.py).

    dem: the navigator's map (terrain.Dem, or a name/path for terrain.load). `required_sensors()` lists the
    sensors its settings need (the scenario check refuses a scenario without them before the flight).
    """

    capabilities = CAPABILITIES
    settings_class = AcqTrackConfig          # what `trn-env navigators` lists as its settings
    integrity_risk = pl.DEFAULT_INTEGRITY_RISK   # per epoch, for the published HPL (registry sets it)
    map_horizontal_sigma_m = 0.0                 # the map's horizontal error in the HPL (registry sets it)

    def __init__(self, dem=None, settings: AcqTrackConfig | None = None, name: str = "acq_track",
                 **overrides):
        self.config = self.settings = cfg = AcqTrackConfig.build(settings, overrides)
        self.integrity = InnovationMonitor(cfg.integrity_window, cfg.integrity_alpha)
        self.consistency = ConsistencyCheck()   # long-window NIS test (navigators.integrity)
        dem = load_map(dem, "acq_track")
        self.dem = dem
        self.name = name
        # the map and the configured interpolation as one kernel record (terrain.kernels.MapRecord)
        self._map = dem.record(cubic=cfg.interpolation == "bicubic")
        self._footprint = None
        self._return_model = cfg.replica_model == "return"
        if cfg.replica_model == "footprint":
            from .footprint import FootprintMaps

            self._footprint = FootprintMaps(dem, cfg.beamwidth_deg)
        sn, se = dem.spacing_m
        self.map_resolution_m = float(0.5 * (sn + se))
        self.sigma_floor_m = float(cfg.position_sigma_floor_m or 0.5 * self.map_resolution_m)
        self._cost = COSTS[cfg.correlation]
        self._disc = tracking.DISCRIMINATORS[cfg.discriminator]
        self._n_min = max(3, int(math.ceil(cfg.min_valid_fraction * cfg.transect_samples)))
        self._fix_overlap = float(cfg.fix_overlap_epochs)
        walk = cfg.aiding_walk_m_per_sqrt_s
        self._walk2 = float(walk) ** 2
        self._speed_set = np.array(cfg.speed_spacings_mps)
        self._heading_set = np.radians(np.array(cfg.heading_spacings_deg))
        # loop_kernel.track_loops' settings (fixed by the config) and its preallocated outputs
        self._loop_settings = loop_kernel.LoopSettings.from_config(
            cfg, self.map_resolution_m, self._cost, self._n_min, self._disc,
            loop_kernel.MITIGATIONS[cfg.bias_mitigation])
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
            from ..inertial.strapdown import StrapdownIns

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
        self.consistency.reset()
        self._integrity_extra: dict = {}
        self.t_epoch = math.nan
        self.next_k = None
        self._tails = {k: _Tail(n) for k, n in (("baro", 1), ("air", 2), ("hdg", 1), ("gnss", 5), ("ins", 5))}
        self.transect.clear()
        self._offs = _Offsets(self.config.transect_samples)  # beam offsets (north, east m)
        self._pending_offset = (0.0, 0.0)
        self._beam_rot = None
        self._beam_cache = None
        self.average.reset()
        self.wind.reset()

    def reset(self, initial: Estimate) -> None:
        self._reset_state()
        self._last_sample_t: dict[str, float] = {}       # frame_defects' memory: gaps across frames
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
        self._init_state = (cov, v, self.t0)
        self._start_ins_growth(*self._init_state)   # with the IMU's specification: the INS's own model
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
        for t_s, reason, message in frame_defects(frames, _DEFECT_SENSORS, self._last_sample_t):
            self.health.skip(t_s, reason, message)
        try:
            self._ingest(frames)
            self._samples(frames)
        except (FloatingPointError, ZeroDivisionError, np.linalg.LinAlgError) as exc:
            self.health.skip(frames.t_end_s, "numerical", f"acq_track: epoch skipped ({exc})")
        return self.estimate(frames.t_end_s)

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
        if self._acquisition_epoch(s):     # a search due and not done or not found (acquire_step)
            self._finish(s)
            return
        self._track(s)
        self._finish(s)

    def _set_lock(self, lock: str, t: float, status: str, reason: str) -> None:
        self.lock_state = lock
        self._set_status(t, status, reason)

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
            log_lik = float(-0.5 * (nis + math.log((2 * math.pi) ** 2 * _det2(S))))
            extra.update(update_extra(innov.copy(), S.copy(), nis, 2, log_lik, float(te)))
        extra.update(self._integrity_extra)
        pl.publish(extra, pl.gaussian_hpl(P, pl.filter_risk(self)), self)   # protection_level
        h = self.health.snapshot(self._consistency_warning, self.consistency)
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
