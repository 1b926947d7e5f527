"""AcqTrackConfig: every setting of the acquisition-and-tracking TRN, checked in __post_init__.

Defaults are the thesis' radar-altimeter-run loop parameters (seed 001 ch. 5; spec section 4's table).
The choices the thesis leaves open (spec section 8) are settings here, each with our default:

- symmetry_ratio_max = 2.0: the symmetry-ratio threshold of the adaptivity block.
- lock thresholds in the loop's own unit (m/s for speed, deg for heading) on |eps|, the change between
  consecutive loop iterations.
- loop_order = "speed_first": speed 1st, speed 2nd, heading 1st, heading 2nd ("heading_first" swaps).
- output_average_length (None: ceil(N / 2), the thesis' minimum) and the agreement limits
  output_average_speed_tol_mps / output_average_heading_tol_deg under which the moving average runs.
- costs: MAD (remove_bias: mean-removed), Pearson (1 - r) and MSD (eq 3.4, garbled in print; our reading
  in correlation.py: the mean squared difference, of the mean-removed difference under remove_bias; the
  loops correlate with its square root).
- bias_mitigation (thesis 3.5.2.2): "ncs" (default, the thesis' choice: a fixed narrow second stage),
  "els" (NCS, then the four-correlator early-late slope refinement, eq 3.7; loop_kernel.py) or "none"
  (the first, adaptive stage only).
- roll_compensation: plumb height = R cos(max(0, tilt - beamwidth/2)) (tilt = acos(cos roll cos pitch)):
  a pulse altimeter returns the shortest range in its cone, which over level ground is the cone's edge
  once the tilt exceeds half the beam. Roll and pitch come from the INS (aiding_source "ins") or, with air
  data, from the coordinated-turn relation roll = atan(V psi_dot / g) (pitch 0).
- acquisition grid: +-10 m/s in 1 m/s, +-10 deg in 1 deg, +-500 m in 50 m (21 x 21 x 441 cells);
  distinct when the minimum is below acquisition_distinct_ratio (0.9) times the best cost farther than
  acquisition_exclusion_m.
- start-point loops (ours, position_* settings): the whole replica shifted along / across the track by two
  more early-late loops; the fit's transect centroid is the position fix, fused by a 2-state Kalman filter
  (fix_sigma_scale, fix_overlap, fix_gate_nis; navigator.py). Defaults that depend on aiding_source are in
  SOURCE_DEFAULTS below.
- lock: a loop that hits the 101-iteration break flags the epoch 'degraded' but keeps its estimate; out of
  lock (V-shape flag, SNR < snr_min_db, false lock) lost_after_epochs times in a row is 'lost'.
- reference_frame: "ne" (default for both sources) keeps the aiding's error as one north/east
  velocity bias e_ne (an INS's velocity error; with air data the wind), estimated with the transect
  centroid by a 4-state filter from the position fixes, its random walk aiding_bias_walk_mps_per_sqrt_s
  (INS 0.03, air data 0.05); an acquisition whose velocity change has an NIS above fix_gate_nis against
  e_ne's sigma is rejected. "speed_track" is the thesis' one reference per loop (b_v, b_psi), which a
  north/east error turns into a ramp in every turn (navigator.py).
- replica_model "return" (the built-in scenario's): the roll correction formula of spec
  section 8 read as a ray: the measured height uses the off-nadir angle of the return predicted on the map
  at the navigator's position and attitude, and the replica samples the map where that return lies
  (beam.py). "footprint" and "plumb" keep the point below the aircraft.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from trn_env.navigators.acquisition_tracking.correlation import COSTS, INTERPOLATIONS

AIDING_SOURCES = ("air_data", "ins")
# Defaults that depend on aiding_source (a setting given as null / None takes these):
# - aiding_speed_sigma_mps / aiding_heading_sigma_deg: the aiding's error over a transect besides what the
#   references absorb - air data in JSBSim's light turbulence (the gusts move the ground vector by ~2 m/s per
#   axis, invisible to air data) 1.5 m/s / 1 deg; an IRS's (strapdown INS) velocity 0.3 m/s / 0.2 deg.
# - aiding_walk_m_per_sqrt_s: the dead reckoning's random walk on top (position variance per second): air
#   data 2 m/s x sqrt(2 x 10 s correlation) ~ 9; an INS 2 (its slow velocity drift, which the slow
#   references follow late; calibrated so the centroid fix's NIS averages 2 on the built-in flight).
# - reference_gain: the aided references are slow biases; the fraction of each epoch's loop change taken
#   (an exponential average over ~2 / gain epochs): air data 0.1, an INS's slower drift 0.02.
# - max_speed_bias_mps / max_heading_bias_deg: a reference beyond is a false lock: air data 15 m/s / 15 deg
#   (wind + sensor bias); an INS 6 m/s / 3 deg (an intermediate-grade IRS's Schuler velocity error, 0.5 mg /
#   1.24e-3 rad/s = 4 m/s, with a margin).
# - reference_frame: "ne" for both (an INS's velocity error and the wind are north/east vectors).
# - aiding_bias_walk_mps_per_sqrt_s: e_ne's walk; an INS's Schuler error drifts slowly (0.03), the wind's
#   apparent part with the slow gusts faster (0.05).
SOURCE_DEFAULTS = {
    "aiding_speed_sigma_mps": {"air_data": 1.5, "ins": 0.3},
    "aiding_heading_sigma_deg": {"air_data": 1.0, "ins": 0.2},
    "aiding_walk_m_per_sqrt_s": {"air_data": 9.0, "ins": 2.0},
    "reference_gain": {"air_data": 0.1, "ins": 0.02},
    "max_speed_bias_mps": {"air_data": 15.0, "ins": 6.0},
    "max_heading_bias_deg": {"air_data": 15.0, "ins": 3.0},
    "reference_frame": {"air_data": "ne", "ins": "ne"},
    "aiding_bias_walk_mps_per_sqrt_s": {"air_data": 0.05, "ins": 0.03},
}
REFERENCE_FRAMES = ("speed_track", "ne")
LOOP_ORDERS = ("speed_first", "heading_first")
BIAS_MITIGATIONS = ("ncs", "els", "none")
DISCRIMINATOR_NAMES = ("thesis", "v_fit")


def _finite(name: str, value, lo: float | None = None, hi: float | None = None, strict_lo: bool = False):
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float, np.integer, np.floating))
        or not math.isfinite(float(value))
    ):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    v = float(value)
    if lo is not None and (v <= lo if strict_lo else v < lo):
        raise ValueError(f"{name} must be {'>' if strict_lo else '>='} {lo:g}, got {value!r}")
    if hi is not None and v > hi:
        raise ValueError(f"{name} must be <= {hi:g}, got {value!r}")
    return v


def _spacing_set(name: str, value) -> tuple[float, ...]:
    try:
        vals = tuple(float(x) for x in value)
    except TypeError as exc:
        raise ValueError(f"{name} must be a list of positive spacings, got {value!r}") from exc
    if not vals:
        raise ValueError(f"{name} must not be empty")
    for x in vals:
        if not (math.isfinite(x) and x > 0):
            raise ValueError(f"{name} must hold finite spacings > 0, got {value!r}")
    return vals


@dataclass(frozen=True)
class AcqTrackConfig:
    """Settings (units in the names). See the module docstring for the choices of spec section 8."""

    transect_samples: int = 25  # N (thesis: 25, also 50; useful 15-40)
    sample_period_s: float = 1.0  # t between transect samples
    correlation: str = "mad"  # "mad" | "pearson" | "msd"
    remove_bias: bool = True  # MAD of the mean-removed difference (baro / map vertical bias)
    interpolation: str = "bilinear"  # "bilinear" | "bicubic" map heights at replica samples
    replica_model: str = "plumb"  # "plumb" | "footprint": the map as the pulse altimeter sees it
    min_valid_fraction: float = 0.6  # of the N samples needed to correlate
    aiding: bool = True  # chapter 4's aided loops (False: constant speed and heading)
    aiding_source: str = "air_data"  # "air_data" (TAS + compass) | "ins" (strapdown INS velocity)
    reference_gain: float | None = None  # aided: fraction of each epoch's loop correction taken into b
    reference_frame: str | None = None  # aided: "speed_track" (b_v, b_psi) | "ne" (a north/east bias)
    aiding_bias_walk_mps_per_sqrt_s: float | None = None  # "ne": the velocity bias' walk (None: by source)
    aiding_interval_mean: bool = True  # air data: the air vector's mean over each sample interval
    air_vector_sideslip: bool = True  # air data: the air vector points along heading + sideslip
    wind_estimation: bool = True  # wind triangle, predicted through heading changes
    wind_gain: float = 0.01  # per tracked sample, low-pass of the wind estimate (GNSS: 0.2)
    loop_order: str = "speed_first"
    speed_spacings_mps: tuple = (0.48, 0.96, 1.44, 1.92, 2.4)
    speed_threshold_mps: float = 0.005
    speed_narrow_spacing_mps: float = 0.24
    speed_narrow_threshold_mps: float = 0.002
    heading_spacings_deg: tuple = (1.0, 2.0, 3.0, 4.0, 5.0)
    heading_threshold_deg: float = 0.03
    heading_narrow_spacing_deg: float = 0.5
    heading_narrow_threshold_deg: float = 0.003
    break_iteration: int = 101
    position_loops: bool = True  # start-point loops along / across the track (ours; tracking.py)
    position_spacings_cells: tuple = (0.25, 0.5, 0.75, 1.0, 1.25)  # 1st stage, x the map resolution
    position_threshold_m: float = 0.5
    position_narrow_spacing_cells: float = 0.125  # 2nd stage (bias_mitigation "ncs")
    position_narrow_threshold_m: float = 0.2
    discriminator: str = "thesis"  # "thesis": s (E - L) / (E + L); "v_fit": floor removed (tracking.py)
    bias_mitigation: str = "ncs"  # "ncs": fixed narrow 2nd stage; "els": + ELS; "none": 1st stage only
    scf_offset_cells: float = 2.0  # f: the SCF/HCF reach f R_db at the transect's far end
    scf_points: int = 10  # correlation-function points on each side of the prompt
    symmetry_ratio_max: float = 2.0
    acquisition_speed_half_mps: float = 10.0
    acquisition_speed_bin_mps: float = 1.0
    acquisition_heading_half_deg: float = 10.0
    acquisition_heading_bin_deg: float = 1.0
    acquisition_position_half_m: float = 500.0
    acquisition_position_bin_m: float = 50.0
    acquisition_distinct_ratio: float = 0.9
    acquisition_exclusion_m: float = 200.0
    acquire_above_sigma_m: float = 100.0  # transect start sigma above which tracking needs an acquisition
    snr_min_db: float = 5.0
    map_sigma_m: float = 5.0  # map height error (1 sigma) in the a-priori noise
    ra_noise_const_m: float = 0.6  # radar-altimeter noise model (1 sigma = const + fraction * R)
    ra_noise_fraction: float = 0.02
    false_lock_sigma_factor: float = 3.0  # residual sigma above this times the a-priori sigma: false lock
    max_speed_bias_mps: float | None = None  # aided: |b_v| beyond is a false lock (None: by source)
    max_heading_bias_deg: float | None = None
    lost_after_epochs: int = 5  # consecutive out-of-lock epochs before "lost" (re-acquire)
    output_average_length: int | None = None
    output_average_speed_tol_mps: float = 0.5
    output_average_heading_tol_deg: float = 0.5
    roll_compensation: bool = True
    beamwidth_deg: float = 17.0
    aiding_speed_sigma_mps: float | None = None  # dead reckoning on the aiding alone (None: by source)
    aiding_heading_sigma_deg: float | None = None
    unaided_speed_sigma_mps: float = 5.0
    unaided_heading_sigma_deg: float = 5.0
    gnss_sigma_m: float = 3.0
    position_sigma_floor_m: float | None = None  # None: half the map's post spacing
    fix_sigma_scale: float = 1.25  # calibration of the centroid fix's sigma (navigator.py; NIS check)
    fix_gate_nis: float = 13.8  # a fix with NIS (2 dof) above this is rejected as a false lock (p = 0.001)
    fix_overlap: float | None = None  # epochs sharing one fix's information (None: N / 2)
    aiding_walk_m_per_sqrt_s: float | None = None  # dead-reckoning random walk (None: by source)
    baro_geopotential: bool = True
    baro_bias_sigma_m: float = 10.0
    integrity_window: int = 3  # in-lock epochs in the innovation test's window (InnovationMonitor)
    integrity_alpha: float = 0.01  # probability outside its chi-square band

    def __post_init__(self):
        src = self.aiding_source if self.aiding_source in AIDING_SOURCES else "air_data"
        for name, by_source in SOURCE_DEFAULTS.items():
            if getattr(self, name) is None:
                object.__setattr__(self, name, by_source[src])
        n = self.transect_samples
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 5 <= int(n) <= 500:
            raise ValueError(f"transect_samples must be a whole number in [5, 500], got {n!r}")
        _finite("sample_period_s", self.sample_period_s, 0.0, strict_lo=True)
        for name, options in (
            ("correlation", tuple(COSTS)),
            ("interpolation", tuple(INTERPOLATIONS)),
            ("aiding_source", AIDING_SOURCES),
            ("loop_order", LOOP_ORDERS),
            ("bias_mitigation", BIAS_MITIGATIONS),
            ("discriminator", DISCRIMINATOR_NAMES),
            ("replica_model", ("plumb", "footprint", "return")),
            ("reference_frame", REFERENCE_FRAMES),
        ):
            if getattr(self, name) not in options:
                raise ValueError(f"{name} must be one of {list(options)}, got {getattr(self, name)!r}")
        for name in (
            "remove_bias",
            "aiding",
            "wind_estimation",
            "roll_compensation",
            "baro_geopotential",
            "aiding_interval_mean",
            "air_vector_sideslip",
            "position_loops",
        ):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ValueError(f"{name} must be true or false, got {getattr(self, name)!r}")
        _finite("min_valid_fraction", self.min_valid_fraction, 0.0, 1.0, strict_lo=True)
        _finite("wind_gain", self.wind_gain, 0.0, 1.0)
        _finite("reference_gain", self.reference_gain, 0.0, 1.0, strict_lo=True)
        object.__setattr__(
            self,
            "position_spacings_cells",
            _spacing_set("position_spacings_cells", self.position_spacings_cells),
        )
        object.__setattr__(
            self, "speed_spacings_mps", _spacing_set("speed_spacings_mps", self.speed_spacings_mps)
        )
        object.__setattr__(
            self, "heading_spacings_deg", _spacing_set("heading_spacings_deg", self.heading_spacings_deg)
        )
        for name in (
            "speed_threshold_mps",
            "speed_narrow_spacing_mps",
            "speed_narrow_threshold_mps",
            "heading_threshold_deg",
            "heading_narrow_spacing_deg",
            "heading_narrow_threshold_deg",
            "position_threshold_m",
            "position_narrow_spacing_cells",
            "position_narrow_threshold_m",
            "scf_offset_cells",
            "symmetry_ratio_max",
            "acquisition_speed_bin_mps",
            "acquisition_heading_bin_deg",
            "acquisition_position_bin_m",
            "acquisition_distinct_ratio",
            "beamwidth_deg",
            "false_lock_sigma_factor",
            "max_speed_bias_mps",
            "max_heading_bias_deg",
            "output_average_speed_tol_mps",
            "output_average_heading_tol_deg",
            "gnss_sigma_m",
            "aiding_speed_sigma_mps",
            "aiding_heading_sigma_deg",
            "unaided_speed_sigma_mps",
            "unaided_heading_sigma_deg",
            "fix_sigma_scale",
            "fix_gate_nis",
        ):
            _finite(name, getattr(self, name), 0.0, strict_lo=True)
        for name, bin_name in (
            ("acquisition_speed_half_mps", "acquisition_speed_bin_mps"),
            ("acquisition_heading_half_deg", "acquisition_heading_bin_deg"),
            ("acquisition_position_half_m", "acquisition_position_bin_m"),
        ):
            half = _finite(name, getattr(self, name), 0.0, strict_lo=True)
            if getattr(self, bin_name) > 2.0 * half:
                raise ValueError(
                    f"{name}: the interval +-{half:g} is empty at {bin_name} = "
                    f"{getattr(self, bin_name):g} (fewer than two bins)"
                )
        for name in (
            "acquisition_exclusion_m",
            "acquire_above_sigma_m",
            "map_sigma_m",
            "ra_noise_const_m",
            "ra_noise_fraction",
            "baro_bias_sigma_m",
        ):
            _finite(name, getattr(self, name), 0.0)
        _finite("snr_min_db", self.snr_min_db)
        if self.symmetry_ratio_max < 1.0:
            raise ValueError(
                f"symmetry_ratio_max must be >= 1 (a ratio of slopes), got {self.symmetry_ratio_max!r}"
            )
        if self.beamwidth_deg >= 90.0:
            raise ValueError(f"beamwidth_deg must lie in (0, 90) deg, got {self.beamwidth_deg!r}")
        for name, lo in (("break_iteration", 2), ("scf_points", 2), ("lost_after_epochs", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or int(v) < lo:
                raise ValueError(f"{name} must be a whole number >= {lo}, got {v!r}")
        L = self.output_average_length
        if L is not None and (isinstance(L, bool) or not isinstance(L, (int, np.integer)) or int(L) < 1):
            raise ValueError(f"output_average_length must be a whole number >= 1 or null, got {L!r}")
        if self.fix_overlap is not None:
            _finite("fix_overlap", self.fix_overlap, 1.0)
        _finite("aiding_walk_m_per_sqrt_s", self.aiding_walk_m_per_sqrt_s, 0.0)
        _finite("aiding_bias_walk_mps_per_sqrt_s", self.aiding_bias_walk_mps_per_sqrt_s, 0.0)
        if self.position_sigma_floor_m is not None:
            _finite("position_sigma_floor_m", self.position_sigma_floor_m, 0.0, strict_lo=True)

    @property
    def average_length(self) -> int:
        """Moving-average length: output_average_length, or ceil(N / 2) (the thesis' minimum)."""
        if self.output_average_length is not None:
            return int(self.output_average_length)
        return int(math.ceil(self.transect_samples / 2))

    @property
    def transect_duration_s(self) -> float:
        return (self.transect_samples - 1) * self.sample_period_s

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))
