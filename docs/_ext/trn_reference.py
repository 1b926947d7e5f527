"""Sphinx extension: the reference pages generated from the code at build time.

Each `*_markdown()` function returns one page's Markdown, read from the code that defines the thing
documented, never hand-copied: the CLI from its argument parser, the scenario file from its JSON schema, the
navigator / monitor / sensor settings from their declared settings, `summary.json` and campaign rows from
`trn_env.output.fields`. `write_pages(folder)` writes them; Sphinx calls it when the build starts, and
tests/test_docs.py calls the functions to check that every option, field and setting appears.
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import json
import re
from importlib import resources
from pathlib import Path

GENERATED = ("cli", "scenario", "campaign", "settings", "outputs", "env")
_SUFFIX_UNITS = (("_deg_s", "deg/s"), ("_mps2", "m/s²"), ("_mps", "m/s"), ("_rps", "rad/s"), ("_deg", "deg"),
                 ("_rad", "rad"), ("_hz", "Hz"), ("_km", "km"), ("_m2", "m²"), ("_m", "m"), ("_s", "s"),
                 ("_kg", "kg"), ("_pa", "Pa"), ("_k", "K"), ("_ft", "ft"), ("_kt", "kt"))


def _cell(text) -> str:
    """Text for one Markdown table cell."""
    s = "" if text is None else str(text)
    return s.replace("|", "\\|").replace("\n", " ").strip()


def unit_of(name: str) -> str:
    """The unit a field's name carries by the project's naming convention (h_msl_m -> m), else ""."""
    low = name.lower()
    for suffix, unit in _SUFFIX_UNITS:
        if low.endswith(suffix):
            return unit
    return ""


# ---------------------------------------------------------------------------------------------------- CLI
def cli_parser() -> argparse.ArgumentParser:
    from trn_env import cli
    return cli._parser()


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _sub_help(parser: argparse.ArgumentParser) -> dict[str, str]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return {a.dest: a.help or "" for a in action._choices_actions}
    return {}


def cli_markdown() -> str:
    parser = cli_parser()
    out = ["# Command line (`trn-env`)", "",
           "Generated from the argument parser of `trn_env.cli`. Every command exits 0 on success, 2 on "
           "bad input (one line naming the field or file, nothing written), 130 on Ctrl-C and 143 on "
           "SIGTERM; `campaign --check` exits 1 when the gate finds a regression. A reader that closes the "
           "output early (`trn-env campaign ... | head -1`) stops nothing: the rest of the output is "
           "dropped and the command finishes its work and its files.", ""]
    top = [a for a in parser._actions if a.option_strings and a.dest != "help"]
    if top:
        out += ["## Global options", "", "| option | meaning |", "|---|---|"]
        out += [f"| `{', '.join(a.option_strings)}` | {_cell(a.help)} |" for a in top]
        out.append("")
    helps = _sub_help(parser)
    for name, sub in _subparsers(parser).items():
        out += [f"## `trn-env {name}`", "", _cell(helps.get(name, sub.description or "")), "", "```text",
                sub.format_usage().replace("usage: ", "").strip(), "```", "",
                "| argument | default | meaning |", "|---|---|---|"]
        for a in sub._actions:
            if a.dest == "help":
                continue
            label = ", ".join(a.option_strings) if a.option_strings else a.dest
            if a.option_strings and a.nargs != 0:
                mv = a.metavar if a.metavar is not None else (
                    "{" + ",".join(map(str, a.choices)) + "}" if a.choices else a.dest.upper())
                label += " " + (" ".join(mv) if isinstance(mv, tuple) else str(mv))
            default = "" if a.default in (None, False, [], argparse.SUPPRESS) else f"`{a.default}`"
            if a.required and a.option_strings:
                default = "required"
            out.append(f"| `{label}` | {default} | {_cell(a.help)} |")
        out.append("")
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------------------------------------- scenario
def scenario_schema() -> dict:
    return json.loads(resources.files("trn_env.scenario").joinpath("schema.json").read_text(encoding="utf-8"))


def _resolve(node: dict, schema: dict) -> dict:
    while isinstance(node, dict) and "$ref" in node:
        ref = node["$ref"]
        target = schema
        for part in ref.lstrip("#/").split("/"):
            target = target[part]
        node = {**target, **{k: v for k, v in node.items() if k != "$ref"}}
    return node


def _type_of(node: dict) -> str:
    if "enum" in node:
        return "one of " + ", ".join(f"`{json.dumps(v)}`" for v in node["enum"])
    if "const" in node:
        return f"`{json.dumps(node['const'])}`"
    t = node.get("type")
    if isinstance(t, list):
        return " or ".join(t)
    if t == "array":
        items = node.get("items", {})
        inner = _type_of(items) if isinstance(items, dict) and items else "value"
        return f"array of {inner}"
    if t:
        return str(t)
    for key in ("oneOf", "anyOf"):
        if key in node:
            return " or ".join(_type_of(n) for n in node[key])
    return "any"


def _range_of(node: dict) -> str:
    parts = []
    if "minimum" in node:
        parts.append(f">= {node['minimum']}")
    if "exclusiveMinimum" in node:
        parts.append(f"> {node['exclusiveMinimum']}")
    if "maximum" in node:
        parts.append(f"<= {node['maximum']}")
    if "exclusiveMaximum" in node:
        parts.append(f"< {node['exclusiveMaximum']}")
    if "minItems" in node or "maxItems" in node:
        parts.append(f"{node.get('minItems', 0)}..{node.get('maxItems', 'any')} items")
    return ", ".join(parts)


_MINIMAL_SCENARIO = {
    "name": "minimal",
    "initial": {"lat_deg": 36.49, "lon_deg": -84.37, "h_agl_m": 1500.0},
    "route": {"waypoints": [{"lat_deg": 36.49, "lon_deg": -84.37, "h_agl_m": 1500.0},
                            {"lat_deg": 36.60, "lon_deg": -84.30, "h_agl_m": 1500.0}]},
    "terrain": {}, "sensors": {}, "navigator": {"name": "ins"},
}


def scenario_defaults() -> dict[str, object]:
    """The value the loader fills in for every field a minimal scenario leaves out, by dotted path."""
    import copy

    from trn_env.scenario import loading
    fill = getattr(loading, "_fill_defaults", None)
    if fill is None:
        return {}
    filled = fill(copy.deepcopy(_MINIMAL_SCENARIO))
    out: dict[str, object] = {}

    def flat(node, given, path):
        if isinstance(node, dict):
            for k, v in node.items():
                sub_given = given.get(k) if isinstance(given, dict) else None
                full = f"{path}.{k}" if path else k
                if isinstance(v, dict):
                    flat(v, sub_given if isinstance(sub_given, dict) else {}, full)
                elif sub_given is None:
                    out[full] = v
    flat(filled, _MINIMAL_SCENARIO, "")
    return out


def schema_fields(schema: dict, defaults: dict[str, object] | None = None) -> list[dict]:
    """Every field of a JSON schema by dotted path (`[]` marks the items of an array of tables); `defaults`:
    the values a loader fills in, by path, where the schema gives none."""
    defaults = defaults or {}
    rows: list[dict] = []

    def walk(node: dict, path: str) -> None:
        node = _resolve(node, schema)
        props = node.get("properties")
        if props is None:
            for key in ("oneOf", "anyOf"):
                for alt in node.get(key, []):
                    alt = _resolve(alt, schema)
                    if "properties" in alt:
                        walk(alt, path)
                        return
            if node.get("type") == "array" and isinstance(node.get("items"), dict):
                walk(node["items"], path + "[]")
            return
        required = set(node.get("required", []))
        for name, sub in props.items():
            sub_r = _resolve(sub, schema)
            full = f"{path}.{name}" if path else name
            unit = sub_r.get("x-unit", unit_of(name))
            if "default" in sub_r:
                default = f"`{json.dumps(sub_r['default'])}`"
            elif name in required:
                default = "required"
            elif full in defaults and not isinstance(defaults[full], dict):
                default = f"`{json.dumps(defaults[full], default=str)}`"
            else:
                default = ""
            rows.append({"path": full, "type": _type_of(sub_r), "unit": unit, "default": default,
                         "range": _range_of(sub_r), "description": sub_r.get("description", "")})
            walk(sub_r, full)

    walk(schema, "")
    return rows


def scenario_fields() -> list[dict]:
    """Every field of the scenario schema by dotted path, with the loader's defaults."""
    return schema_fields(scenario_schema(), scenario_defaults())


