"""AcqTrackConfig: every setting of the acquisition-and-tracking TRN (navigators.core.settings fields).

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
from dataclasses import dataclass

from ..core.capabilities import Capabilities, SensorNeeds
from ..core.settings import Settings, setting
from .correlation import COSTS, INTERPOLATIONS

AIDING_SOURCES = ("air_data", "ins")
# Defaults that depend on aiding_source (a setting given as null / None takes these):
# - aiding_speed_sigma_mps / aiding_heading_sigma_deg: the aiding's error over a transect besides what the
#   references absorb - air data in JSBSim's light turbulence (the gusts move the ground vector by ~2 m/s per
#   axis, invisible to air data) 1.5 m/s / 1 deg; an IRS's (strapdown INS) velocity 0.3 m/s / 0.2 deg.
# - aiding_walk_m_per_sqrt_s: the dead reckoning's random walk on top (position variance per second): air
#   data 2 m/s x sqrt(2 x 10 s correlation) ~ 9; an INS 0: its position error is the integral of its velocity
#   error, which reference_frame "ne" carries as e_ne (the accelerometer noise's integral, N^2 T^3 / 3 per
#   sample, is below 1e-7 m^2 on every grade).
# - fix_sigma_scale / fix_overlap: the centroid fix's noise. R = scale^2 (pi/2) sigma_res^2 / I: pi/2 is the
#   MAD estimator's variance factor for Gaussian noise, and consecutive fixes share N - 1 of their N samples,
#   so a fix's error from the samples' white noise is a moving average whose autocorrelation 1 - |k|/N sums
#   to N: each epoch brings 1/N of a fix's information (fix_overlap N). INS: scale 1, overlap N (these
#   derived values); air data keeps the calibration on its own walks (scale 1.25, overlap N / 2: the
#   centroid fix's NIS averaged 2 on the built-in flight).
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
    "aiding_walk_m_per_sqrt_s": {"air_data": 9.0, "ins": 0.0},
    "fix_sigma_scale": {"air_data": 1.25, "ins": 1.0},
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
REPLICA_MODELS = ("plumb", "footprint", "return")


@dataclass(frozen=True)
class AcqTrackConfig(Settings):
    """Settings (units in the names). See the module docstring for the choices of spec section 8."""

    transect_samples: int = setting(25, "N (thesis: 25, also 50; useful 15-40)", ge=5, le=500)
    sample_period_s: float = setting(1.0, "t between transect samples", "s", gt=0.0)
    correlation: str = setting("mad", "'mad' | 'pearson' | 'msd'", choices=tuple(COSTS))
    remove_bias: bool = setting(True, "MAD of the mean-removed difference (baro / map vertical bias)")
    interpolation: str = setting("bilinear", "'bilinear' | 'bicubic' map heights at replica samples",
        choices=tuple(INTERPOLATIONS))
    replica_model: str = setting("plumb", "'plumb' | 'footprint': the map as the pulse altimeter sees it",
        choices=REPLICA_MODELS)
    min_valid_fraction: float = setting(0.6, "of the N samples needed to correlate", "1", gt=0.0, le=1.0)
    aiding: bool = setting(True, "chapter 4's aided loops (False: constant speed and heading)")
    aiding_source: str = setting("air_data", "'air_data' (TAS + compass) | 'ins' (strapdown INS velocity)",
        choices=AIDING_SOURCES)
    reference_gain: float | None = setting(
        None, "aided: fraction of each epoch's loop correction taken into b", "1", gt=0.0, le=1.0)
    reference_frame: str | None = setting(
        None, "aided: 'speed_track' (b_v, b_psi) | 'ne' (a north/east bias)", choices=REFERENCE_FRAMES)
    aiding_bias_walk_mps_per_sqrt_s: float | None = setting(
        None, "'ne': the velocity bias' walk (None: by source)", "m/s/sqrt(s)", ge=0.0)
    aiding_interval_mean: bool = setting(True, "air data: the air vector mean over each sample interval")
    air_vector_sideslip: bool = setting(True, "air data: the air vector points along heading + sideslip")
    wind_estimation: bool = setting(True, "wind triangle, predicted through heading changes")
    wind_gain: float = setting(0.01, "per tracked sample, low-pass of the wind estimate (GNSS: 0.2)",
        "1", ge=0.0, le=1.0)
    loop_order: str = setting("speed_first", "loop order: speed loops first or heading loops first",
        choices=LOOP_ORDERS)
    speed_spacings_mps: tuple[float, ...] = setting(
        (0.48, 0.96, 1.44, 1.92, 2.4), "1st-stage speed correlator spacings (adaptive)", "m/s", gt=0.0,
        min_length=1)
    speed_threshold_mps: float = setting(0.005, "1st-stage speed lock threshold on |eps|", "m/s", gt=0.0)
    speed_narrow_spacing_mps: float = setting(0.24, "2nd-stage (narrow) speed spacing", "m/s", gt=0.0)
    speed_narrow_threshold_mps: float = setting(0.002, "2nd-stage speed lock threshold", "m/s", gt=0.0)
    heading_spacings_deg: tuple[float, ...] = setting(
        (1.0, 2.0, 3.0, 4.0, 5.0), "1st-stage heading correlator spacings (adaptive)", "deg", gt=0.0,
        min_length=1)
    heading_threshold_deg: float = setting(0.03, "1st-stage heading lock threshold", "deg", gt=0.0)
    heading_narrow_spacing_deg: float = setting(0.5, "2nd-stage (narrow) heading spacing", "deg", gt=0.0)
    heading_narrow_threshold_deg: float = setting(0.003, "2nd-stage heading lock threshold", "deg", gt=0.0)
    break_iteration: int = setting(101, "loop iterations after which an epoch is flagged degraded", ge=2)
    position_loops: bool = setting(True, "start-point loops along / across the track (ours; tracking.py)")
    position_spacings_cells: tuple[float, ...] = setting(
        (0.25, 0.5, 0.75, 1.0, 1.25), "1st stage, x the map resolution", "cells", gt=0.0, min_length=1)
    position_threshold_m: float = setting(0.5, "1st-stage start-point lock threshold", "m", gt=0.0)
    position_narrow_spacing_cells: float = setting(0.125, "2nd stage (bias_mitigation 'ncs')",
        "cells", gt=0.0)
    position_narrow_threshold_m: float = setting(0.2, "2nd-stage start-point lock threshold", "m", gt=0.0)
    discriminator: str = setting(
        "thesis", "'thesis': s (E - L) / (E + L); 'v_fit': floor removed (tracking.py)",
        choices=DISCRIMINATOR_NAMES)
    bias_mitigation: str = setting(
        "ncs", "'ncs': fixed narrow 2nd stage; 'els': + ELS; 'none': 1st stage only",
        choices=BIAS_MITIGATIONS)
    scf_offset_cells: float = setting(2.0, "f: the SCF/HCF reach f R_db at the transect's far end",
        "cells", gt=0.0)
    scf_points: int = setting(10, "correlation-function points on each side of the prompt", ge=2)
    symmetry_ratio_max: float = setting(
        2.0, "symmetry-ratio threshold of the adaptivity block (spec section 8)", "1", ge=1.0)
    acquisition_speed_half_mps: float = setting(10.0, "acquisition grid half-span in speed", "m/s", gt=0.0)
    acquisition_speed_bin_mps: float = setting(1.0, "acquisition grid speed bin", "m/s", gt=0.0)
    acquisition_heading_half_deg: float = setting(10.0, "acquisition grid half-span in heading",
        "deg", gt=0.0)
    acquisition_heading_bin_deg: float = setting(1.0, "acquisition grid heading bin", "deg", gt=0.0)
    acquisition_position_half_m: float = setting(500.0, "acquisition grid half-span in position", "m", gt=0.0)
    acquisition_position_bin_m: float = setting(50.0, "acquisition grid position bin", "m", gt=0.0)
    acquisition_distinct_ratio: float = setting(
        0.9, "a minimum is distinct below this times the best cost farther than the exclusion", "1", gt=0.0)
    acquisition_exclusion_m: float = setting(
        200.0, "distance beyond which a competing acquisition minimum counts", "m", ge=0.0)
    acquire_above_sigma_m: float = setting(
        100.0, "transect start sigma above which tracking needs an acquisition", "m", ge=0.0)
    snr_min_db: float = setting(5.0, "correlation SNR below which the loop is out of lock", "dB")
    map_sigma_m: float = setting(5.0, "map height error (1 sigma) in the a-priori noise", "m", ge=0.0)
    ra_noise_const_m: float = setting(0.6, "radar-altimeter noise model (1 sigma = const + fraction * R)",
        "m", ge=0.0)
    ra_noise_fraction: float = setting(0.02, "radar-altimeter noise proportional to range", "1", ge=0.0)
    false_lock_sigma_factor: float = setting(
        3.0, "residual sigma above this times the a-priori sigma: false lock", gt=0.0)
    max_speed_bias_mps: float | None = setting(None, "aided: |b_v| beyond is a false lock (None: by source)",
        "m/s", gt=0.0)
    max_heading_bias_deg: float | None = setting(
        None, "aided: |b_psi| beyond is a false lock (None: by source)", "deg", gt=0.0)
    lost_after_epochs: int = setting(5, "consecutive out-of-lock epochs before 'lost' (re-acquire)", ge=1)
    output_average_length: int | None = setting(
        None, "moving-average length of the output (None: ceil(N / 2))", ge=1)
    output_average_speed_tol_mps: float = setting(0.5, "speed agreement under which the moving average runs",
        "m/s", gt=0.0)
    output_average_heading_tol_deg: float = setting(
        0.5, "heading agreement under which the moving average runs", "deg", gt=0.0)
    roll_compensation: bool = setting(True, "plumb height from the slant range through roll and pitch")
    beamwidth_deg: float = setting(17.0, "radar altimeter beamwidth", "deg", gt=0.0, lt=90.0)
    aiding_speed_sigma_mps: float | None = setting(
        None, "dead reckoning on the aiding alone (None: by source)", "m/s", gt=0.0)
    aiding_heading_sigma_deg: float | None = setting(
        None, "dead-reckoning heading error on the aiding alone (None: by source)", "deg", gt=0.0)
    unaided_speed_sigma_mps: float = setting(5.0, "speed error of the unaided loops", "m/s", gt=0.0)
    unaided_heading_sigma_deg: float = setting(5.0, "heading error of the unaided loops", "deg", gt=0.0)
    gnss_sigma_m: float = setting(3.0, "GNSS position noise per axis", "m", gt=0.0)
    position_sigma_floor_m: float | None = setting(None, "None: half the map's post spacing", "m", gt=0.0)
    fix_sigma_scale: float | None = setting(
        None, "the centroid fix's sigma over the MAD's (pi/2)^(1/2) sigma_res / I^(1/2) (None: by source)",
        gt=0.0)
    fix_gate_nis: float = setting(
        13.8, "a fix with NIS (2 dof) above this is rejected as a false lock (p = 0.001)", gt=0.0)
    fix_overlap: float | None = setting(
        None, "epochs sharing one fix's information (None: N with the INS as aiding, N / 2 with air data)",
        ge=1.0)
    aiding_walk_m_per_sqrt_s: float | None = setting(None, "dead-reckoning random walk (None: by source)",
        "m/sqrt(s)", ge=0.0)
    baro_geopotential: bool = setting(True, "convert the baro geopotential height to geometric")
    baro_bias_sigma_m: float = setting(10.0, "prior of the barometric height bias", "m", ge=0.0)
    integrity_window: int = setting(3, "in-lock epochs in the innovation test's window (InnovationMonitor)",
        ge=1)
    integrity_alpha: float = setting(0.01, "probability outside its chi-square band", "1", gt=0.0, lt=1.0)

    def resolve(self) -> None:
        for name, by_source in SOURCE_DEFAULTS.items():
            if getattr(self, name) is None:
                object.__setattr__(self, name, by_source[self.aiding_source])

    def check(self) -> list[tuple[str, str]]:
        problems = []
        for name, bin_name in (
            ("acquisition_speed_half_mps", "acquisition_speed_bin_mps"),
            ("acquisition_heading_half_deg", "acquisition_heading_bin_deg"),
            ("acquisition_position_half_m", "acquisition_position_bin_m"),
        ):
            half, width = getattr(self, name), getattr(self, bin_name)
            if width > 2.0 * half:
                problems.append((name, f"the interval +-{half:g} is empty at {bin_name} = {width:g} (fewer "
                                       "than two bins)"))
        return problems

    def sensor_needs(self) -> SensorNeeds:
        why = "the terrain profile is barometric height - radar-altimeter range"
        need = {"radar_altimeter": why, "baro": why}
        if self.aiding:
            if self.aiding_source == "air_data":
                need["air_data"] = "aiding = true with aiding_source = 'air_data' needs the true airspeed"
                need["heading"] = "aiding = true with aiding_source = 'air_data' needs the compass heading"
            else:
                need["imu"] = "aiding = true with aiding_source = 'ins' needs the IMU"
        return SensorNeeds(need, ("gnss",))

    @property
    def average_length(self) -> int:
        """Moving-average length: output_average_length, or ceil(N / 2) (the thesis' minimum)."""
        if self.output_average_length is not None:
            return int(self.output_average_length)
        return int(math.ceil(self.transect_samples / 2))

    @property
    def fix_overlap_epochs(self) -> float:
        """Epochs sharing one centroid fix's information: fix_overlap, or by source (SOURCE_DEFAULTS'
        comment): N with the INS as aiding, N / 2 with air data."""
        if self.fix_overlap is not None:
            return float(self.fix_overlap)
        return float(self.transect_samples) * (1.0 if self.aiding_source == "ins" else 0.5)

    @property
    def transect_duration_s(self) -> float:
        return (self.transect_samples - 1) * self.sample_period_s


def _warm_up(rate_hz: float) -> dict:
    """The warm-up flight's settings (three updates, GNSS in the first): a transect of 5 samples 0.1 update
    apart, full while GNSS places it, so the later updates track (the loops, the integrity checks and the
    centroid fix, whatever the short transect's SNR, V-shape or innovation); lock lost after 5 epochs
    with any sigma asks for an acquisition (the serial search)."""
    return {"transect_samples": 5, "sample_period_s": 0.1 / rate_hz, "snr_min_db": -1e3,
            "false_lock_sigma_factor": 1e3, "fix_gate_nis": 1e9, "acquire_above_sigma_m": 0.0}


# error time constants: GM fits to its GNSS-denied error (scripts/navigator_error_time_constants.py,
# docs/validation/integrity_error_time_constants.json); protection level validated on: docs/validation/
# integrity.md section 6.6
CAPABILITIES = Capabilities(settings=AcqTrackConfig, needs_map=True, uses_imu_spec=True,
                            warm_up_settings=_warm_up,
                            pl_validated=("navigation/as_published", "navigation/dted1"),
                            pl_settings=(("transect_samples", 25), ("replica_model", "return"),
                                         ("aiding_source", "ins")),
                            error_time_constant_s=73.0, height_time_constant_s=3000.0)
