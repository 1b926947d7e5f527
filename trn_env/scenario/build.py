"""A scenario's typed sections -> the components of a run (terrain, flight, wind, sensors, navigator,
guidance).

The one place that knows both the scenario's sections (trn_env.scenario.sections) and the component
constructors. Every builder takes `sc`: a trn_env.scenario.Scenario or its ScenarioSections (the same
section attributes). `check` builds each component from the scenario and turns every rejection into a
problem at the field path, so a scenario is fully checked before the flight starts.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys

import numpy as np
from numba import njit

from trn_env.terrain.kernels import bilinear

SENSOR_KEYS = ("imu", "baro", "radar_altimeter", "ira", "gnss", "air_data", "heading")


# ----------------------------------------------------------------------------------------------- terrain

def _load_dem(value: str, fill_voids: bool):
    from trn_env import terrain
    return terrain.load(value, fill_voids=fill_voids)


def build_terrain(sc, extras: dict, rng: np.random.Generator):
    """(world DEM, navigator's map DEM) for the scenario; map errors drawn from `rng`."""
    wcfg = sc.terrain.world
    world = extras.get("world_dem_raw") or _load_dem(wcfg.dem, bool(wcfg.fill_voids))
    if wcfg.refinement is not None:
        world = refine_dem(world, wcfg.refinement.to_dict(), rng)
    mcfg = sc.terrain.map
    if mcfg.is_world:
        base = world
    else:
        base = extras.get("map_dem_raw") or _load_dem(mcfg.dem, bool(mcfg.fill_voids))
    err = mcfg.error_model
    the_map = apply_map_errors(base, err.to_dict(), rng) if err else base
    faults = map_faults(sc)
    extras["map_faults"] = [f.describe() for f in faults]
    extras["map_fault_schedule"] = []
    if faults:
        from trn_env.terrain.map_error import fault_schedule
        schedule = fault_schedule(the_map, faults)
        the_map = the_map.with_heights(schedule[0][1], name=f"{the_map.name}[faults]")   # never the world
        extras["map_fault_schedule"] = schedule[1:]
        extras["map_fault_heights0"] = schedule[0][1]
    extras["world_dem"] = world
    extras["map_dem"] = the_map
    return world, the_map


def map_faults(sc) -> list:
    """terrain.map_error.MapFault of each [[terrain.map.faults]] entry (source_dem loaded)."""
    from trn_env.terrain.map_error import MapFault
    out = []
    for f in sc.terrain.map.faults:
        kw = f.to_dict()
        if "source_dem" in kw:
            kw["source_dem"] = _load_dem(kw["source_dem"], True)
        out.append(MapFault(**kw))
    return out


def _fault_problems(sc, the_map) -> list[str]:
    from trn_env.terrain.map_error import MapFault, check_fault
    problems = []
    for i, f in enumerate(sc.terrain.map.faults):
        try:
            kw = f.to_dict()
            if "source_dem" in kw:
                kw["source_dem"] = _load_dem(kw["source_dem"], True)
            fault = MapFault(**kw)
            check_fault(the_map, fault)
            if fault.kind in ("shift", "stale"):
                from trn_env.terrain.map_error import apply_fault
                apply_fault(the_map.heights_m.copy(), the_map, fault)
        except Exception as exc:  # noqa: BLE001 - a loader's or the fault's rejection is a problem here
            problems.append(f"terrain.map.faults[{i}]: {exc}")
    return problems


def refine_dem(dem, settings: dict, rng: np.random.Generator):
    """The true terrain with synthetic sub-grid detail (terrain.refine.refine; region_deg in degrees)."""
    from trn_env.terrain.refine import refine
    kw = dict(settings)
    if "region_deg" in kw:
        kw["region"] = tuple(math.radians(x) for x in kw.pop("region_deg"))
    return refine(dem, seed=rng, **kw)


def map_error_model(settings: dict, rng: np.random.Generator):
    """terrain.map_error.MapErrorModel of the scenario's error_model table: a preset accuracy class drawn
    from `rng` (with bias_fraction / correlation_length_m), then any explicit fields override it."""
    from dataclasses import replace

    from trn_env.terrain import map_error
    kw = dict(settings)
    preset = kw.pop("preset", None)
    if preset is None:
        kw.pop("bias_fraction", None)
        return map_error.MapErrorModel(**kw)
    cls_kw = {k: kw.pop(k) for k in ("bias_fraction", "correlation_length_m") if k in kw}
    model = map_error.model_for_class(preset, rng, **cls_kw)
    if "correlation_length_m" in cls_kw:
        kw["correlation_length_m"] = cls_kw["correlation_length_m"]
    return replace(model, **kw)


def _table(error_model) -> dict:
    """The error model as a mapping: the scenario's MapErrorModel section, a mapping, or None (empty)."""
    if error_model is None:
        return {}
    return error_model.to_dict() if hasattr(error_model, "to_dict") else dict(error_model)


def map_noise_settings(settings) -> dict:
    """{map_sigma_m, map_bias_sigma_m} a navigator should assume for the scenario's map error model (1 sigma,
    m): its accuracy class's vertical sigma split by bias_fraction (terrain.map_error.model_for_class), or
    the explicit random_sigma_m and |bias_m|; zeros without an error model."""
    from trn_env.terrain import map_error
    s = _table(settings)
    random_m, bias_m = 0.0, 0.0
    preset = s.get("preset")
    if preset is not None and str(preset).strip().lower() in map_error.ACCURACY_CLASSES:
        sig_v = map_error.ACCURACY_CLASSES[str(preset).strip().lower()].sigma_v_m
        bf = float(s.get("bias_fraction", 0.5))
        random_m, bias_m = sig_v * math.sqrt(max(1.0 - bf, 0.0)), sig_v * math.sqrt(max(bf, 0.0))
    if "random_sigma_m" in s:
        random_m = float(s["random_sigma_m"])
    if "bias_m" in s:
        bias_m = abs(float(s["bias_m"]))
    return {"map_sigma_m": random_m, "map_bias_sigma_m": bias_m}


def apply_map_errors(dem, settings: dict, rng: np.random.Generator):
    """The navigator's map = `dem` with the scenario's map error model applied (terrain.map_error.apply)."""
    from trn_env.terrain import map_error
    model = map_error_model(settings, rng)
    return map_error.apply(dem, model, rng, name=f"{dem.name}[map]")


def world_height(dem, lat_rad: np.ndarray, lon_rad: np.ndarray) -> np.ndarray:
    """Terrain height (m MSL) at 1-D arrays of positions; NaN off the grid or over voids (bilinear).

    Calls the terrain package's numba batch kernel directly (this runs every guidance tick)."""
    from trn_env.terrain import kernels
    lat = np.ascontiguousarray(lat_rad, dtype=np.float64).ravel()
    lon = np.ascontiguousarray(lon_rad, dtype=np.float64).ravel()
    out = np.empty(lat.shape[0])
    heights, lat0, lon0, dlat, dlon = dem.grid
    kernels.bilinear_batch(heights, lat0, lon0, dlat, dlon, lat, lon, out)
    return out


@njit(cache=True)
def _min_height_above_terrain(heights, lat0, lon0, dlat, dlon, lat, lon, h):
    m = np.inf
    n_nan = 0
    for i in range(lat.shape[0]):
        d = h[i] - bilinear(heights, lat0, lon0, dlat, dlon, lat[i], lon[i])
        if d != d:
            n_nan += 1
        elif d < m:
            m = d
    return m, n_nan


def min_height_above_terrain(dem, lat_rad: np.ndarray, lon_rad: np.ndarray, h_msl_m: np.ndarray):
    """(smallest height above the terrain over the finite points (m; inf if none), number of points off
    the grid or over voids) of 1-D arrays of positions (bilinear, the terrain package's numba kernel)."""
    heights, lat0, lon0, dlat, dlon = dem.grid
    m, n_nan = _min_height_above_terrain(heights, lat0, lon0, dlat, dlon, lat_rad, lon_rad, h_msl_m)
    return float(m), int(n_nan)


def world_contains(dem, lat_rad: np.ndarray, lon_rad: np.ndarray) -> np.ndarray:
    return np.asarray(dem.contains(lat_rad, lon_rad), bool)


def map_height(dem, lat_rad: float, lon_rad: float) -> float:
    """Map height (m MSL) at one position; NaN off the map (bilinear, the terrain package's numba kernel)."""
    from trn_env.terrain import kernels
    heights, lat0, lon0, dlat, dlon = dem.grid
    return float(kernels.bilinear(heights, lat0, lon0, dlat, dlon, float(lat_rad), float(lon_rad)))


# ------------------------------------------------------------------------------------------ flight, wind

def build_wind(sc):
    """trn_env.flight.wind.WindConfig from the scenario's [wind] section."""
    from trn_env.flight.wind import CosineGust, Turbulence, WindConfig
    w = sc.wind
    layers = [(lay.altitude_m, lay.direction_from_deg, lay.speed_mps) for lay in w.layers]
    t = w.turbulence
    turb = Turbulence(model=t.model, severity="light" if t.severity is None else t.severity,
                      windspeed_at_20ft_mps=t.windspeed_at_20ft_mps)
    gusts = []
    for g in w.gusts:
        g = g.to_dict()
        if "direction" in g:
            g["direction"] = tuple(g["direction"])
        gusts.append(CosineGust(**g))
    return WindConfig(layers=layers, turbulence=turb, gusts=gusts)


def build_atmosphere(sc):
    """trn_env.flight.Atmosphere of the scenario's optional [atmosphere] section (absent: standard)."""
    from trn_env.flight.atmosphere import Atmosphere
    return Atmosphere.from_mapping(None if sc.atmosphere is None else sc.atmosphere.to_dict())


def initial_h_msl_m(sc, world) -> float:
    """Initial height above MSL: h_msl_m, or h_agl_m above the TRUE terrain at the start."""
    init = sc.initial
    if init.h_msl_m is not None:
        return float(init.h_msl_m)
    h_ground = map_height(world, math.radians(init.lat_deg), math.radians(init.lon_deg))
    return float(init.h_agl_m) + h_ground


@contextlib.contextmanager
def quiet_stdout():
    """Silence C-level stdout (JSBSim's start-up banner and trim chatter) for the duration."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):   # stdout replaced (pytest capture, notebooks)
        yield
        return
    sys.stdout.flush()
    saved = os.dup(fd)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, fd)
    try:
        yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)
        os.close(devnull)


def is_kinematic(sc) -> bool:
    """The scenario's truth is the prescribed motion profile ([truth] source = "kinematic")."""
    return sc.truth.is_kinematic


def build_kinematic_truth(sc, world):
    """trn_env.flight.kinematic.KinematicTruth of a kinematic scenario: [initial]'s position, height and
    heading, [truth]'s speed (default initial.tas_mps) and segments, [wind]'s steady wind at the initial
    height (held constant), [atmosphere], one row per aircraft.dt_s."""
    from trn_env.flight.kinematic import KinematicTruth, Segment
    init, t = sc.initial, sc.truth
    segments = []
    for i, m in enumerate(t.segments or ()):
        try:
            segments.append(Segment.from_mapping(m.to_dict()))
        except ValueError as exc:
            raise ValueError(f"segments[{i}]: {exc}") from None
    if not segments:
        raise ValueError("segments: a kinematic truth needs at least one segment")
    h0 = initial_h_msl_m(sc, world)
    speed_mps = init.tas_mps if t.speed_mps is None else t.speed_mps
    return KinematicTruth(math.radians(init.lat_deg), math.radians(init.lon_deg), h0,
                          float(speed_mps), math.radians(init.heading_deg),
                          segments, rate_hz=1.0 / float(sc.aircraft.dt_s), terrain=world,
                          wind_ned_mps=build_wind(sc).steady_wind_ned_mps(h0),
                          atmosphere=build_atmosphere(sc))


def _truth_problems(sc, world) -> list[str]:
    """[truth] fields against the source: a kinematic profile that cannot be built, or one asked to fly
    turbulence or gusts (it holds one steady wind); kinematic-only fields on a JSBSim truth."""
    import re
    t = sc.truth
    if not is_kinematic(sc):
        return [f"truth.{k}: only used with truth.source = \"kinematic\" (the source is "
                f"{t.source!r})" for k in ("speed_mps", "segments") if getattr(t, k) is not None]
    problems = []
    w = sc.wind
    if w.turbulence.model != "none":
        problems.append("wind.turbulence: the kinematic truth holds a steady wind; turbulence needs "
                        "truth.source = \"jsbsim\" (set wind.turbulence.model = \"none\")")
    if w.gusts:
        problems.append("wind.gusts: the kinematic truth holds a steady wind; gusts need "
                        "truth.source = \"jsbsim\"")
    try:
        build_kinematic_truth(sc, world)
    except ValueError as exc:
        msg = str(exc)
        m = re.match(r"segments\[(\d+)\]: Segment\.(\w+)", msg)
        if m:
            problems.append(f"truth.segments[{m.group(1)}].{m.group(2)}: {msg.split(': ', 1)[1]}")
        elif msg.startswith("segments"):
            problems.append(f"truth.{msg}")
        elif "speed_mps" in msg or "wind" in msg:
            problems.append(f"truth.speed_mps: {msg}")
        else:
            problems.append(f"truth: {msg}")
    return problems


def build_flight(sc, world, rng: np.random.Generator):
    """trn_env.flight.Flight at the scenario's initial condition, trimmed, with its wind and a JSBSim seed;
    for [truth] source = "kinematic" a trn_env.flight.kinematic.KinematicFlight of the prescribed profile
    (rng unused)."""
    if is_kinematic(sc):
        from trn_env.flight.kinematic import KinematicFlight
        return KinematicFlight(build_kinematic_truth(sc, world))
    from trn_env.flight.core import Flight
    init = sc.initial
    lat, lon = math.radians(init.lat_deg), math.radians(init.lon_deg)
    ic = _initial_condition(sc, world)
    seed = int(rng.integers(0, 2**31 - 1))
    with quiet_stdout():
        return Flight(ic, aircraft=sc.aircraft.name, dt_s=float(sc.aircraft.dt_s),
                      wind=build_wind(sc), seed=seed, terrain_elevation_m=map_height(world, lat, lon),
                      atmosphere=build_atmosphere(sc), constant_fuel=bool(sc.aircraft.constant_fuel))


def trim_problems(sc, world) -> list[str]:
    """The flight's own trim at the initial condition (JSBSim, tens of milliseconds), so a start the flight
    would refuse (an airspeed below stall, a height the aircraft cannot hold level) is a validation problem
    before any flight. An initial condition that is itself invalid is reported by its own check."""
    from trn_env.flight.core import TrimError
    try:
        build_flight(sc, world, np.random.default_rng(0))
    except TrimError as exc:
        return [f"initial: {exc} (check initial.tas_mps against the aircraft's speed range and the initial "
                "height)"]
    except (ValueError, TypeError, KeyError):
        return []
    return []


# ----------------------------------------------------------------------------------------------- sensors

def sensor_configs(sc) -> dict:
    """{sensor name: config} of the scenario's fitted sensors (each sensor's Settings class, e.g.
    trn_env.sensors.imu.ImuConfig; absent = not fitted)."""
    return sc.sensors.configs()


def sensor_lever_arms(sc) -> dict:
    """{sensor: lever_arm_b_m} of the scenario's ranging sensors (radar altimeter, IRA), body FRD m."""
    arms = {}
    for name in ("radar_altimeter", "ira"):
        cfg = getattr(sc.sensors, name)
        if cfg is not None:
            arms[name] = [float(x) for x in cfg.lever_arm_b_m]
    return arms


def build_sensors(sc, seed: np.random.SeedSequence):
    """trn_env.sensors.suite.SensorSuite of the scenario's sensors, one random stream per sensor."""
    from trn_env.sensors.suite import SensorSuite
    return SensorSuite.from_config(sensor_configs(sc), seed)


# -------------------------------------------------------------------------------------------- navigator

def imu_spec(imu):
    """The scenario IMU's error specification as the navigators take it (navigators.core.imu_spec.ImuSpec,
    from trn_env.sensors.imu.ImuConfig: its grade and overrides); `imu` is an ImuConfig (the scenario's
    `sensors.imu`) or an [sensors.imu] table; None without an IMU or for a table that does not validate
    (the sensors check reports that)."""
    from trn_env.navigators.core.imu_spec import ImuSpec
    from trn_env.sensors.imu import ImuConfig
    if imu is None or imu is False:
        return None
    if isinstance(imu, ImuConfig):
        return ImuSpec.from_object(imu)
    try:
        cfg = ImuConfig.from_mapping(dict(imu))
    except (ValueError, TypeError):
        return None
    return ImuSpec.from_object(cfg)


def imu_bias_settings(imu, epoch_s: float = 1.0) -> dict:
    """The bias model a navigator should assume for the scenario's IMU (1 sigma per axis, its grade and
    overrides, imu_spec): accel_bias_sigma_mps2 and gyro_bias_sigma_rps, the root sum square of the turn-on
    bias and the bias instability; q_accel_bias_mps2 and q_gyro_bias_rps, the instability's Gauss-Markov
    drive over one filter epoch of epoch_s seconds, sigma sqrt(1 - exp(-2 epoch_s / tau)) (0 for the
    navigation grade, whose biases are constant over a run). Empty without an IMU or for a table that does
    not validate (the sensors check reports that)."""
    spec = imu_spec(imu)
    if spec is None:
        return {}
    return {"accel_bias_sigma_mps2": spec.accel_bias_sigma_mps2,
            "gyro_bias_sigma_rps": spec.gyro_bias_sigma_rps,
            "q_accel_bias_mps2": spec.accel_bias_drive(epoch_s),
            "q_gyro_bias_rps": spec.gyro_bias_drive(epoch_s)}


def _epoch_s(settings: dict) -> float:
    """A navigator's update interval from its trn_rate_hz setting (1 s if absent or not a positive number:
    the navigator's own check then reports a bad one)."""
    try:
        rate = float(settings.get("trn_rate_hz", 1.0))
    except (TypeError, ValueError):
        return 1.0
    return 1.0 / rate if math.isfinite(rate) and rate > 0 else 1.0


def _settings_fields(settings_class) -> set[str]:
    """Names of a navigator settings dataclass's fields (empty for none or not a dataclass)."""
    import dataclasses
    if settings_class is None or not dataclasses.is_dataclass(settings_class):
        return set()
    return {f.name for f in dataclasses.fields(settings_class)}


def navigator_settings(sc, map_dem) -> dict:
    """The keyword settings registry.create gets for the scenario's navigator: its [navigator.settings] and,
    by its declared capabilities (navigators.core.capabilities), the map as dem= (needs_map, and any plug-in
    that declares no settings class, as before capabilities), the bias priors and bias process noise from the
    IMU (imu_bias_settings), map_sigma_m / map_bias_sigma_m from the map error model
    (uses_map_noise: map_noise_settings), terrain_model_sigma_m = 0 when the map is the world, else
    terrain_detail_spacing_m from the world's refinement (models_map_detail), gnss_drift_sigma_m from the
    GNSS sensor's horizontal drift (navigators that declare that setting), each unless the settings give
    it. Every navigator gets map_horizontal_sigma_m from the map's accuracy class (its protection level
    covers it)."""
    from trn_env.navigators import registry
    from trn_env.terrain import map_error
    caps = registry.capabilities(sc.navigator.name)
    settings = sc.navigator.table.to_dict()
    if caps.needs_map or caps.settings is None:
        settings.setdefault("dem", map_dem)
    if caps.imu_bias_settings:
        for key, val in imu_bias_settings(sc.sensors.imu, _epoch_s(settings)).items():
            settings.setdefault(key, val)
    error_model = sc.terrain.map.error_model
    preset = str((error_model.preset if error_model is not None else None) or "").strip().lower()
    if preset in map_error.ACCURACY_CLASSES:   # the protection level covers the map's horizontal error
        settings.setdefault("map_horizontal_sigma_m", map_error.ACCURACY_CLASSES[preset].sigma_h_m)
    if caps.uses_map_noise:
        for key, val in map_noise_settings(error_model).items():
            settings.setdefault(key, val)
    gnss = sc.sensors.gnss
    if gnss is not None and "gnss_drift_sigma_m" in _settings_fields(caps.settings):
        settings.setdefault("gnss_drift_sigma_m", float(gnss.horizontal_drift_m))   # the receiver's drift
    if caps.models_map_detail and sc.terrain.map.is_world:
        settings.setdefault("terrain_model_sigma_m", 0.0)     # the map is the world: nothing unresolved
    elif caps.models_map_detail:
        refinement = sc.terrain.world.refinement
        spacing = None if refinement is None else refinement.spacing_m
        # the finest terrain below the map's posts is the world's (where it is finer than the posts)
        if spacing is not None and 5.0 <= float(spacing) < min(getattr(map_dem, "spacing_m", (0.0,))):
            settings.setdefault("terrain_detail_spacing_m", float(spacing))
    return settings


def build_navigator(sc, map_dem, rng: np.random.Generator | None = None):
    """navigators.registry.create(name, rng=<the scenario's navigator stream>, **navigator_settings(sc,
    map_dem)); the rng reaches only navigators that declare takes_rng. A navigator that declares
    uses_imu_spec and has `apply_imu_spec` then takes its INS error model from the scenario IMU's
    specification (navigators.core.imu_spec)."""
    from trn_env.navigators import registry
    name = sc.navigator.name
    navigator = registry.create(name, rng=rng, **navigator_settings(sc, map_dem))
    spec = imu_spec(sc.sensors.imu) if registry.capabilities(name).uses_imu_spec else None
    if spec is not None and hasattr(navigator, "apply_imu_spec"):
        navigator.apply_imu_spec(spec)
    return navigator


def _navigator_requirements(sc, the_map) -> list[str]:
    try:
        navigator = build_navigator(sc, the_map)
    except (ValueError, TypeError):
        return []          # the navigator.settings check reports it
    return navigator_sensor_problems(sc, navigator)


def navigator_sensor_problems(sc, navigator) -> list[str]:
    """The sensors the navigator requires that the scenario does not fit, each as 'sensors.<name>: ...'
    (its declared capabilities, navigators.registry.sensor_needs; for a plug-in that declares none, its
    `required_sensors()` if it has one), and a transect longer than the flight (a navigator's
    `required_duration_s()`): refused before the flight. (The scenario loader checks the declared sensors
    before any component is built; this also serves an undeclared plug-in and trn_env.testing.)"""
    from trn_env.navigators import registry
    name = sc.navigator.name
    try:
        need = list(registry.sensor_needs(name, sc.navigator.table.to_dict()).required.items())
    except ValueError:
        need = []
    if not need and callable(getattr(navigator, "required_sensors", None)):
        need = list(navigator.required_sensors())
    fitted = set(sc.sensors.fitted)
    problems = [f"sensors.{sensor}: navigator {name!r} needs this sensor ({why}); add a [sensors.{sensor}] "
                "table" for sensor, why in need if sensor not in fitted]
    dur = getattr(navigator, "required_duration_s", None)
    if dur is not None and dur() > float(sc.duration_s):
        problems.append(f"navigator.settings.transect_samples: one transect takes {dur():g} s of flight, "
                        f"more than the scenario's duration_s = {sc.duration_s:g} s (more samples than the "
                        "route provides)")
    return problems


def unused_sensors(sc) -> list[str]:
    """The fitted sensors that neither the navigator nor any monitor reads (by their declared sensor needs);
    summary.json lists them. Empty when a component's needs cannot be read."""
    from trn_env.navigators import registry
    try:
        used = set(registry.sensor_needs(sc.navigator.name, sc.navigator.table.to_dict()).used)
        for mon in sc.monitors:
            used |= set(registry.monitor_sensor_needs(mon.name, mon.settings.to_dict()).used)
    except ValueError:
        return []
    return sorted(set(sc.sensors.fitted) - used)


# -------------------------------------------------------------------------------------------- monitors

def monitor_map_settings(error_model) -> dict:
    """The DEM monitor's map model from the scenario's map error model (terrain.map_error): sigma_m (the
    vertical sigma: random and bias parts together), map_bias_fraction, correlation_length_m and
    correlation_function; empty without a random vertical error (the monitor keeps seed 003's model)."""
    from trn_env.terrain import map_error
    s = _table(error_model)
    noise = map_noise_settings(s)
    sig_r, sig_b = noise["map_sigma_m"], noise["map_bias_sigma_m"]
    if not sig_r > 0.0:
        return {}
    preset = str(s.get("preset", "")).strip().lower()
    cls = map_error.ACCURACY_CLASSES.get(preset)
    length = s.get("correlation_length_m", cls.correlation_length_m if cls else
                   map_error.MapErrorModel().correlation_length_m)
    func = s.get("correlation_function",
                 "exponential" if cls else map_error.MapErrorModel().correlation_function)
    total = math.hypot(sig_r, sig_b)
    return {"sigma_m": total, "map_bias_fraction": (sig_b / total) ** 2,
            "correlation_length_m": float(length), "correlation_function": func}


def monitor_navigator_settings(navigator: str) -> dict:
    """The DEM monitor's model of the navigator's error when the navigator is its height and position source
    (GNSS denied; the monitor uses it only on navigator-sourced epochs): navigator_error_time_constant_s and
    navigator_height_time_constant_s from the navigator's declared error_time_constant_s and
    height_time_constant_s (navigators.core.capabilities), each only where declared (> 0); empty for a
    navigator that declares none (the monitor keeps its error constant over the window)."""
    from trn_env.navigators import registry
    try:
        caps = registry.capabilities(navigator)
    except (KeyError, ValueError):
        return {}
    out = {}
    tau_h = float(getattr(caps, "error_time_constant_s", 0.0))
    tau_v = float(getattr(caps, "height_time_constant_s", 0.0))
    if tau_h > 0.0:
        out["navigator_error_time_constant_s"] = tau_h
    if tau_v > 0.0:
        out["navigator_height_time_constant_s"] = tau_v
    return out


def monitor_settings(sc, name: str) -> dict:
    """A monitor's settings: the scenario's [monitors.<name>] table, with the sensor figures it needs
    filled from the scenario's sensors where not given (dem_integrity: the radar altimeter's noise and
    lever arm, the GNSS vertical sigma, and the navigator's error time constants its GNSS-denied path
    models, from the navigator's declared capabilities where it declares them)."""
    settings = sc.monitor(name).settings.to_dict()
    if name == "dem_integrity":
        for key, val in monitor_navigator_settings(sc.navigator.name).items():
            settings.setdefault(key, val)
        cfg = sc.sensors.radar_altimeter
        if cfg is not None:
            settings.setdefault("radar_altimeter_noise_const_m", float(cfg.noise_const_m))
            settings.setdefault("radar_altimeter_noise_fraction", float(cfg.noise_fraction))
            settings.setdefault("lever_arm_m", float(cfg.lever_arm_b_m[2]))   # FRD z: below the GNSS antenna
            settings.setdefault("beam_half_angle_deg", 0.5 * float(cfg.beamwidth_deg))
            settings.setdefault("max_range_m", float(cfg.max_range_m))
        for key, val in monitor_map_settings(sc.terrain.map.error_model).items():
            settings.setdefault(key, val)
        cfg = sc.sensors.gnss
        if cfg is not None:
            settings.setdefault("gnss_vertical_sigma_m", float(math.hypot(cfg.vertical_noise_m,
                                                                           cfg.vertical_drift_m)))
    return settings


def build_monitors(sc, map_dem) -> dict:
    """{name: monitor} of the scenario's [monitors.*] tables, each on the navigator's map."""
    from trn_env.navigators import registry
    return {name: registry.create_monitor(name, dem=map_dem, **monitor_settings(sc, name))
            for name in sorted(m.name for m in sc.monitors)}


def _monitor_problems(sc, map_dem) -> list[str]:
    from trn_env.navigators import registry
    from trn_env.navigators.core.settings import SettingsError
    problems = []
    for name in sorted(m.name for m in sc.monitors):
        try:
            needs = registry.monitor_sensor_needs(name, sc.monitor(name).settings.to_dict())
            if set(needs.required) - set(sc.sensors.fitted):
                continue                          # reported by the loader's sensor check
            registry.create_monitor(name, dem=map_dem, **monitor_settings(sc, name))
        except SettingsError as exc:
            problems += exc.at(f"monitors.{name}")
        except (ValueError, TypeError) as exc:
            problems.append(f"monitors.{name}: {exc}")
    return problems


# ------------------------------------------------------------------------------------ component checks

def check(sc, extras: dict, known: list[str] | None = None, tolerant: bool = False) -> list[str]:
    """Hand each component its scenario settings; every rejection becomes 'field.path: message'. `sc`: the
    scenario's typed sections (the sensors' own settings were checked when they were built).

    `known`: problems found already; a component whose fields (by path prefix) are among them is skipped.
    `tolerant`: the data failed the schema, so a component tripping over malformed data is skipped too.
    """
    from trn_env.navigators.core.settings import SettingsError
    known = list(known or [])

    def blocked(*prefixes: str) -> bool:
        return any(p.startswith(prefixes) for p in known)

    world = extras.get("world_dem_raw")
    the_map = extras.get("map_dem_raw") or world
    checks = []
    if not blocked("wind"):
        checks.append(("wind", lambda: build_wind(sc)))
    if not blocked("atmosphere"):
        checks.append(("atmosphere", lambda: build_atmosphere(sc)))
    err = sc.terrain.map.error_model
    if err and the_map is not None and not blocked("terrain.map"):
        checks.append(("terrain.map.error_model",
                       lambda: apply_map_errors(the_map, err.to_dict(), np.random.default_rng(0))))
    refinement = sc.terrain.world.refinement
    if refinement is not None and world is not None and not blocked("terrain.world"):
        checks.append(("terrain.world.refinement",
                       lambda: refine_dem(world, refinement.to_dict(), np.random.default_rng(0))))
    if the_map is not None and sc.terrain.map.faults and not blocked("terrain.map"):
        checks.append(("", lambda: _fault_problems(sc, the_map)))
    if the_map is not None and sc.monitors and not blocked("monitors", "sensors"):
        checks.append(("", lambda: _monitor_problems(sc, the_map)))
    if the_map is not None and not blocked("navigator", "terrain"):
        checks.append(("navigator.settings", lambda: build_navigator(sc, the_map)))
        if not blocked("sensors"):
            checks.append(("", lambda: _navigator_requirements(sc, the_map)))
    if world is not None and not blocked("initial", "aircraft", "terrain.world") and not is_kinematic(sc):
        checks.append(("initial", lambda: _initial_condition(sc, world)))
        if not blocked("wind", "atmosphere"):
            checks.append(("", lambda: trim_problems(sc, world)))
    if world is not None and not blocked("initial", "truth", "wind", "atmosphere", "terrain.world",
                                         "aircraft.dt_s"):
        checks.append(("", lambda: _truth_problems(sc, world)))
    if not blocked("route"):
        checks.append(("route", lambda: build_guidance(sc, the_map)))
    problems: list[str] = []
    for path, fn in checks:
        try:
            out = fn()
            if path == "":
                problems += out
        except (ValueError, TypeError, KeyError, AttributeError, ArithmeticError) as exc:
            if tolerant and not isinstance(exc, ValueError):
                continue
            if isinstance(exc, SettingsError) and path:
                problems += exc.at(path)          # every bad setting at its own field path
            else:
                problems.append(_attribute(sc, path, exc))
    return problems


def _attribute(sc, path: str, exc: Exception) -> str:
    """'field.path: message' for a component's rejection, at the setting the message names when it names
    one: navigator.settings.<name>, aircraft.settings.<name>, or initial.<field> (a component's message
    starts with, or quotes, the setting's name)."""
    import re
    msg = str(exc)
    if path == "navigator.settings":
        m = re.match(r"(\w+)\b", msg)     # a runtime argument's own error (dem: ...) names it first
        if m and m.group(1) in sc.navigator.table:
            return f"navigator.settings.{m.group(1)}: {msg}"
        return f"navigator.settings: {msg}"
    if path == "initial":
        m = re.match(r"InitialCondition\.(\w+)", msg)
        name = m.group(1) if m else None
        if name in sc.aircraft.settings:
            return f"aircraft.settings.{name}: {msg}"
        fields = {"lat_rad": "lat_deg", "lon_rad": "lon_deg", "heading_rad": "heading_deg",
                  "tas_mps": "tas_mps",
                  "h_msl_m": "h_msl_m" if sc.initial.h_msl_m is not None else "h_agl_m"}
        if name in fields:
            return f"initial.{fields[name]}: {msg}"
        m = re.search(r"unexpected keyword argument '(\w+)'", msg)
        if m:
            return f"aircraft.settings.{m.group(1)}: unknown setting ({msg})"
        return f"initial: {msg}"
    return f"{path}: {msg}"


def _initial_condition(sc, world):
    from trn_env.flight.core import InitialCondition
    init = sc.initial
    return InitialCondition(lat_rad=math.radians(init.lat_deg), lon_rad=math.radians(init.lon_deg),
                            h_msl_m=initial_h_msl_m(sc, world), tas_mps=float(init.tas_mps),
                            heading_rad=math.radians(init.heading_deg), **_fuel_kw(sc),
                            **sc.aircraft.settings.to_dict())


def _fuel_kw(sc) -> dict:
    fuel_kg = sc.aircraft.fuel_kg
    return {} if fuel_kg is None else {"fuel_kg": float(fuel_kg)}


# --------------------------------------------------------------------------------------------- guidance

def track_agl_targets(track_rad: float, agl_m: float, tas_mps: float):
    """Autopilot targets: hold a ground track, a height above ground and a true airspeed."""
    from trn_env.flight.core import AutopilotTargets, LateralMode, SpeedMode, VerticalMode
    return AutopilotTargets(lateral_mode=LateralMode.TRACK, track_cmd_rad=float(track_rad),
                            heading_cmd_rad=float(track_rad), vertical_mode=VerticalMode.HEIGHT_AGL,
                            agl_cmd_m=float(agl_m), speed_mode=SpeedMode.TAS, tas_cmd_mps=float(tas_mps))


def build_route(sc):
    """trn_env.guidance.Route of the scenario's waypoints (h_msl_m -> alt_ref msl, h_agl_m -> agl)."""
    from trn_env.guidance.route_following import Route, Waypoint
    wps = []
    for w in sc.route.waypoints:
        ref, alt = w.altitude
        wps.append(Waypoint.from_deg(w.lat_deg, w.lon_deg, float(alt), ref))
    return Route(wps)


def build_guidance(sc, map_dem=None):
    """trn_env.guidance.Guidance flying the scenario's route at route.tas_mps (route.settings: kwargs)."""
    from trn_env.guidance.route_following import Guidance
    return Guidance(build_route(sc), tas_mps=float(sc.route.tas_mps), **sc.route.settings.to_dict())


def guidance_complete(guidance) -> bool:
    """True once the guidance has passed the route's last waypoint."""
    return bool(getattr(guidance, "done", False))


# ------------------------------------------------------------------------------- terrain information

# bearings (relative to the commanded track) of the terrain-information samples around the estimate
INFO_BEARINGS_RAD = (None, 0.0, -math.pi / 4, math.pi / 4, -math.pi / 2, math.pi / 2)


NO_INFORMATION_SIGMA_M = 1.0e4      # CRLB stand-in where the terrain (or the map) gives no fix at all


def terrain_information_map(dem, sigma_m: float = 5.0, window_m: float = 2000.0):
    """The map's terrain information as a Dem whose heights_m hold the horizontal position CRLB (m):
    terrain.metrics.terrain_information (Fisher information of altimeter heights with noise sigma_m over a
    window_m square) -> sqrt(trace(I^-1)); flat terrain (singular I) and voids -> NO_INFORMATION_SIGMA_M."""
    from trn_env.terrain import metrics
    info = metrics.terrain_information(dem, sigma_m, window_m)
    crlb = np.asarray(info.crlb_sigma_h_m, float)
    crlb = np.where(np.isfinite(crlb), np.minimum(crlb, NO_INFORMATION_SIGMA_M), NO_INFORMATION_SIGMA_M)
    return dem.with_heights(crlb, name=f"{dem.name}-crlb")


def sample_information(info_map, dem, lat_rad: float, lon_rad: float, track_rad: float,
                       offset_m: float) -> np.ndarray:
    """Position CRLB (m) from `info_map` at the estimate and offset_m away at INFO_BEARINGS_RAD from the
    track; NO_INFORMATION_SIGMA_M off the map."""
    from trn_env.terrain.geodesy import ned_offset_to_latlon
    lats = np.empty(len(INFO_BEARINGS_RAD))
    lons = np.empty(len(INFO_BEARINGS_RAD))
    for k, b in enumerate(INFO_BEARINGS_RAD):
        if b is None:
            lats[k], lons[k] = lat_rad, lon_rad
        else:
            brg = track_rad + b
            lats[k], lons[k] = ned_offset_to_latlon(lat_rad, lon_rad, 0.0, offset_m * math.cos(brg),
                                                    offset_m * math.sin(brg))
    vals = world_height(info_map, lats, lons)
    return np.where(np.isfinite(vals), vals, NO_INFORMATION_SIGMA_M)
