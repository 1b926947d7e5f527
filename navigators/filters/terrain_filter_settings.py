"""Settings of the INS-ridden terrain filters: the point-mass filter (`pmf`) and the particle filter (`pf`).

`TerrainFilterSettings` holds what both share (terrain_filter.InsRiddenFilter: sensors' noise, the map's
error, the vertical channel, GNSS, integrity); `PmfSettings` and `PfSettings` add each filter's belief. The
meaning of each default is in terrain_filter.InsRiddenFilter's, pmf's and pf's docstrings; the measurements
behind them in docs/validation/navigators.md ("Terrain filters: measured grounds of the defaults").
"""

from __future__ import annotations

from dataclasses import dataclass

from ..core.capabilities import Capabilities, SensorNeeds
from ..core.settings import Settings, setting

G0 = 9.80665
AIDING = ("ira", "radar_altimeter", "both")
MAP_INTERPOLATION = ("bicubic", "bilinear")
MAP_CORRELATION = ("exponential", "gaussian")
IRA_FORMULAS = ("conventional", "proposed")
GRAVITY_MODEL_NAMES = ("somigliana", "j2")
BYTES_PER_CELL = 8 * 16     # pmf: float64 arrays held or made per cell in an update
BYTES_PER_PARTICLE = 8 * 30  # pf: float64 arrays per particle


