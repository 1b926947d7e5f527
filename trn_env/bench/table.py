"""The readable form of `trn-env bench`: one row per figure with its same-run reference and their ratio.

`run_all` returns one flat dict (printed as JSON by `trn-env bench --json`; its keys are the design's
contract). `bench_rows` groups it for people: a figure, its value, the reference measured in the same run
and the ratio figure / reference (or the ratio the benchmark computed itself, e.g. the median of segment
ratios). Figures without a reference get their own row with the reference and ratio left empty; errors of a
failing component are listed as rows too. Lists and nested tables (per-segment, per-stage breakdowns) stay
in the JSON.
"""

from __future__ import annotations

import math
from typing import Any

# (figure key, reference key, ratio key or None = computed figure / reference, what the reference is)
PAIRS: list[tuple[str, str, str | None, str]] = [
    ("flight_steps_per_s", "jsbsim_steps_per_s", "flight_ratio", "bare JSBSim run() loop"),
    ("closed_loop_steps_per_s", "closed_loop_jsbsim_reference_steps_per_s", "closed_loop_ratio",
     "bare JSBSim, same aircraft and start"),
    ("closed_loop_steps_per_s_inline", "closed_loop_jsbsim_reference_steps_per_s_inline",
     "closed_loop_ratio_inline", "bare JSBSim (loop in one process)"),
    ("closed_loop_ms_per_tick", "closed_loop_bare_jsbsim_ms_per_tick", None, "bare JSBSim, same steps"),
    ("env_sim_seconds_per_wall_second", "env_jsbsim_reference_sim_seconds_per_wall_second", "env_ratio",
     "bare JSBSim sim s per wall s"),
    ("subproc_vec_env_sim_seconds_per_wall_second",
     "subproc_vec_env_jsbsim_reference_sim_seconds_per_wall_second", "subproc_vec_env_ratio",
     "bare JSBSim sim s per wall s"),
    ("env_route_cpu_agent_steps_per_s", "env_route_cpu_agent_steps_per_s_before", "env_route_speedup",
     "TerrainNav-v0 at the rates before issue 34 (route task, CPU)"),
    ("env_route_decision_rates_cpu_agent_steps_per_s", "env_route_cpu_agent_steps_per_s_before",
     "env_route_decision_rates_speedup", "TerrainNav-v0 at the rates before issue 34 (route task, CPU)"),
    ("env_route_sim_seconds_per_cpu_second", "env_gym_jsbsim_reference_sim_seconds_per_cpu_second",
     "env_route_cpu_ratio_to_gym_jsbsim", "bare JSBSim gym loop, King Air 60 Hz (CPU)"),
    ("env_route_sim_seconds_per_wall_second", "env_gym_jsbsim_reference_sim_seconds_per_wall_second",
     "env_route_ratio_to_gym_jsbsim", "bare JSBSim gym loop, King Air 60 Hz"),
    ("env_route_sim_seconds_per_wall_second", "env_gymnasium_jsbsim_package_sim_seconds_per_wall_second",
     "env_route_ratio_to_gymnasium_jsbsim_package", "the gymnasium-jsbsim package, its Cessna 172P env"),
    ("env_route_jsbsim_alone_sim_seconds_per_wall_second",
     "env_gymnasium_jsbsim_package_sim_seconds_per_wall_second",
     "env_route_jsbsim_alone_ratio_to_gymnasium_jsbsim_package",
     "the package (the env's JSBSim alone: its ceiling)"),
    ("env_route_sim_seconds_per_cpu_second", "env_gym_jsbsim_reference_100hz_sim_seconds_per_cpu_second",
     "env_route_cpu_ratio_to_gym_jsbsim_100hz", "bare JSBSim gym loop, King Air 100 Hz (CPU)"),
    ("env_route_decision_rates_sim_seconds_per_cpu_second",
     "env_gym_jsbsim_reference_sim_seconds_per_cpu_second",
     "env_route_decision_rates_cpu_ratio_to_gym_jsbsim", "bare JSBSim gym loop, King Air 60 Hz (CPU)"),
    ("bilinear_lookups_per_s", "numpy_bilinear_lookups_per_s", None, "numpy bilinear"),
    ("acq_track_closed_loop_steps_per_s", "acq_track_jsbsim_reference_steps_per_s",
     "acq_track_closed_loop_ratio", "bare JSBSim"),
    ("planner_astar_s", "planner_reference_scipy_dijkstra_s", None, "scipy Dijkstra"),
    ("integrity_mass_radius_40k_ms", "integrity_mass_radius_numpy_sort_40k_ms",
     "integrity_mass_radius_ratio_to_numpy_sort", "numpy argsort + cumsum, same 40,000 cells"),
    ("filters_ins_tercom_sim_s_per_wall_s", "filters_bare_jsbsim_sim_s_per_wall_s", None, "bare JSBSim"),
    ("fast_env_agent_steps_per_s", "fast_env_full_tier_agent_steps_per_s", "fast_env_ratio_to_full_tier",
     "TerrainNav-v0 agent steps/s (full JSBSim loop)"),
    ("fast_env_agent_steps_per_cpu_s", "fast_env_bare_jsbsim_agent_steps_per_s", None,
     "bare JSBSim run() loop, 30 s decisions/s"),
    ("campaign_ray_mean_run_wall_s", "campaign_local_mean_run_wall_s", None, "local process pool"),
    ("campaign_ray_runs_per_min", "campaign_local_runs_per_min", "campaign_ray_vs_local",
     "local process pool (Ray's actors warm)"),
    ("campaign_ray_cold_runs_per_min", "campaign_ray_tasks_cold_runs_per_min", None,
     "Ray tasks, both from a fresh instance"),
    ("campaign_ray_first_row_s", "campaign_ray_tasks_first_row_s", None, "Ray tasks, first row"),
]


