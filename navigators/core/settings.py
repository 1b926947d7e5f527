"""One declarative settings system for navigators, monitors and sensors.

A component's settings are a frozen dataclass deriving from `Settings`, each field made by `setting`, which
carries the field's default, unit, range (inclusive or exclusive bounds, allowed values, vector length) and
a one-line doc. Everything else is generated from those declarations:

- validation: `Settings(...)` / `Settings.from_mapping(...)` check every field against its declaration
  (type, finiteness, bounds, allowed values) plus the class's cross-field `check()`, and raise ONE
  `SettingsError` (a `ValueError`) listing every problem by field path (`q_vel_mps[1]`), with the unknown
  names refused against the list of known ones;
- `json_schema(cls)`: the JSON-schema object of the settings (the scenario schema's `sensors.*`,
  `monitors.*` and `navigator.settings` sections are made from it);
- `table_rows(cls)`: one row per setting (name, type, unit, default, range, meaning) for the docs.

The pattern is Stone Soup's `Property(doc=...)` (the settings document themselves) with the units and
ranges of PX4-ECL's parameter struct (a line per field with its unit).

Field kinds come from the annotations: ``bool``, ``int``, ``float``, ``str`` (with `choices`), vectors
``tuple[float, ...]`` (with `length` or `min_length`; the bounds apply to every element) and any of them
``| None`` (None allowed: "not given", the component documents what it then does). A number field may
also accept named strings (`also=("auto",)`). Values are normalised on construction: floats to `float`,
whole numbers to `int` (a whole float such as 50.0 is accepted for an int field, as JSON schema's
"integer" does), vectors to tuples of floats, NumPy booleans to `bool`.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import numbers
import types
import typing
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

_META_KEY = "trn_env.setting"


@dataclass(frozen=True)
class SettingSpec:
    """What `setting` declares about one field (see the module docstring)."""

    doc: str
    unit: str = ""
    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    choices: tuple | None = None
    length: int | None = None
    min_length: int | None = None
    also: tuple[str, ...] = ()


def setting(default: Any, doc: str, unit: str = "", *, ge: float | None = None, gt: float | None = None,
            le: float | None = None, lt: float | None = None, choices: tuple | list | None = None,
            length: int | None = None, min_length: int | None = None, also: tuple[str, ...] = ()) -> Any:
    """A settings field: `default`, a one-line `doc`, its `unit` ("m", "m/s", "deg", "1" for a ratio, "" for
    none), inclusive bounds `ge`/`le`, exclusive bounds `gt`/`lt`, allowed values `choices` (strings), a
    vector's `length` or `min_length`, and named strings a number field also accepts (`also`)."""
    if isinstance(default, list):
        default = tuple(default)
    spec = SettingSpec(doc=doc, unit=unit, ge=ge, gt=gt, le=le, lt=lt,
                       choices=None if choices is None else tuple(choices), length=length,
                       min_length=min_length, also=tuple(also))
    return dataclasses.field(default=default, metadata={_META_KEY: spec})


class SettingsError(ValueError):
    """Every problem of one settings object. `.problems`: (field path, message) pairs; str(): all of them,
    each as 'path: message', joined by '; '."""

    def __init__(self, problems: list[tuple[str, str]], owner: str = ""):
        self.problems = [(str(p), str(m)) for p, m in problems]
        self.owner = owner
        text = "; ".join(f"{p}: {m}" if p else m for p, m in self.problems)
        super().__init__(f"{owner}: {text}" if owner else text)

    def at(self, prefix: str) -> list[str]:
        """Each problem as '<prefix>.<path>: message' (a scenario's field paths)."""
        out = []
        for p, m in self.problems:
            path = f"{prefix}.{p}" if p and not p.startswith("[") else f"{prefix}{p}"
            out.append(f"{path}: {m}")
        return out


# ------------------------------------------------------------------------------------------ field kinds

@dataclass(frozen=True)
class _Field:
    name: str
    kind: str                    # "bool" | "int" | "float" | "str" | "vector" | "any"
    nullable: bool
    spec: SettingSpec
    default: Any


