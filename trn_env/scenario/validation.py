"""Scenario validation: a parsed scenario dict checked completely, every problem by field path.

Three passes before any flight starts (trn_env.scenario.loading describes the order and why the schema
checks the dict): every number finite (`nonfinite_problems`), the JSON schema (`schema_problems`, the
schema with the components' generated sections: `schema`), then the semantic checks that need the data and
the components (`_semantic_problems`, trn_env.scenario.build.check). `validate` raises one `ScenarioError`
listing them all or returns the `Scenario` of typed sections.
"""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Mapping
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import jsonschema

from trn_env.scenario.sections import ScenarioSections
from trn_env.scenario.sections import from_dict as from_sections_dict

if TYPE_CHECKING:
    from trn_env.scenario.loading import Scenario


# seed 000 Table 2: initial position error 30 m, 30 m, 15 m (1 sigma); velocity 0.1 m/s; attitude
# 0.05 mrad, 0.05 mrad, 1 mrad (roll, pitch, heading).
DEFAULT_INITIAL_ERRORS: dict[str, list[float]] = {
    "position_ned_m": [30.0, 30.0, 15.0],
    "velocity_ned_mps": [0.1, 0.1, 0.1],
    "attitude_mrad": [0.05, 0.05, 1.0],
}


DEFAULT_SEED = 0


DEFAULT_DURATION_S = 600.0


DEFAULT_GUIDANCE_RATE_HZ = 10.0


DEFAULT_NAVIGATOR_RATE_HZ = 1.0   # navigator updates (sensor frames handed over, estimate published)


DEFAULT_NAVIGATOR_LATENCY_UPDATES = 1   # guidance flies on the previous update's estimate (sim.py)


DEFAULT_MAX_HORIZONTAL_SIGMA_M = 5000.0


class ScenarioError(ValueError):
    """A scenario that cannot be flown. `.problems` lists every problem, each starting with its field path."""

    def __init__(self, source: str, problems: list[str]):
        self.source = source
        self.problems = list(problems)
        lines = "\n".join(f"  - {p}" for p in self.problems)
        super().__init__(f"scenario {source}: {len(self.problems)} problem(s)\n{lines}")


@lru_cache(maxsize=1)
def schema() -> dict:
    """The scenario JSON schema: trn_env/scenario/schema.json with the sections generated from the
    components' Settings classes (trn_env.scenario.schema_sections) in place."""
    from trn_env.scenario.schema_sections import with_generated_sections
    return with_generated_sections(json.loads((Path(__file__).with_name("schema.json")).read_text(
        encoding="utf-8")))


def field_path(parts) -> str:
    """`route.waypoints[2].lat_deg` from a jsonschema absolute path."""
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out or "(top level)"


def _schema_child(node: dict | None, key) -> dict | None:
    """The schema node of `key` (a property name or a list index) below `node`; None if unconstrained."""
    if not isinstance(node, dict):
        return None
    ref = node.get("$ref")
    if isinstance(ref, str) and ref.startswith("#/$defs/"):
        node = schema().get("$defs", {}).get(ref.split("/")[-1], {})
    if isinstance(key, int):
        items = node.get("items")
        return items if isinstance(items, dict) else None
    child = node.get("properties", {}).get(key)
    if child is None and isinstance(node.get("additionalProperties"), dict):
        child = node["additionalProperties"]
    return child


def nonfinite_problems(data, path: tuple = (), node: dict | None = None) -> list[str]:
    """Every NaN or infinite number in the parsed scenario as 'field.path: message' (free-form tables such as
    navigator.settings included); a field whose schema says `"x-allow-nonfinite": true` is exempt."""
    if not path:
        node = schema()
    if isinstance(node, dict) and node.get("x-allow-nonfinite"):
        return []
    if isinstance(data, dict):
        out = []
        for k, v in data.items():
            out += nonfinite_problems(v, path + (k,), _schema_child(node, k))
        return out
    if isinstance(data, (list, tuple)):
        out = []
        for i, v in enumerate(data):
            out += nonfinite_problems(v, path + (i,), _schema_child(node, i))
        return out
    if isinstance(data, float) or type(data).__module__ == "numpy" and hasattr(data, "dtype"):
        try:
            bad = not math.isfinite(float(data))
        except (TypeError, ValueError):
            return []
        if bad:
            return [f"{field_path(path)}: {data!r} is not allowed here (NaN and infinity are refused: give a "
                    "finite number)"]
    return []


