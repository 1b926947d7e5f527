"""What `trn-env navigators` prints: every navigator and monitor with its settings (name, type, unit,
default, meaning), read from the plug-in itself.

The settings of a factory are found, in order, in

1. a settings dataclass the class names (`settings_class`, `Settings`, `config_class` or `Config`
   attribute; e.g. AcqTrackConfig): its fields, with `unit` / `doc` from each field's metadata when given,
   else the field's trailing comment in the source;
2. the keyword parameters of the constructor (a factory function's `settings_class` attribute names the
   class whose constructor it forwards to), followed through the base classes while a constructor passes
   `**settings` on; the meaning from a numpydoc "Parameters" section of the class or constructor docstring.

The unit comes from the name's suffix when the metadata does not give it (`_m` metres, `_s` seconds,
`_mps` m/s, ...: the project's naming rule, DESIGN.md "Conventions").
"""

from __future__ import annotations

import dataclasses
import inspect
import re
import tokenize
from dataclasses import dataclass
from io import StringIO

_UNIT_SUFFIXES = {
    "_mps2_rthz": "m/s²/√Hz", "_rps_rthz": "rad/s/√Hz", "_m_per_sqrt_s": "m/√s",
    "_mps_per_sqrt_s": "m/s/√s", "_rad_per_sqrt_s": "rad/√s", "_mps2": "m/s²", "_mps": "m/s", "_rps": "rad/s",
    "_mrad": "mrad", "_rad": "rad", "_deg": "deg", "_hz": "Hz", "_km": "km", "_m": "m", "_s": "s",
    "_kg": "kg", "_db": "dB", "_mb": "MB", "_pa": "Pa",
}
_SETTINGS_ATTRS = ("settings_class", "Settings", "config_class", "Config")
_SKIP = {"self", "rng", "name"}
_DEM_MEANING = ("terrain map (terrain.Dem, or a name/path for terrain.load); a scenario gives the "
                "navigator's map")


@dataclass
class SettingDoc:
    """One setting: name, type (annotation text), unit ("-" when dimensionless or not stated), default
    (repr; "required" when there is none) and meaning (may be empty)."""

    name: str
    type: str
    unit: str
    default: str
    meaning: str

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def unit_of(name: str) -> str:
    """The unit a setting's name states by its suffix, or "-"."""
    low = name.lower()
    for suffix in sorted(_UNIT_SUFFIXES, key=len, reverse=True):
        if low.endswith(suffix):
            return _UNIT_SUFFIXES[suffix]
    return "-"


def summary_of(factory) -> str:
    """The first line of the factory's (or its settings class's) docstring."""
    for obj in (factory, getattr(factory, "settings_class", None)):
        doc = inspect.getdoc(obj) if obj is not None else None
        if doc:
            return doc.strip().splitlines()[0]
    return ""


def settings_of(factory) -> list[SettingDoc]:
    """The settings a navigator or monitor factory accepts (see the module docstring for where from)."""
    declared = _declared_rows(factory)
    if declared is not None:
        return declared
    target = getattr(factory, "settings_class", None) if not inspect.isclass(factory) else factory
    target = target or factory
    fixed = set(getattr(factory, "fixed_settings", {}) or {})
    overrides = dict(getattr(factory, "setting_defaults", {}) or {})
    docs: list[SettingDoc] = []
    seen: set[str] = set()
    if inspect.isclass(target):
        _constructor_settings(target, docs, seen)
    else:
        _params(target, inspect.getdoc(target) or "", docs, seen)
    out = []
    for s in docs:
        if s.name in fixed:
            continue
        if s.name in overrides:
            s.default = repr(overrides[s.name])
        out.append(s)
    return out


def _declared_rows(factory) -> list[SettingDoc] | None:
    """The rows of the declarative settings system (navigators.core.settings.settings_rows), when it is
    present and knows the factory."""
    try:
        from .core import settings as core_settings
    except ImportError:
        return None
    rows_of = getattr(core_settings, "settings_rows", None)
    if rows_of is None:
        return None
    try:
        rows = rows_of(getattr(factory, "settings_class", None) or factory)
    except Exception:  # noqa: BLE001 - a factory it does not know: fall back to introspection
        return None
    if rows is None:
        return None
    fixed = set(getattr(factory, "fixed_settings", {}) or {})
    out = []
    for r in rows:
        if r.get("name") in fixed:
            continue
        default = r.get("default")
        out.append(SettingDoc(str(r.get("name")), _type_text(r.get("type", "")), str(r.get("unit") or "-"),
                              "required" if default is None and r.get("required") else repr(default),
                              str(r.get("doc") or r.get("meaning") or "")))
    return out


def _constructor_settings(cls, docs: list[SettingDoc], seen: set[str]) -> None:
    for attr in _SETTINGS_ATTRS:
        spec = getattr(cls, attr, None)
        if inspect.isclass(spec) and dataclasses.is_dataclass(spec):
            init_only = [s for s in _param_docs(cls.__init__, _docstrings(cls)) if s.name not in _SKIP]
            for s in init_only:
                if s.name not in seen:
                    seen.add(s.name)
                    docs.append(s)
            _dataclass_settings(spec, docs, seen)
            return
    for klass in cls.__mro__:
        init = klass.__dict__.get("__init__")
        if init is None:
            continue
        more = _params(init, _docstrings(klass), docs, seen)
        if not more:
            return