def _kind_of(tp) -> tuple[str, bool]:
    """(kind, nullable) of an annotation."""
    nullable = False
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        nullable = len(args) < len(typing.get_args(tp))
        kinds = {_kind_of(a)[0] for a in args}
        if len(kinds) > 1:
            kinds.discard("str")      # float | str: a number that also takes named strings (`also`)
        return (kinds.pop() if len(kinds) == 1 else "any"), nullable
    if tp is bool:
        return "bool", False
    if tp is int:
        return "int", False
    if tp is float:
        return "float", False
    if tp is str:
        return "str", False
    if origin is tuple or tp is tuple:
        nested = any(typing.get_origin(a) is tuple for a in typing.get_args(tp))
        return ("any" if nested else "vector"), False
    return "any", False


def settings_fields(cls) -> tuple[_Field, ...]:
    """The declared fields of a Settings class (kinds resolved from its annotations), in order."""
    cached = cls.__dict__.get("_settings_fields_cache")
    if cached is not None:
        return cached
    hints = typing.get_type_hints(cls)
    out = []
    for f in fields(cls):
        spec = f.metadata.get(_META_KEY)
        if spec is None:
            raise TypeError(f"{cls.__name__}.{f.name}: every settings field is declared with setting()")
        kind, nullable = _kind_of(hints[f.name])
        out.append(_Field(f.name, kind, nullable or f.default is None, spec, f.default))
    result = tuple(out)
    type.__setattr__(cls, "_settings_fields_cache", result)
    return result


def _bounds_text(spec: SettingSpec) -> str:
    lo = f"[{spec.ge:g}" if spec.ge is not None else (f"({spec.gt:g}" if spec.gt is not None else None)
    hi = f"{spec.le:g}]" if spec.le is not None else (f"{spec.lt:g})" if spec.lt is not None else None)
    if lo and hi:
        return f"{lo}, {hi}"
    if lo:
        return f"{'>=' if spec.ge is not None else '>'} {spec.ge if spec.ge is not None else spec.gt:g}"
    if hi:
        return f"{'<=' if spec.le is not None else '<'} {spec.le if spec.le is not None else spec.lt:g}"
    return ""


def _number_problem(x: float, spec: SettingSpec) -> str | None:
    if not math.isfinite(x):
        return "must be a finite number"
    if ((spec.ge is not None and x < spec.ge) or (spec.gt is not None and x <= spec.gt)
            or (spec.le is not None and x > spec.le) or (spec.lt is not None and x >= spec.lt)):
        return f"must be {'in ' if ',' in _bounds_text(spec) else ''}{_bounds_text(spec)}"
    return None


def _unit(spec: SettingSpec) -> str:
    return f" {spec.unit}" if spec.unit and spec.unit != "1" else ""


def _is_number(v) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_))


def _coerce(f: _Field, v: Any) -> tuple[Any, list[tuple[str, str]]]:
    """(normalised value, problems) of one field's value."""
    spec = f.spec
    if v is None:
        return (None, []) if f.nullable else (v, [(f.name, "must be given (null is not allowed here)")])
    if isinstance(v, str) and v in spec.also:
        return v, []
    got = f"got {v!r}"
    if f.kind == "bool":
        if isinstance(v, (bool, np.bool_)):
            return bool(v), []
        return v, [(f.name, f"must be true or false, {got}")]
    if f.kind == "str":
        if not isinstance(v, str) or (spec.choices is not None and v not in spec.choices):
            what = f"one of {list(spec.choices)}" if spec.choices is not None else "a string"
            return v, [(f.name, f"must be {what}, {got}")]
        return v, []
    if f.kind in ("int", "float"):
        also = f" or one of {list(spec.also)}" if spec.also else ""
        if not _is_number(v):
            return v, [(f.name, f"must be a{' whole' if f.kind == 'int' else ''} number{also}, {got}")]
        x = float(v)
        if f.kind == "int":
            if not (math.isfinite(x) and x == int(x)):
                return v, [(f.name, f"must be a whole number{also}, {got}")]
            value: Any = int(x)
        else:
            value = x
        msg = _number_problem(x, spec)
        if msg:
            return v, [(f.name, f"{msg}{_unit(spec)}{also}, {got}")]
        return value, []
    if f.kind == "vector":
        if isinstance(v, (str, bytes)) or not hasattr(v, "__iter__"):
            return v, [(f.name, f"must be a list of numbers, {got}")]
        items = list(v.ravel() if hasattr(v, "ravel") else v)
        if spec.length is not None and len(items) != spec.length:
            return v, [(f.name, f"must hold {spec.length} numbers, {got}")]
        if spec.min_length is not None and len(items) < spec.min_length:
            return v, [(f.name, f"must hold at least {spec.min_length} number(s), {got}")]
        problems, out = [], []
        for i, x in enumerate(items):
            if not _is_number(x):
                problems.append((f"{f.name}[{i}]", f"must be a number, got {x!r}"))
                continue
            msg = _number_problem(float(x), spec)
            if msg:
                problems.append((f"{f.name}[{i}]", f"{msg}{_unit(spec)}, got {x!r}"))
            out.append(float(x))
        return (tuple(out) if not problems else v), problems
    return v, []


