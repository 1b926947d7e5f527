"""Campaigns over sensor logs: replay a set of logs across navigators, settings and navigator seeds.

    name = "my_logs"
    logs = ["flights/a.trnlog", "flights/b.trnlog"]   # paths relative to this file
    navigators = ["pmf", { name = "rbpf", label = "rbpf_1k", settings = { n_particles = 1000 } }]
    seeds = [0, 1]               # optional: the navigators' random stream (default: each log's own seed)

    [[sweeps]]                   # optional, navigator settings only: navigator.settings.<name>
    path = "navigator.settings.integrity_alpha"
    values = [1e-4, 1e-3]

A variant is one (log, navigator, sweep point) and flies every seed; one row per run, with the flight
campaigns' columns (the log's name as `scenario`, its path as `scenario_source`) and every metric when the
log holds truth. The rows' `replay_command` is the `trn-env replay` command that gives the same numbers.
Every log is read and validated, every navigator built on it, before any run (CampaignError listing
every problem by field).
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import shlex
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from trn_env.campaign.spec import (
    INT64_MAX,
    SCHEMA,
    CampaignError,
    NavigatorChoice,
    RunKey,
    SeedMajorRuns,
    _repeats,
    _schema_problems,
    _size_problems,
    grid_values,
    is_number,
)
from trn_env.output.metrics import MetricSettings, horizontal_series, navigation_metrics

# A log campaign's file: the flight campaign's keys (SCHEMA) with logs for scenarios, and seeds only as a list
# of the navigators' seeds (a log's own seed when left out); sweeps set navigator settings only.
LOG_SCHEMA: dict = {
    "type": "object",
    "additionalProperties": False,
    "required": ["logs", "navigators"],
    "properties": {
        **{k: SCHEMA["properties"][k] for k in ("name", "description", "metrics")},
        "navigators": {**SCHEMA["properties"]["navigators"],
                       "description": "navigator names or {name, label, settings} tables, each replayed on "
                                      "every log"},
        "sweeps": {**SCHEMA["properties"]["sweeps"],
                   "description": "navigator settings swept by dotted path (`navigator.settings.<name>`, one "
                                  "every navigator listed takes); several sweeps form a grid"},
        "logs": {"type": "array", "minItems": 1, "items": {"type": "string", "minLength": 1},
                 "description": "log folders, relative to the campaign file"},
        "seeds": {"type": "array", "minItems": 1, "uniqueItems": True,
                  "items": {"type": "integer", "minimum": 0, "maximum": INT64_MAX},
                  "description": "the navigators' random streams (default: each log's own seed)"},
    },
}


@dataclass
class LogVariant:
    index: int
    log_ref: str
    log_path: str
    log_name: str
    navigator: NavigatorChoice
    sweep: dict
    settings: dict


@dataclass(frozen=True)
class LogReplayTask(RunKey):
    log_path: str
    log_name: str
    navigator_label: str
    navigator_name: str
    settings: dict
    sweep: dict
    metric_settings: dict
    replay_command: str
    attempt: int = 1
    kind: str = "replay"


@dataclass
class LogCampaign(SeedMajorRuns):
    variants: list[LogVariant]
    sweep_paths: list[str]
    metric_settings: MetricSettings
    keep_logs: bool = False
    extra: dict = field(default_factory=dict)

    def tasks(self, skip: set[str]):
        """The campaign's replays not in `skip`, seed-major, made lazily."""
        from dataclasses import asdict
        for index, si, seed, v, rid in self.pending_runs(skip):
            argv = ["trn-env", "replay", v.log_path, "--navigator", v.navigator.name]
            if seed is not None:
                argv += ["--seed", str(seed)]
            argv += [f"--set=navigator.settings.{k}={_toml(val)}" for k, val in v.settings.items()]
            yield LogReplayTask(self.name, self.hash, rid, index, v.index, si, seed, v.log_path, v.log_name,
                                v.navigator.label, v.navigator.name, dict(v.settings), dict(v.sweep),
                                asdict(self.metric_settings), shlex.join(argv))


def _toml(v: Any) -> str:
    from trn_env.scenario.overrides import toml_value
    return toml_value(v)


