"""Scenario files: load a TOML scenario, validate it completely, and list the built-in ones.

A scenario is a TOML file holding everything one closed-loop run needs (see
trn_env/scenario/schema.json and the built-in files in builtin/). `load_scenario` checks it in two passes
before any flight starts and reports EVERY problem, each prefixed with the field's path
(e.g. ``route.waypoints[2].lat_deg: 95 is greater than the maximum of 90``):

0. every number in the file finite: NaN and infinity are refused at their field path wherever they stand
   (free-form settings tables included), unless the schema marks the field `"x-allow-nonfinite": true`
   and says what they mean there (no field does today) - a JSON-schema minimum or maximum is false for
   NaN, so the schema alone lets it through;
1. the JSON schema (types, ranges, required keys, unknown keys);
2. semantic checks that need the data: exactly one altitude per waypoint, GNSS outages ordered, the
   DEM files readable, the initial position and every waypoint inside the true terrain and the
   navigator's map, the navigator name known, every sensor the navigator and the monitors require
   (their declared capabilities) fitted, the component settings accepted by their components.

Problems are raised together as one `ScenarioError` whose `.problems` is the list of messages. A valid
dict then becomes the `Scenario`'s typed sections (trn_env.scenario.sections.from_dict): from here on no
component reads the dict.

Why the schema checks the dict rather than the typed sections doing it all: the schema states every field's
type and range in one place that several components extend at once; its `sensors.*`, `monitors.*` and
`navigator.settings` sections are generated from the components' declared settings
(navigators.core.settings, trn_env.scenario.schema_sections), which the components also validate in their
constructors, so `registry.create` and the Python API get the same checks as a scenario file; the
finite-number walk closes the NaN/infinity class for every present and future numeric field without
restating them. The sections are built once all of that holds.

This module reads the files and holds the `Scenario`; the checks themselves are trn_env.scenario.validation
(re-exported here).
"""

from __future__ import annotations

import copy
import os
import sys
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from trn_env.scenario.sections import ScenarioSections, SectionsError
from trn_env.scenario.sections import from_dict as from_sections_dict
from trn_env.scenario.validation import (
    DEFAULT_DURATION_S,
    DEFAULT_GUIDANCE_RATE_HZ,
    DEFAULT_INITIAL_ERRORS,
    DEFAULT_MAX_HORIZONTAL_SIGMA_M,
    DEFAULT_NAVIGATOR_LATENCY_UPDATES,
    DEFAULT_NAVIGATOR_RATE_HZ,
    DEFAULT_SEED,
    ScenarioError,
    _fill_defaults,
    _sensor_need_problems,
    field_path,
    fitted_sensors,
    nonfinite_problems,
    schema,
    schema_problems,
    validate,
)

# the validation (trn_env.scenario.validation) is re-exported: its names stay importable from here
__all__ = ["DEFAULT_DURATION_S", "DEFAULT_GUIDANCE_RATE_HZ", "DEFAULT_INITIAL_ERRORS",
           "DEFAULT_MAX_HORIZONTAL_SIGMA_M", "DEFAULT_NAVIGATOR_LATENCY_UPDATES", "DEFAULT_NAVIGATOR_RATE_HZ",
           "DEFAULT_SEED", "Scenario", "ScenarioError", "_fill_defaults", "_sensor_need_problems",
           "apply_overrides", "builtin_names", "field_path", "fitted_sensors", "list_scenarios",
           "load_scenario", "nonfinite_problems", "read_scenario_file", "schema", "schema_problems",
           "validate"]

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


_SECTION_NAMES = ("aircraft", "truth", "initial", "initial_errors", "route", "wind", "atmosphere", "terrain",
                  "sensors", "gnss", "navigator", "monitors", "guidance", "limits")