def scenario_markdown() -> str:
    schema = scenario_schema()
    out = ["# Scenario file", "", _cell(schema.get("description", "")), "",
           "Generated from `trn_env/scenario/schema.json`, the schema every scenario is validated against "
           "(`trn-env validate FILE` lists every problem with its field path), and from the loader, which "
           "fills the defaults shown. A path with `[]` is a field of each table in an array of tables "
           "(`[[route.waypoints]]`). Units follow the field's name (`_m` metres, `_s` seconds, `_deg` "
           "degrees, `_mps` m/s). The navigator's, monitors' and sensors' own settings are listed on the "
           "[settings reference](settings.md).", ""]
    header = ["| field | type | unit | default | range | meaning |", "|---|---|---|---|---|---|"]
    rows = scenario_fields()
    tops = {r["path"].split(".")[0].split("[")[0] for r in rows if "." in r["path"] or "[" in r["path"]}
    scalars = [r for r in rows if r["path"] not in tops and "." not in r["path"] and "[" not in r["path"]]
    out += ["## Top level", ""] + header
    out += [_row(r) for r in scalars]
    section = None
    for row in rows:
        if row in scalars:
            continue
        top = row["path"].split(".")[0].split("[")[0]
        if top != section:
            section = top
            out += ["", f"## `[{section}]`", ""] + header
        out.append(_row(row))
    return "\n".join(out + [""] + scenario_sections_markdown()) + "\n"


