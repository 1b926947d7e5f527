"""Navigator registry: `create(name, **settings)` and `available()`.

"ins"          strapdown INS + barometer, no terrain aiding (navigators.filters.InsTrnNavigator)
"acq_track"    the GPS-inspired acquisition-and-tracking TRN of seed 001
               (navigators.acquisition_tracking.AcqTrackNavigator; settings: AcqTrackConfig's fields)
"ins_tercom"   INS + batch TERCOM (IRA by default, aiding="radar_altimeter" for eq 1) + 13-state EKF;
               needs dem= (terrain.Dem or a name/path for terrain.load); formula="proposed" | ...
"rbpf"         seed 002's IRA-aided Rao-Blackwellized particle filter (navigators.filters.rbpf); needs dem=,
               takes rng=
"pmf"          point-mass filter over the INS horizontal position error (navigators.filters.pmf); dem=
"pf"           SIR particle filter over the INS error state (navigators.filters.pf); dem=, rng=

Monitors run beside a navigator on the same frames and its estimate (`create_monitor(name, **settings)`,
`available_monitors()`): "dem_integrity" is the terrain-database integrity monitor of seed 003
(navigators.integrity.dem_monitor; needs dem=, the navigator's map).

Each entry is a factory and its declared `Capabilities` (navigators.core.capabilities: its Settings class,
whether it needs the map or takes an rng, uses the IMU's specification or the map's error model, the
sensors it requires and those it can use). A built-in navigator is registered the same way a plug-in is;
a class registered without `capabilities` gets its class attribute `capabilities`, else `Capabilities()`.

Settings: every navigator and monitor with a Settings class validates them in its constructor and raises
one `SettingsError` (a `ValueError`) naming every bad setting, unknown names refused against the list of
known ones; `create` prefixes the navigator's name. `integrity_risk` (per epoch, in (0, 1), default 1e-3)
and `map_horizontal_sigma_m` (the map's horizontal error per axis, m, default 0) are taken here for every
navigator (`PublishedIntegritySettings`, reported together with the navigator's own problems): the risk its
published horizontal protection level is computed for and the map error it covers
(navigators.integrity.protection_level). For a plug-in without a Settings class the keyword
arguments are checked against its factory's signature. A navigator that `takes_rng` gets the scenario's
`navigator` random stream as `rng=` (a `numpy.random.Generator`), so one scenario seed fixes its run bit for
bit; `create(..., rng=None)` leaves it to the navigator's own documented default.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from trn_env.navigators.acquisition_tracking.settings import CAPABILITIES as ACQ_TRACK_CAPABILITIES
from trn_env.navigators.core.capabilities import Capabilities, SensorNeeds
from trn_env.navigators.core.settings import Settings, SettingsError, setting, unknown_message
from trn_env.navigators.filters.ins_trn_settings import (
    INS_CAPABILITIES,
    INS_TERCOM_CAPABILITIES,
    InsTercomSettings,
    InsTrnSettings,
)
from trn_env.navigators.filters.rbpf_settings import CAPABILITIES as RBPF_CAPABILITIES
from trn_env.navigators.filters.terrain_filter_settings import PF_CAPABILITIES, PMF_CAPABILITIES
from trn_env.navigators.integrity.dem_monitor_settings import CAPABILITIES as DEM_INTEGRITY_CAPABILITIES


@dataclass(frozen=True)
class PublishedIntegritySettings(Settings):
    """The settings `create` takes for every navigator: its published protection level's risk and the map's
    horizontal error it covers (navigators.integrity.protection_level.configure)."""

    integrity_risk: float = setting(1e-3, "per-epoch integrity risk of the published horizontal protection "
                                          "level", "1", gt=0.0, lt=1.0)
    map_horizontal_sigma_m: float = setting(0.0, "the map's horizontal error per axis the protection level "
                                                 "covers (a scenario: its accuracy class)", "m", ge=0.0)


PUBLISHED_INTEGRITY_KEYS = ("integrity_risk", "map_horizontal_sigma_m")


@dataclass(frozen=True)
class Entry:
    """A registered navigator or monitor: its factory (keyword settings) and capabilities."""

    factory: Callable[..., object]
    capabilities: Capabilities


_NAVIGATORS: dict[str, Entry] = {}
_MONITORS: dict[str, Entry] = {}


def _entry(table: dict[str, Entry], kind: str, name: str) -> Entry:
    if name not in table:
        raise ValueError(f"unknown {kind} {name!r}; available: {sorted(table)}")
    return table[name]


def _caps_of(factory, capabilities: Capabilities | None, takes_rng: bool) -> Capabilities:
    if capabilities is not None:
        return capabilities
    caps = getattr(factory, "capabilities", None)
    if isinstance(caps, Capabilities):
        return caps
    return Capabilities(takes_rng=takes_rng)


def _call(kind: str, name: str, entry: Entry, kwargs: dict[str, Any]):
    """factory(**kwargs) with the settings problems reported under the component's name."""
    if entry.capabilities.settings is None:      # a plug-in taking free keyword arguments
        try:
            sig = inspect.signature(entry.factory)
        except (TypeError, ValueError):
            sig = None
        if sig is not None and not any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
            known = [p for p in sig.parameters if p not in ("rng", "dem")]
            bad = [(k, unknown_message(k, known)) for k in kwargs if k not in sig.parameters]
            if bad:
                raise SettingsError(bad, owner=f"{kind} {name!r}")
    try:
        return entry.factory(**kwargs)
    except SettingsError as exc:
        raise SettingsError(exc.problems, owner=f"{kind} {name!r}") from None