def schema_problems(data: dict) -> list[str]:
    """Every JSON-schema violation, as 'field.path: message', in document order."""
    validator = jsonschema.Draft202012Validator(schema())
    problems = []
    for err in sorted(validator.iter_errors(data), key=lambda e: [str(p) for p in e.absolute_path]):
        path = list(err.absolute_path)
        if err.validator == "additionalProperties":
            allowed = sorted(err.schema.get("properties", {}))
            extra = sorted(set(err.instance) - set(allowed)) if isinstance(err.instance, dict) else []
            for key in extra:
                problems.append(f"{field_path(path + [key])}: unknown key "
                                f"(allowed here: {', '.join(allowed)})")
            continue
        if err.validator == "required":
            missing = err.message.split("'")[1] if "'" in err.message else err.message
            problems.append(f"{field_path(path + [missing])}: required key is missing")
            continue
        if err.validator in ("oneOf", "anyOf") and err.context:
            alternatives = sorted({sub.message for sub in err.context if not sub.relative_path})
            problems.append(f"{field_path(path)}: {' / '.join(alternatives)}")
            continue
        problems.append(f"{field_path(path)}: {err.message}")
    return problems


def _fill_defaults(data: dict) -> dict:
    """A copy with every optional key filled; tolerant of malformed data (the schema reports that)."""
    d = copy.deepcopy(data)
    for key in ("initial", "route", "terrain", "navigator"):
        if not isinstance(d.get(key), dict):
            d[key] = {}
    d["terrain"].setdefault("world", {"dem": "jacksboro"})
    if not isinstance(d["terrain"]["world"], dict):
        d["terrain"]["world"] = {"dem": "jacksboro"}
    d["initial"].setdefault("tas_mps", 85.0)
    d.setdefault("description", "")
    d.setdefault("seed", DEFAULT_SEED)
    d.setdefault("duration_s", DEFAULT_DURATION_S)
    d.setdefault("aircraft", {})
    d["aircraft"].setdefault("name", "kingair")
    d["aircraft"].setdefault("dt_s", 0.01)
    d["aircraft"].setdefault("settings", {})
    d["aircraft"].setdefault("constant_fuel", False)
    if not isinstance(d.get("truth"), dict):
        d["truth"] = {}
    d["truth"].setdefault("source", "jsbsim")
    errs = d.setdefault("initial_errors", {})
    for k, v in DEFAULT_INITIAL_ERRORS.items():
        errs.setdefault(k, list(v))
    d["route"].setdefault("tas_mps", d["initial"]["tas_mps"])
    d["route"].setdefault("settings", {})
    d.setdefault("wind", {})
    d["wind"].setdefault("layers", [])
    d["wind"].setdefault("turbulence", {"model": "none"})
    d["wind"].setdefault("gusts", [])
    d["terrain"].setdefault("map", {})
    d["terrain"]["map"].setdefault("dem", "world")
    d["terrain"]["map"].setdefault("faults", [])
    d.setdefault("monitors", {})
    d["terrain"]["world"].setdefault("fill_voids", False)
    d.setdefault("gnss", {})
    d["gnss"].setdefault("outages", [])
    d["navigator"].setdefault("settings", {})
    d["navigator"].setdefault("rate_hz", DEFAULT_NAVIGATOR_RATE_HZ)
    d["navigator"].setdefault("latency_updates", DEFAULT_NAVIGATOR_LATENCY_UPDATES)
    d.setdefault("guidance", {})
    d["guidance"].setdefault("rate_hz", DEFAULT_GUIDANCE_RATE_HZ)
    d["guidance"].setdefault("log_rate_hz", d["navigator"]["rate_hz"])   # rows are logged at updates
    d.setdefault("limits", {})
    d["limits"].setdefault("max_horizontal_sigma_m", DEFAULT_MAX_HORIZONTAL_SIGMA_M)
    return d


