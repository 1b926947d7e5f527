"""Navigator and monitor registry: `create(name, **settings)`, `available()`, plug-ins.

A navigator (or monitor) name is one of

- a built-in: "ins" (strapdown INS + barometer, no terrain aiding), "ins_tercom" (INS + batch TERCOM + EKF,
  seed 000), "acq_track" (seed 001's acquisition-and-tracking TRN), "pmf" (point-mass filter), "pf" (SIR
  particle filter), "rbpf" (seed 002's IRA-aided Rao-Blackwellized particle filter); monitor
  "dem_integrity" (seed 003's terrain-database integrity monitor);
- an installed plug-in: an entry point of an installed distribution in the group `trn_env.navigators`
  (monitors: `trn_env.monitors`), e.g. in the plug-in's pyproject.toml::

      [project.entry-points."trn_env.navigators"]
      sitan = "sitan_navigator:SitanNavigator"

  The built-ins are declared the same way in trn-env's own pyproject.toml (`navigators.builtin`);
- a reference `package.module:Name` to any importable class or factory (no installation needed in this
  process; other processes need to import it too: see docs/guide/own_navigator.md);
- a name given to `register(name, factory)` in this process (it does not reach spawned or Ray workers).

The factory (a class or a callable) is called with the settings as keyword arguments and must return an
object with `reset(initial: Estimate)` and `update(frames: SensorFrames) -> Estimate` (navigators.protocol);
a monitor's with `update(frames, estimate)`. A factory with an `rng` parameter (particle filters) gets the
scenario's `navigator` random stream as `rng=` (a `numpy.random.Generator`), so one scenario seed fixes
its run bit for bit; `create(..., rng=None)` leaves it to the navigator's own documented default.

`integrity_risk` (per epoch, in (0, 1), default 1e-3) and `map_horizontal_sigma_m` (the map's horizontal
error per axis, m, default 0) are taken here for every navigator: the risk its published horizontal
protection level is computed for and the map error it covers (navigators.integrity.protection_level); the
terrain filters (pmf, pf, rbpf) also publish that error's share in their covariance
(navigators.filters.map_shift).

Each navigator and monitor declares what it needs as `Capabilities` (navigators.core.capabilities: its
Settings class, whether it needs the map or takes an rng, uses the IMU's specification or the map's error
model, the sensors it requires and those it can use): the factory's `capabilities` attribute, or
`register(..., capabilities=)`; a plug-in without one gets `Capabilities(takes_rng=<it has an rng
parameter>)`. Nothing is inferred from a navigator's name.

Settings: a navigator or monitor with a Settings class (navigators.core.settings) validates them in its
constructor and raises one `SettingsError` (a `ValueError`) naming every bad setting, unknown names refused
against the list of known ones; `create` prefixes the component's name and reports the published-integrity
settings' problems (`PublishedIntegritySettings`) in the same error. For a plug-in without a Settings class
the keyword arguments are checked against its factory's signature. A plug-in that cannot be imported, or
whose object is not a navigator, raises `PluginError` (a ValueError) naming the plug-in, the module and the
error or what it lacks.
"""

from __future__ import annotations

import importlib
import inspect
import re
import sys
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path

import numpy as np

from .builtin import BUILTIN_MONITORS, BUILTIN_NAVIGATORS
from .core.capabilities import Capabilities, SensorNeeds
from .core.settings import Settings, SettingsError, setting, unknown_message
from .integrity.protection_level import configure

NAVIGATOR_GROUP = "trn_env.navigators"
MONITOR_GROUP = "trn_env.monitors"
_REFERENCE = re.compile(r"^[A-Za-z_]\w*(\.[A-Za-z_]\w*)*:[A-Za-z_]\w*(\.[A-Za-z_]\w*)*$")
# what each kind must provide: method name -> how the message describes it
_NEEDS = {"navigator": {"reset": "reset(initial: Estimate)",
                        "update": "update(frames: SensorFrames) -> Estimate"},
          "monitor": {"update": "update(frames: SensorFrames, estimate: Estimate) -> MonitorOutput"}}



@dataclass(frozen=True)
class PublishedIntegritySettings(Settings):
    """The settings `create` takes for every navigator: its published protection level's risk and the map's
    horizontal error it covers (navigators.integrity.protection_level.configure)."""

    integrity_risk: float = setting(1e-3, "per-epoch integrity risk of the published horizontal protection "
                                          "level", "1", gt=0.0, lt=1.0)
    map_horizontal_sigma_m: float = setting(0.0, "the map's horizontal error per axis the protection level "
                                                 "covers, and pmf's, pf's and rbpf's covariance (a "
                                                 "scenario: its accuracy class)", "m", ge=0.0)