def scenario_sections_markdown() -> list[str]:
    """The typed sections a validated scenario is read through (trn_env.scenario.sections), one row per
    table: its attribute on `Scenario` and its class."""
    import typing

    from trn_env.scenario import sections as secs
    hints = typing.get_type_hints(secs.ScenarioSections)
    out = ["## In Python", "",
           "`load_scenario` returns a `Scenario` whose tables are typed, frozen sections "
           "(`trn_env.scenario.sections`), the fields named as the keys above; `scenario.to_dict()` gives "
           "the validated dict back ([scenarios guide](../guide/scenarios.md)).", "",
           "| table | attribute | class | holds |", "|---|---|---|---|"]
    for name, tp in hints.items():
        if typing.get_origin(tp) is tuple:
            cls = typing.get_args(tp)[0]
            shown = f"tuple of `{cls.__name__}`"
        else:
            args = [a for a in typing.get_args(tp) if a is not type(None)]
            cls = args[0] if args else tp
            shown = f"`{getattr(cls, '__name__', str(cls))}`" + (" or None" if args else "")
        if not isinstance(cls, type) or cls.__module__ != secs.__name__:
            continue
        doc = " ".join((cls.__doc__ or "").strip().split("\n\n")[0].split())
        doc = _cell(doc.split("]: ", 1)[1] if doc.startswith("[") and "]: " in doc else doc)
        out.append(f"| `[{name}]` | `scenario.{name}` | {shown} | {doc} |")
    return out


def _row(row: dict) -> str:
    return (f"| `{row['path']}` | {_cell(row['type'])} | {row['unit']} | {row['default']} | "
            f"{_cell(row['range'])} | {_cell(row['description'])} |")