def _docstrings(cls) -> str:
    init = cls.__dict__.get("__init__")
    own = inspect.cleandoc(init.__doc__) if getattr(init, "__doc__", None) else None   # not object's
    return "\n".join(filter(None, (inspect.getdoc(cls), own)))


def _params(func, doc: str, docs: list[SettingDoc], seen: set[str]) -> bool:
    """Append func's keyword parameters; True when it also takes **kwargs (more settings downstream)."""
    try:
        sig = inspect.signature(func)
    except (TypeError, ValueError):
        return False
    more = False
    for s in _param_docs(func, doc, sig):
        if s.name not in seen and s.name not in _SKIP:
            seen.add(s.name)
            docs.append(s)
    for p in sig.parameters.values():
        if p.kind is p.VAR_KEYWORD:
            more = True
    return more


def _param_docs(func, doc: str, sig=None) -> list[SettingDoc]:
    try:
        sig = sig or inspect.signature(func)
    except (TypeError, ValueError):
        return []
    meanings = _numpydoc_params(doc)
    out = []
    for p in sig.parameters.values():
        if p.kind in (p.VAR_KEYWORD, p.VAR_POSITIONAL) or p.name == "self":
            continue
        default = "required" if p.default is p.empty else repr(p.default)
        ann = p.annotation if p.annotation is not p.empty else (
            type(p.default).__name__ if p.default not in (p.empty, None) else "")
        meaning = meanings.get(p.name) or (_DEM_MEANING if p.name == "dem" else _prose_meaning(doc, p.name))
        out.append(SettingDoc(p.name, _type_text(ann), unit_of(p.name), default, meaning))
    return out


def _dataclass_settings(spec, docs: list[SettingDoc], seen: set[str]) -> None:
    comments = _field_comments(spec)
    meanings = _numpydoc_params(inspect.getdoc(spec) or "")
    for f in dataclasses.fields(spec):
        if f.name in seen or not f.init:
            continue
        seen.add(f.name)
        if f.default is not dataclasses.MISSING:
            default = repr(f.default)
        elif f.default_factory is not dataclasses.MISSING:
            default = repr(f.default_factory())
        else:
            default = "required"
        md = f.metadata or {}
        unit = md.get("unit") or unit_of(f.name)
        meaning = md.get("doc") or md.get("meaning") or meanings.get(f.name) or comments.get(f.name, "")
        docs.append(SettingDoc(f.name, _type_text(f.type), str(unit), default, str(meaning)))


def _type_text(ann) -> str:
    if isinstance(ann, str):
        return ann
    if inspect.isclass(ann):
        return ann.__name__
    return str(ann).replace("typing.", "")


def _numpydoc_params(doc: str) -> dict[str, str]:
    """name -> description from a numpydoc "Parameters" section."""
    lines = doc.splitlines()
    out: dict[str, str] = {}
    try:
        start = next(i for i, ln in enumerate(lines) if ln.strip() == "Parameters"
                     and i + 1 < len(lines) and set(lines[i + 1].strip()) == {"-"})
    except StopIteration:
        return out
    current = None
    body = lines[start + 2:]
    for i, ln in enumerate(body):
        if i + 1 < len(body) and body[i + 1].strip() and set(body[i + 1].strip()) == {"-"}:
            break                                   # the next section's title
        m = re.match(r"^\*{0,2}(\w+)\s*(:.*)?$", ln)
        if m and not ln.startswith(" "):
            current = m.group(1)
            out[current] = ""
        elif current is not None and ln.strip():
            out[current] = (out[current] + " " + ln.strip()).strip()
    return out


def _prose_meaning(doc: str, name: str) -> str:
    """A setting's description in a prose docstring: the parenthesis or the `name: ...` clause after its
    first mention (up to the next ';' or sentence end), or ""."""
    text = " ".join(doc.split())
    m = re.search(rf"(?<![\w.]){re.escape(name)}\b(?: \w+)?\s*"
                  rf"(?:\((?P<p>[^()\[\]]*(?:\([^()]*\)[^()\[\]]*)*)\)"
                  rf"|:\s*(?P<c>[^;]*?)(?:;|\.\s|\.$|$))", text)
    if not m:
        return ""
    out = (m.group("p") or m.group("c") or "").strip()
    return out if len(out) <= 160 else out[:157] + "..."


def _field_comments(spec) -> dict[str, str]:
    """field name -> its trailing `# comment` in the dataclass's source."""
    try:
        src = inspect.getsource(spec)
    except (OSError, TypeError):
        return {}
    out: dict[str, str] = {}
    try:
        tokens = list(tokenize.generate_tokens(StringIO(src).readline))
    except (tokenize.TokenError, IndentationError):
        return out
    line_name: dict[int, str] = {}
    for tok in tokens:
        if tok.type == tokenize.NAME and tok.start[1] == 4 and tok.start[0] not in line_name:
            line_name[tok.start[0]] = tok.string
        if tok.type == tokenize.COMMENT and tok.start[0] in line_name:
            out[line_name[tok.start[0]]] = tok.string.lstrip("# ").strip()
    return out
