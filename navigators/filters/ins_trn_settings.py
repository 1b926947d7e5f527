"""Settings of the INS + batch TERCOM + error-state Kalman filter (`ins_tercom`) and the free INS (`ins`).

Defaults are seed 000 Table 2 (fix period, search window and cell, fix noise, the navigation-grade IMU's
biases and noise densities, the 50 Hz filter rate); the GNSS, integrity and recovery settings are ours
(navigators.filters.ins_trn_ekf's docstrings state what each does).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.capabilities import Capabilities, SensorNeeds
from ..core.settings import Settings, setting

G0 = 9.80665
CHI2_2DOF_99_99 = 18.42
CHI2_5DOF_99_99 = 25.74
IRA_FORMULAS = ("simple", "attitude", "conventional", "proposed")
AIDINGS = ("ira", "radar_altimeter")
FIX_NOISE_MODELS = ("batch", "fixed")
TURN_ANGLES = ("total", "excursion")


@dataclass(frozen=True)
class InsTrnSettings(Settings):
    """Settings of navigators.filters.ins_trn_ekf.InsTrnNavigator (SI, 1 sigma); `aiding` None is the free
    inertial navigator ("ins")."""

    aiding: str | None = setting(None, "terrain aiding: None (free inertial), 'ira' (seed 000 eq 2) or "
                                       "'radar_altimeter' (eq 1)", choices=AIDINGS)
    formula: str = setting("proposed", "IRA closest-point formula (seed 000)", choices=IRA_FORMULAS)
    fix_period_s: float = setting(40.0, "TERCOM batch length between fixes (Table 2)", "s", gt=0.0)
    half_cells: int = setting(50, "TERCOM search half-width in cells", ge=1)
    cell_m: float = setting(5.0, "TERCOM search cell", "m", gt=0.0)
    fix_sigma_m: float = setting(10.0, "TERCOM fix noise per axis (Table 2)", "m", gt=0.0)
    fix_noise: str = setting("fixed", "TERCOM fix covariance: 'fixed' (fix_sigma_m per axis) or 'batch' "
                                      "(ins_tercom's default: the MAD shift's from the batch's residuals and "
                                      "map slopes, tercom.fix_noise)", choices=FIX_NOISE_MODELS)
    terrain_model_sigma_m: float | str = setting(
        "auto", "terrain a coarse map cannot hold between posts, in the 'batch' fix covariance (auto: from "
        "the map's spectrum)", "m", ge=0.0, also=("auto",))
    turn_angle: str = setting("total", "angle the turn terms' attitude walk runs in (with the IMU's "
                              "specification): integral of |yaw rate| (total) or growth of the net heading "
                              "change since the reset (excursion; navigators.core.imu_spec.TurnAngle)",
                              choices=TURN_ANGLES)
    ekf_rate_hz: float = setting(50.0, "error-state propagation rate (Table 2)", "Hz", gt=0.0)
    gravity_model: str = setting("j2", "INS gravity model", choices=("somigliana", "j2"))
    tau_baro_s: float = setting(30.0, "time constant of the baro-damped vertical channel", "s", gt=0.0)
    accel_bias_mps2: float = setting(50e-6 * G0, "accelerometer bias prior per axis (Table 2)", "m/s^2",
                                     ge=0.0)
    accel_noise_mps2_rthz: float = setting(10e-6 * G0, "accelerometer noise density (Table 2)",
                                           "m/s^2/sqrt(Hz)", ge=0.0)
    gyro_bias_rps: float = setting(math.radians(0.005) / 3600, "z-gyro bias prior (Table 2)", "rad/s", ge=0.0)
    gyro_noise_rps_rthz: float = setting(math.radians(0.005) / 60, "gyro noise density (Table 2)",
                                         "rad/s/sqrt(Hz)", ge=0.0)
    ira_decimation: int = setting(1, "use every n-th IRA sample in a batch", ge=1)
    ira_average: int = setting(1, "enter each n consecutive IRA samples of a batch as their mean "
                                  "(tercom.mad.TercomBatch)", ge=1)
    gate_chi2: float = setting(CHI2_2DOF_99_99, "chi-square gate of a TERCOM fix (2 dof)", gt=0.0)
    min_samples: int = setting(20, "samples a batch needs for a fix", ge=1)
    dp_min_m: float = setting(0.0, "keep IRA samples whose formulas' closest points differ by more (Table 3)",
                              "m", ge=0.0)
    dp_reference_formula: str = setting("conventional", "the formula dp_min_m compares against",
                                        choices=IRA_FORMULAS)
    imu_samples: str = setting("interval", "IMU samples are interval means or instant values",
                               choices=("interval", "instant"))
    baro_geopotential: bool = setting(True, "convert the baro's geopotential height to geometric")
    baro_lag_s: float = setting(0.0, "the barometer's first-order lag, taken out of each terrain sample's "
                                     "height (h = baro - lag x v_down; a scenario gives its sensors.baro."
                                     "lag_tau_s)", "s", ge=0.0)
    remove_bias: bool = setting(False, "mean-removed MAD in TERCOM")
    init_height_from_baro: bool = setting(True, "take the INS height from the first baro sample")
    baro_bias_sigma_m: float = setting(10.0, "bias of the baro height the vertical channel follows", "m",
                                       ge=0.0)
    use_gnss: bool = setting(True, "fuse GNSS fixes while they arrive")
    gnss_sigma_h_m: float = setting(2.0, "GNSS horizontal position noise per axis", "m", gt=0.0)
    gnss_sigma_v_mps: float = setting(0.1, "GNSS velocity noise per axis", "m/s", gt=0.0)
    gnss_correlated_sigma_m: float = setting(1.5, "floor of the north/east sigma after a GNSS update", "m",
                                             ge=0.0)
    gnss_gate_chi2: float = setting(CHI2_5DOF_99_99, "chi-square gate of a GNSS update (5 dof)", gt=0.0)
    gnss_timeout_s: float = setting(2.5, "no valid fix for this long: GNSS lost", "s", gt=0.0)
    integrity_window: int = setting(3, "fixes in the innovation test's window", ge=1)
    integrity_alpha: float = setting(0.01, "probability outside the innovation test's chi-square band", "1",
                                     gt=0.0, lt=1.0)
    recovery_half_cells: int | None = setting(None, "search half-width after a failed test (None: 2 x "
                                                    "half_cells)", ge=1)
    recovery_sigma_m: float = setting(100.0, "horizontal sigma added on a failed test", "m", ge=0.0)

    def resolve(self) -> None:
        if self.recovery_half_cells is None:
            object.__setattr__(self, "recovery_half_cells", 2 * self.half_cells)

    def check(self) -> list[tuple[str, str]]:
        if self.recovery_half_cells < self.half_cells:
            return [("recovery_half_cells", f"must be an integer >= half_cells ({self.half_cells}), got "
                                            f"{self.recovery_half_cells!r}")]
        return []

    def sensor_needs(self) -> SensorNeeds:
        req = {"imu": "the INS"}
        if self.aiding is not None:
            req[self.aiding] = f"aiding = {self.aiding!r}: the TERCOM batch's terrain profile"
        return SensorNeeds(req, ("baro", "gnss"))


@dataclass(frozen=True)
class InsTercomSettings(InsTrnSettings):
    """InsTrnSettings with the IRA aiding of `ins_tercom` by default, its batch fix covariance and its turn
    term in the heading's excursion (navigators.filters.ins_trn_ekf, ins_trn_propagation)."""

    aiding: str | None = setting("ira", "terrain aiding: 'ira' (seed 000 eq 2) or 'radar_altimeter' (eq 1)",
                                 choices=AIDINGS)
    fix_noise: str = setting("batch", "TERCOM fix covariance: 'batch' (the MAD shift's from the batch's "
                                      "residuals and map slopes, tercom.fix_noise) or 'fixed' (fix_sigma_m "
                                      "per axis, Table 2)", choices=FIX_NOISE_MODELS)
    turn_angle: str = setting("excursion", "angle the turn terms' attitude walk runs in (with the IMU's "
                              "specification): growth of the net heading change since the reset (excursion; "
                              "navigators.core.imu_spec.TurnAngle) or integral of |yaw rate| (total)",
                              choices=TURN_ANGLES)