def _number(v: Any) -> float | None:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    return float(v)


def fmt(v: float | None) -> str:
    """A figure with 3-4 significant digits and thousands separators for large values."""
    if v is None:
        return ""
    if not math.isfinite(v):
        return str(v)
    if abs(v) >= 1000:
        return f"{v:,.0f}"
    if abs(v) >= 10:
        return f"{v:.1f}"
    return f"{v:.3g}"


def bench_rows(results: dict) -> list[tuple[str, str, str, str, str]]:
    """(figure, value, reference, reference value, ratio) rows, paired figures first, then the rest in the
    order of `results`, then errors."""
    used: set[str] = set()
    rows = []
    for fig, ref, ratio_key, ref_name in PAIRS:
        v = _number(results.get(fig))
        if v is None:
            continue
        r = _number(results.get(ref))
        ratio = _number(results.get(ratio_key)) if ratio_key else None
        if ratio is None and r:
            ratio = v / r
        rows.append((fig, fmt(v), f"{ref_name} ({ref})" if r is not None else "", fmt(r), fmt(ratio)))
        used |= {fig, ref} | ({ratio_key} if ratio_key else set())
    for key, value in results.items():
        if key in used or key.endswith((".error", ".traceback")) or key == "quick":
            continue
        v = _number(value)
        if v is not None:
            rows.append((key, fmt(v), "", "", ""))
    for key, value in results.items():
        if key.endswith(".error"):
            rows.append((key, str(value), "", "", ""))
    return rows


def bench_table(results: dict):
    """A rich Table of `bench_rows(results)`."""
    from rich.table import Table
    quick = " (--quick: short measurements)" if results.get("quick") else ""
    table = Table(title=f"trn-env bench{quick}: figures beside same-run references "
                        "(trn-env bench --json for every key, breakdowns included)")
    table.add_column("figure")
    table.add_column("value", justify="right")
    table.add_column("reference (same run)")
    table.add_column("reference value", justify="right")
    table.add_column("ratio", justify="right")
    for row in bench_rows(results):
        table.add_row(*row)
    return table