# ------------------------------------------------------------------------------------------ the base

@dataclass(frozen=True)
class Settings:
    """Base of every component's settings (see the module docstring). Subclasses are
    ``@dataclass(frozen=True)`` classes whose fields are all made with `setting`; they may override
    `resolve` (fill settings whose default depends on others) and `check` (cross-field constraints)."""

    def __post_init__(self):
        problems: list[tuple[str, str]] = []
        for f in settings_fields(type(self)):
            value, probs = _coerce(f, getattr(self, f.name))
            if probs:
                problems += probs
            else:
                object.__setattr__(self, f.name, value)
        if not problems:
            self.resolve()
            problems += [(p, m) for p, m in self.check()]
        if problems:
            raise SettingsError(problems)

    def resolve(self) -> None:
        """Fill settings whose default depends on others (use object.__setattr__); runs before `check`."""

    def check(self) -> list[tuple[str, str]]:
        """Cross-field problems as (field path, message); runs once every field is valid on its own."""
        return []

    # ---------------------------------------------------------------------------------- construction
    @classmethod
    def names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))

    @classmethod
    def from_mapping(cls, mapping: dict | None = None, base: Settings | None = None):
        """Settings from a mapping of names to values (`base` supplies the defaults); every unknown name and
        every bad value are reported together in one SettingsError."""
        mapping = dict(mapping or {})
        known = cls.names()
        problems = [(k, unknown_message(k, known)) for k in sorted(mapping, key=str) if k not in known]
        kw = {k: v for k, v in mapping.items() if k in known}
        try:
            obj = dataclasses.replace(base, **kw) if base is not None else cls(**kw)
        except SettingsError as exc:
            problems += exc.problems
            obj = None
        if problems:
            raise SettingsError(sorted(problems, key=lambda pm: _order(cls, pm[0])))
        return obj

    @classmethod
    def build(cls, settings: Settings | dict | None = None, overrides: dict | None = None):
        """A component constructor's settings: a `cls` instance, a mapping, or None (the defaults), with
        keyword `overrides` on top (the constructor's own keyword arguments)."""
        if settings is None or isinstance(settings, dict):
            return cls.from_mapping({**(settings or {}), **(overrides or {})})
        if not isinstance(settings, cls):
            raise SettingsError([("settings", f"must be a {cls.__name__} or a mapping, got "
                                              f"{type(settings).__name__}")])
        return cls.from_mapping(overrides, base=settings) if overrides else settings

    def as_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def copy_to(self, obj: Any, names: str) -> None:
        """Set ``obj.<name>`` to this object's setting of that name, for each of the space-separated
        `names`: the settings a component reads as its own attributes, copied in one statement."""
        for name in names.split():
            setattr(obj, name, getattr(self, name))


def _order(cls, path: str) -> int:
    name = path.split("[", 1)[0]
    names = cls.names()
    return names.index(name) if name in names else -1