def _resolve_dem_path(value: str, base_dir: Path | None) -> str:
    """A DEM value that looks like a relative file path is taken relative to the scenario file; a leading
    `~` is the user's home folder."""
    if value.startswith("~"):
        return str(Path(value).expanduser())
    p = Path(value)
    if base_dir is not None and not p.is_absolute() and (p.suffix or "/" in value):
        cand = base_dir / p
        if cand.exists():
            return str(cand)
    return value


def _semantic_problems(d: dict, base_dir: Path | None, check_components: bool, extras: dict,
                       prior: list[str] | None = None, dems: dict | None = None) -> list[str]:
    """Checks that need more than the schema. With `tolerant` (the data already failed the schema) a
    check that trips over malformed data is skipped instead of raising, so the remaining problems are
    still reported. `prior`: the schema's problems (non-empty makes the checks tolerant)."""
    prior = list(prior or [])
    tolerant = bool(prior)
    problems: list[str] = []
    checks = [_altitude_problems, _gnss_problems, _wind_problems, _rate_problems, _aircraft_problems,
              _navigator_problems, _integrity_problems, _sensor_need_problems,
              lambda dd: _terrain_problems(dd, base_dir, extras, dems),
              lambda dd: _ceiling_problems(dd, extras)]
    for check in checks:
        try:
            problems += check(d)
        except (KeyError, TypeError, ValueError, AttributeError, IndexError, ArithmeticError):
            if not tolerant:
                raise
    sections, section_problems = None, []
    try:
        sections = from_sections_dict(d, problems=section_problems)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, ArithmeticError):
        if not tolerant:
            raise
    known = tuple(p.split(": ", 1)[0] for p in prior + problems)
    problems += [p for p in section_problems if not p.split(": ", 1)[0].startswith(known or ("\0",))]
    if sections is not None:
        known = tuple(p.split(": ", 1)[0] for p in prior + problems)
        problems += [p for p in _sensor_rate_problems(sections)
                     if not p.split(": ", 1)[0].startswith(known or ("\0",)) and "aircraft.dt_s" not in known]
    if check_components and sections is not None:
        problems += _component_problems(sections, extras, prior + problems, tolerant)
    extras["_sections"] = sections
    return problems


def _places(d: dict) -> list[tuple[str, dict]]:
    out = []
    if isinstance(d.get("initial"), dict):
        out.append(("initial", d["initial"]))
    wps = d.get("route", {}).get("waypoints", []) if isinstance(d.get("route"), dict) else []
    for i, w in enumerate(wps if isinstance(wps, list) else []):
        if isinstance(w, dict):
            out.append((f"route.waypoints[{i}]", w))
    return out


def _altitude_problems(d: dict) -> list[str]:
    """Exactly one of h_msl_m / h_agl_m at the initial state and at every waypoint."""
    problems = []
    for path, obj in _places(d):
        n = ("h_msl_m" in obj) + ("h_agl_m" in obj)
        if n != 1:
            problems.append(f"{path}: give exactly one of h_msl_m or h_agl_m (got {n})")
    return problems


def _window(o: dict) -> str:
    return f"[{o['start_s']:g}, {o['end_s']:g}) s" if "end_s" in o else f"[{o['start_s']:g} s, end of flight)"