@dataclass
class Scenario:
    """A validated scenario: its typed sections (trn_env.scenario.sections) and how it is being run.

    ``scenario.route.waypoints[0].lat_deg``, ``scenario.sensors.imu`` (an ImuConfig),
    ``scenario.navigator.settings`` (the navigator's Settings object) ...: every section of the file is an
    attribute (`sections` holds them). `seed` and `duration_s` are the run's (the file's unless a caller runs
    it otherwise, e.g. an env episode's seed); `extras` holds what is not part of the file (loaded DEMs).
    `to_dict()` gives the scenario back as the validated dict (what the resolved scenario.toml is written
    from)."""

    name: str
    source: str
    sections: ScenarioSections
    description: str = ""
    seed: int = DEFAULT_SEED
    duration_s: float = DEFAULT_DURATION_S
    extras: dict[str, Any] = field(default_factory=dict)   # not part of the file (e.g. loaded DEMs)

    @classmethod
    def from_dict(cls, data: dict, *, name: str | None = None, source: str = "<dict>",
                  seed: int | None = None, duration_s: float | None = None,
                  extras: dict[str, Any] | None = None) -> Scenario:
        """A Scenario of an already validated dict (a `to_dict()` edited by code that keeps it valid, such
        as a warm-up or an episode's start) without validating it again; `validate` checks a dict."""
        try:
            secs = from_sections_dict(data)
        except SectionsError as exc:
            raise ScenarioError(source, exc.problems) from None
        return cls(name=secs.name if name is None else name, source=source, sections=secs,
                   description=secs.description, seed=int(secs.seed if seed is None else seed),
                   duration_s=float(secs.duration_s if duration_s is None else duration_s),
                   extras={} if extras is None else extras)

    def to_dict(self) -> dict[str, Any]:
        """The scenario as the validated dict (defaults filled in): a copy the caller may edit."""
        return self.sections.to_dict()

    @property
    def navigator_name(self) -> str:
        return str(self.sections.navigator.name)

    def monitor(self, name: str):
        """The [monitors.<name>] section (trn_env.scenario.sections.MonitorSection), None if absent."""
        return self.sections.monitor(name)

    def with_overrides(self, **overrides: Any) -> Scenario:
        """A re-validated copy with `seed`, `duration_s` or `navigator` replaced (None = keep)."""
        data = apply_overrides(self.to_dict(), **overrides)
        return validate(data, source=self.source)

    def with_fields(self, assignments: dict[str, Any]) -> Scenario:
        """A re-validated copy with fields set by dotted path (``{"guidance.rate_hz": 5.0}``, as
        ``trn-env fly --set`` and campaign sweeps set them: trn_env.scenario.overrides)."""
        from trn_env.scenario.overrides import apply_fields
        data = apply_fields(self.to_dict(), list(assignments.items()))
        return validate(data, source=self.source)


def _section_property(key: str) -> property:
    return property(lambda self: getattr(self.sections, key),
                    doc=f"The scenario's [{key}] section (trn_env.scenario.sections).")


for _key in _SECTION_NAMES:
    setattr(Scenario, _key, _section_property(_key))


def _builtin_dir():
    return resources.files("trn_env.scenario.builtin")


def builtin_names() -> list[str]:
    """Names of the scenarios shipped with the package (the TOML files in trn_env/scenario/builtin/)."""
    return sorted(p.name[:-5] for p in _builtin_dir().iterdir() if p.name.endswith(".toml"))


def list_scenarios() -> list[tuple[str, str]]:
    """(name, description) of every built-in scenario."""
    out = []
    for name in builtin_names():
        text = (_builtin_dir() / f"{name}.toml").read_text(encoding="utf-8")
        try:
            desc = str(tomllib.loads(text).get("description", ""))
        except tomllib.TOMLDecodeError as exc:
            desc = f"(unreadable: {exc})"
        out.append((name, desc))
    return out


