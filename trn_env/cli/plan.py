"""`trn-env plan`: a route from the scenario's start to a goal over the map's terrain information, written
as a [route] table and a plot, with why it differs from the straight line."""

from __future__ import annotations

import os
import shlex
import sys

from trn_env.cli.common import _print_problems

# the figure formats `--plot` takes (matplotlib writes each without extra software)
PLOT_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".webp", ".eps", ".ps", ".tif", ".tiff")


def cmd_plan(args) -> int:
    import math

    from trn_env.scenario.loading import ScenarioError, load_scenario
    try:
        scenario = load_scenario(args.scenario)
    except ScenarioError as err:
        _print_problems(err)
        return 2
    import trn_env.scenario.build as components
    from trn_env.guidance.planner import PlannerConfig, TerrainInformationPlanner, plot_route
    from trn_env.output.run_folder import file_target_problem
    from trn_env.sim.closed_loop import spawn_rngs
    sc = scenario
    out = args.out
    plot_path = args.plot or out.with_suffix(".png")
    try:
        if not all(math.isfinite(v) for v in args.goal):
            raise ValueError(f"--goal must be finite latitude and longitude, got {args.goal}")
        for problem in (file_target_problem(out, "--out"),
                        file_target_problem(plot_path, "--plot" if args.plot else "--out (its plot)",
                                            PLOT_SUFFIXES)):
            if problem is not None:
                raise ValueError(problem)
        if out.absolute() == plot_path.absolute():
            raise ValueError(f"--plot {plot_path}: the same file as --out" if args.plot else
                             f"--out {out}: the plot's default name ({plot_path}) is the route file's own; "
                             "give --plot or a route file name ending in .toml")
        config = PlannerConfig(weight=args.weight, max_featureless_m=args.max_featureless, agl_m=args.agl,
                               cell_m=args.cell, tas_mps=float(sc.route.tas_mps),
                               climb_rate_mps=None if args.no_climb_limit else args.climb_rate)
        _, the_map = components.build_terrain(sc, scenario.extras, spawn_rngs(scenario.seed)["map"])
        planner = TerrainInformationPlanner(the_map, config)
        s_lat, s_lon = math.radians(sc.initial.lat_deg), math.radians(sc.initial.lon_deg)
        g_lat, g_lon = math.radians(args.goal[0]), math.radians(args.goal[1])
        route = planner.plan(s_lat, s_lon, g_lat, g_lon)
        straight = TerrainInformationPlanner(the_map, PlannerConfig(
            weight=0.0, cell_m=args.cell, agl_m=args.agl, climb_rate_mps=None)).plan(s_lat, s_lon, g_lat,
                                                                                      g_lon)
        limits = planner.straight_line_limits(s_lat, s_lon, g_lat, g_lon)
        text = route.toml(float(sc.route.tas_mps), header=_plan_header(scenario, args))
        route_problems = _route_problems(scenario, text)
        if route_problems:
            print(f"error: the planned route is not one scenario {scenario.name!r} can fly "
                  "(nothing written):", file=sys.stderr)
            for prob in route_problems:
                print(f"  - {prob}", file=sys.stderr)
            return 2
    except ValueError as err:
        msg = str(err).replace("PlannerConfig.weight", "--weight").replace(
            "PlannerConfig.max_featureless_m", "--max-featureless").replace(
            "PlannerConfig.agl_m", "--agl").replace("PlannerConfig.climb_rate_mps", "--climb-rate").replace(
            "PlannerConfig.cell_m", "--cell")
        print(f"error: {msg}", file=sys.stderr)
        return 2
    # both files are made beside their targets and renamed into place together: never a partial or empty
    # file, nor a route without its plot
    tmp_out = out.with_name(f".{out.name}.tmp{os.getpid()}")
    tmp_plot = plot_path.with_name(f".{plot_path.stem}.tmp{os.getpid()}{plot_path.suffix}")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        plot_path.parent.mkdir(parents=True, exist_ok=True)
        tmp_out.write_text(text, encoding="utf-8")
        plot_route(tmp_plot, planner, {f"planned (weight {args.weight:g})": route, "straight": straight},
                   title=f"{scenario.name}: route over the map's terrain information")
        os.replace(tmp_plot, plot_path)
        os.replace(tmp_out, out)
    except OSError as exc:
        print(f"error: cannot write {exc.filename or out}: {exc.strerror or exc} (nothing written)",
              file=sys.stderr)
        return 2
    finally:
        for tmp in (tmp_out, tmp_plot):
            tmp.unlink(missing_ok=True)
    print(f"{out}: {len(route.waypoints_deg)} waypoints, {route.length_m / 1000:.2f} km "
          f"(straight {route.straight_length_m / 1000:.2f} km, "
          f"+{100 * route.extra_distance_fraction:.1f} %), featureless {route.featureless_m / 1000:.2f} km "
          f"(straight {straight.featureless_m / 1000:.2f} km), "
          f"longest featureless stretch {route.longest_featureless_m / 1000:.2f} km; plot {plot_path}")
    print(_plan_reason(route, straight, sc, config, limits))
    return 0