def _gnss_problems(d: dict) -> list[str]:
    """Each outage window [start_s, end_s) non-empty; the windows in time order and disjoint (touching is
    fine), none after an open window (no end_s: GNSS never returns). Overlaps are refused rather than merged
    so the file says what is flown."""
    problems = []
    outages = d["gnss"]["outages"]
    for i, o in enumerate(outages):
        if "end_s" in o and o["end_s"] <= o["start_s"]:
            problems.append(f"gnss.outages[{i}].end_s: must be after start_s "
                            f"({o['end_s']} <= {o['start_s']})")
    for i in range(1, len(outages)):
        prev, o = outages[i - 1], outages[i]
        if o["start_s"] < prev["start_s"]:
            problems.append(f"gnss.outages[{i}].start_s: the outages must be in time order ({_window(o)} "
                            f"starts before gnss.outages[{i - 1}] {_window(prev)})")
        elif "end_s" not in prev:
            problems.append(f"gnss.outages[{i}]: {_window(o)} lies inside the open outage "
                            f"gnss.outages[{i - 1}] {_window(prev)} (no end_s: GNSS never returns); "
                            f"remove it or give gnss.outages[{i - 1}] an end_s")
        elif o["start_s"] < prev["end_s"]:
            problems.append(f"gnss.outages[{i}]: {_window(o)} overlaps gnss.outages[{i - 1}] "
                            f"{_window(prev)}; give one window from the first start to the last end instead")
    return problems


def _integrity_problems(d: dict) -> list[str]:
    """Map faults that appear after the flight's end; monitors without the sensor they need."""
    problems = []
    for i, f in enumerate(d["terrain"]["map"]["faults"]):
        t = f.get("start_s") if isinstance(f, dict) else None
        if isinstance(t, (int, float)) and t >= d["duration_s"]:
            problems.append(f"terrain.map.faults[{i}].start_s: {t} s is not before the scenario's end "
                            f"(duration_s = {d['duration_s']} s)")
    return problems


def fitted_sensors(d: dict) -> set[str]:
    """The sensors a scenario fits (its [sensors.*] tables that are not false or null)."""
    sensors = d.get("sensors") if isinstance(d.get("sensors"), dict) else {}
    return {n for n, cfg in sensors.items() if cfg is not None and cfg is not False}


def _sensor_need_problems(d: dict) -> list[str]:
    """Every sensor the navigator or a monitor requires (its declared capabilities, with its settings) that
    the scenario does not fit, as 'sensors.<name>: ...': refused before anything runs. A component whose
    settings are refused is left to the settings check."""
    from trn_env.navigators import registry
    from trn_env.navigators.core.settings import SettingsError
    fitted = fitted_sensors(d)
    problems = []
    nav_settings = d["navigator"]["settings"] if isinstance(d["navigator"]["settings"], dict) else {}
    users = [("navigator", d["navigator"]["name"], lambda n: registry.sensor_needs(n, nav_settings))]
    mons = d["monitors"] if isinstance(d["monitors"], dict) else {}
    for name in sorted(mons):
        users.append(("monitor", name, lambda n: registry.monitor_sensor_needs(
            n, mons[n] if isinstance(mons[n], dict) else {})))
    for kind, name, needs_of in users:
        try:
            needs = needs_of(name)
        except (SettingsError, ValueError, TypeError):
            continue
        for sensor, why in needs.required.items():
            if sensor not in fitted:
                where = "navigator.name" if kind == "navigator" else f"monitors.{name}"
                problems.append(f"sensors.{sensor}: {kind} {name!r} needs this sensor ({why}); add a "
                                f"[sensors.{sensor}] table or choose another {kind} ({where})")
    return problems


def _wind_problems(d: dict) -> list[str]:
    problems = []
    hs = [layer["altitude_m"] for layer in d["wind"]["layers"]]
    for i in range(1, len(hs)):
        if hs[i] <= hs[i - 1]:
            problems.append(f"wind.layers[{i}].altitude_m: altitudes must increase ({hs[i]} <= {hs[i - 1]})")
    return problems


def _whole(x: float) -> bool:
    return abs(x - round(x)) <= 1e-6 and round(x) >= 1


def _rate_problems(d: dict) -> list[str]:
    g, nav, log = d["guidance"]["rate_hz"], d["navigator"]["rate_hz"], d["guidance"]["log_rate_hz"]
    problems = []
    if not _whole(1.0 / (g * d["aircraft"]["dt_s"])):
        problems.append(f"guidance.rate_hz: {g} Hz is not a whole number of "
                        f"JSBSim steps of aircraft.dt_s = {d['aircraft']['dt_s']} s")
    if not _whole(g / nav):
        problems.append(f"navigator.rate_hz: {nav} Hz must divide guidance.rate_hz = {g} Hz (a whole number "
                        "of guidance ticks per navigator update)")
    if not _whole(nav / log):
        problems.append(f"guidance.log_rate_hz: {log} Hz must divide navigator.rate_hz = {nav} Hz (rows are "
                        "logged at navigator updates)")
    return problems