# ----------------------------------------------------------------------------------------------- campaign
def campaign_markdown() -> str:
    from trn_env.campaign.log_replay import LOG_SCHEMA
    from trn_env.campaign.spec import MAX_RUNS, SCHEMA
    header = ["| key | type | unit | default | range | meaning |", "|---|---|---|---|---|---|"]
    out = ["# Campaign file", "",
           "Generated from the JSON schemas every campaign file is checked against "
           "(`trn_env.campaign.spec.SCHEMA`, `trn_env.campaign.log_replay.LOG_SCHEMA`); the "
           "[campaigns guide](../guide/campaigns.md) shows them at work. Every problem is listed by its key "
           "and `trn-env campaign` exits 2 before the first run. A file asking for more than "
           f"{MAX_RUNS:,} runs is refused, and so is a scenario, navigator label, seed or sweep point given "
           "twice.", "", "## Flights: `scenarios = [...]`", ""] + header
    out += [_row(r) for r in schema_fields(SCHEMA)]
    out += ["", "## Sensor logs: `logs = [...]`", "",
            "A file with `logs` replays recorded logs open loop ([sensor logs](../guide/logs.md)).", ""]
    out += header
    out += [_row(r) for r in schema_fields(LOG_SCHEMA)]
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------------------------------------- settings
def _settings_rows(factory) -> list[dict]:
    """The settings of a navigator / monitor / sensor class: its declared settings when it has them
    (trn_env.navigators.core.settings), else its constructor's keyword arguments."""
    try:
        from trn_env.navigators.core import settings as core_settings  # the declarative settings system
    except ImportError:
        core_settings = None
    if core_settings is not None and hasattr(core_settings, "settings_rows"):
        rows = core_settings.settings_rows(factory)
        if rows is not None:
            return list(rows)
    target = factory
    if dataclasses.is_dataclass(target):
        return [{"name": f.name, "type": getattr(f.type, "__name__", str(f.type)), "unit": unit_of(f.name),
                 "default": None if f.default is dataclasses.MISSING else f.default, "range": "",
                 "doc": f.metadata.get("doc", "")} for f in dataclasses.fields(target)]
    try:
        sig = inspect.signature(target)
    except (TypeError, ValueError):
        return []
    doc = inspect.getdoc(target) or ""
    rows = []
    for p in sig.parameters.values():
        if p.kind in (p.VAR_KEYWORD, p.VAR_POSITIONAL) or p.name in ("self", "dem", "rng"):
            continue
        m = re.search(rf"^\s*{re.escape(p.name)}\s*:[^\n]*\n\s+([^\n]+)", doc, re.M)
        rows.append({"name": p.name, "type": "" if p.annotation is p.empty else str(p.annotation),
                     "unit": unit_of(p.name), "default": None if p.default is p.empty else p.default,
                     "range": "", "doc": m.group(1).strip() if m else ""})
    return rows


def settings_sections() -> list[tuple[str, str, list[dict]]]:
    """(kind, name, rows) for every registered navigator and monitor and every sensor configuration."""
    from trn_env.navigators import registry
    sections = []
    for name in registry.available():
        sections.append(("navigator", name, _settings_rows(registry.settings_class(name)
                                                           if hasattr(registry, "settings_class")
                                                           else registry._FACTORIES[name][0]
                                                           if name in getattr(registry, "_FACTORIES", {})
                                                           else None)))
    for name in registry.available_monitors():
        cls = registry.monitor_settings_class(name) if hasattr(registry, "monitor_settings_class") else None
        sections.append(("monitor", name, _settings_rows(cls) if cls is not None else []))
    from trn_env.sensors.suite import SENSOR_MODELS
    for name, model in SENSOR_MODELS.items():
        sections.append(("sensor", name, _settings_rows(model.config_cls)))
    return sections