def _plan_header(scenario, args) -> str:
    """The route file's header: what it plans and the command that plans it again."""
    sc = scenario.sections
    return (f"route for scenario {scenario.name!r} from ({sc.initial.lat_deg}, {sc.initial.lon_deg}) "
            f"to ({args.goal[0]}, {args.goal[1]}) deg\n" + _plan_command(args))


def _route_problems(scenario, text: str) -> list[str]:
    """The scenario's problems with the planned [route] table in place of its own: the file is one the
    scenario accepts as it is (a waypoint above the aircraft's service ceiling, say, from --agl), or none is
    written. Every waypoint has the planner's height, so a problem repeated along the route is given once,
    at its first waypoint, with how many more share it."""
    import re

    from trn_env.scenario.loading import ScenarioError, tomllib
    try:
        scenario.with_fields({"route": tomllib.loads(text)["route"]})
    except ScenarioError as err:
        first: dict[tuple[str, str], str] = {}
        count: dict[tuple[str, str], int] = {}
        for prob in err.problems:
            m = re.match(r"route\.waypoints\[\d+\](\.\w+)?: (.*)", prob)
            key = (m.group(1) or "", re.sub(r"\d[\d.e+-]*", "#", m.group(2))) if m else (prob, "")
            first.setdefault(key, prob)
            count[key] = count.get(key, 0) + 1
        out = []
        for key, prob in first.items():
            more = f"; the same at {count[key] - 1} more waypoint(s)" if count[key] > 1 else ""
            agl = " (the height is --agl above the map" if key[0] == ".h_agl_m" else ""
            out.append(prob + (f"{agl}{more})" if agl else f" ({more[2:]})" if more else ""))
        return out
    return []


def _plan_command(args) -> str:
    """The `trn-env plan` command that plans this route again: every planning option spelled out (repr of
    each float, so the file's command reproduces the route bit for bit whatever the defaults become)."""
    climb = "--no-climb-limit" if args.no_climb_limit else f"--climb-rate {args.climb_rate!r}"
    featureless = "" if args.max_featureless is None else f" --max-featureless {args.max_featureless!r}"
    return (f"trn-env plan {shlex.quote(str(args.scenario))} --goal {args.goal[0]!r} {args.goal[1]!r} "
            f"--weight {args.weight!r}{featureless} --agl {args.agl!r} --cell {args.cell!r} {climb}")


def _plan_reason(route, straight, sc, config, limits: list[str]) -> str:
    """Why the planned route is longer than the straight line: each one's featureless flight, the expected
    horizontal error at the end of its longest featureless stretch (where the navigator must find the
    terrain again) and at the goal (trn_env.guidance.goal_error, with the scenario's IMU); when neither
    crosses featureless terrain, the constraint the straight line breaks (limits:
    TerrainInformationPlanner.straight_line_limits) or else the planning grid."""
    from trn_env.guidance.goal_error import expected_goal_error_m
    from trn_env.scenario.build import imu_bias_settings
    imu = imu_bias_settings(sc.sensors.imu)
    b_a, b_g = imu.get("accel_bias_sigma_mps2", 0.0), imu.get("gyro_bias_sigma_rps", 0.0)
    tas = float(sc.route.tas_mps)

    def err(featureless_m: float) -> float:
        return expected_goal_error_m(featureless_m, tas, b_a, b_g, sigma_fix_m=config.informative_crlb_m)

    def describe(r) -> str:
        return (f"{r.featureless_m / 1000:.1f} km of featureless terrain (longest stretch "
                f"{r.longest_featureless_m / 1000:.1f} km: about {err(r.longest_featureless_m):.0f} m "
                f"expected error at its end; last {r.final_featureless_m / 1000:.1f} km before the goal: "
                f"about {err(r.final_featureless_m):.0f} m at the goal)")

    model = "(INS drift over featureless flight with the scenario's IMU, trn_env.guidance.goal_error)"
    if route.length_m <= straight.length_m * 1.001:
        return f"why: the straight line is already the best route: {describe(straight)} {model}"
    if straight.featureless_m <= route.featureless_m + 0.5 * config.cell_m:
        head = (f"why +{100 * route.extra_distance_fraction:.0f} % distance: not featureless terrain (the "
                f"straight line crosses {straight.featureless_m / 1000:.1f} km of it, the planned route "
                f"{route.featureless_m / 1000:.1f} km); ")
        if "map" in limits:
            return head + ("the straight line passes over map voids or near the map's edge, which the "
                           "route keeps away from")
        if "climb" in limits:
            return head + (f"the map rises along the straight line faster than the aircraft may climb "
                           f"(--climb-rate {config.climb_rate_mps:g} m/s at {tas:g} m/s: a gradient of "
                           f"{config.climb_gradient:.3f}), so the route goes around the rise: "
                           f"--no-climb-limit or a higher --climb-rate flies straighter")
        return head + (f"the extra distance comes from the planning grid ({config.cell_m:.0f} m cells, 16 "
                       f"directions): try a smaller --cell")
    return (f"why +{100 * route.extra_distance_fraction:.0f} % distance: the straight line crosses "
            f"{describe(straight)}; the planned route {describe(route)} {model}")