def load_log_campaign(path: Path, data: dict, raw: bytes) -> LogCampaign:
    """Validate a `logs = [...]` campaign (module docstring); CampaignError with every problem."""
    from trn_env.logs import LogError, read_log
    from trn_env.logs.replay import build_maps, check_sensors, scenario_of
    source = str(path)
    problems = _schema_problems(data, LOG_SCHEMA) or _size_problems(data)
    if problems:
        raise CampaignError(source, problems)
    logs = data["logs"]
    navs = [NavigatorChoice(n, n, {}) if isinstance(n, str) else
            NavigatorChoice(n.get("label", n["name"]), n["name"], dict(n.get("settings", {})))
            for n in data["navigators"]]
    labels = [n.label for n in navs]
    problems += [f"navigators[{i}]: label {lab!r} is used twice" for i, lab in enumerate(labels)
                 if labels.index(lab) != i]
    seeds = data.get("seeds", [None])
    paths, values = [], []
    for j, s in enumerate(data.get("sweeps", [])):
        p = s["path"]
        if not p.startswith("navigator.settings.") or p.count(".") != 2:
            problems.append(f"sweeps[{j}].path: a log campaign sweeps navigator settings only "
                            "(navigator.settings.<name>)")
            continue
        if p in paths:
            problems.append(f"sweeps[{j}].path: {p!r} is swept twice")
            continue
        vals = list(s["values"]) if "values" in s else grid_values(s["grid"])
        what = "values" if "values" in s else "grid"
        problems += [f"sweeps[{j}].{what}: {vals[k]!r} (point {k}) repeats point {first}: give each value "
                     "once" for k, first in _repeats(vals)]
        paths.append(p)
        values.append(vals)
    try:
        metric_settings = MetricSettings(**data.get("metrics", {}))
    except (TypeError, ValueError) as exc:
        problems.append(f"metrics: {exc}")
        metric_settings = MetricSettings()
    base = path.resolve().parent
    opened = []
    for i, ref in enumerate(logs):
        p = Path(ref).expanduser()
        p = p if p.is_absolute() else base / p
        try:
            opened.append((ref, p, read_log(p)))
        except LogError as exc:
            problems.append(f"logs[{i}] ({ref}): {exc}")
    variants: list[LogVariant] = []
    from trn_env.scenario.build import build_navigator
    for ref, p, log in opened:
        try:
            the_map = build_maps(log, scenario_of(log, None, None, None), None)[1]
        except (LogError, ValueError, KeyError) as exc:
            problems.append(f"logs ({ref}): its map: {exc}")
            continue
        for ni, nav in enumerate(navs):
            for combo in itertools.product(*[list(v) for v in values]):
                sweep = dict(zip(paths, combo, strict=True))
                settings = {**nav.settings, **{k.split(".", 2)[2]: v for k, v in sweep.items()}}
                try:
                    d = scenario_of(log, nav.name, settings, None)
                    navigator = build_navigator(d, the_map, None)
                    check_sensors(navigator, nav.name, log)
                except (ValueError, TypeError, KeyError, LogError) as exc:
                    msg = f"navigators[{ni}] ({nav.label}) on {ref}: {exc}"
                    if msg not in problems:
                        problems.append(msg)
                    continue
                variants.append(LogVariant(len(variants), ref, str(p), log.path.name, nav, sweep, settings))
    if problems:
        raise CampaignError(source, problems)
    h = hashlib.sha256(raw)
    for _, p, _ in opened:
        h.update((p / "metadata.json").read_bytes())
    return LogCampaign(name=str(data.get("name", path.stem)), source=source,
                       description=str(data.get("description", "")), hash=h.hexdigest(),
                       text=raw.decode("utf-8"), seeds=list(seeds), variants=variants, sweep_paths=paths,
                       metric_settings=metric_settings)


def replay_run(task: LogReplayTask) -> tuple[dict, None]:
    """One replay as a campaign row (never raises on the run's own failure: termination 'error')."""
    import json
    import os
    import socket

    from trn_env.campaign.runs import unflown, versions
    from trn_env.logs.replay import replay
    row = {"campaign": task.campaign, "campaign_hash": task.campaign_hash, "run_id": task.run_id,
           "run_index": task.run_index, "variant_index": task.variant_index, "seed_index": task.seed_index,
           "seed": -1 if task.seed is None else int(task.seed), "scenario": task.log_name,
           "scenario_source": task.log_path, "scenario_hash": "", "navigator": task.navigator_label,
           "navigator_name": task.navigator_name, "sweep_json": json.dumps(task.sweep, sort_keys=True),
           "replay_command": task.replay_command, "termination": "error", "error": None,
           "attempts": task.attempt, "wall_time_s": float("nan"), "sim_time_s": float("nan"),
           "distance_flown_m": float("nan"), "jsbsim_steps": 0, "host": socket.gethostname(),
           "pid": os.getpid()} | versions()
    unflown(row, task.sweep)
    wall0 = time.perf_counter()
    try:
        res = replay(task.log_path, task.navigator_name, settings=copy.deepcopy(task.settings),
                     seed=task.seed)
    except Exception as exc:  # noqa: BLE001 - a run's failure is its row
        row["error"] = f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=6)}"
        row["wall_time_s"] = time.perf_counter() - wall0
        return row, None
    row["termination"] = res.termination
    row["wall_time_s"] = time.perf_counter() - wall0
    s = res.summary
    row["sim_time_s"] = float(s.get("sim_time_s", float("nan")))
    row["distance_flown_m"] = float(s.get("distance_flown_m", float("nan")))
    if res.has_truth:
        row.update(navigation_metrics(res.arrays, MetricSettings(**task.metric_settings)))
        for k, v in horizontal_series(res.arrays).items():
            row[f"series_{k}"] = v.tolist()
    return row, None


__all__ = ["LogCampaign", "LogReplayTask", "is_number", "load_log_campaign", "replay_run"]