@dataclass(frozen=True)
class TerrainFilterSettings(Settings):
    """Settings shared by the PMF and the PF (SI, 1 sigma)."""

    aiding: str = setting("ira", "terrain sensor(s) the filter updates on", choices=AIDING)
    measurement_rate_hz: float = setting(1.0, "terrain samples used per second", "Hz", gt=0.0)
    ira_formula: str = setting("proposed", "IRA closest-point formula (seed 000)", choices=IRA_FORMULAS)
    ira_range_sigma_m: float = setting(3.5, "IRA range noise (seed 002 Table 1)", "m", ge=0.0)
    ira_look_angle_sigma_deg: float = setting(0.1, "IRA look-angle noise (seed 002 Table 1)", "deg", ge=0.0)
    ra_sigma_m: float = setting(2.0, "radar-altimeter noise", "m", ge=0.0)
    ra_half_beam_deg: float = setting(10.0, "radar-altimeter half beamwidth", "deg", gt=0.0, lt=60.0)
    ra_cone_rings: int = setting(2, "rings of the radar altimeter's cone model (0: the axis ray only)",
                                 ge=0, le=16)
    map_sigma_m: float = setting(0.0, "map's random vertical error (a scenario: its map error model)", "m",
                                 ge=0.0)
    map_bias_sigma_m: float = setting(0.0, "map's vertical bias (a scenario: its map error model)", "m",
                                      ge=0.0)
    map_correlation_length_m: float = setting(
        0.0, "correlation length of the map's random vertical error along the ground (a scenario: its map "
        "error model); 0: white per sample", "m", ge=0.0)
    map_correlation_function: str = setting("exponential", "the map error's correlation function (a "
                                            "scenario: its map error model)", choices=MAP_CORRELATION)
    terrain_model_sigma_m: float = setting(2.5, "terrain between the map's posts (white)", "m", ge=0.0)
    map_interpolation: str = setting("bicubic", "how the update reads the map between its posts",
                                     choices=MAP_INTERPOLATION)
    outlier_prob: float = setting(0.02, "weight of the likelihood's heavy tail", "1", ge=0.0, lt=1.0)
    outlier_width_m: float = setting(500.0, "width of the heavy tail's uniform density", "m", gt=0.0)
    gnss_sigma_m: float = setting(2.0, "GNSS horizontal position noise per axis", "m", gt=0.0)
    gnss_drift_sigma_m: float = setting(0.0, "GNSS horizontal error common to successive fixes (receiver "
                                        "drift) per axis: no run of fixes narrows the belief below it", "m",
                                        ge=0.0)
    gnss_vertical_sigma_m: float = setting(4.0, "GNSS vertical position noise", "m", gt=0.0)
    gnss_velocity_sigma_mps: float = setting(0.05, "GNSS velocity noise per axis", "m/s", gt=0.0)
    baro_bias_sigma_m: float = setting(10.0, "prior of the barometric height's bias", "m", ge=0.0)
    vertical_noise_m_per_sqrt_s: float = setting(0.3, "random walk of the vertical offset", "m/sqrt(s)",
                                                 ge=0.0)
    converged_sigma_m: float = setting(50.0, "horizontal 1-sigma below which Health says 'ok'", "m", gt=0.0)
    accel_noise_mps2_rthz: float = setting(10e-6 * G0 * 10.0, "accelerometer noise density",
                                           "m/s^2/sqrt(Hz)", ge=0.0)
    gyro_noise_rps_rthz: float = setting(1e-6, "gyro noise density", "rad/s/sqrt(Hz)", ge=0.0)
    gravity_model: str = setting("j2", "INS gravity model", choices=GRAVITY_MODEL_NAMES)
    tau_baro_s: float = setting(30.0, "time constant of the baro-damped vertical channel", "s", gt=0.0)
    imu_samples: str = setting("interval", "IMU samples are interval means or instant values",
                               choices=("interval", "instant"))
    baro_geopotential: bool = setting(True, "convert the baro's geopotential height to geometric")
    baro_lag_s: float = setting(0.0, "the barometer's first-order lag, taken out of the height the INS's "
                                     "vertical channel follows (h = baro - lag x v_down; a scenario gives "
                                     "its sensors.baro.lag_tau_s)", "s", ge=0.0)
    integrity_window: int = setting(3, "terrain updates in the innovation test's window", ge=1)
    integrity_alpha: float = setting(1e-4, "probability outside the innovation test's chi-square band", "1",
                                     gt=0.0, lt=1.0)
    recovery_sigma_m: float = setting(100.0, "horizontal 1-sigma added by a recovery's re-spread", "m",
                                      ge=0.0)

    def sensor_needs(self) -> SensorNeeds:
        req = {"imu": "the INS the filter corrects"}
        if self.aiding in ("ira", "both"):
            req["ira"] = f"aiding = {self.aiding!r} updates on the IRA's range and look angle"
        if self.aiding in ("radar_altimeter", "both"):
            req["radar_altimeter"] = f"aiding = {self.aiding!r} updates on the radar altimeter's range"
        return SensorNeeds(req, ("baro", "gnss"))


@dataclass(frozen=True)
class PmfSettings(TerrainFilterSettings):
    """Settings of navigators.filters.pmf.PointMassFilter."""

    grid_size: int = setting(200, "cells per side of the point-mass grid", ge=3)
    spacing_min_m: float = setting(2.0, "smallest cell spacing", "m", gt=0.0)
    spacing_max_m: float = setting(100.0, "largest cell spacing", "m", gt=0.0)
    span_sigmas: float = setting(5.0, "grid half-span in posterior sigmas", gt=0.0)
    position_noise_m_per_sqrt_s: float = setting(0.1, "random walk of the horizontal position error",
                                                 "m/sqrt(s)", ge=0.0)
    velocity_noise_mps_per_sqrt_s: float = setting(0.001, "random walk of the velocity offset",
                                                   "m/s/sqrt(s)", ge=0.0)
    accel_bias_sigma_mps2: float = setting(50e-6 * G0, "accelerometer turn-on bias per body axis", "m/s^2",
                                           ge=0.0)
    max_memory_mb: float = setting(2048.0, "refuse a grid needing more memory than this", "MB", gt=0.0)

    def check(self) -> list[tuple[str, str]]:
        problems = []
        need_mb = float(self.grid_size) ** 2 * BYTES_PER_CELL / 2**20
        if need_mb > self.max_memory_mb:
            problems.append(("grid_size", f"{self.grid_size} needs about {need_mb:.0f} MB, more than "
                                          f"max_memory_mb {self.max_memory_mb:g}"))
        if self.spacing_max_m < self.spacing_min_m:
            problems.append(("spacing_max_m", f"({self.spacing_max_m:g}) must be >= spacing_min_m "
                                              f"({self.spacing_min_m:g})"))
        return problems


