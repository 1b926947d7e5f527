"""Campaign throughput: the same short flights serially in this process, on the local backend (a process
pool over every core) and on a local Ray instance - runs per minute and parallel efficiency.

- campaign_serial_runs_per_min: the runs one after another in this process (the reference);
- campaign_local_runs_per_min, campaign_local_parallel_efficiency: the local pool on all cores, and its
  speed-up over the serial runs divided by the number of workers (1.0 = linear; the target is >= 0.8);
- campaign_ray_runs_per_min, campaign_ray_vs_local: Ray on a local instance with as many CPUs, after a
  warm-up round (a Ray worker is a fresh process that imports the packages and loads the numba caches once;
  campaign_ray_warmup_s is that round), and its ratio to the local pool (target >= 0.8). Starting Ray
  takes 10-15 s here, so `quick` leaves Ray out (campaign_ray.skipped).
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

    rows: list[dict] = []
    t0 = time.perf_counter()
    with LocalBackend(workers) as pool:
        pool.run(todo, dems, lambda row, _log: rows.append(row))
    t_local = time.perf_counter() - t0
    out["campaign_local_runs_per_min"] = 60.0 * n_runs / t_local
    out["campaign_local_parallel_efficiency"] = (t_serial / t_local) / workers
    out["campaign_local_same_results"] = _same(serial, rows)
    out["campaign_local_mean_run_wall_s"] = _mean_wall(rows)

    if quick:
        out["campaign_ray.skipped"] = "quick: starting Ray alone takes 10-15 s (run trn-env bench)"
        return out
    try:
        from trn_env.campaign.ray_backend import RayBackend, import_ray
        import_ray()
    except ImportError as exc:       # BackendError is a ValueError, not this: only a broken install
        out["campaign_ray.error"] = str(exc)
        return out
    except ValueError as exc:
        out["campaign_ray.error"] = str(exc)
        return out
    t0 = time.perf_counter()
    with RayBackend(workers=workers) as ray_backend:
        out["campaign_ray_init_s"] = time.perf_counter() - t0
        warm: list[dict] = []
        t0 = time.perf_counter()
        ray_backend.run(todo[:workers], dems, lambda row, _log: warm.append(row))
        out["campaign_ray_warmup_s"] = time.perf_counter() - t0
        ray_rows: list[dict] = []
        t0 = time.perf_counter()
        ray_backend.run(todo, dems, lambda row, _log: ray_rows.append(row))
        t_ray = time.perf_counter() - t0
    out["campaign_ray_runs_per_min"] = 60.0 * n_runs / t_ray
    out["campaign_ray_vs_local"] = t_local / t_ray
    out["campaign_ray_parallel_efficiency"] = (t_serial / t_ray) / workers
    out["campaign_ray_same_results"] = _same(serial, ray_rows)
    out["campaign_ray_mean_run_wall_s"] = _mean_wall(ray_rows)
    return out


def _mean_wall(rows: list[dict]) -> float:
    """Mean wall time of a run inside its worker (the flight alone, without the backend's hand-over)."""
    return sum(r["wall_time_s"] for r in rows) / len(rows)


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
