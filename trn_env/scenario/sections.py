"""The validated scenario as typed, frozen sections.

A scenario file is a dict only until it is validated (TOML load, ``--set`` overrides, campaign sweep paths
work on the dict). `from_dict` turns the validated dict (defaults filled in by the loader) into one
`ScenarioSections` of frozen dataclasses, one per table of the file; every component reads attributes of
these (``scenario.route.waypoints[0].lat_deg``), never ``d["route"]["waypoints"][0]["lat_deg"]``.
`to_dict` gives the dict back (``to_dict(from_dict(d)) == d``), which is what the resolved ``scenario.toml``,
``summary.json`` and campaign rows are written from.

Field names are the file's keys and carry their unit (``lat_deg``, ``tas_mps``, ``duration_s``); a field is
None where the file leaves an optional key out (``Waypoint.h_msl_m`` when the waypoint gives ``h_agl_m``).
Numbers keep the type the file gave them (a ``float`` field may hold an int), so a component sees exactly
the values it saw when the scenario travelled as a dict.

Where a component declares its settings (navigators.core.settings), the section holds that component's
`Settings` object too: the fitted sensors' configs (`SensorsSection.imu` is a trn_env.sensors.imu.ImuConfig,
...) and the navigator's settings (`NavigatorSection.settings`, from the registry's declared settings class;
None for a plug-in that declares none). Free-form tables (``aircraft.settings``, ``route.settings``, the
navigator's and monitors' tables as written) are `Table`: a read-only mapping.

Problems found while building (a setting a component's Settings class refuses beyond what the schema says)
are raised together as one `SectionsError` whose `.problems` are 'field.path: message' strings.

The module is one data model, a declaration per table of the file, read together; it runs a little over
the project's ~600 lines for that reason rather than splitting the model across files.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, fields
from functools import cache
from typing import Any


class SectionsError(ValueError):
    """The validated dict could not be turned into sections; `.problems` are 'field.path: message'."""

    def __init__(self, problems: list[str]):
        self.problems = list(problems)
        super().__init__("; ".join(self.problems))


def _freeze(v: Any) -> Any:
    if isinstance(v, Mapping):
        return Table(v)
    if isinstance(v, list | tuple):
        return tuple(_freeze(x) for x in v)
    return v


def _thaw(v: Any) -> Any:
    if isinstance(v, Table):
        return v.to_dict()
    if isinstance(v, Section):
        return v.to_dict()
    if isinstance(v, tuple):
        return [_thaw(x) for x in v]
    return v


class Table(Mapping):
    """A read-only mapping (a free-form table of the scenario: keyword settings of a component); nested
    tables are Tables and lists are tuples. `to_dict()` gives plain dicts and lists back."""

    __slots__ = ("_items",)

    def __init__(self, mapping: Mapping | None = None):
        object.__setattr__(self, "_items", {str(k): _freeze(v) for k, v in (mapping or {}).items()})

    def __getitem__(self, key: str) -> Any:
        return self._items[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("a scenario Table is read-only")

    def __repr__(self) -> str:
        return f"Table({self._items!r})"

    def __hash__(self) -> int:
        return hash(tuple(self._items))

    def __getstate__(self):
        return self._items

    def __setstate__(self, state):
        object.__setattr__(self, "_items", state)

    def to_dict(self) -> dict[str, Any]:
        """The table as a plain dict (nested tables dicts, sequences lists): a copy the caller may edit."""
        return {k: _thaw(v) for k, v in self._items.items()}


# ------------------------------------------------------------------------------------------- the base

@cache
def _hints(cls) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _inner(tp) -> Any:
    """The non-None member of `X | None`, else tp."""
    args = [a for a in typing.get_args(tp) if a is not type(None)]
    if type(None) in typing.get_args(tp) and len(args) == 1:
        return args[0]
    return tp


def _convert(tp, value: Any, path: str, problems: list[str]) -> Any:
    tp = _inner(tp)
    origin = typing.get_origin(tp)
    if isinstance(tp, type) and issubclass(tp, Section):
        return tp.from_mapping(value, path, problems)
    if origin is tuple:
        (item_tp, *_rest) = typing.get_args(tp)
        if not isinstance(value, list | tuple):
            problems.append(f"{path}: must be a list, got {value!r}")
            return ()
        return tuple(_convert(item_tp, x, f"{path}[{i}]", problems) for i, x in enumerate(value))
    if tp is Table:
        if not isinstance(value, Mapping):
            problems.append(f"{path}: must be a table, got {value!r}")
            return Table()
        return Table(value)
    return value


class Section:
    """Base of the sections: frozen dataclasses whose fields are the file's keys. `from_mapping` builds one
    from its table (nested sections, lists of sections and free-form tables by the field's annotation);
    `to_dict` writes the table back, leaving out the optional keys that are None."""

    @classmethod
    def from_mapping(cls, mapping: Any, path: str, problems: list[str]):
        if not isinstance(mapping, Mapping):
            problems.append(f"{path}: must be a table, got {mapping!r}")
            mapping = {}
        hints = _hints(cls)
        names = {f.name for f in fields(cls) if f.init}
        for key in mapping:
            if key not in names:
                problems.append(f"{path}.{key}: unknown key (allowed here: {', '.join(sorted(names))})")
        kw = {}
        for f in fields(cls):
            if f.init and f.name in mapping:
                kw[f.name] = _convert(hints[f.name], mapping[f.name], f"{path}.{f.name}", problems)
        missing = [f.name for f in fields(cls) if f.init and f.name not in kw
                   and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING]
        for name in missing:
            problems.append(f"{path}.{name}: required key is missing")
            kw[name] = None
        return cls(**kw)

    def to_dict(self) -> dict[str, Any]:
        """The section as the scenario file's table (plain dicts and lists; absent optional keys left out)."""
        return {f.name: _thaw(getattr(self, f.name)) for f in fields(self)
                if f.init and getattr(self, f.name) is not None}


def _top_path(path: str, name: str) -> str:
    return f"{path}.{name}" if path else name


# ----------------------------------------------------------------------------------------- aircraft

@dataclass(frozen=True)
class AircraftSection(Section):
    """[aircraft]: the JSBSim aircraft and its loading."""

    name: str = "kingair"            # aircraft folder under aircraft/
    dt_s: float = 0.01               # JSBSim integration step, s
    fuel_kg: float | None = None     # fuel at the start, kg (None: the aircraft file's load)
    constant_fuel: bool = False      # tanks frozen for the whole flight
    settings: Table = field(default_factory=Table)   # extra keyword arguments of the initial condition


@dataclass(frozen=True)
class Segment(Section):
    """One leg of a kinematic truth profile ([[truth.segments]])."""

    kind: str                                 # straight | turn | climb
    duration_s: float
    bank_deg: float | None = None
    flight_path_deg: float | None = None
    transition_s: float | None = None         # raised-cosine blend from the previous leg, s


@dataclass(frozen=True)
class TruthSection(Section):
    """[truth]: where the true motion comes from (jsbsim, or a prescribed kinematic profile)."""

    source: str = "jsbsim"
    speed_mps: float | None = None            # kinematic true airspeed (None: initial.tas_mps)
    segments: tuple[Segment, ...] | None = None

    @property
    def is_kinematic(self) -> bool:
        return self.source == "kinematic"


# ----------------------------------------------------------------------------------- initial state, route

@dataclass(frozen=True)
class InitialSection(Section):
    """[initial]: the aircraft's state at the start (WGS84; exactly one of h_msl_m / h_agl_m)."""

    lat_deg: float
    lon_deg: float
    tas_mps: float = 85.0                     # true airspeed, m/s
    heading_deg: float = 0.0                  # true heading, clockwise from north, deg
    h_msl_m: float | None = None              # height above MSL, m
    h_agl_m: float | None = None              # height above the world's terrain, m


@dataclass(frozen=True)
class InitialErrorsSection(Section):
    """[initial_errors]: 1-sigma errors of the navigator's initial estimate (seed 000 Table 2)."""

    position_ned_m: tuple[float, ...] = (30.0, 30.0, 15.0)
    velocity_ned_mps: tuple[float, ...] = (0.1, 0.1, 0.1)
    attitude_mrad: tuple[float, ...] = (0.05, 0.05, 1.0)      # roll, pitch, yaw


@dataclass(frozen=True)
class Waypoint(Section):
    """One route waypoint (exactly one of h_msl_m / h_agl_m; h_agl_m is over the navigator's map)."""

    lat_deg: float
    lon_deg: float
    h_msl_m: float | None = None
    h_agl_m: float | None = None

    @property
    def altitude(self) -> tuple[str, float]:
        """("agl", h_agl_m) or ("msl", h_msl_m): the height reference and value, m."""
        return ("agl", self.h_agl_m) if self.h_agl_m is not None else ("msl", self.h_msl_m)


@dataclass(frozen=True)
class RouteSection(Section):
    """[route]: the waypoints guidance flies on the estimate, at tas_mps."""

    waypoints: tuple[Waypoint, ...]
    tas_mps: float = 85.0
    settings: Table = field(default_factory=Table)   # extra keyword arguments of the guidance law


# --------------------------------------------------------------------------------- wind, atmosphere

@dataclass(frozen=True)
class WindLayer(Section):
    """A steady wind layer: the wind blows FROM direction_from_deg (clockwise from true north)."""

    altitude_m: float                # MSL
    direction_from_deg: float
    speed_mps: float


@dataclass(frozen=True)
class Turbulence(Section):
    """JSBSim's turbulence model (none, milspec, tustin) with a MIL-F-8785C severity."""

    model: str = "none"
    severity: str | int | None = None
    windspeed_at_20ft_mps: float | None = None


@dataclass(frozen=True)
class Gust(Section):
    """A discrete 1 - cosine gust."""

    start_time_s: float
    magnitude_mps: float
    direction: tuple[float, ...] | None = None   # in `frame`, normalised by JSBSim
    startup_s: float | None = None
    steady_s: float | None = None
    end_s: float | None = None
    frame: str | None = None                     # ned | body | wind


@dataclass(frozen=True)
class WindSection(Section):
    """[wind]: steady layers, turbulence, gusts (trn_env.flight.wind.WindConfig)."""

    layers: tuple[WindLayer, ...] = ()
    turbulence: Turbulence = field(default_factory=Turbulence)
    gusts: tuple[Gust, ...] = ()


@dataclass(frozen=True)
class AtmosphereSection(Section):
    """[atmosphere]: ISA offset by delta_T_K, sea-level pressure p_sl_pa (absent: standard day)."""

    delta_T_K: float | None = None
    p_sl_pa: float | None = None


# ------------------------------------------------------------------------------------------- terrain

@dataclass(frozen=True)
class Refinement(Section):
    """[terrain.world.refinement]: synthetic sub-grid detail on the true terrain (terrain.refine.refine)."""

    spacing_m: float
    region_deg: tuple[float, ...] | None = None     # lat_min, lat_max, lon_min, lon_max
    detail: bool | None = None


@dataclass(frozen=True)
class WorldSection(Section):
    """[terrain.world]: the true terrain the aircraft flies over."""

    dem: str                                         # built-in name or file path (made absolute)
    fill_voids: bool = False
    refinement: Refinement | None = None


@dataclass(frozen=True)
class MapFault(Section):
    """One regional fault of the navigator's map ([[terrain.map.faults]], terrain.map_error.MapFault)."""

    kind: str                                        # bias | ramp | spike | shift | stale
    center_lat_deg: float
    center_lon_deg: float
    size_n_m: float
    size_e_m: float
    start_s: float | None = None
    bias_m: float | None = None
    direction_deg: float | None = None
    shift_n_m: float | None = None
    shift_e_m: float | None = None
    source_dem: str | None = None
    source_offset_n_m: float | None = None
    source_offset_e_m: float | None = None


@dataclass(frozen=True)
class MapErrorModel(Section):
    """[terrain.map.error_model] (terrain.map_error.MapErrorModel): a preset accuracy class drawn from the
    seed and/or explicit fields that set or override it (None: not given)."""

    preset: str | None = None                  # DEM accuracy class: srtm, cartodem, aster, dted0/1/2
    bias_fraction: float | None = None         # with a preset: share of the vertical variance as one bias
    bias_m: float | None = None                # constant vertical offset, m
    tilt_n: float | None = None                # vertical ramp, m per m north of the grid centre
    tilt_e: float | None = None                # vertical ramp, m per m east of the grid centre
    random_sigma_m: float | None = None        # correlated random vertical error, 1 sigma, m
    correlation_length_m: float | None = None  # its correlation length, m
    correlation_function: str | None = None    # its covariance (terrain.map_error.correlation)
    shift_n_m: float | None = None             # horizontal shift north, m
    shift_e_m: float | None = None             # horizontal shift east, m
    spacing_arcsec: float | None = None        # coarser (area-averaged) post spacing, arcsec

    def __bool__(self) -> bool:
        """False for an empty table: no error model (the map is its DEM as published)."""
        return bool(self.to_dict())


@dataclass(frozen=True)
class MapSection(Section):
    """[terrain.map]: the navigator's terrain database ("world" = the true terrain, unrefined), its error
    model (terrain.map_error: a preset accuracy class and/or MapErrorModel fields) and regional faults."""

    dem: str = "world"
    fill_voids: bool | None = None
    error_model: MapErrorModel | None = None
    faults: tuple[MapFault, ...] = ()

    @property
    def is_world(self) -> bool:
        return self.dem == "world"


@dataclass(frozen=True)
class TerrainSection(Section):
    """[terrain]: the true terrain (world) and the navigator's map."""

    world: WorldSection
    map: MapSection = field(default_factory=MapSection)


# ------------------------------------------------------------------------------------------- sensors

SENSOR_KEYS = ("imu", "baro", "radar_altimeter", "ira", "gnss", "air_data", "heading")


@dataclass(frozen=True)
class SensorsSection:
    """[sensors.*]: each fitted sensor's config (the sensor's Settings class: trn_env.sensors.imu.ImuConfig,
    ...), None where not fitted; `tables` holds the tables as written (what `to_dict` gives back)."""

    imu: Any = None
    baro: Any = None
    radar_altimeter: Any = None
    ira: Any = None
    gnss: Any = None
    air_data: Any = None
    heading: Any = None
    tables: Table = field(default_factory=Table)

    @classmethod
    def from_mapping(cls, mapping: Any, path: str, problems: list[str]) -> SensorsSection:
        from trn_env.navigators.core.settings import SettingsError
        from trn_env.sensors import suite
        mapping = mapping if isinstance(mapping, Mapping) else {}
        kw: dict[str, Any] = {}
        for name, value in mapping.items():
            if name not in SENSOR_KEYS:
                problems.append(f"{path}.{name}: unknown sensor (known: {', '.join(SENSOR_KEYS)})")
                continue
            try:
                kw[name] = suite._make_config(name, True if value == {} else
                                              (dict(value) if isinstance(value, Mapping) else value))
            except SettingsError as exc:
                problems += exc.at(f"{path}.{name}")
            except (ValueError, TypeError) as exc:
                problems.append(f"{path}.{name}: {exc}")
        return cls(**kw, tables=Table(mapping))

    @property
    def fitted(self) -> tuple[str, ...]:
        """Names of the fitted sensors, in SENSOR_KEYS order."""
        return tuple(n for n in SENSOR_KEYS if getattr(self, n) is not None)

    def configs(self) -> dict[str, Any]:
        """{name: config} of the fitted sensors (trn_env.sensors.suite.SensorSuite takes it)."""
        return {n: getattr(self, n) for n in self.fitted}

    def table(self, name: str) -> Table | None:
        """The [sensors.<name>] table as written (None: not fitted)."""
        return self.tables.get(name)

    def without(self, *names: str) -> SensorsSection:
        """A copy with the sensors `names` not fitted."""
        return dataclasses.replace(self, **{n: None for n in names},
                                   tables=Table({k: v for k, v in self.tables.items() if k not in names}))

    def to_dict(self) -> dict[str, Any]:
        return self.tables.to_dict()


# ------------------------------------------------------------------------------------ gnss, navigator

@dataclass(frozen=True)
class Outage(Section):
    """A GNSS outage [start_s, end_s); end_s None = for the rest of the flight."""

    start_s: float
    end_s: float | None = None


@dataclass(frozen=True)
class GnssSection(Section):
    """[gnss]: when GNSS fixes reach the navigator."""

    outages: tuple[Outage, ...] = ()


@dataclass(frozen=True)
class NavigatorSection:
    """[navigator]: the navigator's name (built-in, plug-in or module:Name), its settings as written
    (`table`) and as its declared Settings class reads them (`settings`; None for a plug-in without one),
    its update rate and the guidance's latency in updates."""

    name: str
    table: Table = field(default_factory=Table)
    settings: Any = None
    rate_hz: float = 1.0
    latency_updates: int = 1

    @classmethod
    def of(cls, name: str, settings: Mapping | None = None, *, rate_hz: float = 1.0, latency_updates: int = 1,
           strict: bool = True) -> NavigatorSection:
        """The section of navigator `name` with `settings` (a mapping). `strict`: raise SectionsError for
        settings its Settings class refuses; else keep them as written with `settings` None (building the
        navigator then reports them, as registry.create does)."""
        problems: list[str] = []
        out = cls.from_mapping({"name": name, "settings": dict(settings or {}), "rate_hz": rate_hz,
                                "latency_updates": latency_updates}, "navigator", problems)
        if problems and strict:
            raise SectionsError(problems)
        return out

    @classmethod
    def from_mapping(cls, mapping: Any, path: str, problems: list[str]) -> NavigatorSection:
        from trn_env.navigators import registry
        from trn_env.navigators.core.settings import SettingsError
        mapping = dict(mapping) if isinstance(mapping, Mapping) else {}
        name = mapping.get("name")
        table = mapping.get("settings") or {}
        settings = None
        try:
            caps = registry.capabilities(name)
        except (ValueError, TypeError) as exc:
            problems.append(f"{path}.name: {exc}")
            caps = None
        if caps is not None and caps.settings is not None:
            skip = ("dem", "rng", "name") + registry.PUBLISHED_INTEGRITY_KEYS
            try:
                settings = caps.settings.from_mapping({k: v for k, v in table.items() if k not in skip})
            except SettingsError as exc:
                problems += exc.at(f"{path}.settings")
        kw = {k: mapping[k] for k in ("rate_hz", "latency_updates") if k in mapping}
        return cls(name=name, table=Table(table), settings=settings, **kw)

    def with_name(self, name: str) -> NavigatorSection:
        """The navigator `name` at this one's rate and latency, with no settings (settings belong to the
        navigator they were written for)."""
        problems: list[str] = []
        out = NavigatorSection.from_mapping({**self.to_dict(), "name": name, "settings": {}}, "navigator",
                                            problems)
        if problems:
            raise SectionsError(problems)
        return out

    def with_settings(self, **updates: Any) -> NavigatorSection:
        """A copy whose settings table has `updates` on top (its Settings object rebuilt from it)."""
        problems: list[str] = []
        table = {**self.table.to_dict(), **updates}
        out = NavigatorSection.from_mapping({**self.to_dict(), "settings": table}, "navigator", problems)
        if problems:
            raise SectionsError(problems)
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "settings": self.table.to_dict(), "rate_hz": self.rate_hz,
                "latency_updates": self.latency_updates}


