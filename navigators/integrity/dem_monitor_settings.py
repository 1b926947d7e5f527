"""DemMonitorConfig: the settings of the terrain-database integrity monitor of seed 003 (`dem_integrity`).

Defaults are the paper's (N = 50 consecutive disparities, threshold 96, DTED-1's 18.9 m disparity sigma);
the sensor figures (radar-altimeter noise and lever arm, beam, GNSS vertical sigma) are filled from a
scenario's sensors by trn_env's build. See navigators.integrity.dem_monitor for the statistic.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..core.capabilities import Capabilities
from ..core.settings import Settings, setting

DEFAULT_N = 50            # seed 003 section III: N = 50 consecutive measurements
DEFAULT_THRESHOLD = 96.0  # seed 003 section III: "the statistic threshold is found to be 96"
VARIANTS = ("plain", "kalman", "kalman_innovation")
CORRELATION_CODES = {"exponential": 0, "gaussian": 1}   # correlated_disparity.whitened_statistic's func codes


@dataclass(frozen=True)
class DemMonitorConfig(Settings):
    """Settings of the DEM integrity monitor (SI). Give at most one of `threshold` and
    `false_alarm_probability` (neither: the paper's 96); `sigma_m` overrides the class's sigma."""

    n_window: int = setting(DEFAULT_N, "N consecutive disparities in the statistic (seed 003)", ge=2,
                            le=100_000)
    threshold: float | None = setting(None, "alarm threshold of the statistic (None: the paper's 96 or from "
                                            "false_alarm_probability)", gt=0.0)
    false_alarm_probability: float | None = setting(None, "false-alarm probability the threshold is set for",
                                                    "1", gt=0.0, lt=1.0)
    map_class: str = setting("dted1", "map error class whose disparity sigma the statistic assumes")
    sigma_m: float | None = setting(None, "disparity sigma overriding the class's", "m", gt=0.0)
    variant: str = setting("plain", "statistic: 'plain' (eq 4), 'kalman' (eq 5 on the filter's estimate) or "
                                    "'kalman_innovation' (eq 5 on its innovations)", choices=VARIANTS)
    sample_period_s: float = setting(1.0, "one radar-altimeter sample per period", "s", gt=0.0)
    lever_arm_m: float = setting(0.0, "eq 1's l_ar: GNSS antenna above the radar altimeter", "m")
    radar_altimeter_noise_const_m: float = setting(0.0, "radar-altimeter noise, constant part", "m", ge=0.0)
    radar_altimeter_noise_fraction: float = setting(0.0, "radar-altimeter noise, fraction of range", "1",
                                                    ge=0.0)
    gnss_vertical_sigma_m: float = setting(0.0, "GNSS vertical sigma", "m", ge=0.0)
    gnss_max_age_s: float = setting(1.0, "oldest GNSS fix used for a sample's position", "s", gt=0.0)
    kf_process_ratio: float = setting(0.01, "eq 5 filter: random-walk variance per epoch / sigma^2", "1",
                                      gt=0.0)
    beam_half_angle_deg: float = setting(0.0, "> 0: compare with the map's own return in this cone", "deg",
                                         ge=0.0, lt=90.0)
    max_range_m: float = setting(5000.0, "radar altimeter maximum range", "m", gt=0.0)
    correlation_length_m: float = setting(0.0, "the map error's correlation length (0: white, seed 003's "
                                               "eq 4 as is)", "m", ge=0.0)
    correlation_function: str = setting("exponential", "the map error's correlation function "
                                                       "(terrain.map_error.correlation)",
                                        choices=tuple(CORRELATION_CODES))
    map_bias_fraction: float = setting(0.0, "share of the map variance common to the whole window", "1",
                                       ge=0.0, le=1.0)
    navigator_error_time_constant_s: float = setting(
        0.0, "GNSS denied: the navigator's horizontal position error as first-order Gauss-Markov in time "
             "with this time constant, correlated between a window's epochs (0: constant over the window)",
        "s", ge=0.0)
    navigator_height_time_constant_s: float = setting(
        0.0, "GNSS denied: the same for the navigator's height error (0: constant over the window)", "s",
        ge=0.0)
    bias_glrt_false_alarm_probability: float = setting(
        0.0, "> 0: also alarm on the whitened bias GLRT (1' Sigma^-1 p)^2 / (1' Sigma^-1 1), chi2(1), at "
             "this false-alarm probability per test (0: off)", "1", ge=0.0, lt=1.0)

    def check(self) -> list[tuple[str, str]]:
        from .dem_monitor_thresholds import class_sigma_m
        problems = []
        if self.threshold is not None and self.false_alarm_probability is not None:
            problems.append(("false_alarm_probability", "give at most one of threshold and "
                                                        "false_alarm_probability"))
        try:
            class_sigma_m(self.map_class)
        except ValueError as exc:
            problems.append(("map_class", str(exc).split(": ", 1)[-1]))
        return problems

    @property
    def map_sigma_m(self) -> float:
        from .dem_monitor_thresholds import class_sigma_m
        return float(self.sigma_m) if self.sigma_m is not None else class_sigma_m(self.map_class)

    @property
    def effective_threshold(self) -> float:
        from .dem_monitor_thresholds import chi2_threshold, kalman_threshold
        if self.threshold is not None:
            return float(self.threshold)
        if self.false_alarm_probability is None:
            return DEFAULT_THRESHOLD
        if self.variant != "plain":
            reading = "rw_posterior" if self.variant == "kalman" else "innovation"
            return kalman_threshold(self.false_alarm_probability, int(self.n_window), self.kf_process_ratio,
                                    reading)
        return chi2_threshold(self.false_alarm_probability, int(self.n_window))


CAPABILITIES = Capabilities(
    settings=DemMonitorConfig, needs_map=True,
    required_sensors=(("radar_altimeter", "seed 003 eq 1 synthesises the terrain height from it"),),
    optional_sensors=("gnss",))