PUBLISHED_INTEGRITY_KEYS = ("integrity_risk", "map_horizontal_sigma_m")


class PluginError(ValueError):
    """A navigator or monitor plug-in that cannot be used: not importable, not found, or not a navigator."""


@dataclass
class Plugin:
    """One resolved navigator or monitor: where it came from and its factory.

    kind: "navigator" or "monitor"; origin: "built-in", "entry point", "reference" or "registered";
    reference: "module:attribute" (None for a registered factory); distribution: "name version" of the
    installed package declaring the entry point (None otherwise)."""

    name: str
    kind: str
    origin: str
    factory: Callable[..., object]
    reference: str | None = None
    distribution: str | None = None
    takes_rng: bool = False
    extra: dict = field(default_factory=dict)
    capabilities: Capabilities = field(default_factory=Capabilities)

    @property
    def module(self) -> str | None:
        return None if self.reference is None else self.reference.split(":", 1)[0]


_REGISTERED: dict[str, dict[str, tuple[Callable[..., object], Capabilities]]] = {"navigator": {},
                                                                                   "monitor": {}}
_CACHE: dict[tuple[str, str], Plugin] = {}
_ENTRY_POINTS: dict[str, dict[str, list]] = {}


def refresh() -> None:
    """Forget the entry points and plug-ins looked up so far (after installing a package in this process)."""
    _CACHE.clear()
    _ENTRY_POINTS.clear()
    importlib.invalidate_caches()


def _entry_points(kind: str) -> dict[str, list]:
    """name -> [EntryPoint, ...] of the kind's group over the installed distributions."""
    if kind not in _ENTRY_POINTS:
        table: dict[str, list] = {}
        group = NAVIGATOR_GROUP if kind == "navigator" else MONITOR_GROUP
        seen = set()
        for ep in metadata.entry_points(group=group):
            dist = getattr(ep, "dist", None)
            key = (ep.name, ep.value, getattr(dist, "name", None))
            if key in seen:            # the same distribution seen twice on sys.path
                continue
            seen.add(key)
            table.setdefault(ep.name, []).append(ep)
        _ENTRY_POINTS[kind] = table
    return _ENTRY_POINTS[kind]


def _builtins(kind: str) -> dict[str, str]:
    return BUILTIN_NAVIGATORS if kind == "navigator" else BUILTIN_MONITORS


def _names(kind: str) -> list[str]:
    return sorted(set(_builtins(kind)) | set(_entry_points(kind)) | set(_REGISTERED[kind]))


def available() -> list[str]:
    """Navigator names accepted by ``create`` besides ``module:Name`` references.

    Returns
    -------
    list of str
        The built-in, installed (entry point) and registered names, sorted.
    """
    return _names("navigator")


def available_monitors() -> list[str]:
    """Monitor names accepted by create_monitor() besides `module:Name` references."""
    return _names("monitor")


def is_reference(name: str) -> bool:
    """True for a `package.module:Name` reference."""
    return isinstance(name, str) and _REFERENCE.match(name) is not None


def load_reference(reference: str, what: str) -> object:
    """The object `module:attribute` names, imported; PluginError naming the module and the error."""
    module_name, _, attr = reference.partition(":")
    try:
        obj = importlib.import_module(module_name)
    except BaseException as exc:  # noqa: BLE001 - any failure of a user's module is reported, not raised through
        if isinstance(exc, KeyboardInterrupt):
            raise
        where = _not_found_hint(exc, module_name) or _where(exc)
        raise PluginError(f"{what}: cannot import module {module_name!r}: {type(exc).__name__}: {exc}"
                          f"{where}") from exc
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise PluginError(f"{what}: module {module_name!r} has no attribute {attr!r}")
        obj = getattr(obj, part)
    return obj


def _not_found_hint(exc: BaseException, module_name: str) -> str:
    """Where to put a module the import did not find (the module named, or one of its parents), else ""."""
    if not isinstance(exc, ModuleNotFoundError) or not exc.name:
        return ""
    if module_name != exc.name and not module_name.startswith(exc.name + "."):
        return ""            # a module the plug-in imports is missing: _where points into the plug-in
    top = exc.name.split(".")[0]
    local = [p for p in (Path.cwd() / f"{top}.py", Path.cwd() / top) if p.exists()]
    if local:
        return (f"; {local[0].name} is in the current directory, which the trn-env command does not search: "
                f"add it to the path (PYTHONPATH=.) or install its package")
    return "; install its package, or add the folder holding it to PYTHONPATH"