@dataclass(frozen=True)
class MonitorSection:
    """One [monitors.<name>] table: a monitor (built-in, plug-in or module:Name), its settings as written."""

    name: str
    settings: Table = field(default_factory=Table)


@dataclass(frozen=True)
class GuidanceSection(Section):
    """[guidance]: guidance ticks per second and log rows per second (taken at navigator updates)."""

    rate_hz: float = 10.0
    log_rate_hz: float = 1.0


@dataclass(frozen=True)
class LimitsSection(Section):
    """[limits]: divergence thresholds, m."""

    max_horizontal_sigma_m: float = 5000.0
    max_horizontal_error_m: float | None = None


# ------------------------------------------------------------------------------------------ the whole

@dataclass(frozen=True)
class ScenarioSections:
    """Every section of one validated scenario (see the module docstring)."""

    name: str
    description: str
    seed: int
    duration_s: float
    aircraft: AircraftSection
    truth: TruthSection
    initial: InitialSection
    initial_errors: InitialErrorsSection
    route: RouteSection
    wind: WindSection
    atmosphere: AtmosphereSection | None
    terrain: TerrainSection
    sensors: SensorsSection
    gnss: GnssSection
    navigator: NavigatorSection
    monitors: tuple[MonitorSection, ...]
    guidance: GuidanceSection
    limits: LimitsSection

    def monitor(self, name: str) -> MonitorSection | None:
        return next((m for m in self.monitors if m.name == name), None)

    def to_dict(self) -> dict[str, Any]:
        """The scenario as the validated dict it was built from (defaults filled in)."""
        out: dict[str, Any] = {"name": self.name, "description": self.description, "seed": self.seed,
                               "duration_s": self.duration_s}
        for key in ("aircraft", "truth", "initial", "initial_errors", "route", "wind", "atmosphere",
                    "terrain", "sensors", "gnss", "navigator"):
            value = getattr(self, key)
            if value is not None:
                out[key] = value.to_dict()
        out["monitors"] = {m.name: m.settings.to_dict() for m in self.monitors}
        out["guidance"] = self.guidance.to_dict()
        out["limits"] = self.limits.to_dict()
        return out