def settings_markdown() -> str:
    out = ["# Navigator, monitor and sensor settings", "",
           "Generated from each component's declared settings. In a scenario they go under "
           "`[navigator.settings]`, `[[monitors]]` and `[sensors.<name>]`; from Python they are the keyword "
           "arguments of `trn_env.navigators.registry.create(name, **settings)`. A bad value is refused "
           "with a `ValueError` naming the setting.", ""]
    def table(rows: list[dict]) -> list[str]:
        lines = ["| setting | type | unit | default | range | meaning |", "|---|---|---|---|---|---|"]
        for r in rows:
            default = "" if r.get("default") is None else f"`{r['default']!r}`"
            lines.append(f"| `{r['name']}` | {_cell(r.get('type'))} | {_cell(r.get('unit'))} | {default} | "
                         f"{_cell(r.get('range'))} | {_cell(r.get('doc'))} |")
        return lines + [""]

    from trn_env.navigators import registry
    out += ["## every navigator", "",
            "`registry.create` takes these for every navigator besides its own settings below (its published "
            "horizontal protection level: [integrity](../guide/integrity.md)); in a scenario they go under "
            "`[navigator.settings]` too.", ""]
    out += table(_settings_rows(registry.PublishedIntegritySettings))
    for kind, name, rows in settings_sections():
        out += [f"## {kind} `{name}`", ""]
        if not rows:
            out += ["(no settings)", ""]
            continue
        out += table(rows)
    return "\n".join(out) + "\n"


# ------------------------------------------------------------------------------------------------ outputs
def outputs_markdown() -> str:
    from trn_env.output.fields import CAMPAIGN_ROW_FIELDS, SUMMARY_FIELDS
    out = ["# Outputs: `summary.json` and campaign rows", "",
           "Generated from `trn_env.output.fields`; a test checks that every key a real run writes is "
           "listed.",
           "", "## `summary.json`", "", "| field | unit | meaning |", "|---|---|---|"]
    out += [f"| `{k}` | {f.unit} | {_cell(f.meaning)} |" for k, f in SUMMARY_FIELDS.items()]
    out += ["", "## Campaign rows (`rows/*.parquet`)", "",
            "One Parquet row per run; a name ending in `.` or `_` stands for every column with that "
            "prefix.", "",
            "| column | unit | meaning |", "|---|---|---|"]
    out += [f"| `{k}` | {f.unit} | {_cell(f.meaning)} |" for k, f in CAMPAIGN_ROW_FIELDS.items()]
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------------------------------------------- env
def _docstring_page(cls, title: str, intro: str) -> str:
    """A class docstring written in Markdown (gymnasium's env-page style) as a page, its headings one level
    down under the page title."""
    doc = inspect.getdoc(cls) or ""
    lines = []
    for line in doc.splitlines():
        lines.append("#" + line if line.startswith("## ") or line.startswith("### ") else line)
    first, _, rest = "\n".join(lines).partition("\n")
    return f"# {title}\n\n{intro}\n\n{first}\n{rest}\n"


def env_markdown() -> str:
    import gymnasium

    import trn_env  # noqa: F401 - registers the ids
    parts = []
    for env_id in sorted(i for i in gymnasium.registry if i.startswith("trn_env/")):
        spec = gymnasium.registry[env_id]
        entry = spec.entry_point if spec.entry_point is not None else spec.vector_entry_point
        if not isinstance(entry, str):
            entry = f"{entry.__module__}:{entry.__qualname__}"
        module, _, name = str(entry).partition(":")
        import importlib
        cls = getattr(importlib.import_module(module), name)
        page = _docstring_page(cls, f"`{env_id}`", f"`{module}.{name}`, registered by `import trn_env`. "
                               "Generated from the class docstring.")
        parts.append(page.replace("\n# ", "\n## ", 1) if parts else page)
    head = ("# The gymnasium environments\n\n`import trn_env` registers the ids below; each section is its "
            "class docstring: spaces with per-element bounds, reward, starting state, episode end, arguments "
            "and version history.\n\n")
    return head + "\n".join("#" + p if p.startswith("# ") else p for p in parts)


PAGES = {"cli": cli_markdown, "scenario": scenario_markdown, "campaign": campaign_markdown,
         "settings": settings_markdown, "outputs": outputs_markdown, "env": env_markdown}


def write_pages(folder: Path) -> list[Path]:
    """Write every generated page into `folder` (only when its text changed, so Sphinx rebuilds less)."""
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, make in PAGES.items():
        path = folder / f"{name}.md"
        text = make()
        if not path.exists() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")
        written.append(path)
    return written


def _on_builder_inited(app) -> None:
    write_pages(Path(app.srcdir) / "reference")


def setup(app):
    app.connect("builder-inited", _on_builder_inited)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
