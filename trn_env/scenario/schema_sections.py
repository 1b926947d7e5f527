"""The scenario schema's sections generated from the components' Settings classes.

`sensors.*` (each sensor's config, plus its preset switches: `noise_free`, and the IMU's `grade`),
`monitors.*` (each registered monitor's settings) and `navigator.settings` (one `if name == X then
settings is X's schema` branch per registered navigator with a Settings class) come from the
declarations in navigators.core.settings, never by hand. `with_generated_sections(schema)` puts them into
the hand-written rest of trn_env/scenario/schema.json at load time (so plug-ins registered before
validation get theirs too); `scripts/generate_schema.py` writes the built-ins' into the file itself for
editors and the docs, and tests/test_settings.py checks the file is up to date.
"""

from __future__ import annotations

import copy
from collections.abc import Iterator
from typing import Any

from trn_env.navigators.core.settings import Settings, json_schema, table_rows


def _declared(cls) -> bool:
    return isinstance(cls, type) and issubclass(cls, Settings)

# a navigator that needs the map may be given another one than terrain.map's (a DEM name or file)
_RUNTIME = {"dem": {"type": "string", "description": "the navigator's map, a DEM name or file (default: "
                                                     "terrain.map's)"}}
NAVIGATOR_SETTINGS_DESCRIPTION = ("settings of the named navigator (navigators.registry.create's keyword "
                                  "arguments); the built-ins' are listed per name below")


def sensor_sections() -> dict[str, dict]:
    """{sensor name: JSON schema of its [sensors.<name>] table}."""
    from trn_env.sensors.imu import GRADE_NAMES
    from trn_env.sensors.suite import SENSOR_MODELS
    out = {}
    for name, model in SENSOR_MODELS.items():
        cls = model.config_cls
        if name == "imu":
            extra = {"grade": {"enum": list(GRADE_NAMES), "default": "navigation",
                               "description": "the preset the other keys override"}}
        else:
            extra = {"noise_free": {"type": "boolean", "default": False,
                                    "description": "start from the error-free configuration"}}
        out[name] = json_schema(cls, (cls.__doc__ or "").strip().split("\n")[0], extra)
    return out


def _loadable(get):
    """get() - a plug-in's settings class - or None when the plug-in cannot be loaded: an installed plug-in
    that fails to import must not break every scenario; one that names it gets the plug-in's error from the
    navigator.name / monitors.<name> check."""
    from trn_env.navigators.registry import PluginError
    try:
        return get()
    except PluginError:
        return None


def monitor_sections() -> dict[str, dict]:
    """{monitor name: JSON schema of its [monitors.<name>] table} of the registered monitors that declare a
    Settings class."""
    from trn_env.navigators import registry
    out = {}
    for name in registry.available_monitors():
        cls = _loadable(lambda n=name: registry.monitor_capabilities(n).settings)
        if _declared(cls):
            out[name] = json_schema(cls, f"settings of monitor {name!r} ({cls.__module__}.{cls.__name__})")
    return out


def navigator_branches() -> list[dict]:
    """One `if name == X then settings: X's schema` branch per registered navigator with a Settings class."""
    from trn_env.navigators import registry
    branches = []
    for name in registry.available():
        cls = _loadable(lambda n=name: registry.settings_class(n))
        if not _declared(cls):
            continue
        extra = dict(json_schema(registry.PublishedIntegritySettings)["properties"])   # every navigator's
        if registry.capabilities(name).needs_map:
            extra.update(_RUNTIME)
        node = json_schema(cls, f"settings of navigator {name!r} ({cls.__module__}.{cls.__name__})", extra)
        branches.append({"if": {"properties": {"name": {"const": name}}, "required": ["name"]},
                         "then": {"properties": {"settings": node}}})
    return branches


def with_generated_sections(schema: dict[str, Any]) -> dict[str, Any]:
    """A copy of the scenario schema with the generated sections in place."""
    out = copy.deepcopy(schema)
    props = out["properties"]
    props["sensors"]["properties"] = sensor_sections()
    props["monitors"]["properties"] = monitor_sections()
    nav = props["navigator"]
    nav["properties"]["settings"] = {"type": "object", "description": NAVIGATOR_SETTINGS_DESCRIPTION}
    nav["allOf"] = navigator_branches()
    return out


def settings_tables() -> Iterator[tuple[str, type, list[dict[str, str]]]]:
    """(scenario section, Settings class, rows) for every registered navigator and monitor with a Settings
    class and every sensor: the docs' settings tables, each row name, type, unit, default, range, meaning
    (navigators.core.settings.table_rows)."""
    from trn_env.navigators import registry
    from trn_env.sensors.suite import SENSOR_MODELS
    for name in registry.available():
        cls = _loadable(lambda n=name: registry.settings_class(n))
        if _declared(cls):
            yield f"navigator.settings ({name})", cls, table_rows(cls)
    for name in registry.available_monitors():
        cls = _loadable(lambda n=name: registry.monitor_settings_class(n))
        if _declared(cls):
            yield f"monitors.{name}", cls, table_rows(cls)
    for name, model in SENSOR_MODELS.items():
        yield f"sensors.{name}", model.config_cls, table_rows(model.config_cls)