def _sensor_rate_problems(sections) -> list[str]:
    """Every fitted sensor's rate at most the truth's step rate (1 / aircraft.dt_s, JSBSim's or the kinematic
    profile's): a sensor samples the truth's steps (trn_env.sensors.common.sample_steps refuses a finer
    grid during the flight; here it is found before it)."""
    dt_s = float(sections.aircraft.dt_s)
    if not dt_s > 0.0:
        return []                  # aircraft.dt_s's own problem
    truth_hz = 1.0 / dt_s
    problems = []
    for name, config in sections.sensors.configs().items():
        rate_hz = getattr(config, "rate_hz", None)
        if rate_hz is None or float(rate_hz) * dt_s <= 1.0 + 1e-6:
            continue
        given = sections.sensors.table(name)
        how = "" if isinstance(given, Mapping) and "rate_hz" in given else " (the sensor's default)"
        problems.append(f"sensors.{name}.rate_hz: {float(rate_hz):g} Hz{how} is faster than the truth's "
                        f"{truth_hz:g} Hz steps (aircraft.dt_s = {dt_s:g} s): a sensor samples the truth's "
                        f"steps; set sensors.{name}.rate_hz to at most {truth_hz:g} or a smaller "
                        "aircraft.dt_s")
    return problems


def _aircraft_problems(d: dict) -> list[str]:
    from trn_env.flight.aircraft_data import available_aircraft
    try:
        known = available_aircraft()
    except FileNotFoundError as exc:
        return [f"aircraft.name: {exc}"]
    if d["aircraft"]["name"] not in known:
        return [f"aircraft.name: unknown aircraft {d['aircraft']['name']!r} "
                f"(available: {', '.join(known) or 'none'})"]
    return _fuel_problems(d)


def _fuel_problems(d: dict) -> list[str]:
    """aircraft.fuel_kg finite, > 0 and within the aircraft's tank capacity; not given twice."""
    from trn_env.flight.aircraft_data import fuel_tanks_kg
    fuel_kg = d["aircraft"].get("fuel_kg")
    if fuel_kg is None or isinstance(fuel_kg, bool) or not isinstance(fuel_kg, int | float):
        return []   # absent (the aircraft file's load), or a type error the schema reports
    capacity_kg = sum(fuel_tanks_kg(d["aircraft"]["name"]).values())
    if not math.isfinite(fuel_kg) or fuel_kg <= 0.0:
        return [f"aircraft.fuel_kg: must be a finite number > 0 kg, got {fuel_kg}"]
    if fuel_kg > capacity_kg * (1.0 + 1e-9):
        return [f"aircraft.fuel_kg: {fuel_kg} kg is more than the fuel tanks of {d['aircraft']['name']!r} "
                f"hold ({capacity_kg:.1f} kg)"]
    settings = d["aircraft"]["settings"]
    if isinstance(settings, dict) and ({"fuel_kg", "fuel_fraction"} & set(settings)):
        return ["aircraft.fuel_kg: give the fuel load once (aircraft.fuel_kg or aircraft.settings."
                f"{'fuel_kg' if 'fuel_kg' in settings else 'fuel_fraction'}, not both)"]
    return []


def _navigator_problems(d: dict) -> list[str]:
    """navigator.name: a built-in, an installed plug-in (entry point) or an importable `module:Name`
    reference to a navigator; monitors.<name> likewise for monitors (navigators.registry.resolve)."""
    from trn_env.navigators import registry
    problems = []
    try:
        registry.resolve(d["navigator"]["name"], "navigator")
    except ValueError as exc:
        problems.append(f"navigator.name: {exc}")
    mons = d.get("monitors")
    for name in sorted(mons) if isinstance(mons, dict) else ():
        try:
            registry.resolve(name, "monitor")
        except ValueError as exc:
            problems.append(f"monitors.{name}: {exc}")
    return problems


