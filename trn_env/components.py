"""Scenario data -> the components of a run (terrain, flight, wind, sensors, navigator, guidance).

The one place that knows both the scenario file's layout and the component constructors. `check` builds
each component's configuration from the scenario and turns every rejection into a problem at the field
path, so a scenario is fully checked before the flight starts.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys

import numpy as np

SENSOR_KEYS = ("imu", "baro", "radar_altimeter", "ira", "gnss", "air_data", "heading")


# ----------------------------------------------------------------------------------------------- terrain

def _load_dem(value: str, fill_voids: bool):
    import terrain
    return terrain.load(value, fill_voids=fill_voids)


def build_terrain(d: dict, extras: dict, rng: np.random.Generator):
    """(world DEM, navigator's map DEM) for the scenario; map errors drawn from `rng`."""
    wcfg = d["terrain"]["world"]
    world = extras.get("world_dem_raw") or _load_dem(wcfg["dem"], bool(wcfg.get("fill_voids", False)))
    if wcfg.get("refinement"):
        world = refine_dem(world, wcfg["refinement"], rng)
    mcfg = d["terrain"]["map"]
    if mcfg.get("dem", "world") == "world":
        base = world
    else:
        base = extras.get("map_dem_raw") or _load_dem(mcfg["dem"], bool(mcfg.get("fill_voids", False)))
    err = mcfg.get("error_model")
    the_map = apply_map_errors(base, err, rng) if err else base
    extras["world_dem"] = world
    extras["map_dem"] = the_map
    return world, the_map


def refine_dem(dem, settings: dict, rng: np.random.Generator):
    """Synthetic sub-grid detail on the true terrain (terrain.synthetic)."""
    from terrain import synthetic
    fn = getattr(synthetic, "refine", None) or getattr(synthetic, "add_detail", None)
    if fn is None:
        raise ValueError("terrain.world.refinement: terrain.synthetic has no refine/add_detail function")
    return fn(dem, rng=rng, **settings)


def apply_map_errors(dem, settings: dict, rng: np.random.Generator):
    """The navigator's map = the world with a map error model (terrain.map_error) applied."""
    from terrain import map_error
    settings = dict(settings)
    preset = settings.pop("preset", None)
    fn = getattr(map_error, "apply", None)
    if fn is None:
        raise ValueError("terrain.map.error_model: terrain.map_error has no apply function")
    if preset is not None:
        return fn(dem, preset=preset, rng=rng, **settings)
    return fn(dem, rng=rng, **settings)


def world_height(dem, lat_rad: np.ndarray, lon_rad: np.ndarray) -> np.ndarray:
    """Terrain height (m MSL) at 1-D arrays of positions; NaN off the grid or over voids (bilinear).

    Calls the terrain package's numba batch kernel directly (this runs every guidance tick)."""
    from terrain import kernels
    lat = np.ascontiguousarray(lat_rad, dtype=np.float64).ravel()
    lon = np.ascontiguousarray(lon_rad, dtype=np.float64).ravel()
    out = np.empty(lat.shape[0])
    heights, lat0, lon0, dlat, dlon = dem.grid
    kernels.bilinear_batch(heights, lat0, lon0, dlat, dlon, lat, lon, out)
    return out


def world_contains(dem, lat_rad: np.ndarray, lon_rad: np.ndarray) -> np.ndarray:
    return np.asarray(dem.contains(lat_rad, lon_rad), bool)


def map_height(dem, lat_rad: float, lon_rad: float) -> float:
    """Map height (m MSL) at one position; NaN off the map."""
    return float(dem.height(float(lat_rad), float(lon_rad)))


# ------------------------------------------------------------------------------------------ flight, wind

def build_wind(d: dict):
    """trn_env.wind.WindConfig from the scenario's [wind] table."""
    from .wind import CosineGust, Turbulence, WindConfig
    w = d["wind"]
    layers = [(lay["altitude_m"], lay["direction_from_deg"], lay["speed_mps"]) for lay in w["layers"]]
    t = dict(w.get("turbulence") or {})
    turb = Turbulence(model=t.get("model", "none"), severity=t.get("severity", "light"),
                      windspeed_at_20ft_mps=t.get("windspeed_at_20ft_mps"))
    gusts = []
    for g in w.get("gusts", []):
        g = dict(g)
        if "direction" in g:
            g["direction"] = tuple(g["direction"])
        gusts.append(CosineGust(**g))
    return WindConfig(layers=layers, turbulence=turb, gusts=gusts)


def initial_h_msl_m(d: dict, world) -> float:
    """Initial height above MSL: h_msl_m, or h_agl_m above the TRUE terrain at the start."""
    init = d["initial"]
    if "h_msl_m" in init:
        return float(init["h_msl_m"])
    h_ground = map_height(world, math.radians(init["lat_deg"]), math.radians(init["lon_deg"]))
    return float(init["h_agl_m"]) + h_ground


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


def build_flight(d: dict, world, rng: np.random.Generator):
    """trn_env.flight.Flight at the scenario's initial condition, trimmed, with its wind and a JSBSim seed."""
    from .flight import Flight, InitialCondition
    init = d["initial"]
    lat, lon = math.radians(init["lat_deg"]), math.radians(init["lon_deg"])
    ic = InitialCondition(lat_rad=lat, lon_rad=lon, h_msl_m=initial_h_msl_m(d, world),
                          tas_mps=float(init["tas_mps"]),
                          heading_rad=math.radians(init["heading_deg"]), **d["aircraft"]["settings"])
    seed = int(rng.integers(0, 2**31 - 1))
    with quiet_stdout():
        return Flight(ic, aircraft=d["aircraft"]["name"], dt_s=float(d["aircraft"]["dt_s"]),
                      wind=build_wind(d), seed=seed, terrain_elevation_m=map_height(world, lat, lon))


# ----------------------------------------------------------------------------------------------- sensors

def sensor_configs(d: dict) -> dict:
    """{sensor name: config mapping} of the scenario's [sensors.*] tables (absent = not fitted)."""
    return {name: dict(cfg) for name, cfg in d["sensors"].items()}


def build_sensors(d: dict, seed: np.random.SeedSequence):
    """trn_env.sensors.suite.SensorSuite of the scenario's sensors, one random stream per sensor."""
    from .sensors.suite import SensorSuite
    return SensorSuite.from_config(sensor_configs(d), seed)


def _sensor_problems(d: dict) -> list[str]:
    from .sensors import suite
    problems = []
    for name, cfg in d["sensors"].items():
        try:
            suite._make_config(name, dict(cfg))
        except (ValueError, TypeError) as exc:
            problems.append(f"sensors.{name}: {exc}")
    return problems


# -------------------------------------------------------------------------------------------- navigator

def build_navigator(d: dict, map_dem, rng: np.random.Generator | None = None):
    """navigators.registry.create(name, dem=<the navigator's map>, **settings)."""
    from navigators import registry
    settings = dict(d["navigator"]["settings"])
    settings.setdefault("dem", map_dem)
    return registry.create(d["navigator"]["name"], **settings)


# ------------------------------------------------------------------------------------ component checks

def check(d: dict, extras: dict) -> list[str]:
    """Hand each component its scenario settings; every rejection becomes 'field.path: message'."""
    problems: list[str] = []
    try:
        build_wind(d)
    except (ValueError, TypeError) as exc:
        problems.append(f"wind: {exc}")
    problems += _sensor_problems(d)
    world = extras.get("world_dem_raw")
    the_map = extras.get("map_dem_raw") or world
    err = d["terrain"]["map"].get("error_model")
    if err:
        try:
            the_map = apply_map_errors(the_map, err, np.random.default_rng(0))
        except (ValueError, TypeError, KeyError) as exc:
            problems.append(f"terrain.map.error_model: {exc}")
    if d["terrain"]["world"].get("refinement"):
        try:
            refine_dem(world, d["terrain"]["world"]["refinement"], np.random.default_rng(0))
        except (ValueError, TypeError, KeyError) as exc:
            problems.append(f"terrain.world.refinement: {exc}")
    try:
        build_navigator(d, the_map)
    except (ValueError, TypeError) as exc:
        problems.append(f"navigator.settings: {exc}")
    try:
        init = d["initial"]
        from .flight import InitialCondition
        InitialCondition(lat_rad=math.radians(init["lat_deg"]), lon_rad=math.radians(init["lon_deg"]),
                         h_msl_m=initial_h_msl_m(d, world), tas_mps=float(init["tas_mps"]),
                         heading_rad=math.radians(init["heading_deg"]), **d["aircraft"]["settings"])
    except (ValueError, TypeError) as exc:
        problems.append(f"aircraft.settings: {exc}")
    try:
        build_guidance(d, the_map)
    except (ValueError, TypeError) as exc:
        problems.append(f"route: {exc}")
    return problems


# --------------------------------------------------------------------------------------------- guidance

def track_agl_targets(track_rad: float, agl_m: float, tas_mps: float):
    """Autopilot targets: hold a ground track, a height above ground and a true airspeed."""
    from .flight import AutopilotTargets, LateralMode, SpeedMode, VerticalMode
    return AutopilotTargets(lateral_mode=LateralMode.TRACK, track_cmd_rad=float(track_rad),
                            heading_cmd_rad=float(track_rad), vertical_mode=VerticalMode.HEIGHT_AGL,
                            agl_cmd_m=float(agl_m), speed_mode=SpeedMode.TAS, tas_cmd_mps=float(tas_mps))


def build_route(d: dict):
    """trn_env.guidance.Route of the scenario's waypoints (h_msl_m -> alt_ref msl, h_agl_m -> agl)."""
    from .guidance import Route, Waypoint
    wps = []
    for w in d["route"]["waypoints"]:
        ref, alt = ("agl", w["h_agl_m"]) if "h_agl_m" in w else ("msl", w["h_msl_m"])
        wps.append(Waypoint.from_deg(w["lat_deg"], w["lon_deg"], float(alt), ref))
    return Route(wps)


def build_guidance(d: dict, map_dem=None):
    """trn_env.guidance.Guidance flying the scenario's route at route.tas_mps (route.settings: kwargs)."""
    from .guidance import Guidance
    return Guidance(build_route(d), tas_mps=float(d["route"]["tas_mps"]), **d["route"]["settings"])


def guidance_complete(guidance) -> bool:
    """True once the guidance has passed the route's last waypoint."""
    return bool(getattr(guidance, "done", False))


# ------------------------------------------------------------------------------- terrain information

# bearings (relative to the commanded track) of the terrain-information samples around the estimate
INFO_BEARINGS_RAD = (None, 0.0, -math.pi / 4, math.pi / 4, -math.pi / 2, math.pi / 2)


def local_roughness_m(dem, window_m: float = 1000.0) -> np.ndarray:
    """Standard deviation of the heights (m) in a window_m square around each post: the terrain roughness
    sigma_T that TERCOM's fix accuracy scales with. Used when terrain.metrics is not available."""
    from scipy import ndimage
    dy_m, dx_m = dem.spacing_m
    size = (max(3, int(round(window_m / dy_m)) | 1), max(3, int(round(window_m / dx_m)) | 1))
    h = np.asarray(dem.heights_m, float)
    fill = np.where(np.isfinite(h), h, np.nanmean(h))
    m1 = ndimage.uniform_filter(fill, size, mode="nearest")
    m2 = ndimage.uniform_filter(fill * fill, size, mode="nearest")
    return np.sqrt(np.clip(m2 - m1 * m1, 0.0, None))


def terrain_information_map(dem):
    """The map's terrain-information grid, as a Dem whose heights_m hold the information.

    terrain.metrics.terrain_information_map when the terrain package has it; otherwise the local terrain
    roughness (local_roughness_m)."""
    try:
        from terrain import metrics
        fn = getattr(metrics, "terrain_information_map", None) or getattr(metrics, "information_map", None)
    except ImportError:
        fn = None
    info = fn(dem) if fn is not None else local_roughness_m(dem)
    grid = np.asarray(getattr(info, "heights_m", info), float)
    if grid.shape != dem.heights_m.shape:
        raise ValueError(f"terrain information map shape {grid.shape} differs from the DEM's "
                         f"{dem.heights_m.shape}")
    return dem.with_heights(np.where(np.isfinite(grid), grid, 0.0), name=f"{dem.name}-information")


def sample_information(info_map, dem, lat_rad: float, lon_rad: float, track_rad: float,
                       offset_m: float) -> np.ndarray:
    """Terrain information at the estimate and offset_m away at INFO_BEARINGS_RAD from the track (0 off
    the map)."""
    from terrain.geodesy import ned_offset_to_latlon
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
    return np.where(np.isfinite(vals), vals, 0.0)