@dataclass(frozen=True)
class PfSettings(TerrainFilterSettings):
    """Settings of navigators.filters.pf.ParticleFilter."""

    n_particles: int = setting(10_000, "particles", ge=2)
    ess_threshold: float = setting(0.5, "resample when the effective sample size falls below this x N", "1",
                                   gt=0.0, le=1.0)
    roughening: float = setting(0.1, "roughening after a resample, in the cloud's spread", "1", ge=0.0)
    position_noise_m_per_sqrt_s: float = setting(0.1, "random walk of the horizontal position error",
                                                 "m/sqrt(s)", ge=0.0)
    velocity_noise_mps_per_sqrt_s: float = setting(0.02, "random walk of the velocity offset",
                                                   "m/s/sqrt(s)", ge=0.0)
    velocity_noise_model: str = setting("imu_spec", "'imu_spec': the IMU specification's acceleration error "
                                        "on the cloud's velocity, GNSS by an ensemble Kalman update; 'walk': "
                                        "the velocity's noise is the random walk (the specification's "
                                        "equivalent walk as a floor), GNSS by the particles' likelihoods",
                                        choices=("walk", "imu_spec"))
    heading_noise_rad_per_sqrt_s: float = setting(2e-5, "random walk of the heading error", "rad/sqrt(s)",
                                                  ge=0.0)
    acquisition_particles: int = setting(0, "particles from a reset until the cloud's horizontal spread "
                                            "falls below acquisition_spread_m, then resampled down to "
                                            "n_particles (0: off, n_particles throughout)", ge=0)
    acquisition_spread_m: float = setting(10.0, "horizontal spread (the root of the position covariance's "
                                                "trace) that ends the acquisition", "m", gt=0.0)
    max_memory_mb: float = setting(2048.0, "refuse a cloud needing more memory than this", "MB", gt=0.0)

    def check(self) -> list[tuple[str, str]]:
        problems = []
        if 0 < self.acquisition_particles < self.n_particles:
            problems.append(("acquisition_particles",
                             f"0 (off) or at least n_particles ({self.n_particles}), "
                             f"got {self.acquisition_particles}"))
        for name in ("n_particles", "acquisition_particles"):
            n = getattr(self, name)
            need_mb = float(n) * BYTES_PER_PARTICLE / 2**20
            if need_mb > self.max_memory_mb:
                problems.append((name, f"{n} needs about {need_mb:.0f} MB, more than "
                                       f"max_memory_mb {self.max_memory_mb:g}"))
        return problems


# error time constants: GM fits to the GNSS-denied error over the flights of docs/validation/integrity.md
# section 6.6 (scripts/navigator_error_time_constants.py, docs/validation/integrity_error_time_constants.json,
# two significant figures); pl_validated: the same section
PMF_CAPABILITIES = Capabilities(settings=PmfSettings, needs_map=True, uses_map_noise=True, uses_imu_spec=True,
                                error_time_constant_s=98.0, height_time_constant_s=41.0,
                                pl_validated=("navigation/as_published", "tactical/dted1"),
                                pl_settings=(("grid_size", 200),))
PF_CAPABILITIES = Capabilities(settings=PfSettings, needs_map=True, takes_rng=True, uses_map_noise=True,
                               uses_imu_spec=True, error_time_constant_s=73.0, height_time_constant_s=41.0,
                               pl_validated=("navigation/as_published", "tactical/dted1"),
                               pl_settings=(("n_particles", 10_000),))