def unknown_message(name: str, known) -> str:
    """'unknown setting' with the close matches and the known names."""
    close = difflib.get_close_matches(str(name), list(known), n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    return f"unknown setting{hint}; known: {', '.join(sorted(known))}"


# ------------------------------------------------------------------------------------- generated parts

def _json_default(v):
    if isinstance(v, tuple):
        return list(v)
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def field_schema(f: _Field) -> dict:
    """The JSON-schema node of one field."""
    spec = f.spec
    node: dict[str, Any] = {}
    bounds = {k: v for k, v in (("minimum", spec.ge), ("exclusiveMinimum", spec.gt), ("maximum", spec.le),
                                ("exclusiveMaximum", spec.lt)) if v is not None}
    if f.kind == "bool":
        node["type"] = "boolean"
    elif f.kind == "str":
        node["type"] = "string"
        if spec.choices is not None:
            node["enum"] = list(spec.choices)
    elif f.kind in ("int", "float"):
        num = {"type": "integer" if f.kind == "int" else "number", **bounds}
        node = {"anyOf": [num, {"enum": list(spec.also)}]} if spec.also else num
    elif f.kind == "vector":
        node = {"type": "array", "items": {"type": "number", **bounds}}
        if spec.length is not None:
            node["minItems"] = node["maxItems"] = spec.length
        if spec.min_length is not None:
            node["minItems"] = spec.min_length
    doc = spec.doc + (f" ({spec.unit})" if spec.unit and spec.unit != "1" else "")
    node["description"] = doc
    if f.default is not None:
        node["default"] = _json_default(f.default)
    return node


def json_schema(cls, description: str = "", extra: dict[str, dict] | None = None) -> dict:
    """The JSON-schema object of a Settings class (unknown keys refused); `extra`: further properties a
    file may hold beside the settings (e.g. a sensor's "noise_free" preset switch)."""
    props = {f.name: field_schema(f) for f in settings_fields(cls)}
    props.update(extra or {})
    node: dict[str, Any] = {"type": "object", "additionalProperties": False, "properties": props}
    if description:
        node["description"] = description
    return node


def type_name(f: _Field) -> str:
    base = {"bool": "bool", "int": "int", "float": "float", "str": "str", "any": "any"}.get(f.kind)
    if f.kind == "vector":
        base = f"float[{f.spec.length}]" if f.spec.length else "list of float"
    if f.spec.also:
        base += " | " + " | ".join(f'"{s}"' for s in f.spec.also)
    return base + (" | None" if f.nullable else "")


def range_text(f: _Field) -> str:
    if f.spec.choices is not None:
        return ", ".join(f'"{c}"' for c in f.spec.choices)
    text = _bounds_text(f.spec)
    if f.kind == "vector" and text:
        text = f"each {text}"
    return text


def default_text(v) -> str:
    if v is None:
        return "None"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, tuple):
        return "[" + ", ".join(default_text(x) for x in v) + "]"
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def table_rows(cls) -> list[dict[str, str]]:
    """One row per setting of a Settings class: name, type, unit, default, range, meaning (the docs'
    settings tables)."""
    return [{"name": f.name, "type": type_name(f), "unit": f.spec.unit, "default": default_text(f.default),
             "range": range_text(f), "meaning": f.spec.doc} for f in settings_fields(cls)]


def settings_rows(cls) -> list[dict[str, Any]] | None:
    """The rows of `table_rows` with the raw default value (not its text) and the doc under "doc" as well as
    "meaning"; None when `cls` is not a Settings class (a plug-in without one)."""
    if not (isinstance(cls, type) and issubclass(cls, Settings)):
        return None
    rows = table_rows(cls)
    for row, f in zip(rows, settings_fields(cls), strict=True):
        row["default"] = f.default
        row["doc"] = row["meaning"]
    return rows


def markdown_table(cls) -> str:
    """`table_rows(cls)` as a Markdown table."""
    cols = ("name", "type", "unit", "default", "range", "meaning")
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for row in table_rows(cls):
        cells = [f"`{row['name']}`"] + [row[c].replace("|", "\\|") for c in cols[1:]]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