def _where(exc: BaseException) -> str:
    """' (at file:line)' of the innermost frame of a plug-in import failure, when it has one."""
    tb = [f for f in traceback.extract_tb(exc.__traceback__) if not f.filename.startswith("<frozen")]
    if not tb or tb[-1].filename == __file__:
        return ""
    frame = tb[-1]
    return f" (at {frame.filename}:{frame.lineno})"


def lacks(obj: object, kind: str) -> list[str]:
    """What `obj` (a class or an instance) lacks to be a `kind` ("navigator" or "monitor"): the missing
    methods as signatures; empty when it has them all."""
    return [sig for meth, sig in _NEEDS[kind].items() if not callable(getattr(obj, meth, None))]


def _check_factory(obj: object, what: str, kind: str) -> Callable[..., object]:
    if inspect.ismodule(obj) or not callable(obj):
        raise PluginError(f"{what} is not a {kind}: it is {_describe(obj)}, not a class or a factory "
                          f"returning an object with {' and '.join(_NEEDS[kind].values())}")
    if inspect.isclass(obj):
        missing = lacks(obj, kind)
        if missing:
            raise PluginError(f"{what} is not a {kind}: class {obj.__qualname__} lacks {', '.join(missing)}")
    return obj


def _describe(obj: object) -> str:
    if inspect.ismodule(obj):
        return f"module {obj.__name__!r}"
    return f"a {type(obj).__name__} ({obj!r:.60})"


def _caps_of(factory, capabilities: Capabilities | None, takes_rng: bool) -> Capabilities:
    """The declared capabilities: given, else the factory's `capabilities` attribute, else
    Capabilities(takes_rng=...)."""
    if capabilities is not None:
        return capabilities
    caps = getattr(factory, "capabilities", None)
    return caps if isinstance(caps, Capabilities) else Capabilities(takes_rng=takes_rng)


def _takes_rng(factory: Callable[..., object]) -> bool:
    try:
        params = inspect.signature(factory).parameters
    except (TypeError, ValueError):
        return False
    return "rng" in params


def takes_argument(name: str, argument: str, kind: str = "navigator") -> bool:
    """Whether the factory of navigator (or monitor) `name` takes keyword `argument`: a parameter of that
    name or **kwargs (True too when its signature cannot be read)."""
    factory = resolve(name, kind).factory
    try:
        params = inspect.signature(factory).parameters
    except (TypeError, ValueError):
        return True
    return argument in params or any(p.kind is p.VAR_KEYWORD for p in params.values())


def _dist_label(ep) -> str | None:
    dist = getattr(ep, "dist", None)
    return None if dist is None else f"{dist.name} {dist.version}"


def resolve(name: str, kind: str = "navigator") -> Plugin:
    """The navigator (kind="navigator") or monitor (kind="monitor") called `name`, its factory loaded.

    Raises ValueError for an unknown name and PluginError (a ValueError) for a plug-in that cannot be
    imported or is not a navigator/monitor."""
    if kind not in _NEEDS:
        raise ValueError(f"kind must be 'navigator' or 'monitor', got {kind!r}")
    if not isinstance(name, str) or not name:
        raise ValueError(f"{kind} name must be a non-empty string, got {name!r}")
    key = (kind, name)
    if key in _CACHE:
        return _CACHE[key]
    if name in _REGISTERED[kind]:
        factory, caps = _REGISTERED[kind][name]
        return Plugin(name, kind, "registered", factory, takes_rng=caps.takes_rng,
                      capabilities=caps)   # not cached: re-registrable
    eps = _entry_points(kind)
    if name in _builtins(kind):
        ref = _builtins(kind)[name]
        own = [ep for ep in eps.get(name, []) if ep.value.replace(" ", "") != ref]
        if own:
            raise PluginError(f"{kind} {name!r}: the entry point of {_dist_label(own[0])} ({own[0].value}) "
                              f"takes the name of a built-in {kind}; rename it")
        plugin = _load(name, kind, "built-in", ref, f"built-in {kind} {name!r} ({ref})", None)
    elif name in eps:
        found = eps[name]
        if len({ep.value for ep in found}) > 1:
            raise PluginError(f"{kind} {name!r}: declared by several installed packages ("
                              + "; ".join(f"{_dist_label(ep)}: {ep.value}" for ep in found)
                              + "); uninstall one or use a module:Name reference")
        ep = found[0]
        dist = _dist_label(ep)
        what = f"{kind} plug-in {name!r} (entry point {ep.value!r} of {dist or 'an installed package'})"
        plugin = _load(name, kind, "entry point", ep.value.replace(" ", ""), what, dist)
    elif is_reference(name):
        plugin = _load(name, kind, "reference", name, f"{kind} plug-in {name!r}", None)
    else:
        hint = "" if ":" in name else "; or a plug-in as package.module:Name"
        raise ValueError(f"unknown {kind} {name!r}; available: {_names(kind)}{hint}")
    _CACHE[key] = plugin
    return plugin


