"""A scenario's typed sections -> the components of a run (terrain, flight, wind, sensors, navigator,
guidance).

The one place that knows both the scenario's sections (trn_env.scenario.sections) and the component
constructors. Every builder takes `sc`: a trn_env.scenario.Scenario or its ScenarioSections (the same
section attributes). `check` builds each component from the scenario and turns every rejection into a
problem at the field path, so a scenario is fully checked before the flight starts.

This module builds the flight, wind, atmosphere, sensors and guidance and runs the checks; the terrain
builders live in trn_env.scenario.maps and the navigator's and monitors' in trn_env.scenario.navigation,
both re-exported here so every builder stays reachable as trn_env.scenario.build.<name>.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys

import numpy as np

from trn_env.scenario.maps import (
    INFO_BEARINGS_RAD,
    NO_INFORMATION_SIGMA_M,
    _fault_problems,
    _load_dem,
    apply_map_errors,
    build_terrain,
    check_refinement,
    map_error_model,
    map_faults,
    map_height,
    map_noise_settings,
    min_height_above_terrain,
    refine_dem,
    sample_information,
    terrain_information_map,
    world_contains,
    world_height,
)
from trn_env.scenario.navigation import (
    _monitor_problems,
    _navigator_requirements,
    build_monitors,
    build_navigator,
    imu_bias_settings,
    imu_spec,
    monitor_map_settings,
    monitor_settings,
    navigator_sensor_problems,
    navigator_settings,
    unused_sensors,
)

# the terrain (trn_env.scenario.maps) and navigator/monitor (trn_env.scenario.navigation) builders are
# re-exported: callers reach every builder as trn_env.scenario.build.<name>
__all__ = ["INFO_BEARINGS_RAD", "NO_INFORMATION_SIGMA_M", "SENSOR_KEYS", "_load_dem", "apply_map_errors",
           "build_atmosphere", "build_flight", "build_guidance", "build_kinematic_truth", "build_monitors",
           "build_navigator", "build_route", "build_sensors", "build_terrain", "build_wind", "check",
           "guidance_complete", "imu_bias_settings", "imu_spec", "initial_h_msl_m", "is_kinematic",
           "map_error_model", "map_faults", "map_height", "map_noise_settings", "min_height_above_terrain",
           "monitor_map_settings", "monitor_settings", "navigator_sensor_problems", "navigator_settings",
           "quiet_stdout", "refine_dem", "sample_information", "sensor_configs", "sensor_lever_arms",
           "terrain_information_map", "track_agl_targets", "trim_problems", "unused_sensors",
           "world_contains", "world_height"]

SENSOR_KEYS = ("imu", "baro", "radar_altimeter", "ira", "gnss", "air_data", "heading")


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
    ic, kwargs = _flight_arguments(sc, world, rng)
    with quiet_stdout():
        return Flight(ic, **kwargs)


def _flight_arguments(sc, world, rng: np.random.Generator) -> tuple:
    """(initial condition, keyword arguments) of the scenario's JSBSim Flight: all it is built from."""
    init = sc.initial
    lat, lon = math.radians(init.lat_deg), math.radians(init.lon_deg)
    return _initial_condition(sc, world), dict(
        aircraft=sc.aircraft.name, dt_s=float(sc.aircraft.dt_s), wind=build_wind(sc),
        seed=int(rng.integers(0, 2**31 - 1)), terrain_elevation_m=map_height(world, lat, lon),
        atmosphere=build_atmosphere(sc), constant_fuel=bool(sc.aircraft.constant_fuel))


# trim_problems' answers by the flight's arguments (their repr): a campaign validates one scenario per
# sweep point and navigator, and most share the initial condition, aircraft, wind and atmosphere
_TRIM_CHECKED: dict[str, list[str]] = {}
_TRIM_CHECKED_MAX = 1024


def trim_problems(sc, world) -> list[str]:
    """The flight's own trim at the initial condition (JSBSim, tens of milliseconds), so a start the flight
    would refuse (an airspeed below stall, a height the aircraft cannot hold level) is a validation problem
    before any flight. An initial condition that is itself invalid is reported by its own check. The answer
    is kept for the flight's arguments, which fix the trim (JSBSim's, from the bundled aircraft)."""
    from trn_env.flight.core import Flight, TrimError
    try:
        ic, kwargs = _flight_arguments(sc, world, np.random.default_rng(0))
        key = repr((ic, sorted(kwargs.items())))
        if key in _TRIM_CHECKED:
            return list(_TRIM_CHECKED[key])
        with quiet_stdout():
            Flight(ic, **kwargs)
        problems: list[str] = []
    except TrimError as exc:
        problems = [f"initial: {exc} (check initial.tas_mps against the aircraft's speed range and the "
                    "initial height)"]
    except (ValueError, TypeError, KeyError):
        return []
    if len(_TRIM_CHECKED) >= _TRIM_CHECKED_MAX:
        _TRIM_CHECKED.clear()
    _TRIM_CHECKED[key] = problems
    return list(problems)


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
                       lambda: check_refinement(world, refinement.to_dict())))
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
