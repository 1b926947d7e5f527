"""RbpfSettings: every setting of seed 002's IRA-aided Rao-Blackwellized particle filter (`rbpf`).

Defaults are seed 002 Table 1 (1,000 particles, sigma_R 3.5 m, sigma_theta 0.1 deg, the initial and
process-noise sigmas) with the departures the rbpf module docstring explains (vertical-velocity and
horizontal-position process noise, the acquisition cloud, the look-angle gates). The map-dependent checks
(terrain_detail_spacing_m finer than the map's posts) stay in the filter, which holds the map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.capabilities import Capabilities, SensorNeeds
from ..core.settings import Settings, setting
from .terrain_filter_settings import MAP_CORRELATION

MAX_PARTICLES = 200_000       # 12 x 12 covariance per particle: 230 MB at this count
INV_SQRT2 = 0.7071067811865476


@dataclass(frozen=True)
class RbpfSettings(Settings):
    """Settings of navigators.filters.rbpf.RaoBlackwellizedPF (SI, 1 sigma; see its module docstring)."""

    n_particles: int = setting(1000, "particles after acquisition (seed 002 Table 1)", ge=2, le=MAX_PARTICLES)
    acquisition_particles: int = setting(
        5000, "particles until the cloud's spread falls below acquisition_spread_m (0: off)", ge=0,
        le=MAX_PARTICLES)
    ess_threshold: float = setting(0.5, "resample when the effective sample size falls below this x N", "1",
                                   gt=0.0, le=1.0)
    trn_rate_hz: float = setting(1.0, "IRA measurement updates per second (Table 1)", "Hz", gt=0.0)
    error_model_rate_hz: float = setting(50.0, "steps of the 15-state error model per second", "Hz", gt=0.0)
    range_sigma_m: float = setting(3.5, "IRA range noise sigma_R (Table 1)", "m", gt=0.0)
    look_angle_sigma_deg: float = setting(0.1, "IRA look-angle noise sigma_theta (Table 1)", "deg", gt=0.0)
    look_angle: bool = setting(True, "update on the IRA's look angle as well as its range (seed 002); false: "
                               "the range alone")
    half_window_deg: float = setting(45.0, "half of the IRA's look window (as the sensor's)", "deg", gt=0.0,
                                     lt=90.0)
    window_edge_margin_deg: float = setting(
        1.0, "a look angle this close to the window's edge is not an interior minimum", "deg", ge=0.0)
    window_edge_range: bool = setting(True, "a window-edge sample updates on its range (False: skipped)")
    theta_velocity_rows: bool = setting(True, "add the look angle's sensitivity to velocity (differences)")
    ambiguity_gap_m: float = setting(3.0, "range gap under which a second basin makes the update range-only",
                                     "m", ge=0.0)
    ambiguity_weight: float = setting(0.5, "cloud weight holding such a second basin for range-only", "1",
                                      ge=0.0, le=1.0)
    ambiguity_probability: float = setting(
        0.05, "probability of a map-made basin jump above which the update is range-only", "1", ge=0.0,
        le=1.0)
    prior_from_initial: bool = setting(True, "take the prior from the initial estimate's covariance")
    theta_linearity_sigmas: float = setting(
        3.0, "range-only when theta departs from its velocity row by this many sigmas (0: off)", ge=0.0)
    theta_collapse_ess: float = setting(
        0.01, "range-only when theta would leave fewer effective particles than this fraction (0: off)",
        "1", ge=0.0, lt=1.0)
    theta_gate_sigmas: float = setting(
        3.0, "range-only when theta's innovation exceeds this many predictive sigmas (0: off)", ge=0.0)
    max_range_m: float = setting(10000.0, "IRA maximum range (as the sensor's)", "m", gt=0.0)
    search_step_m: float | str = setting("auto", "coarse-scan step along the zero-Doppler line (eq 23)", "m",
                                         gt=0.0, also=("auto",))
    init_pos_sigma_m: tuple[float, ...] = setting((50.0, 50.0, 20.0), "initial position sigma (N, E, up)",
                                                  "m", gt=0.0, length=3)
    init_vel_sigma_mps: tuple[float, ...] = setting(
        (INV_SQRT2, INV_SQRT2, 0.5), "initial velocity sigma (NED)", "m/s", ge=0.0, length=3)
    init_att_sigma_deg: tuple[float, ...] = setting((0.1, 0.1, 0.1), "initial attitude sigma", "deg", ge=0.0,
                                                    length=3)
    accel_bias_sigma_mps2: float = setting(1e-4, "accelerometer bias prior per axis (a scenario: its IMU's)",
                                           "m/s^2", ge=0.0)
    gyro_bias_sigma_rps: float = setting(1e-6, "gyro bias prior per axis (a scenario: its IMU's)", "rad/s",
                                         ge=0.0)
    q_pos_m: tuple[float, ...] = setting((0.25, 0.25, 0.5), "position process noise per epoch (N, E, up)",
                                         "m", gt=0.0, length=3)
    q_vel_mps: tuple[float, ...] = setting((1e-4, 1e-2), "velocity process noise per epoch (horizontal, "
                                           "vertical)", "m/s", ge=0.0, length=2)
    q_att_rad: float = setting(1e-6, "attitude process noise per epoch", "rad", ge=0.0)
    q_accel_bias_mps2: float = setting(1e-7, "accelerometer-bias process noise per epoch (a scenario: its "
                                       "IMU's instability)", "m/s^2", ge=0.0)
    q_gyro_bias_rps: float = setting(1e-7, "gyro-bias process noise per epoch (a scenario: its IMU's "
                                     "instability)", "rad/s", ge=0.0)
    gnss_pos_sigma_m: tuple[float, ...] = setting((1.0, 2.0), "GNSS position noise (horizontal, vertical)",
                                                  "m", gt=0.0, length=2)
    gnss_pos_bias_sigma_m: tuple[float, ...] = setting(
        (1.5, 3.0), "GNSS drift floor on the fused position (horizontal, vertical)", "m", ge=0.0, length=2)
    gnss_vel_sigma_mps: float = setting(0.1, "GNSS velocity noise per axis", "m/s", gt=0.0)
    imu_samples: str = setting("interval", "IMU samples are interval means or instant values",
                               choices=("interval", "instant"))
    gravity_gradient: bool = setting(True, "gravity's gradient in the error model")
    acquisition_spread_m: float = setting(10.0, "horizontal spread below which the cloud is converged", "m",
                                          ge=0.0)
    map_sigma_m: float = setting(0.0, "map's random vertical error (a scenario: its map error model)", "m",
                                 ge=0.0)
    map_bias_sigma_m: float = setting(0.0, "map's vertical bias (a scenario: its map error model)", "m",
                                      ge=0.0)
    map_correlation_length_m: float = setting(
        0.0, "correlation length of the map's random vertical error along the ground: without GNSS the "
        "cloud's height carries it as a walk, and the published height its error (a scenario: its map error "
        "model); 0: white per sample", "m", ge=0.0)
    map_correlation_function: str = setting("exponential", "the map error's correlation function (a "
                                            "scenario: its map error model)", choices=MAP_CORRELATION)
    terrain_model_sigma_m: float | str = setting(
        "auto", "terrain a coarse map cannot hold between posts (auto: from the map's spectrum)", "m",
        ge=0.0, also=("auto",))
    map_noise_model: str = setting("calibrated", "map-noise variances of the IRA measurement (calibrated: "
                                   "on the map, at the flight's height)",
                                   choices=("calibrated", "flat_ground"))
    terrain_detail_spacing_m: float | str = setting(
        "auto", "finest terrain the map-noise calibration assumes (auto: post spacing / 3; below the "
        "map's posts)", "m", ge=5.0, also=("auto",))
    integrity_window: int = setting(3, "IRA updates in the innovation test's window", ge=1)
    integrity_alpha: float = setting(1e-4, "probability outside the innovation test's chi-square band", "1",
                                     gt=0.0, lt=1.0)
    recovery_sigma_m: float = setting(100.0, "horizontal re-spread of a recovery", "m", ge=0.0)
    recovery_reset_kalman: bool = setting(True, "a recovery also resets the Kalman parts' covariance")
    turn_angle: str = setting("excursion", "angle the turn terms' attitude walk runs in: integral of |yaw "
                              "rate| (total) or growth of the net heading change since the reset (excursion)",
                              choices=("total", "excursion"))
    regularisation: str = setting("shrunk", "after resampling, move the copies by a Gaussian kernel of the "
                                  "cloud's covariance at the optimal bandwidth (gaussian; shrunk: drawn "
                                  "towards the mean first, the cloud's covariance kept) or not (none)",
                                  choices=("none", "gaussian", "shrunk"))
    tempering: str = setting("spread", "when the IRA variances are inflated by (spread / "
                             "acquisition_spread_m)^2: while the cloud acquires (acquisition: before the "
                             "hand-over, or re-acquiring after a recovery), whenever its spread exceeds "
                             "acquisition_spread_m (spread), or never (none)",
                             choices=("acquisition", "spread", "none"))
    progressive_correction: bool = setting(False, "apply each IRA update in stages that keep the effective "
                                           "sample size above ess_threshold, resampled between them")
    map_error_in_height: bool = setting(False, "once GNSS no longer pins the height, carry the map's bias "
                                        "and correlated vertical error in the cloud's height instead of as "
                                        "IRA noise")

    def check(self) -> list[tuple[str, str]]:
        problems = []
        na = self.acquisition_particles
        if not (na == 0 or self.n_particles <= na):
            problems.append(("acquisition_particles",
                             f"must be 0 (off) or in [n_particles, {MAX_PARTICLES}], got {na}"))
        if not self.window_edge_margin_deg < self.half_window_deg:
            problems.append(("window_edge_margin_deg", "must lie in [0, half_window_deg), got "
                                                       f"{self.window_edge_margin_deg!r}"))
        return problems

    def sensor_needs(self) -> SensorNeeds:
        return SensorNeeds({"imu": "the INS it corrects", "ira": "its measurement (seed 002: IRA range and "
                                                                   "look angle)"}, ("gnss",))


CAPABILITIES = Capabilities(settings=RbpfSettings, needs_map=True, takes_rng=True, uses_imu_spec=True,
                            imu_bias_settings=True,
                            uses_map_noise=True, models_map_detail=True,
                            # GM fits to its GNSS-denied error (scripts/navigator_error_time_constants.py,
                            # docs/validation/integrity_error_time_constants.json)
                            error_time_constant_s=640.0, height_time_constant_s=190.0,
                            # protection level validated on navigation/dted1 (docs/validation/integrity.md
                            # 6.8, with the map noise calibrated at the flight's height); with
                            # look_angle=false on navigation/as_published (6.8,
                            # docs/validation/integrity_pl_campaign_rbpf_range.json)
                            pl_validated=("navigation/dted1",),
                            pl_variants=(((("look_angle", False),), ("navigation/as_published",)),))


def table1_covariance() -> np.ndarray:
    """Seed 002 Table 1's initial distribution as a 9 x 9 covariance (NED position m, velocity m/s, attitude
    rad; diagonal): position (50, 50, 20) m, velocity (1/sqrt 2, 1/sqrt 2, 0.5) m/s, attitude 0.1 deg - the
    RBPF's init_* defaults, for an Estimate that states them (prior_from_initial)."""
    return np.diag(np.r_[50.0, 50.0, 20.0, 1 / math.sqrt(2), 1 / math.sqrt(2), 0.5,
                         np.radians([0.1, 0.1, 0.1])] ** 2)