def _load(name: str, kind: str, origin: str, ref: str, what: str, dist: str | None) -> Plugin:
    factory = _check_factory(load_reference(ref, what), what, kind)
    caps = _caps_of(factory, None, _takes_rng(factory))
    return Plugin(name, kind, origin, factory, reference=ref, distribution=dist, takes_rng=caps.takes_rng,
                  capabilities=caps)


def _call(plugin: Plugin, settings: dict) -> object:
    owner = f"{plugin.kind} {plugin.name!r}"
    if plugin.capabilities.settings is None:      # a plug-in taking free keyword arguments
        try:
            sig = inspect.signature(plugin.factory)
        except (TypeError, ValueError):
            sig = None
        if sig is not None and not any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
            known = [p for p in sig.parameters if p not in ("rng", "dem")]
            bad = [(k, unknown_message(k, known)) for k in settings if k not in sig.parameters]
            if bad:
                raise SettingsError(bad, owner=owner)
    try:
        obj = plugin.factory(**settings)
    except SettingsError as exc:
        raise SettingsError(exc.problems, owner=owner) from None
    missing = lacks(obj, plugin.kind)
    if missing:
        raise PluginError(f"{plugin.kind} {plugin.name!r}: its factory returned {_describe(obj)}, which is "
                          f"not a {plugin.kind}: it lacks {', '.join(missing)}")
    return obj


def create(name: str, rng: np.random.Generator | None = None, **settings):
    """A new navigator by name or ``module:Name`` reference, with its settings.

    Parameters
    ----------
    name : str
        A built-in name (``ins``, ``ins_tercom``, ``pmf``, ``pf``, ``rbpf``, ``acq_track``), an installed
        plug-in's entry-point name (group ``trn_env.navigators``) or a ``package.module:Name`` reference.
    rng : numpy.random.Generator, optional
        Reaches only navigators that declare ``takes_rng`` (particle filters); one seed then fixes the run.
    **settings
        The navigator's settings (the settings reference lists them with unit, range and default), plus
        ``integrity_risk`` and ``map_horizontal_sigma_m`` for the published protection level; a map is
        ``dem=`` (a ``Dem`` or a DEM name or path).

    Returns
    -------
    object
        A navigator: ``reset(initial_estimate)`` then ``update(frames) -> Estimate``.

    Raises
    ------
    ValueError
        For an unknown name (listing the known ones), a plug-in that fails to import or is not a
        navigator, or bad settings (every problem at once, each naming its setting).
    """
    plugin = resolve(name, "navigator")
    # every navigator's published protection level is for this per-epoch risk (protection_level); its
    # problems are reported with the navigator's own
    published = {k: settings.pop(k) for k in PUBLISHED_INTEGRITY_KEYS if k in settings}
    problems: list[tuple[str, str]] = []
    try:
        pl = PublishedIntegritySettings.from_mapping(published)
    except SettingsError as exc:
        problems, pl = exc.problems, None
    if plugin.capabilities.takes_rng:
        settings["rng"] = rng
    try:
        nav = _call(plugin, settings)
    except SettingsError as exc:
        raise SettingsError(exc.problems + problems, owner=exc.owner) from None
    if problems:
        raise SettingsError(problems, owner=f"navigator {name!r}")
    if hasattr(nav, "integrity_risk"):
        configure(nav, pl.integrity_risk, pl.map_horizontal_sigma_m)
    return nav