def _tercom_warm_up(rate_hz: float) -> dict:
    """A TERCOM fix due at the warm-up's third update (after the last GNSS fix in the first)."""
    return {"fix_period_s": 2.0 / rate_hz, "min_samples": 1}


INS_CAPABILITIES = Capabilities(settings=InsTrnSettings, uses_imu_spec=True)
INS_TERCOM_CAPABILITIES = Capabilities(settings=InsTercomSettings, needs_map=True, uses_imu_spec=True,
                                       models_map_detail=True,
                                       # protection level validated on (docs/validation/integrity.md 6.6)
                                       pl_validated=("navigation/as_published", "tactical/as_published",
                                                     "navigation/dted1", "tactical/dted1"),
                                       pl_settings=(("remove_bias", True),),   # the campaign's
                                       warm_up_settings=_tercom_warm_up,
                                       # GM fits to its GNSS-denied error
                                       # (scripts/navigator_error_time_constants.py, docs/validation/
                                       # integrity_error_time_constants.json; its baro-slaved height
                                       # error is near constant over a window)
                                       error_time_constant_s=69.0, height_time_constant_s=6200.0)


def initial_covariance(
    sigma_ne_m: float = 30.0,
    sigma_d_m: float = 15.0,
    sigma_v_mps: float = 0.1,
    sigma_tilt_rad: float = 0.05e-3,
    sigma_yaw_rad: float = 1e-3,
) -> np.ndarray:
    """9 x 9 initial covariance; defaults are seed 000 Table 2's initial errors."""
    return np.diag(
        [sigma_ne_m**2, sigma_ne_m**2, sigma_d_m**2]
        + [sigma_v_mps**2] * 3
        + [sigma_tilt_rad**2, sigma_tilt_rad**2, sigma_yaw_rad**2]
    )