def read_scenario_file(name_or_path: str | Path) -> tuple[dict, str]:
    """Parse a built-in scenario name or a TOML path into a dict; returns (data, source description)."""
    if not isinstance(name_or_path, (str, os.PathLike)):
        raise TypeError(f"a scenario is a built-in name, a TOML file's path, a Scenario or a scenario dict, "
                        f"got {type(name_or_path).__name__}")
    text_path = Path(name_or_path)
    if str(name_or_path) in builtin_names() and not text_path.suffix:
        res = _builtin_dir() / f"{name_or_path}.toml"
        source = f"built-in '{name_or_path}'"
        text = res.read_text(encoding="utf-8")
    else:
        source = str(text_path)
        if text_path.is_dir():
            raise ScenarioError(source, ["file: is a directory, not a scenario file (give a .toml file or a "
                                         f"built-in name: {', '.join(builtin_names())})"])
        if text_path.exists() and not text_path.is_file():
            raise ScenarioError(source, ["file: not a regular file (a device, a pipe or a socket): give a "
                                         ".toml file"])
        if not text_path.is_file():
            known = ", ".join(builtin_names())
            raise ScenarioError(source, [f"file: no such scenario file or built-in name "
                                         f"(built-ins: {known})"])
        try:
            text = text_path.read_text(encoding="utf-8-sig")      # (an editor's byte-order mark is fine)
        except UnicodeDecodeError as exc:
            raise ScenarioError(source, [f"file: not a UTF-8 text file ({exc.reason} at byte {exc.start})"]
                                ) from None
        except OSError as exc:
            raise ScenarioError(source, [f"file: cannot read: {exc}"]) from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        hint = (" (it looks like JSON: a scenario file is TOML, e.g. a resolved scenario.toml of a run "
                "folder)" if text.lstrip().startswith(("{", "[{")) else "")
        raise ScenarioError(source, [f"file: not valid TOML: {exc}{hint}"]) from exc
    if source == str(text_path):
        data.setdefault("name", text_path.stem)
    return data, source


def load_scenario(name_or_path: str | Path = "default", *, check_components: bool = True,
                  **overrides: Any) -> Scenario:
    """Read, override and validate a scenario.

    Parameters
    ----------
    name_or_path : str, Path, Scenario or dict
        A built-in scenario name (``trn-env scenarios`` lists them), a TOML file's path, a Scenario (run
        with other overrides) or a scenario dict.
    check_components : bool
        Also build what validation cannot judge from the file alone (DEMs load, the start trims, the
        navigator accepts its settings); False checks the file against the schema only.
    **overrides
        ``seed=`` (int), ``duration_s=`` (float, s) and ``navigator=`` (a navigator name or reference),
        applied before validation as ``trn-env fly --seed/--duration/--navigator`` do.

    Returns
    -------
    Scenario
        The validated scenario.

    Raises
    ------
    ScenarioError
        Listing every problem, each with its field path.
    """
    data, source, base = scenario_data(name_or_path)
    data = apply_overrides(data, **overrides)
    return validate(data, source=source, base_dir=base, check_components=check_components)


def scenario_data(scenario) -> tuple[dict, str, Path | None]:
    """(data, source description, folder its relative paths are taken from) of a built-in name, a TOML
    path, a Scenario (its `to_dict()`: paths already resolved) or a scenario dict (paths taken as given)."""
    if isinstance(scenario, Scenario):
        return scenario.to_dict(), scenario.source, None
    if isinstance(scenario, dict):
        return copy.deepcopy(scenario), "<dict>", None
    data, source = read_scenario_file(scenario)
    return data, source, Path(scenario).resolve().parent if source == str(Path(scenario)) else None


def apply_overrides(data: dict, *, seed: int | None = None, duration_s: float | None = None,
                    navigator: str | None = None, **unknown: Any) -> dict:
    """A copy of `data` with the command-line overrides applied. TypeError for any other keyword, naming the
    overrides and the dotted-path form for other fields."""
    if unknown:
        raise TypeError(
            f"unknown scenario override(s) {', '.join(map(repr, unknown))}: the overrides are seed=, "
            f"duration_s= (s) and navigator=; any other field by dotted path, e.g. run_scenario('default', "
            f"sets={{'wind.layers.0.speed_mps': 12.0}})"
        )
    data = copy.deepcopy(data)
    if seed is not None:
        data["seed"] = seed
    if duration_s is not None:
        data["duration_s"] = duration_s
    if navigator is not None:
        nav = data.setdefault("navigator", {})
        if isinstance(nav, dict):
            if nav.get("name") != navigator:
                nav.pop("settings", None)   # settings belong to the navigator they were written for
            nav["name"] = navigator
    return data