def create_monitor(name: str, **settings):
    """A new monitor by name or reference; it runs beside a navigator as ``monitor.update(frames, estimate)``.

    Parameters
    ----------
    name : str
        ``dem_integrity``, an installed plug-in's entry-point name (group ``trn_env.monitors``) or a
        ``package.module:Name`` reference.
    **settings
        The monitor's settings; ``dem=`` is the navigator's map.

    Returns
    -------
    object
        The monitor.

    Raises
    ------
    ValueError
        For an unknown name or bad settings (each naming its setting).
    """
    return _call(resolve(name, "monitor"), settings)


def register(name: str, factory: Callable[..., object], takes_rng: bool = False,
             capabilities: Capabilities | None = None) -> None:
    """Add a navigator factory under a name, in this process only.

    Processes that do not run this call (spawned or Ray workers, a row's ``replay_command``) do not know
    the name: prefer an entry point or a ``module:Name`` reference (the own-navigator guide).

    Parameters
    ----------
    name : str
        The name ``create`` will accept.
    factory : callable
        A class or a callable taking the settings as keyword arguments.
    takes_rng : bool
        The factory takes ``rng=`` (used when ``capabilities`` is not given).
    capabilities : Capabilities, optional
        What the navigator needs (map, rng, IMU specification, required and optional sensors); default:
        the factory's ``capabilities`` attribute, else ``Capabilities(takes_rng=takes_rng)``.
    """
    _REGISTERED["navigator"][name] = (factory, _caps_of(factory, capabilities, bool(takes_rng)))
    _CACHE.pop(("navigator", name), None)


def register_monitor(name: str, factory: Callable[..., object],
                     capabilities: Capabilities | None = None) -> None:
    """Add a monitor factory in this process only (keyword settings; `dem=` is the navigator's map) with its
    capabilities."""
    _REGISTERED["monitor"][name] = (factory, _caps_of(factory, capabilities, False))
    _CACHE.pop(("monitor", name), None)


def unregister(name: str, kind: str = "navigator") -> None:
    """Forget a name given to register() / register_monitor() (no-op for other names)."""
    _REGISTERED[kind].pop(name, None)
    _CACHE.pop((kind, name), None)


def plugin_modules() -> list[str]:
    """Top-level modules of the plug-ins resolved so far in this process that no installed distribution
    provides (`module:Name` references to a module on sys.path only): what a Ray worker on another node or
    with another working directory cannot import unless it is shipped (`runtime_env={"py_modules": ...}`)."""
    provided = metadata.packages_distributions()
    out = []
    for plugin in _CACHE.values():
        if plugin.origin != "reference" or plugin.module is None:
            continue
        top = plugin.module.split(".")[0]
        if top not in provided and top in sys.modules and top not in out:
            out.append(top)
    return out


def settings_class(name: str, kind: str = "navigator"):
    """The class whose settings a navigator (or monitor) takes: its declared Settings class
    (capabilities.settings), else its factory's `settings_class` when it names one, else the factory."""
    plugin = resolve(name, kind)
    if plugin.capabilities.settings is not None:
        return plugin.capabilities.settings
    return getattr(plugin.factory, "settings_class", None) or plugin.factory


def monitor_settings_class(name: str):
    """settings_class(name, "monitor")."""
    return settings_class(name, "monitor")


def capabilities(name: str) -> Capabilities:
    """The declared capabilities of navigator `name` (a name or a `module:Name` reference)."""
    return resolve(name, "navigator").capabilities


def monitor_capabilities(name: str) -> Capabilities:
    """The declared capabilities of monitor `name`."""
    return resolve(name, "monitor").capabilities


def _needs(kind: str, name: str, settings: dict | None) -> SensorNeeds:
    caps = resolve(name, kind).capabilities
    if caps.settings is None:
        return caps.sensor_needs(None)
    skip = ("dem", "rng", "name") + (PUBLISHED_INTEGRITY_KEYS if kind == "navigator" else ())
    given = {k: v for k, v in (settings or {}).items() if k not in skip}
    try:
        return caps.sensor_needs(caps.settings.from_mapping(given))
    except SettingsError as exc:
        raise SettingsError(exc.problems, owner=f"{kind} {name!r}") from None


def sensor_needs(name: str, settings: dict | None = None) -> SensorNeeds:
    """The sensors navigator `name` requires and can use with `settings` (a mapping; runtime arguments such
    as dem= and rng= are ignored), from its declared capabilities, without building it. Raises
    SettingsError for settings it refuses."""
    return _needs("navigator", name, settings)


def monitor_sensor_needs(name: str, settings: dict | None = None) -> SensorNeeds:
    """The sensors monitor `name` requires and can use with `settings` (see sensor_needs)."""
    return _needs("monitor", name, settings)
