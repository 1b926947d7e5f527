"""Field overrides by dotted path (`wind.layers.0.speed_mps = 12`), shared by `trn-env fly --set` and the
campaigns' sweeps, so a campaign run replays alone with the same overrides.

A path's parts are dictionary keys, or list indices for lists (`route.waypoints.1.h_agl_m`). Missing
tables on the way are created (the scenario schema then decides whether the key exists: an unknown key is a
schema problem at its field path); an index beyond a list's end, or a path through a value that is not a
table or a list, is a `ValueError` naming the path.
"""

from __future__ import annotations

import copy
import json
import math
import sys
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def set_field(data: dict, path: str, value: Any) -> None:
    """Set `value` at dotted `path` inside `data` (in place). Raises ValueError naming the path."""
    parts = path.split(".")
    if not path or any(p == "" for p in parts):
        raise ValueError(f"{path!r}: not a dotted path (e.g. wind.layers.0.speed_mps)")
    node: Any = data
    for i, part in enumerate(parts):
        last = i == len(parts) - 1
        where = ".".join(parts[:i]) or "(top level)"
        if isinstance(node, list):
            if not part.lstrip("-").isdigit():
                raise ValueError(f"{path}: {where} is a list, {part!r} is not an index")
            k = int(part)
            if not 0 <= k < len(node):
                raise ValueError(f"{path}: index {k} is out of range ({where} has {len(node)} item(s))")
            if last:
                node[k] = value
            else:
                node = node[k]
        elif isinstance(node, dict):
            if last:
                node[part] = value
            else:
                if part not in node:
                    node[part] = {}
                node = node[part]
        else:
            raise ValueError(f"{path}: {where} is a {type(node).__name__} ({node!r}), not a table or list")


def get_field(data: dict, path: str) -> Any:
    """The value at dotted `path` (KeyError naming the path if absent)."""
    node: Any = data
    for part in path.split("."):
        if isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        elif isinstance(node, dict) and part in node:
            node = node[part]
        else:
            raise KeyError(path)
    return node


def toml_value(value: Any) -> str:
    """A TOML literal for a value of a scenario field (bool, int, float, string, list, table)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)   # a JSON string is a TOML basic string
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(str(k))} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise ValueError(f"cannot write {type(value).__name__} {value!r} as a TOML value")


def parse_assignment(text: str) -> tuple[str, Any]:
    """'path=value' (value a TOML literal: 12, 1.5, true, "text", [1, 2]) -> (path, value)."""
    if "=" not in text:
        raise ValueError(f"--set {text!r}: expected PATH=VALUE (e.g. wind.layers.0.speed_mps=12)")
    path, raw = (s.strip() for s in text.split("=", 1))
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw      # a bare word is taken as a string
    return path, value


def apply_fields(data: dict, assignments: list[tuple[str, Any]]) -> dict:
    """A copy of `data` with each (path, value) set in order."""
    out = copy.deepcopy(data)
    for path, value in assignments:
        set_field(out, path, copy.deepcopy(value))
    return out


def load_scenario_with(name_or_path, assignments: list[tuple[str, Any]] | None = None, **overrides: Any):
    """`load_scenario` with dotted-path assignments applied after the seed/duration/navigator overrides
    (the order a campaign applies them). `name_or_path` may also be a Scenario (its `to_dict()`, paths
    already resolved) or a scenario dict. Raises ScenarioError."""
    from trn_env.scenario.loading import ScenarioError, apply_overrides, scenario_data, validate
    data, source, base = scenario_data(name_or_path)
    data = apply_overrides(data, **overrides)
    try:
        data = apply_fields(data, assignments or [])
    except ValueError as exc:
        raise ScenarioError(source, [str(exc)]) from None
    return validate(data, source=source, base_dir=base)