# ------------------------------------------------------------------------------------------ navigators

def available() -> list[str]:
    """Names accepted by create()."""
    return sorted(_NAVIGATORS)


def capabilities(name: str) -> Capabilities:
    """The declared capabilities of a registered navigator."""
    return _entry(_NAVIGATORS, "navigator", name).capabilities


def settings_class(name: str) -> type | None:
    """The Settings class of a registered navigator (None for a plug-in without one)."""
    return capabilities(name).settings


def sensor_needs(name: str, settings: dict | None = None) -> SensorNeeds:
    """The sensors navigator `name` requires and can use with `settings` (a mapping; runtime arguments such
    as dem= and rng= are ignored). Raises SettingsError for settings it refuses."""
    return _needs("navigator", name, capabilities(name), settings)


def _needs(kind: str, name: str, caps: Capabilities, settings: dict | None) -> SensorNeeds:
    if caps.settings is None:
        return caps.sensor_needs(None)
    skip = ("dem", "rng", "name") + (PUBLISHED_INTEGRITY_KEYS if kind == "navigator" else ())
    given = {k: v for k, v in (settings or {}).items() if k not in skip}
    try:
        return caps.sensor_needs(caps.settings.from_mapping(given))
    except SettingsError as exc:
        raise SettingsError(exc.problems, owner=f"{kind} {name!r}") from None


def create(name: str, rng: np.random.Generator | None = None, **settings):
    """A new navigator by name with its settings (keyword arguments of its class); `rng` reaches only the
    navigators whose capabilities say takes_rng. Bad settings: one SettingsError (ValueError) naming each."""
    entry = _entry(_NAVIGATORS, "navigator", name)
    kwargs = dict(settings)
    if entry.capabilities.takes_rng:
        kwargs["rng"] = rng
    published = {k: kwargs.pop(k) for k in PUBLISHED_INTEGRITY_KEYS if k in kwargs}
    problems = []
    try:
        pl = PublishedIntegritySettings.from_mapping(published)
    except SettingsError as exc:
        problems, pl = exc.problems, None
    try:
        nav = _call("navigator", name, entry, kwargs)
    except SettingsError as exc:
        raise SettingsError(exc.problems + problems, owner=exc.owner) from None
    if problems:
        raise SettingsError(problems, owner=f"navigator {name!r}")
    if hasattr(nav, "integrity_risk"):
        from trn_env.navigators.integrity.protection_level import configure
        configure(nav, pl.integrity_risk, pl.map_horizontal_sigma_m)
    return nav