_SIMPLE = {"aircraft": AircraftSection, "truth": TruthSection, "initial": InitialSection,
           "initial_errors": InitialErrorsSection, "route": RouteSection, "wind": WindSection,
           "atmosphere": AtmosphereSection, "terrain": TerrainSection, "gnss": GnssSection,
           "guidance": GuidanceSection, "limits": LimitsSection}
_TOP_KEYS = ("name", "description", "seed", "duration_s", *_SIMPLE, "sensors", "navigator", "monitors")


def from_dict(d: Mapping[str, Any], *, partial: bool = False,
              problems: list[str] | None = None) -> ScenarioSections:
    """The typed sections of a validated scenario dict (the loader's, defaults filled in).

    `partial`: the dict is the part of a scenario a sensor log carries (trn_env.logs.replay: terrain,
    sensors, navigator, monitors, GNSS outages, initial errors); absent tables get their defaults, and
    `initial` and `route`, which have none, are None.

    `problems`: a list to which the problems are added instead of raising; the sections are then built as
    far as they go (a sensor or navigator whose settings are refused has no Settings object), so the
    validator can still hand the other components their settings.

    Raises
    ------
    SectionsError
        Every problem at once, each 'field.path: message' (a setting a component's Settings class refuses,
        a table that is not a table); not when `problems` is given.
    """
    collect = problems is not None
    problems = problems if collect else []
    for key in d:
        if key not in _TOP_KEYS:
            problems.append(f"{key}: unknown key (allowed here: {', '.join(sorted(_TOP_KEYS))})")
    kw: dict[str, Any] = {k: d.get(k) for k in ("name", "description", "seed", "duration_s")}
    if partial and kw["description"] is None:
        kw["description"] = ""
    for key, cls in _SIMPLE.items():
        if key in d:
            kw[key] = cls.from_mapping(d[key], key, problems)
        elif key == "atmosphere" or (partial and key in ("initial", "route")):
            kw[key] = None
        elif partial:
            kw[key] = cls.from_mapping({}, key, problems)
        else:
            problems.append(f"{key}: required table is missing")
    kw["sensors"] = SensorsSection.from_mapping(d.get("sensors", {}), "sensors", problems)
    kw["navigator"] = NavigatorSection.from_mapping(d.get("navigator", {}), "navigator", problems)
    mons = d.get("monitors") or {}
    kw["monitors"] = tuple(MonitorSection(name=str(n), settings=Table(s if isinstance(s, Mapping) else {}))
                           for n, s in mons.items())
    if problems and not collect:
        raise SectionsError(problems)
    return ScenarioSections(**kw)


def to_dict(sections: ScenarioSections) -> dict[str, Any]:
    """`sections.to_dict()`: the scenario as a plain dict (to_dict(from_dict(d)) == d)."""
    return sections.to_dict()