def _load_dem(value: str, fill_voids: bool):
    from trn_env import terrain
    return terrain.load(value, fill_voids=fill_voids)


def _terrain_problems(d: dict, base_dir: Path | None, extras: dict, dems_loaded: dict | None = None
                      ) -> list[str]:
    """DEM files readable; the initial position and every waypoint inside the world and the map.
    `dems_loaded`: validate's `dems`."""
    problems: list[str] = []
    # a position that is no position on Earth (NaN, infinite, beyond the poles) is the schema's problem
    places = [(path, obj) for path, obj in _places(d)
              if -90.0 <= obj["lat_deg"] <= 90.0 and -180.0 <= obj["lon_deg"] <= 180.0]
    world_cfg = d["terrain"]["world"]
    world_cfg["dem"] = _resolve_dem_path(world_cfg["dem"], base_dir)
    map_cfg = d["terrain"]["map"]
    if map_cfg["dem"] != "world":
        map_cfg["dem"] = _resolve_dem_path(map_cfg["dem"], base_dir)
    for fault in map_cfg.get("faults") or []:
        if isinstance(fault, dict) and isinstance(fault.get("source_dem"), str):
            fault["source_dem"] = _resolve_dem_path(fault["source_dem"], base_dir)
    dems = {}
    dems_loaded = {} if dems_loaded is None else dems_loaded     # a map naming the world's DEM: read once
    for key, cfg in (("world", world_cfg), ("map", map_cfg)):
        if key == "map" and cfg["dem"] == "world":
            continue
        spec = (cfg["dem"], bool(cfg.get("fill_voids", world_cfg["fill_voids"])))
        if spec in dems_loaded:
            dems[key] = dems_loaded[spec]
            continue
        try:
            dems[key] = _load_dem(*spec)
        except Exception as exc:  # noqa: BLE001 - any loader failure is a problem to report
            problems.append(f"terrain.{key}.dem: cannot load DEM {cfg['dem']!r}: {exc}")
            continue
        dems_loaded[spec] = dems[key]
    extras["world_dem_raw"] = dems.get("world")
    extras["map_dem_raw"] = dems.get("map")
    region = (world_cfg.get("refinement") or {}).get("region_deg")
    if region is not None:
        lat0, lat1, lon0, lon1 = region
        for path, obj in places:
            if not (lat0 <= obj["lat_deg"] <= lat1 and lon0 <= obj["lon_deg"] <= lon1):
                problems.append(f"{path}: ({obj['lat_deg']:.5f}, {obj['lon_deg']:.5f}) deg is outside "
                                f"terrain.world.refinement.region_deg {list(region)}")
    for key, dem in dems.items():
        lat_min, lat_max, lon_min, lon_max = dem.bounds
        for path, obj in places:
            lat, lon = math.radians(obj["lat_deg"]), math.radians(obj["lon_deg"])
            if not (lat_min <= lat <= lat_max and lon_min <= lon <= lon_max):
                across = lat_min <= lat <= lat_max and any(lon_min <= lon + k * 2.0 * math.pi <= lon_max
                                                           for k in (-1, 1))
                problems.append(
                    f"{path}: ({obj['lat_deg']:.5f}, {obj['lon_deg']:.5f}) deg is outside the "
                    f"{'true terrain' if key == 'world' else 'navigator map'} terrain.{key}.dem "
                    f"(lat {math.degrees(lat_min):.4f}..{math.degrees(lat_max):.4f}, "
                    f"lon {math.degrees(lon_min):.4f}..{math.degrees(lon_max):.4f} deg)"
                    + (": the DEM crosses the antimeridian and this place lies on its other side; trn-env "
                       "does not fly across 180 deg: keep the flight on one side (a DEM cropped to it)"
                       if across else ""))
            elif (key == "world" and path == "initial" and not math.isfinite(float(dem.height(lat, lon)))
                  and ("h_agl_m" in obj or d["truth"]["source"] != "kinematic")):
                # JSBSim starts on the ground's height there, and h_agl_m is taken above it
                fill = "" if world_cfg.get("fill_voids") else ", or set terrain.world.fill_voids = true"
                problems.append(f"{path}: ({obj['lat_deg']:.5f}, {obj['lon_deg']:.5f}) deg is over a void of "
                                f"the true terrain terrain.world.dem (no height there, and the flight starts "
                                f"on the ground's height): move the start{fill}")
            elif key == "world" and "h_msl_m" in obj:
                h_ground = float(dem.height(lat, lon))
                if math.isfinite(h_ground) and obj["h_msl_m"] <= h_ground:
                    problems.append(f"{path}.h_msl_m: {obj['h_msl_m']} m is at or below the terrain "
                                    f"({h_ground:.0f} m MSL there)")
    return problems