def register(name: str, factory: Callable[..., object], takes_rng: bool = False,
             capabilities: Capabilities | None = None) -> None:
    """Add a navigator factory (a class or a callable taking the settings as keyword arguments) with its
    capabilities (default: the factory's `capabilities` attribute, else `Capabilities(takes_rng=...)`)."""
    _NAVIGATORS[name] = Entry(factory, _caps_of(factory, capabilities, takes_rng))


def _ins(dem=None, name: str | None = None, **kw):
    from trn_env.navigators.filters.ins_trn_ekf import InsTrnNavigator
    if kw.get("aiding") is not None:
        raise SettingsError([("aiding", "the free-inertial 'ins' takes no terrain aiding (use "
                                        "'ins_tercom')")])
    return InsTrnNavigator(dem=dem, settings=InsTrnSettings.from_mapping(kw), name=name)


def _ins_tercom(dem=None, name: str | None = None, **kw):
    from trn_env.navigators.filters.ins_trn_ekf import InsTrnNavigator
    return InsTrnNavigator(dem=dem, settings=InsTercomSettings.from_mapping(kw), name=name)


def _acq_track(**kw):
    from trn_env.navigators.acquisition_tracking import AcqTrackNavigator
    return AcqTrackNavigator(**kw)


def _pmf(**kw):
    from trn_env.navigators.filters.pmf import PointMassFilter
    return PointMassFilter(**kw)


def _pf(**kw):
    from trn_env.navigators.filters.pf import ParticleFilter
    return ParticleFilter(**kw)


def _rbpf(**kw):
    from trn_env.navigators.filters.rbpf import RaoBlackwellizedPF
    return RaoBlackwellizedPF(**kw)


register("ins", _ins, capabilities=INS_CAPABILITIES)
register("ins_tercom", _ins_tercom, capabilities=INS_TERCOM_CAPABILITIES)
register("acq_track", _acq_track, capabilities=ACQ_TRACK_CAPABILITIES)
register("pmf", _pmf, capabilities=PMF_CAPABILITIES)
register("pf", _pf, capabilities=PF_CAPABILITIES)
register("rbpf", _rbpf, capabilities=RBPF_CAPABILITIES)


# ------------------------------------------------------------------------------------------ monitors

def _dem_integrity(**kw):
    from trn_env.navigators.integrity.dem_monitor import DemIntegrityMonitor
    return DemIntegrityMonitor(**kw)


def available_monitors() -> list[str]:
    """Names accepted by create_monitor()."""
    return sorted(_MONITORS)


def monitor_capabilities(name: str) -> Capabilities:
    """The declared capabilities of a registered monitor."""
    return _entry(_MONITORS, "monitor", name).capabilities


def monitor_sensor_needs(name: str, settings: dict | None = None) -> SensorNeeds:
    """The sensors monitor `name` requires and can use with `settings` (see sensor_needs)."""
    return _needs("monitor", name, monitor_capabilities(name), settings)


def monitor_settings_class(name: str) -> type | None:
    """The Settings class of a registered monitor (None for a plug-in without one)."""
    return monitor_capabilities(name).settings


def create_monitor(name: str, **settings):
    """A new monitor by name (it runs beside a navigator: `monitor.update(frames, estimate)`)."""
    return _call("monitor", name, _entry(_MONITORS, "monitor", name), dict(settings))


def register_monitor(name: str, factory: Callable[..., object],
                     capabilities: Capabilities | None = None) -> None:
    """Add a monitor factory (keyword settings; `dem=` is the navigator's map) with its capabilities."""
    _MONITORS[name] = Entry(factory, _caps_of(factory, capabilities, False))


register_monitor("dem_integrity", _dem_integrity, capabilities=DEM_INTEGRITY_CAPABILITIES)
