"""Campaign files: the TOML format, its validation (every problem by field path), and the runs it expands to.

    name = "ci_small"
    description = "INS against INS + TERCOM, 2 seeds"
    root_seed = 16                       # seeds drawn from it through numpy SeedSequence ...
    seeds = 2                            # ... this many; or a list of scenario seeds, [0, 1, 7]
    scenarios = ["../scenarios/default_short.toml"]   # paths (relative to this file) or built-in names
    duration_s = 40.0                    # optional: every scenario's time limit
    navigators = ["ins", { name = "ins_tercom", label = "tercom", settings = { remove_bias = true } }]
    keep_logs = false                    # also keep each run's full time-series log (logs/<run>.npz)

    [metrics]                            # optional: trn_env.output.metrics.MetricSettings
    converge_threshold_m = 50.0

    [[sweeps]]                           # any scenario field by its dotted path; all sweeps as a grid
    path = "wind.layers.0.speed_mps"
    values = [5.0, 10.0]                 # or grid = { start = 0.0, stop = 10.0, num = 3 }

Without `navigators` each scenario flies its own. A variant is one (scenario, navigator, sweep point); every
variant flies every seed, and seed i is the same number in every variant (common random numbers: two
navigators meet the same turbulence and sensor noise). Each variant is validated as a scenario before any
flight, so a bad sweep path or value is reported at `sweeps[j]` with the scenario's own message.

Replay: the run's scenario is the scenario file with, in order, the seed, `duration_s` and the navigator
name overridden, then `navigator.settings` and each sweep value set by dotted path - exactly what
`trn-env fly SCENARIO --seed S --duration D --navigator N --set PATH=VALUE ...` does (the row's
`replay_command`), so the replay gives the same bits.
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np

from trn_env.output.metrics import MetricSettings
from trn_env.scenario.loading import (
    ScenarioError,
    apply_overrides,
    builtin_names,
    field_path,
    read_scenario_file,
    validate,
)
from trn_env.scenario.overrides import apply_fields, toml_value
from trn_env.scenario.sections import ScenarioSections

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

_NUMBER = {"type": "number"}
INT64_MAX = 2**63 - 1          # seeds are int64 columns in the rows (and TOML integers are 64-bit)
_METRIC_DOCS = {
    "converge_threshold_m": "time to converge: the horizontal error below this",
    "track_loss_threshold_m": "track loss: the horizontal error above this ...",
    "track_loss_k_sigma": "... or above k x sigma_h (0 disables the sigma test) ...",
    "track_loss_min_s": "... for at least this long",
    "alert_limit_m": "the horizontal alert limit of the protection-level metrics",
}
# The campaign file (docs/reference/campaign.md is generated from the descriptions).
SCHEMA: dict = {
    "type": "object",
    "additionalProperties": False,
    "required": ["scenarios", "seeds"],
    "properties": {
        "name": {"type": "string", "minLength": 1, "pattern": "^[A-Za-z0-9_.-]+$",
                 "description": "the campaign's name: its rows' `campaign` column and its default folder "
                                "`campaigns/<name>-<UTC time>` (default: the file's name)"},
        "description": {"type": "string", "description": "free text, kept in campaign.json"},
        "root_seed": {"type": "integer", "minimum": 0, "maximum": INT64_MAX, "default": 0,
                      "description": "the seed a seed count is drawn from (numpy SeedSequence.spawn)"},
        "seeds": {"oneOf": [
            {"type": "integer", "minimum": 1, "description": "a count of seeds drawn from root_seed"},
            {"type": "array", "minItems": 1, "uniqueItems": True,
             "items": {"type": "integer", "minimum": 0, "maximum": INT64_MAX},
             "description": "a list of scenario seeds"},
        ], "description": "a count of seeds drawn from root_seed, or a list of distinct scenario seeds; "
                          "seed i is the same in every variant (paired comparisons)"},
        "scenarios": {"type": "array", "minItems": 1, "items": {"type": "string", "minLength": 1},
                      "description": "scenario files (relative to this file, ~ the home folder) or built-in "
                                     "names, each listed once"},
        "duration_s": {"type": "number", "exclusiveMinimum": 0,
                       "description": "every scenario's time limit (default: each scenario's own)"},
        "navigators": {"type": "array", "minItems": 1, "items": {"oneOf": [
            {"type": "string", "minLength": 1},
            {"type": "object", "additionalProperties": False, "required": ["name"],
             "properties": {"name": {"type": "string", "minLength": 1,
                                     "description": "a built-in or plug-in navigator, or module:Name"},
                            "label": {"type": "string", "minLength": 1,
                                      "description": "its rows' `navigator` column (default: name)"},
                            "settings": {"type": "object",
                                         "description": "its settings (docs/reference/settings.md)"}}},
        ]}, "description": "navigator names or {name, label, settings} tables, each flown on every scenario "
                           "(default: each scenario's own navigator)"},
        "keep_logs": {"type": "boolean", "default": False,
                      "description": "also keep each run's full log as `logs/<run_id>.npz`"},
        "metrics": {"type": "object", "additionalProperties": False,
                    "description": "thresholds of the run metrics (trn_env.output.metrics.MetricSettings)",
                    "properties": {k: {**_NUMBER, "default": f.default, "description": _METRIC_DOCS[k]}
                                   for k, f in MetricSettings.__dataclass_fields__.items()}},
        "sweeps": {"type": "array", "description": "scenario fields swept by dotted path; several sweeps "
                                                   "form a grid (every combination)", "items": {
            "type": "object", "additionalProperties": False, "required": ["path"],
            "properties": {
                "path": {"type": "string", "pattern": r"^[A-Za-z0-9_]+(\.[A-Za-z0-9_]+)*$",
                         "description": "the field's dotted path, as `trn-env fly --set` takes it"},
                "values": {"type": "array", "minItems": 1,
                           "description": "the values, each once (5 and 5.0 count as one)"},
                "grid": {"type": "object", "additionalProperties": False,
                         "required": ["start", "stop", "num"],
                         "description": "num evenly spaced values from start to stop (numpy linspace)",
                         "properties": {"start": {**_NUMBER, "description": "the first value"},
                                        "stop": {**_NUMBER, "description": "the last value"},
                                        "num": {"type": "integer", "minimum": 1,
                                                "description": "how many values"}}},
            },
            "oneOf": [{"required": ["values"]}, {"required": ["grid"]}],
        }},
    },
}


class CampaignError(ValueError):
    """A campaign file that cannot be run; `.problems` lists every problem, each starting with its field."""

    def __init__(self, source: str, problems: list[str]):
        self.source = source
        self.problems = list(problems)
        lines = "\n".join(f"  - {p}" for p in self.problems)
        super().__init__(f"campaign {source}: {len(self.problems)} problem(s)\n{lines}")


@dataclass(frozen=True)
class NavigatorChoice:
    label: str
    name: str | None              # None: the scenario's own navigator
    settings: dict | None         # None: the scenario's own settings (only with name None)


@dataclass
class Variant:
    """One (scenario, navigator, sweep point), validated; flies every seed of the campaign."""

    index: int
    scenario_ref: str             # as written in the campaign file
    scenario_source: str          # the path or built-in name `trn-env fly` takes
    navigator: NavigatorChoice
    sweep: dict[str, Any]         # dotted path -> value
    sections: ScenarioSections    # the validated scenario's typed sections, seed not yet set
    scenario_name: str
    assignments: list[tuple[str, Any]]
    overrides: dict[str, Any]
    dem_keys: tuple[str | None, str | None] = (None, None)
    dems: tuple[Any, Any] = (None, None)


@dataclass(frozen=True)
class RunKey:
    """The fields every kind of worker task (runs.RunTask, episodes.EpisodeTask, log_replay.LogReplayTask)
    starts with: the campaign (name, hash) and which of its runs the task is (None seed: the log's own)."""

    campaign: str
    campaign_hash: str
    run_id: str
    run_index: int
    variant_index: int
    seed_index: int
    seed: int | None


@dataclass
class SeedMajorRuns:
    """The fields and the run numbering every campaign kind shares (Campaign, EpisodeCampaign,
    LogCampaign; each adds `variants`, every variant with its `index`): a run is one (variant, seed),
    numbered seed-major."""

    name: str
    source: str
    description: str
    hash: str                     # sha256 of the campaign file and the files it names
    text: str
    seeds: list

    @property
    def n_runs(self) -> int:
        return len(self.seeds) * len(self.variants)

    def run_id(self, variant_index: int, seed_index: int) -> str:
        return f"v{variant_index:03d}-s{seed_index:04d}"

    def pending_runs(self, skip: set[str]):
        """(run_index, seed_index, seed, variant, run_id) of the runs whose id is not in `skip`, seed-major,
        made lazily; run_index counts the skipped runs too."""
        index = 0
        for si, seed in enumerate(self.seeds):
            for v in self.variants:
                run_id = self.run_id(v.index, si)
                if run_id not in skip:
                    yield index, si, seed, v, run_id
                index += 1


@dataclass
class Campaign(SeedMajorRuns):
    variants: list[Variant]
    sweep_paths: list[str]
    keep_logs: bool
    metric_settings: MetricSettings
    extra: dict = field(default_factory=dict)


# The most runs one campaign file may ask for. Counted from the file before anything is drawn, validated
# or flown: drawing the seeds, checking the sweep points and validating every variant all grow with it, so a
# slip (seeds = 1000000000) would otherwise spend hours and gigabytes before the first run or its refusal.
MAX_RUNS = 1_000_000


def _size_problems(data: dict) -> list[str]:
    """The campaign's run count (seeds x scenarios x navigators x sweep points; a log campaign's logs
    instead of scenarios) above MAX_RUNS, from the schema-checked file alone."""
    seeds = data.get("seeds", [None])
    seeds = len(seeds) if isinstance(seeds, list) else int(seeds)
    what = "logs" if "logs" in data else "scenarios"
    factors = [("seeds", seeds), (what, len(data[what])),
               ("navigators", max(1, len(data.get("navigators", []))))]
    factors += [(f"sweeps[{j}]", len(sw["values"]) if "values" in sw else int(sw["grid"]["num"]))
                for j, sw in enumerate(data.get("sweeps", []))]
    runs = math.prod(n for _, n in factors)
    if runs <= MAX_RUNS:
        return []
    big = max(factors, key=lambda f: f[1])[0]
    product = " x ".join(f"{n:,} " + (f"points of {k}" if k.startswith("sweeps") else k) for k, n in factors)
    return [f"{big}: the campaign asks for {runs:,} runs ({product}), more than {MAX_RUNS:,}: split it into "
            "campaigns of fewer runs"]


def draw_seeds(root_seed: int, n: int) -> list[int]:
    """n scenario seeds (63-bit, so they fit an int64 column) from one root seed via SeedSequence.spawn."""
    return [int(c.generate_state(1, np.uint64)[0] >> np.uint64(1))
            for c in np.random.SeedSequence(int(root_seed)).spawn(int(n))]


def grid_values(g: dict) -> list[float]:
    return [float(x) for x in np.linspace(float(g["start"]), float(g["stop"]), int(g["num"]))]


def _schema_problems(data: dict, schema: dict | None = None) -> list[str]:
    """Every problem of `data` against `schema` (default: the flight campaign's SCHEMA), by field path."""
    v = jsonschema.Draft202012Validator(SCHEMA if schema is None else schema)
    out = []
    for err in sorted(v.iter_errors(data), key=lambda e: [str(p) for p in e.absolute_path]):
        path = list(err.absolute_path)
        if err.validator == "additionalProperties" and isinstance(err.instance, dict):
            allowed = sorted(err.schema.get("properties", {}))
            for key in sorted(set(err.instance) - set(allowed)):
                out.append(f"{field_path(path + [key])}: unknown key (allowed here: {', '.join(allowed)})")
            continue
        if err.validator == "required":
            missing = err.message.split("'")[1] if "'" in err.message else err.message
            out.append(f"{field_path(path + [missing])}: required key is missing")
            continue
        if err.validator == "oneOf" and path and path[0] == "seeds":
            if isinstance(err.instance, int) and not isinstance(err.instance, bool) and err.instance < 1:
                out.append(f"seeds: {err.instance} seeds: give at least one seed (a count >= 1 or a list)")
            else:
                out.append(f"seeds: {err.instance!r} is neither a seed count >= 1 nor a list of distinct "
                           f"seeds from 0 to {INT64_MAX} (64-bit)")
            continue
        if err.validator == "oneOf" and len(path) == 2 and path[0] == "sweeps":
            out.append(f"{field_path(path)}: give exactly one of values or grid")
            continue
        if err.validator == "oneOf" and err.context:
            alts = sorted({sub.message for sub in err.context if not sub.relative_path})
            out.append(f"{field_path(path)}: {' / '.join(alts)}")
            continue
        out.append(f"{field_path(path)}: {err.message}")
    return out


def _scenario_path(ref: str, base: Path) -> str:
    p = Path(ref).expanduser()
    if ref in builtin_names() and not p.suffix:
        return ref
    return str((base / p).resolve()) if not p.is_absolute() else str(p.resolve())


def _dotted(problem_path: str) -> str:
    """'wind.layers[0].speed_mps' -> 'wind.layers.0.speed_mps'."""
    return re.sub(r"\[(\d+)\]", r".\1", problem_path)


def _attribute(problem: str, sweep_at: dict[str, tuple[int, int]], nav_at: str,
               scen_at: str) -> str | tuple[int, int, str]:
    """The campaign field that caused a scenario problem: (sweep, point, problem) for a sweep's point,
    else the problem prefixed with the navigator or scenario entry."""
    field_ = _dotted(problem.split(":", 1)[0])
    for path, (j, k) in sweep_at.items():
        if field_ == path or field_.startswith(path + ".") or path.startswith(field_ + "."):
            return (j, k, problem)
    if field_.startswith("navigator"):
        return f"{nav_at}: {problem}"
    return f"{scen_at}: {problem}"


def _sweep_point_problem(j: int, path: str, values: list, points: list[int], problem: str) -> str:
    """A problem found at one or more points of sweep j, said once: a sweep over a key the scenario does
    not have fails at every point, and listing each would bury the other problems."""
    if len(points) == 1:
        return f"sweeps[{j}].values[{points[0]}] ({path} = {values[points[0]]!r}): {problem}"
    if len(points) == len(values):
        return f"sweeps[{j}] ({path}, all {len(values)} points): {problem}"
    shown, more = points[:5], ", ..." if len(points) > 5 else ""
    return (f"sweeps[{j}].values[{', '.join(map(str, shown))}{more}] ({path} = "
            f"{', '.join(repr(values[k]) for k in shown)}{more}; {len(points)} points): {problem}")


def _same_value(a: Any, b: Any) -> bool:
    """Two sweep values that make the same scenario (5 and 5.0 do; true and 1 do not)."""
    if isinstance(a, bool) or isinstance(b, bool):
        return type(a) is type(b) and a == b
    try:
        return bool(a == b)
    except (TypeError, ValueError):
        return False


def _repeats(values: list) -> list[tuple[int, int]]:
    """(k, first) for every point k that repeats an earlier point first (as _same_value judges): through a
    dict when the values are hashable (a grid's floats: linear in the points), pairwise otherwise."""
    seen: dict = {}
    out = []
    try:
        for k, v in enumerate(values):
            key = (isinstance(v, bool), v)       # 5 and 5.0 share a key, true and 1 do not
            if key in seen:
                out.append((k, seen[key]))
            else:
                seen[key] = k
        return out
    except TypeError:                            # tables or arrays among the values
        return [(k, first) for k, v in enumerate(values)
                if (first := next(i for i, w in enumerate(values) if _same_value(v, w))) != k]


def _normalise(value: Any) -> Any:
    """A sweep value as a TOML file would give it (floats stay floats, ints ints)."""
    if isinstance(value, np.generic):
        return value.item()
    return value


def campaign_hash(text: bytes, scenario_files: list[Path]) -> str:
    h = hashlib.sha256()
    h.update(text)
    for p in scenario_files:
        h.update(b"\0" + str(p.name).encode() + b"\0")
        h.update(p.read_bytes())
    return h.hexdigest()


def load_campaign(path: str | Path) -> Campaign:
    """Read and validate a campaign file and every variant it expands to. Raises CampaignError."""
    path = Path(path)
    source = str(path)
    if not path.is_file():
        raise CampaignError(source, ["file: no such campaign file"])
    try:
        raw = path.read_bytes()
        text = raw.decode("utf-8-sig")            # (an editor's byte-order mark is fine)
        data = tomllib.loads(text)
    except UnicodeDecodeError as exc:
        raise CampaignError(source, [f"file: not a UTF-8 text file ({exc.reason} at byte {exc.start})"]
                            ) from None
    except OSError as exc:
        raise CampaignError(source, [f"file: cannot read: {exc}"]) from None
    except tomllib.TOMLDecodeError as exc:
        hint = " (it looks like JSON: a campaign file is TOML)" if text.lstrip().startswith("{") else ""
        raise CampaignError(source, [f"file: not valid TOML: {exc}{hint}"]) from None
    if "logs" in data:                  # a campaign over sensor logs (trn_env.campaign.log_replay)
        from trn_env.campaign.log_replay import load_log_campaign
        return load_log_campaign(path, data, raw)
    problems = _schema_problems(data) or _size_problems(data)
    if problems:
        raise CampaignError(source, problems)
    base = path.resolve().parent
    name = data.get("name", path.stem)
    try:
        metric_settings = MetricSettings(**data.get("metrics", {}))
    except ValueError as exc:
        problems.append(str(exc))
        metric_settings = MetricSettings()

    seeds = list(data["seeds"]) if isinstance(data["seeds"], list) else draw_seeds(data.get("root_seed", 0),
                                                                                   data["seeds"])
    navs: list[NavigatorChoice] = []
    for n in data.get("navigators", []):
        if isinstance(n, str):
            navs.append(NavigatorChoice(n, n, {}))
        else:
            navs.append(NavigatorChoice(n.get("label", n["name"]), n["name"], dict(n.get("settings", {}))))
    labels = [n.label for n in navs]
    for i, lab in enumerate(labels):
        if labels.index(lab) != i:
            problems.append(f"navigators[{i}]: label {lab!r} is used twice (give each a distinct label)")
    sweeps = data.get("sweeps", [])
    sweep_paths = [s["path"] for s in sweeps]
    for j, p in enumerate(sweep_paths):
        if sweep_paths.index(p) != j:
            problems.append(f"sweeps[{j}].path: {p!r} is swept twice")
        if p == "seed" or p == "navigator.name":
            problems.append(f"sweeps[{j}].path: {p!r} has its own campaign key (seeds / navigators)")
    sweep_values = [[_normalise(v) for v in (s["values"] if "values" in s else grid_values(s["grid"]))]
                    for s in sweeps]
    # a repeated point would fly the same runs twice and count them twice in its group's statistics
    for j, values in enumerate(sweep_values):
        for k, first in _repeats(values):
            what = "values" if "values" in sweeps[j] else "grid"
            problems.append(f"sweeps[{j}].{what}: {values[k]!r} (point {k}) repeats point {first}: give each "
                            "value once")

    scen_files: list[Path] = []
    scen_raw: list[tuple[str, str, dict | None]] = []
    sources: list[str] = []
    for i, ref in enumerate(data["scenarios"]):
        src = _scenario_path(ref, base)
        if src in sources:     # its runs would be flown twice and pooled twice in every group
            problems.append(f"scenarios[{i}] ({ref}): the same scenario as scenarios[{sources.index(src)}]; "
                            "list each once")
        sources.append(src)
        try:
            d, _ = read_scenario_file(src)
            if Path(src).is_file():
                scen_files.append(Path(src))
            scen_raw.append((ref, src, d))
        except ScenarioError as err:
            problems += [f"scenarios[{i}] ({ref}): {p}" for p in err.problems]
            scen_raw.append((ref, src, None))
    if problems:
        raise CampaignError(source, problems)

    variants: list[Variant] = []
    # each problem once, in the order found; a sweep point's problem gathers the points that share it (the
    # point's own value masked: "-1.0 is less than the minimum" and "-2.0 is ..." are one problem)
    found: dict[str | tuple[int, str], tuple[str, list[int]]] = {}

    def note(problem: str | tuple[int, int, str]) -> None:
        if isinstance(problem, str):
            found.setdefault(problem, (problem, []))
            return
        j, k, text = problem
        value = re.escape(repr(sweep_values[j][k]))
        _first, points = found.setdefault((j, re.sub(rf"(?<![\w.]){value}(?![\w.])", "<value>", text)),
                                          (text, []))
        if k not in points:
            points.append(k)

    dem_cache: dict[str, Any] = {}
    dems_loaded: dict = {}           # each DEM read once for the whole campaign (its flights share them too)
    combos = list(itertools.product(*[list(enumerate(v)) for v in sweep_values]))
    for si, (ref, src, raw_data) in enumerate(scen_raw):
        for ni, nav in enumerate(navs or [None]):
            for combo in combos:
                sweep = {sweep_paths[j]: v for j, (_k, v) in enumerate(combo)}
                sweep_at = {sweep_paths[j]: (j, k) for j, (k, _v) in enumerate(combo)}
                overrides: dict[str, Any] = {}
                if "duration_s" in data:
                    overrides["duration_s"] = float(data["duration_s"])
                assignments: list[tuple[str, Any]] = []
                if nav is not None:
                    overrides["navigator"] = nav.name
                    if nav.settings:
                        assignments.append(("navigator.settings", copy.deepcopy(nav.settings)))
                assignments += list(sweep.items())
                d = apply_overrides(raw_data, **overrides)
                nav_at = f"navigators[{ni}] ({nav.label})" if nav is not None else f"scenarios[{si}] ({ref})"
                scen_at = f"scenarios[{si}] ({ref})"
                try:
                    d = apply_fields(d, assignments)
                except ValueError as exc:
                    msg = str(exc)
                    jk = next((jk for p, jk in sweep_at.items() if msg.startswith(p + ":")), None)
                    note(f"{scen_at}: {msg}" if jk is None else (*jk, msg))
                    continue
                bdir = Path(src).resolve().parent if Path(src).is_file() else None
                try:
                    sc = validate(d, source=src, base_dir=bdir, dems=dems_loaded)
                except ScenarioError as err:
                    for p in err.problems:
                        note(_attribute(p, sweep_at, nav_at, scen_at))
                    continue
                label = nav.label if nav is not None else sc.navigator_name
                choice = nav if nav is not None else NavigatorChoice(label, None, None)
                world_key = _dem_key(sc, "world")
                map_key = _dem_key(sc, "map")
                for key, raw_dem in ((world_key, sc.extras.get("world_dem_raw")),
                                     (map_key, sc.extras.get("map_dem_raw"))):
                    if key is not None and raw_dem is not None:
                        dem_cache.setdefault(key, raw_dem)
                variants.append(Variant(
                    index=len(variants), scenario_ref=ref, scenario_source=src, navigator=choice,
                    sweep=sweep, sections=sc.sections, scenario_name=sc.name, assignments=assignments,
                    overrides=overrides, dem_keys=(world_key, map_key)))
    problems = [text if isinstance(key, str) else
                _sweep_point_problem(key[0], sweep_paths[key[0]], sweep_values[key[0]], sorted(points), text)
                for key, (text, points) in found.items()]
    if problems:
        raise CampaignError(source, problems)
    for v in variants:
        v.dems = (dem_cache.get(v.dem_keys[0]) if v.dem_keys[0] else None,
                  dem_cache.get(v.dem_keys[1]) if v.dem_keys[1] else None)
    return Campaign(name=name, source=source, description=data.get("description", ""),
                    hash=campaign_hash(raw, scen_files), text=text, seeds=seeds, variants=variants,
                    sweep_paths=sweep_paths, keep_logs=bool(data.get("keep_logs", False)),
                    metric_settings=metric_settings, extra={"dems": dem_cache})


def _dem_key(sc, which: str) -> str | None:
    """Key of the raw (unrefined, error-free) DEM a variant loads: its spec and void filling."""
    cfg = getattr(sc.terrain, which)
    if which == "map" and cfg.is_world:
        return None
    fill = bool(sc.terrain.world.fill_voids if cfg.fill_voids is None else cfg.fill_voids)
    return json.dumps([str(cfg.dem), fill])


def replay_argv(variant: Variant, seed: int) -> list[str]:
    """`trn-env fly` arguments that fly one run of the campaign alone, bit for bit."""
    argv = ["trn-env", "fly", variant.scenario_source, "--seed", str(seed)]
    if "duration_s" in variant.overrides:
        argv += ["--duration", repr(variant.overrides["duration_s"])]
    if variant.overrides.get("navigator") is not None:
        argv += ["--navigator", variant.overrides["navigator"]]
    for path, value in variant.assignments:
        argv += ["--set", f"{path}={toml_value(value)}"]
    return argv


def sweep_label(sweep: dict[str, Any]) -> str:
    """'wind.layers.0.speed_mps=5.0, ...' or '-' with no sweep."""
    return ", ".join(f"{p}={v!r}" if not isinstance(v, str) else f"{p}={v}" for p, v in sweep.items()) or "-"


def is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(float(v))