def _ceiling_problems(d: dict, extras: dict) -> list[str]:
    """The initial height and every waypoint at or below the aircraft's service ceiling (above it the
    aircraft cannot trim or cannot climb to the route: refused before the flight). A height above ground is
    taken over the true terrain there."""
    from trn_env.flight.aircraft_data import service_ceiling_m
    if d["truth"]["source"] == "kinematic":
        return []   # a prescribed profile, no aircraft to trim or climb
    ceiling = service_ceiling_m(d["aircraft"]["name"])
    if ceiling is None:
        return []
    world = extras.get("world_dem_raw")
    problems = []
    for path, obj in _places(d):
        if "h_msl_m" in obj:
            key, h = "h_msl_m", float(obj["h_msl_m"])
        elif "h_agl_m" in obj and world is not None:
            ground = float(world.height(math.radians(obj["lat_deg"]), math.radians(obj["lon_deg"])))
            if not math.isfinite(ground):
                continue
            key, h = "h_agl_m", float(obj["h_agl_m"]) + ground
        else:
            continue
        if h > ceiling:
            height = f"{h:.0f}" if abs(h) < 1e7 else f"{h:.3g}"
            problems.append(f"{path}.{key}: {height} m MSL is above the {d['aircraft']['name']}'s service "
                            f"ceiling ({ceiling:.0f} m): it cannot fly there")
    return problems


def _component_problems(sections: ScenarioSections, extras: dict, known: list[str],
                        tolerant: bool) -> list[str]:
    """Hand each component its settings; whatever it rejects becomes a problem at that field. Components
    whose fields already have a problem are not built (no duplicate or follow-on messages)."""
    import trn_env.scenario.build as components
    return components.check(sections, extras, known, tolerant)


def validate(data: dict, *, source: str = "<dict>", base_dir: Path | None = None,
             check_components: bool = True, dems: dict | None = None) -> Scenario:
    """Validate a parsed scenario (schema, then semantics) and build its typed sections
    (trn_env.scenario.sections.from_dict); raise ScenarioError listing every problem.

    A DEM named by both the world and the map (with the same fill_voids) is read once, one Dem for both.
    `dems`: DEMs loaded by earlier validations, {(the DEM as the scenario names it, resolved; fill_voids):
    trn_env.terrain.Dem}, read and extended here: the scenarios of one campaign share one dict, so each DEM
    is read once (and a file changed in between is not read again). Shared Dems are never modified (their
    heights are read-only; map errors and faults make new ones)."""
    from trn_env.scenario.loading import Scenario  # (loading imports this module)
    problems = nonfinite_problems(data)
    bad_paths = tuple(p.split(": ", 1)[0] for p in problems)
    problems += [p for p in schema_problems(data) if not p.split(": ", 1)[0].startswith(bad_paths or ("\0",))]
    extras: dict = {}
    try:
        d = _fill_defaults(data)
    except (KeyError, TypeError, ValueError, AttributeError):
        if not problems:
            raise
        raise ScenarioError(source, problems) from None
    problems += _semantic_problems(d, base_dir, check_components, extras, prior=problems, dems=dems)
    sections = extras.pop("_sections", None)
    if problems:
        raise ScenarioError(source, problems)
    return Scenario(name=sections.name, source=source, sections=sections, description=sections.description,
                    seed=int(sections.seed), duration_s=float(sections.duration_s), extras=extras)
