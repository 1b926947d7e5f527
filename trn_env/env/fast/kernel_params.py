"""The fast tier's kernel parameters from a scenario: the arrays and records its numba kernels take.

`build_kernel_params(env, sc, info_offset_m, informative_crlb_m)` turns the scenario (wind layers and
turbulence, IMU, GNSS outages, IRA, navigator settings, initial errors) and the env's task settings into
the flight parameters fp (dynamics.FP_*), the navigator's parameters nav (navigator.NP_*), the initial-error
parameters (reset.IP_*), the observation parameters op (observation.OP_*), the route offsets and the wind
record (altitudes m, north, east m/s). vector_env.py builds them once per env.

Turbulence is a first-order Gauss-Markov gust per horizontal axis: std (m/s) by severity (MIL-F-8785C's
medium-altitude intensities at exceedance 1e-2, 1e-3, 1e-5) and the Dryden length scale 533 m.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

import trn_env.scenario.build as components
from trn_env.env import task
from trn_env.env.fast import dynamics as dyn
from trn_env.env.fast import navigator as nv
from trn_env.env.fast import observation as ob
from trn_env.env.fast.envelope import KINGAIR_ENVELOPE

TURBULENCE_SIGMA_MPS = {"light": 1.5, "moderate": 3.0, "severe": 6.0}
TURBULENCE_LENGTH_M = 533.0
DT_S = 1.0  # flight step (s); the navigator samples terrain at 1 Hz
BARO_SIGMA_M = 10.0  # the barometer's height error (1 sigma), navigators' baro_bias_sigma_m


@dataclass(frozen=True)
class KernelParams:
    """The kernels' parameters (module docstring): wind = (altitudes m, north m/s, east m/s) of the layers,
    fp (dynamics.N_FLIGHT_PARAMS,), nav (navigator.NP_*), init_params (reset.IP_*), op
    (observation.N_OBS_PARAMS,), route_offsets (rad)."""

    wind: tuple
    fp: np.ndarray
    nav: np.ndarray
    init_params: np.ndarray
    op: np.ndarray
    route_offsets: np.ndarray


def _uncompensated_baro_lag_s(sc, settings: dict) -> float:
    """The barometer's lag (s) left in the full navigator's terrain heights: the sensor's lag_tau_s less the
    navigator's baro_lag_s compensation (trn_env.scenario.build.navigator_settings gives it the sensor's
    unless [navigator.settings] sets it); 0 without a barometer."""
    if sc.sensors.baro is None:
        return 0.0
    lag_s = float(sc.sensors.baro.lag_tau_s)
    return lag_s - float(settings.get("baro_lag_s", lag_s))


def build_kernel_params(env, sc, info_offset_m: float, informative_crlb_m: float) -> KernelParams:
    """The kernels' parameters of TerrainNavFastVectorEnv `env` (its task settings: tas_mps, goal_radius_m,
    max_episode_s, action_limits, decision_interval_s, bearing_offset_max_rad, action_mode, reward_mode,
    agl_min_m, agl_max_m, navigator) on the validated scenario sc."""
    from trn_env.navigators import registry
    from trn_env.sensors.imu import ImuConfig
    from trn_env.sensors.ira import IraConfig

    env_ = KINGAIR_ENVELOPE
    wind = sc.wind
    layers = sorted(
        (float(la.altitude_m), float(la.direction_from_deg), float(la.speed_mps))
        for la in wind.layers
    )
    wind_alt = np.array([la[0] for la in layers])
    wind_n = np.array([-la[2] * math.cos(math.radians(la[1])) for la in layers])
    wind_e = np.array([-la[2] * math.sin(math.radians(la[1])) for la in layers])
    turb = wind.turbulence
    sigma_t = (
        0.0
        if turb.model == "none"
        else TURBULENCE_SIGMA_MPS.get("light" if turb.severity is None else turb.severity, 1.5)
    )
    fp = np.zeros(dyn.N_FLIGHT_PARAMS)
    fp[dyn.FP_DT] = DT_S
    fp[dyn.FP_TAS] = env.tas_mps
    fp[dyn.FP_BANK_MAX] = env_.bank_max_rad
    fp[dyn.FP_BANK_TAU] = env_.bank_tau_s
    fp[dyn.FP_CLIMB] = env_.climb_rate_max_mps
    fp[dyn.FP_DESCENT] = env_.descent_rate_max_mps
    fp[dyn.FP_TRACK_GAIN] = env_.track_gain_per_s
    fp[dyn.FP_HEIGHT_GAIN] = env_.height_gain_per_s
    fp[dyn.FP_VS_ACCEL] = env_.vs_accel_max_mps2
    fp[dyn.FP_TURB_SIGMA] = sigma_t
    fp[dyn.FP_TURB_TAU] = TURBULENCE_LENGTH_M / env.tas_mps
    fp[dyn.FP_GOAL_RADIUS] = env.goal_radius_m
    fp[dyn.FP_MAX_EP] = env.max_episode_s
    fp[dyn.FP_OMEGA] = env.action_limits[0] / env.decision_interval_s
    fp[dyn.FP_OFFSET_MAX] = env.bearing_offset_max_rad
    fp[dyn.FP_PURSUIT] = 1.0 if env.action_mode == "pursuit" else 0.0
    fp[dyn.FP_ARRIVAL] = 1.0 if env.reward_mode == "arrival" else 0.0
    fp[dyn.FP_SAMPLE_DT] = 1.0
    fp[dyn.FP_TAS_PER_VS] = env_.tas_per_vs
    fp[dyn.FP_TAS_TAU] = env_.tas_tau_s
    # the wander was measured in the scenarios' light turbulence: none in calm air
    fp[dyn.FP_WANDER_SIGMA] = env_.tas_wander_mps if sigma_t > 0.0 else 0.0
    fp[dyn.FP_WANDER_TAU] = env_.tas_wander_tau_s
    imu = asdict(sc.sensors.imu if sc.sensors.imu is not None else ImuConfig())
    outages = sc.gnss.outages
    gnss_until = (
        (min(float(o.start_s) for o in outages) if outages else math.inf)
        if sc.sensors.gnss is not None
        else 0.0
    )
    ira = sc.sensors.ira if sc.sensors.ira is not None else IraConfig()
    spec = (
        components.imu_spec(sc.sensors.imu)
        if registry.capabilities(env.navigator).uses_imu_spec
        else None
    )
    settings = sc.navigator.table.to_dict()
    terrain_sigma_m = 0.0
    fix_noise_model = settings.get("fix_noise", nv.ins_tercom_default("fix_noise"))
    if env.navigator == "ins_tercom" and fix_noise_model == "batch":
        # the map's unresolved terrain, as the full navigator takes it (its batch fix covariance)
        from trn_env.navigators.measurements.ira_map_noise import interpolation_sigma_m

        terrain_sigma_m = interpolation_sigma_m(env._map)
    nav = nv.navigator_params(
        env.navigator,
        settings,
        imu,
        gnss_until,
        float(ira.range_noise_m),
        float(ira.rate_hz),
        spec,
        sample_dt_s=float(fp[dyn.FP_SAMPLE_DT]),
        terrain_sigma_m=terrain_sigma_m,
        baro_lag_s=_uncompensated_baro_lag_s(sc, settings),
    )
    ie = sc.initial_errors
    pos = ie.position_ned_m
    vel = ie.velocity_ned_mps
    att = ie.attitude_mrad
    init_params = np.array(
        [
            float(np.hypot(pos[0], pos[1]) / math.sqrt(2.0)),
            float(np.hypot(vel[0], vel[1]) / math.sqrt(2.0)),
            float(np.hypot(att[0], att[1]) / math.sqrt(2.0)) * 1e-3,
            float(imu["accel_bias_mps2"]),
            float(imu["gyro_bias_rps"]),
            BARO_SIGMA_M,
            env.agl_min_m,
            env.agl_max_m,
            float(att[2]) * 1e-3,
            float(nav[nv.NP_SIG_BA_PRIOR]),
            float(imu.get("gyro_misalignment_rad", 0.0)),
            float(imu.get("gyro_scale_factor_ppm", 0.0)) * 1e-6,
        ]
    )
    op = np.zeros(ob.N_OBS_PARAMS)
    op[ob.OP_INFO_OFFSET] = info_offset_m
    op[ob.OP_MAX_EP] = env.max_episode_s
    op[ob.OP_TAS] = env.tas_mps
    op[ob.OP_BARO_SIGMA] = BARO_SIGMA_M
    op[ob.OP_UNHEALTHY] = nav[nv.NP_UNHEALTHY]
    op[ob.OP_GOAL_RADIUS] = env.goal_radius_m
    op[ob.OP_OMEGA] = fp[dyn.FP_OMEGA]
    op[ob.OP_INFORMATIVE] = informative_crlb_m
    op[ob.OP_NO_INFO] = components.NO_INFORMATION_SIGMA_M
    route_offsets = np.array(task.ROUTE_OFFSET_FRACTIONS) * env.bearing_offset_max_rad
    return KernelParams((wind_alt, wind_n, wind_e), fp, nav, init_params, op, route_offsets)
