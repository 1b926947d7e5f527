"""The `trn-env` command line: fly a scenario, list scenarios, validate one, run the benchmarks.

    trn-env fly [SCENARIO] [--seed N] [--out DIR] [--navigator NAME] [--duration S] [--no-plots]
    trn-env scenarios
    trn-env validate SCENARIO
    trn-env bench [--quick]
    trn-env plan SCENARIO --goal LAT LON [--weight W] [--max-featureless M] [--agl M] --out route.toml

Exit status: 0 success, 2 invalid scenario or bad input (every problem printed, nothing written), 130
interrupted.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="trn-env",
                                description="Closed-loop terrain-referenced-navigation test range.")
    sub = p.add_subparsers(dest="command", required=True)
    fly = sub.add_parser("fly", help="fly a scenario in closed loop and write summary, log and plots")
    fly.add_argument("scenario", nargs="?", default="default",
                     help="built-in name or TOML path (default: default)")
    fly.add_argument("--seed", type=int, default=None, help="override the scenario seed")
    fly.add_argument("--out", type=Path, default=None,
                     help="output directory (default runs/<scenario>-<time>)")
    fly.add_argument("--navigator", default=None, help="override the navigator (e.g. ins, ins_tercom)")
    fly.add_argument("--duration", type=float, default=None, help="override the time limit, seconds")
    fly.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    fly.add_argument("--quiet", action="store_true", help="no progress bar")
    fly.add_argument("--no-pipeline", action="store_true",
                     help="run the sensors and the navigator in this process, not beside the flight in a "
                          "second one (same results, slower)")
    sub.add_parser("scenarios", help="list the built-in scenarios")
    val = sub.add_parser("validate", help="check a scenario file and list every problem")
    val.add_argument("scenario")
    bench = sub.add_parser("bench", help="print throughput figures as one JSON object")
    bench.add_argument("--quick", action="store_true", help="shorter measurements (less precise)")
    plan = sub.add_parser("plan", help="plan a route from the scenario's start to a goal over the terrain "
                                       "information of the navigator's map; write its [route] table and a "
                                       "plot")
    plan.add_argument("scenario", help="built-in name or TOML path (its start, map and airspeed are used)")
    plan.add_argument("--goal", nargs=2, type=float, required=True, metavar=("LAT", "LON"),
                      help="goal latitude and longitude, degrees")
    plan.add_argument("--weight", type=float, default=3.0,
                      help="extra cost of a featureless metre (0 = shortest route; default 3)")
    plan.add_argument("--max-featureless", type=float, default=None, metavar="M",
                      help="no featureless stretch longer than M metres")
    plan.add_argument("--agl", type=float, default=600.0, help="height above ground of the waypoints, m")
    plan.add_argument("--cell", type=float, default=500.0, help="planning cell size, m")
    plan.add_argument("--out", type=Path, required=True, help="route TOML to write")
    plan.add_argument("--plot", type=Path, default=None,
                      help="PNG of the route over the information map (default: OUT with .png)")
    return p


def _print_problems(err) -> None:
    print(f"error: scenario {err.source} is invalid ({len(err.problems)} problem(s)):", file=sys.stderr)
    for prob in err.problems:
        print(f"  - {prob}", file=sys.stderr)


def cmd_scenarios() -> int:
    from trn_env.scenario.loading import list_scenarios
    rows = list_scenarios()
    width = max(len(n) for n, _ in rows) if rows else 0
    for name, desc in rows:
        print(f"{name:<{width}}  {desc}")
    return 0


def cmd_validate(args) -> int:
    from trn_env.scenario.loading import ScenarioError, load_scenario
    try:
        sc = load_scenario(args.scenario)
    except ScenarioError as err:
        _print_problems(err)
        return 2
    print(f"{sc.source}: ok (scenario {sc.name!r}, navigator {sc.navigator_name}, seed {sc.seed}, "
          f"time limit {sc.duration_s:g} s)")
    return 0


def _summary_table(summary: dict, out_dir: Path):
    from rich.table import Table
    table = Table(title=f"trn-env fly: {summary['scenario']}  ->  {out_dir}", show_header=True)
    table.add_column("figure")
    table.add_column("value", justify="right")
    rows = [
        ("termination", summary["termination"]),
        ("navigator", summary["navigator"]),
        ("seed", str(summary["seed"])),
        ("simulated time", f"{summary['sim_time_s']:.1f} s"),
        ("wall time", f"{summary['wall_time_s']:.1f} s"),
        ("real-time factor", f"{summary['realtime_factor']:.1f} x"),
        ("distance flown", f"{summary['distance_flown_m'] / 1000:.1f} km"),
        ("GNSS-denied time", f"{summary['gnss_denied_time_s']:.0f} s"),
        ("horizontal error RMS", f"{summary['horizontal_error_rms_m']:.1f} m"),
        ("horizontal error final", f"{summary['horizontal_error_final_m']:.1f} m"),
        ("horizontal error max", f"{summary['horizontal_error_max_m']:.1f} m"),
        ("vertical error RMS", f"{summary['vertical_error_rms_m']:.1f} m"),
        ("final 1-sigma horizontal", f"{summary['horizontal_sigma_final_m']:.1f} m"),
        ("within 3 sigma (N and E)", f"{100 * summary['fraction_within_3sigma']:.0f} %"),
        ("min true height above ground", f"{summary['min_true_agl_m']:.0f} m"),
        ("navigator status", summary["navigator_status"]),
    ]
    for k, v in rows:
        table.add_row(k, v)
    return table


def cmd_fly(args) -> int:
    from trn_env.scenario.loading import ScenarioError, load_scenario
    try:
        scenario = load_scenario(args.scenario, seed=args.seed, navigator=args.navigator,
                                 duration_s=args.duration)
    except ScenarioError as err:
        _print_problems(err)
        return 2
    import time

    from rich.console import Console
    from tqdm import tqdm

    from trn_env.output.run_folder import default_out_dir, write_run
    from trn_env.sim.closed_loop import ClosedLoop

    out_dir = args.out or default_out_dir(scenario.name)
    console = Console()
    bar = None

    def progress(t_s: float, _total: float) -> None:
        bar.update(max(0.0, round(t_s, 1) - bar.n))

    loop = None
    try:
        # the loop (and its worker process, forked from this one) before the progress bar's thread
        loop = ClosedLoop(scenario, progress=progress, pipeline=not args.no_pipeline)
        bar = tqdm(total=round(scenario.duration_s, 1), unit="sim s", desc=f"fly {scenario.name}",
                   disable=args.quiet, mininterval=0.5,
                   bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} sim s [{elapsed}<{remaining}]")
        wall0 = time.perf_counter()
        while loop.termination is None:
            loop.tick()
        result = loop.result(time.perf_counter() - wall0)
    except KeyboardInterrupt:
        if bar is not None:
            bar.close()
        print("interrupted: nothing written", file=sys.stderr)
        return 130
    finally:
        if loop is not None:
            loop.close()
    bar.close()
    plot = None if args.no_plots else _plotter(result)
    try:
        write_run(out_dir, result.summary, result.arrays, result.events, plot=plot)
    except KeyboardInterrupt:
        print("interrupted while writing: no summary written", file=sys.stderr)
        return 130
    console.print(_summary_table(result.summary, out_dir))
    return 0


def _plotter(result):
    import trn_env.output.plots as plots

    def plot(tmp: Path) -> list[str]:
        sc = result.scenario
        wps = [(w["lat_deg"], w["lon_deg"]) for w in sc.data["route"]["waypoints"]]
        title = f"{sc.name} / {sc.navigator_name} / seed {sc.seed}: {result.termination}"
        plots.plot_track(tmp / "track.png", result.world_dem, result.arrays, title=title, waypoints_deg=wps)
        plots.plot_errors(tmp / "errors.png", result.arrays, title=title)
        return ["track.png", "errors.png"]

    return plot


def cmd_bench(args) -> int:
    from trn_env.bench.runner import run_all
    print(json.dumps(run_all(quick=args.quick), indent=2))
    return 0


def cmd_plan(args) -> int:
    import math
    import os

    from trn_env.scenario.loading import ScenarioError, load_scenario
    try:
        scenario = load_scenario(args.scenario)
    except ScenarioError as err:
        _print_problems(err)
        return 2
    import trn_env.scenario.build as components
    from trn_env.guidance.planner import PlannerConfig, TerrainInformationPlanner, plot_route
    from trn_env.sim.closed_loop import spawn_rngs
    d = scenario.data
    try:
        if not all(math.isfinite(v) for v in args.goal):
            raise ValueError(f"--goal must be finite latitude and longitude, got {args.goal}")
        config = PlannerConfig(weight=args.weight, max_featureless_m=args.max_featureless, agl_m=args.agl,
                               cell_m=args.cell, tas_mps=float(d["route"]["tas_mps"]))
        _, the_map = components.build_terrain(d, scenario.extras, spawn_rngs(scenario.seed)["map"])
        planner = TerrainInformationPlanner(the_map, config)
        s_lat, s_lon = math.radians(d["initial"]["lat_deg"]), math.radians(d["initial"]["lon_deg"])
        g_lat, g_lon = math.radians(args.goal[0]), math.radians(args.goal[1])
        route = planner.plan(s_lat, s_lon, g_lat, g_lon)
        straight = TerrainInformationPlanner(the_map, PlannerConfig(weight=0.0, cell_m=args.cell,
                                                                   agl_m=args.agl)).plan(s_lat, s_lon, g_lat,
                                                                                         g_lon)
    except ValueError as err:
        msg = str(err).replace("PlannerConfig.weight", "--weight").replace(
            "PlannerConfig.max_featureless_m", "--max-featureless").replace("PlannerConfig.agl_m", "--agl")
        print(f"error: {msg}", file=sys.stderr)
        return 2
    out = args.out
    plot_path = args.plot or out.with_suffix(".png")
    header = (f"route for scenario {scenario.name!r} from ({d['initial']['lat_deg']}, "
              f"{d['initial']['lon_deg']}) "
              f"to ({args.goal[0]}, {args.goal[1]}) deg\n"
              f"trn-env plan {args.scenario} --goal {args.goal[0]} {args.goal[1]} --weight {args.weight:g}"
              + (f" --max-featureless {args.max_featureless:g}" if args.max_featureless else ""))
    text = route.toml(float(d["route"]["tas_mps"]), header=header)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp{os.getpid()}")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, out)                          # never a partial or empty file
    plot_route(plot_path, planner, {f"planned (weight {args.weight:g})": route, "straight": straight},
               title=f"{scenario.name}: route over the map's terrain information")
    print(f"{out}: {len(route.waypoints_deg)} waypoints, {route.length_m / 1000:.2f} km "
          f"(straight {route.straight_length_m / 1000:.2f} km, "
          f"+{100 * route.extra_distance_fraction:.1f} %), featureless {route.featureless_m / 1000:.2f} km "
          f"(straight {straight.featureless_m / 1000:.2f} km), "
          f"longest featureless stretch {route.longest_featureless_m / 1000:.2f} km; plot {plot_path}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.command == "scenarios":
        return cmd_scenarios()
    if args.command == "validate":
        return cmd_validate(args)
    if args.command == "fly":
        return cmd_fly(args)
    if args.command == "bench":
        return cmd_bench(args)
    if args.command == "plan":
        return cmd_plan(args)
    return 2


if __name__ == "__main__":
    sys.exit(main())
