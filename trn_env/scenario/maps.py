"""The terrain components of a scenario: the true world DEM (with its refinement), the navigator's map
(with its error model and faults), height and containment queries on them, and the terrain information
map the planner and the information-seeking guidance sample. Part of trn_env.scenario.build (which
re-exports every name here).
"""

from __future__ import annotations

import hashlib
import math

import numpy as np
from numba import njit

from trn_env.terrain.kernels import bilinear


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


def _refine_kwargs(settings: dict) -> dict:
    kw = dict(settings)
    if "region_deg" in kw:
        kw["region"] = tuple(math.radians(x) for x in kw.pop("region_deg"))
    return kw


def refine_dem(dem, settings: dict, rng: np.random.Generator):
    """The true terrain with synthetic sub-grid detail (terrain.refine.refine; region_deg in degrees)."""
    from trn_env.terrain.refine import refine
    return refine(dem, seed=rng, **_refine_kwargs(settings))


def check_refinement(dem, settings: dict) -> None:
    """Raise what refine_dem(dem, settings, rng) would raise, without building the refined grid (a tenth
    of a second and up per scenario validated): the arguments, the region and the size
    (terrain.refine.refinement_plan), and the coarse spectrum's fit that the detail continues."""
    import inspect

    from trn_env.terrain.refine import fit_dem_spectrum, refine, refinement_plan
    kw = _refine_kwargs(settings)
    try:
        inspect.signature(refine).bind(dem, seed=None, **kw)
    except TypeError as exc:                                    # a field refine does not take
        raise TypeError(f"refine() {exc}") from None
    plan = refinement_plan(dem, **{k: kw[k] for k in ("spacing_m", "region", "max_posts") if k in kw})
    if kw.get("detail", True):
        coarse = dem.subset(*plan.region) if kw.get("region") is not None else dem
        key = (hashlib.blake2b(np.ascontiguousarray(coarse.heights_m).tobytes(), digest_size=16).digest(),
               tuple(coarse.spacing_m))
        if key not in _SPECTRUM_FITTED:
            fit_dem_spectrum(coarse)
            if len(_SPECTRUM_FITTED) >= 256:
                _SPECTRUM_FITTED.clear()
            _SPECTRUM_FITTED.add(key)


# the coarse grids (heights' digest, spacing) whose spectrum check_refinement has fitted: a campaign
# validates the same terrain once per sweep point and navigator, and the fit costs tens of milliseconds
_SPECTRUM_FITTED: set[tuple[bytes, tuple[float, float]]] = set()


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
