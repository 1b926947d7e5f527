"""Campaign throughput: the same short flights serially in this process, on the local backend (a process
pool over every core) and on a local Ray instance - runs per minute and parallel efficiency.

- campaign_serial_runs_per_min: the runs one after another in this process (the reference);
- campaign_local_runs_per_min, campaign_local_parallel_efficiency: the local pool on all cores, and its
  speed-up over the serial runs divided by the number of workers (1.0 = linear; the target is >= 0.8);
- Ray on a local instance with as many CPUs, twice from a fresh instance (Ray's start: campaign_ray_init_s
  and campaign_ray_tasks_init_s; it takes 10-25 s here, so `quick` leaves Ray out: campaign_ray.skipped):
  - as plain Ray tasks (RayBackend(warm=False)), cold: campaign_ray_tasks_first_row_s (the seconds to the
    first row), campaign_ray_tasks_cold_runs_per_min and its ratio to the local pool;
  - on warm actors (the default, trn_env.campaign.ray_pool), cold: campaign_ray_first_row_s,
    campaign_ray_cold_runs_per_min, campaign_ray_cold_vs_local (the actors start, import the packages -
    campaign_ray_actor_import_s - and fly the first run's warm-up copy - campaign_ray_actor_warm_up_s; the
    slowest actor's figures), then the same runs again on the now warm actors: campaign_ray_runs_per_min,
    campaign_ray_vs_local (target >= 0.8);
  - campaign_ray_same_results, campaign_ray_tasks_same_results: every row equal to the serial one to the
    bit (termination, RMS and the error series); if not, campaign_ray_differences says which run, field
    and value, with that row's termination, attempts and error;
- campaign_local_first_row_s: the seconds to the local pool's first row (its workers are forked from this
  process, which has flown the serial runs: their kernels are loaded already);
- campaign_local_mean_run_wall_s, campaign_ray_mean_run_wall_s: a run's wall time inside its worker (the
  flight alone; beside campaign_run_wall_s, the serial one, they show how much the workers slowed each
  other down and how much of a backend's wall time is hand-over);
- campaign_load_average_1min: the machine's load when the measurement started (the efficiency is only
  meaningful on an otherwise idle machine: other processes take the cores the pool counts on).

The flights: the built-in `default` scenario (INS + TERCOM over the refined Jacksboro DEM) cut to
campaign_run_sim_s simulated seconds, one seed per run. Each wall time covers handing out the tasks,
flying, and writing nothing (rows are collected in memory here).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

from trn_env.campaign.driver import tasks
from trn_env.campaign.local import LocalBackend, default_workers
from trn_env.campaign.runs import fly_run, set_dems
from trn_env.campaign.spec import load_campaign


def _campaign(n_runs: int, sim_s: float):
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "bench.toml"
        p.write_text(f'name = "bench"\nseeds = {n_runs}\nscenarios = ["default"]\nduration_s = {sim_s}\n',
                     encoding="utf-8")
        return load_campaign(p)


def benchmark(quick: bool = False) -> dict:
    workers = default_workers()
    n_runs = 2 * workers if quick else 4 * workers
    sim_s = 15.0 if quick else 30.0
    camp = _campaign(n_runs, sim_s)
    dems = camp.extra["dems"]
    todo = list(tasks(camp, set()))
    out: dict = {"campaign_runs": n_runs, "campaign_run_sim_s": sim_s, "campaign_workers": workers,
                 "campaign_load_average_1min": os.getloadavg()[0]}

    set_dems(dems)
    fly_run(todo[0])                        # warm-up (numba kernels compiled or loaded in this process)
    t0 = time.perf_counter()
    serial = [fly_run(t)[0] for t in todo]
    t_serial = time.perf_counter() - t0
    out["campaign_serial_runs_per_min"] = 60.0 * n_runs / t_serial
    out["campaign_run_wall_s"] = t_serial / n_runs

    t0 = time.perf_counter()
    with LocalBackend(workers) as pool:
        local = _timed(pool, todo, dems)
    t_local = time.perf_counter() - t0
    rows = local["rows"]
    out["campaign_local_runs_per_min"] = 60.0 * n_runs / t_local
    out["campaign_local_first_row_s"] = local["first_row_s"]
    out["campaign_local_parallel_efficiency"] = (t_serial / t_local) / workers
    out["campaign_local_same_results"] = _same(serial, rows)
    out["campaign_local_mean_run_wall_s"] = _mean_wall(rows)

    if quick:
        out["campaign_ray.skipped"] = "quick: starting Ray alone takes 10-15 s (run trn-env bench)"
        return out
    try:
        from trn_env.campaign.ray_backend import import_ray
        import_ray()
    except ImportError as exc:       # BackendError is a ValueError, not this: only a broken install
        out["campaign_ray.error"] = str(exc)
        return out
    except ValueError as exc:
        out["campaign_ray.error"] = str(exc)
        return out
    try:
        _ray_figures(out, todo, dems, serial, t_serial, t_local, workers)
    except ValueError as exc:        # BackendError: e.g. the workers import another trn-env than this one
        out["campaign_ray.error"] = str(exc)
    return out


def _ray_figures(out: dict, todo: list, dems: dict, serial: list[dict], t_serial: float, t_local: float,
                 workers: int) -> None:
    from trn_env.campaign.ray_backend import RayBackend
    n_runs = len(todo)
    # Ray tasks (warm=False): a fresh instance, the campaign flown cold (new worker processes)
    t0 = time.perf_counter()
    with RayBackend(workers=workers, warm=False) as ray_backend:
        out["campaign_ray_tasks_init_s"] = time.perf_counter() - t0
        cold = _timed(ray_backend, todo, dems)
    out["campaign_ray_tasks_first_row_s"] = cold["first_row_s"]
    out["campaign_ray_tasks_cold_runs_per_min"] = 60.0 * n_runs / cold["wall_s"]
    out["campaign_ray_tasks_cold_vs_local"] = t_local / cold["wall_s"]
    out["campaign_ray_tasks_same_results"] = _same(serial, cold["rows"])
    # Ray's warm actors (the default): a fresh instance, the campaign flown cold (the actors start, import
    # and fly the warm-up copy of the first run), then again on the same, now warm, actors
    t0 = time.perf_counter()
    with RayBackend(workers=workers) as ray_backend:
        out["campaign_ray_init_s"] = time.perf_counter() - t0
        cold = _timed(ray_backend, todo, dems)
        actors = list(ray_backend._pool.timings)
        warm = _timed(ray_backend, todo, dems)
    out["campaign_ray_first_row_s"] = cold["first_row_s"]
    out["campaign_ray_cold_runs_per_min"] = 60.0 * n_runs / cold["wall_s"]
    out["campaign_ray_cold_vs_local"] = t_local / cold["wall_s"]
    out["campaign_ray_actor_import_s"] = max(a.get("import_s", float("nan")) for a in actors)
    out["campaign_ray_actor_warm_up_s"] = max(a.get("warm_up_s", float("nan")) for a in actors)
    out["campaign_ray_runs_per_min"] = 60.0 * n_runs / warm["wall_s"]
    out["campaign_ray_vs_local"] = t_local / warm["wall_s"]
    out["campaign_ray_parallel_efficiency"] = (t_serial / warm["wall_s"]) / workers
    out["campaign_ray_same_results"] = _same(serial, cold["rows"]) and _same(serial, warm["rows"])
    diff = _differences(serial, cold["rows"]) + _differences(serial, warm["rows"])
    if diff:
        out["campaign_ray_differences"] = diff
    out["campaign_ray_mean_run_wall_s"] = _mean_wall(warm["rows"])


def _timed(backend, todo: list, dems: dict) -> dict:
    """Fly `todo` on an entered backend: its rows, the wall seconds and the seconds to the first row."""
    rows: list[dict] = []
    first = [float("nan")]
    t0 = time.perf_counter()

    def take(row: dict, _log) -> None:
        if not rows:
            first[0] = time.perf_counter() - t0
        rows.append(row)
    backend.run(todo, dems, take)
    return {"rows": rows, "wall_s": time.perf_counter() - t0, "first_row_s": first[0]}


def _mean_wall(rows: list[dict]) -> float:
    """Mean wall time of a run inside its worker (the flight alone, without the backend's hand-over)."""
    return sum(r["wall_time_s"] for r in rows) / len(rows)


def _differences(a: list[dict], b: list[dict]) -> list[str]:
    """What differs between the rows of the same runs (run id, field, the two values, and the second row's
    termination, attempts and error): empty when _same holds."""
    key = {r["run_id"]: r for r in a}
    out = [] if len(a) == len(b) else [f"{len(a)} rows against {len(b)}"]
    for r in b:
        ref = key.get(r["run_id"])
        if ref is None:
            out.append(f"{r['run_id']}: not among the reference runs")
            continue
        for k in ("termination", "horizontal_error_rms_m", "series_err_h_m"):
            if r[k] != ref[k]:
                why = str(r["error"]).strip().splitlines()[-1][:200] if r["error"] else None
                out.append(f"{r['run_id']} {k}: {_first_difference(ref[k], r[k])} (termination "
                           f"{r['termination']}, attempts {r['attempts']}, error {why!r})")
                break                                    # one line per run
    return out if len(out) <= 8 else out[:8] + [f"... and {len(out) - 8} more"]


def _first_difference(a, b) -> str:
    if not isinstance(a, list) or not isinstance(b, list):
        return f"{a!r} against {b!r}"
    if len(a) != len(b):
        return f"{len(a)} values against {len(b)}"
    i = next(i for i, (x, y) in enumerate(zip(a, b, strict=True)) if x != y)
    return f"first at index {i} of {len(a)}: {a[i]!r} against {b[i]!r}"


def _same(a: list[dict], b: list[dict]) -> bool:
    """The same runs with the same metrics, to the bit."""
    key = {r["run_id"]: r for r in a}
    return len(a) == len(b) and all(
        r["horizontal_error_rms_m"] == key[r["run_id"]]["horizontal_error_rms_m"]
        and r["series_err_h_m"] == key[r["run_id"]]["series_err_h_m"] for r in b)


if __name__ == "__main__":
    import json
    import sys
    print(json.dumps(benchmark(quick="--quick" in sys.argv), indent=2))
