"""One campaign run: its task (a small picklable description) and the worker function that flies it into
a result row. The backends (local process pool, Ray) only move tasks and rows; this is what runs.

A run's own exception becomes a row with `termination = "error"` and the message, never a crashed
campaign. The worker flies inline (no pipelined second process: the backends already use every core), which
gives the same bits as `trn-env fly` pipelined or not (trn_env.sim.closed_loop).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import platform
import socket
import time
import traceback
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from trn_env.campaign.spec import RunKey
from trn_env.output.metrics import METRIC_KEYS, MetricSettings, horizontal_series, navigation_metrics
from trn_env.scenario.sections import ScenarioSections

SERIES_KEYS = ("t_s", "err_h_m", "err_v_m", "sigma_h_m", "hpl_m", "nav_ok")


@dataclass(frozen=True)
class RunTask(RunKey):
    """Everything a worker needs to fly one run (the DEMs travel separately, once per worker)."""

    scenario_name: str
    scenario_source: str
    navigator_label: str
    sweep: dict
    sections: ScenarioSections      # the validated scenario's typed sections (seed: the variant's)
    dem_keys: tuple
    metric_settings: dict
    keep_logs: bool
    replay_command: str
    attempt: int = 1


def versions() -> dict[str, str]:
    import jsbsim

    import trn_env
    try:
        from importlib.metadata import version
        pkg = version("trn-env")
    except Exception:  # noqa: BLE001 - not installed as a distribution (source tree)
        pkg = getattr(trn_env, "__version__", "unknown")
    return {"trn_env_version": pkg, "jsbsim_version": str(getattr(jsbsim, "__version__", "unknown")),
            "numpy_version": np.__version__, "python_version": platform.python_version()}


def scenario_hash(data: dict) -> str:
    """sha256 of the run's scenario (defaults filled, seed set), canonical JSON."""
    text = json.dumps(data, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


# DEMs of the campaign by key (spec.Variant.dem_keys); the local pool's parent fills it before forking,
# Ray workers get it from the object store; a spawned worker without it loads the DEM itself.
_DEMS: dict[str, Any] = {}


def set_dems(dems: dict[str, Any]) -> None:
    _DEMS.clear()
    _DEMS.update(dems)


def _base_row(task: RunTask) -> dict:
    row = {
        "campaign": task.campaign, "campaign_hash": task.campaign_hash, "run_id": task.run_id,
        "run_index": task.run_index, "variant_index": task.variant_index, "seed_index": task.seed_index,
        "seed": task.seed, "scenario": task.scenario_name, "scenario_source": task.scenario_source,
        "scenario_hash": "", "navigator": task.navigator_label,
        "navigator_name": str(task.sections.navigator.name),
        "sweep_json": json.dumps(task.sweep, sort_keys=True), "replay_command": task.replay_command,
        "navigator_settings_json": json.dumps(task.sections.navigator.table.to_dict(), sort_keys=True,
                                              default=str),
        "gnss_outages_json": json.dumps([o.to_dict() for o in task.sections.gnss.outages], sort_keys=True),
        "termination": "error", "error": None, "attempts": task.attempt,
        "wall_time_s": float("nan"), "sim_time_s": float("nan"), "distance_flown_m": float("nan"),
        "jsbsim_steps": 0, "host": socket.gethostname(), "pid": os.getpid(),
    }
    row.update(versions())
    return unflown(row, task.sweep)


def unflown(row: dict, sweep: dict) -> dict:
    """row (in place) with every metric NaN (track_lost False) and every series empty, as a run that has
    not flown yet, and the sweep point's values under "sweep.<path>"; returns row."""
    for k in METRIC_KEYS:
        row[k] = float("nan") if k != "track_lost" else False
    for k in SERIES_KEYS:
        row[f"series_{k}"] = []
    for path, v in sweep.items():
        row[f"sweep.{path}"] = v
    return row


def task_scenario(task: RunTask, dems: dict[str, Any] | None = None):
    """The run's own Scenario (the variant's typed sections with the run's seed; its DEMs from `dems`, else
    from the table set_dems filled)."""
    from trn_env.scenario.loading import Scenario
    table = _DEMS if dems is None else dems
    sections = replace(task.sections, seed=int(task.seed))
    extras: dict[str, Any] = {}
    wk, mk = task.dem_keys
    if wk is not None and wk in table:
        extras["world_dem_raw"] = table[wk]
    if mk is not None and mk in table:
        extras["map_dem_raw"] = table[mk]
    return Scenario(name=task.scenario_name, source=task.scenario_source, sections=sections,
                    description=str(sections.description), seed=int(task.seed),
                    duration_s=float(sections.duration_s), extras=extras)


def fly_run(task: RunTask, dems: dict[str, Any] | None = None) -> tuple[dict, bytes | None]:
    """Fly one run; returns (row, the compressed log.npz bytes if the campaign keeps logs). Never raises
    on the run's own failure: the row carries termination 'error' and the message. An env-episode task
    (`trn_env.campaign.episodes.EpisodeTask`, kind "episode") flies its episode instead."""
    if getattr(task, "kind", "flight") == "episode":
        from trn_env.campaign.episodes import fly_episode
        return fly_episode(task, dems)
    if getattr(task, "kind", "flight") == "replay":       # a log campaign (trn_env.campaign.log_replay)
        from trn_env.campaign.log_replay import replay_run
        return replay_run(task)
    from trn_env.sim.closed_loop import ClosedLoop

    row = _base_row(task)
    scenario = task_scenario(task, dems)
    row["scenario_hash"] = scenario_hash(scenario.sections.to_dict())
    wall0 = time.perf_counter()
    try:
        loop = ClosedLoop(scenario, pipeline=False)
        result = loop.run()
        wall = time.perf_counter() - wall0
        summary = result.summary
        metrics = navigation_metrics(result.arrays, MetricSettings(**task.metric_settings))
    except Exception as exc:  # noqa: BLE001 - a run's failure is its row, not the campaign's end
        row["error"] = f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=6)}"
        row["wall_time_s"] = time.perf_counter() - wall0
        return row, None
    row["termination"] = summary["termination"]
    row["wall_time_s"] = wall
    for k in ("sim_time_s", "distance_flown_m", "jsbsim_steps"):
        row[k] = summary[k]
    row.update(metrics)
    for k, v in horizontal_series(result.arrays).items():
        row[f"series_{k}"] = v.tolist()
    log_bytes = None
    if task.keep_logs:
        buf = io.BytesIO()
        np.savez_compressed(buf, **result.arrays)
        log_bytes = buf.getvalue()
    return row, log_bytes


def retry_task(task: RunTask) -> RunTask:
    return replace(task, attempt=task.attempt + 1)


def died_row(task: RunTask, why: str) -> dict:
    """The row of a run whose worker process died on every attempt."""
    if getattr(task, "kind", "flight") == "episode":
        from trn_env.campaign.episodes import died_episode_row
        return died_episode_row(task, why)
    row = _base_row(task)
    row["scenario_hash"] = scenario_hash(replace(task.sections, seed=int(task.seed)).to_dict())
    row["error"] = why
    return row
