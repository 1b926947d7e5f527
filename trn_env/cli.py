"""The `trn-env` command line: fly a scenario, list scenarios, validate one, run the benchmarks.

    trn-env --version
    trn-env fly [SCENARIO] [--seed N] [--out DIR [--overwrite]] [--navigator NAME] [--duration S] [--no-plots]
    trn-env record SCENARIO --out LOG [--seed N] [--navigator NAME] [--duration S] [--set PATH=VALUE]
    trn-env replay LOG [--navigator NAME] [--monitor NAME] [--map DEM] [--out DIR] [--no-plots]
    trn-env scenarios
    trn-env navigators [NAME ...] [--json]
    trn-env validate SCENARIO
    trn-env bench [--quick] [--json]
    trn-env precompile [--workers N]
    trn-env campaign FILE [--out DIR] [--workers N] [--backend local|ray] [--address ADDR] [--resume]
                     [--check BASELINE.json] [--write-baseline BASELINE.json]
    trn-env report DIR [--out DIR]
    trn-env plan SCENARIO --goal LAT LON [--weight W] [--max-featureless M] [--agl M] [--climb-rate M/S |
                 --no-climb-limit] --out route.toml

Exit status: 0 success, 1 regression gate failed (`campaign --check`), 2 invalid input (every problem
printed, nothing written), 130 interrupted (Ctrl-C at any point: a one-line message, no traceback), 143
terminated (SIGTERM, handled as Ctrl-C is: partial outputs removed, one line).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
from pathlib import Path

from trn_env import __version__


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the signal lands so it unwinds as Ctrl-C does (partial outputs removed)."""


def _interrupt_exit(exc: BaseException) -> tuple[int, str]:
    """(exit status, word) of an interrupt: 143 'terminated' for SIGTERM, 130 'interrupted' for Ctrl-C."""
    return (143, "terminated") if isinstance(exc, Terminated) else (130, "interrupted")


def _install_sigterm():
    """SIGTERM in this process raises Terminated; a process forked from it (the estimation worker, a pool
    worker) keeps the default action, so stopping a worker stays a plain kill. Returns the handler it
    replaced (main() puts it back), or None if it could not install one."""
    main_pid = os.getpid()

    def on_sigterm(signum, frame):
        if os.getpid() != main_pid:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            os.kill(os.getpid(), signal.SIGTERM)
            return
        raise Terminated

    try:
        return signal.signal(signal.SIGTERM, on_sigterm)
    except ValueError:            # not the main thread (main() called from a thread): leave it alone
        return None


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose epilog may be a function, called only when the help is shown (the navigator
    list needs the registry, which is not imported for a plain run)."""

    def format_help(self) -> str:
        if callable(self.epilog):
            self.epilog = self.epilog()
        return super().format_help()


def _navigators_epilog() -> str:
    try:
        from trn_env.navigators import registry
        names = ", ".join(registry.available())
        monitors = ", ".join(registry.available_monitors())
    except Exception as exc:  # noqa: BLE001 - the help must show even if a plug-in is broken
        return f"navigators: (the registry could not be read: {exc})"
    return (f"navigators (--navigator NAME): {names}; or package.module:Name of a plug-in. "
            f"Monitors ([monitors] in a scenario): {monitors}.")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="trn-env",
                                description="Closed-loop terrain-referenced-navigation test range.")
    p.add_argument("--version", action="version", version=f"trn-env {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    fly = sub.add_parser("fly", help="fly a scenario in closed loop and write summary, log and plots",
                         epilog=_navigators_epilog)
    fly.add_argument("scenario", nargs="?", default="default",
                     help="built-in name or TOML path (default: default)")
    fly.add_argument("--seed", type=int, default=None, help="override the scenario seed")
    fly.add_argument("--out", type=Path, default=None,
                     help="output directory (default runs/<scenario>-<time>)")
    fly.add_argument("--overwrite", action="store_true",
                     help="replace the --out folder of a previous run as a whole (without it a non-empty "
                          "--out is refused before flying)")
    fly.add_argument("--navigator", default=None,
                     help="override the navigator (the names are listed below)")
    fly.add_argument("--duration", type=float, default=None, help="override the time limit, seconds")
    fly.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    fly.add_argument("--set", action="append", default=[], metavar="PATH=VALUE",
                     help="set a scenario field by dotted path, VALUE a TOML literal (repeatable; applied "
                          "after --seed/--duration/--navigator, as a campaign's sweeps are)")
    fly.add_argument("--quiet", action="store_true", help="no progress bar")
    fly.add_argument("--no-pipeline", action="store_true",
                     help="run the sensors and the navigator in this process, not beside the flight in a "
                          "second one (same results, slower)")
    rec = sub.add_parser("record", help="fly a scenario in closed loop and write its sensor log (frames, "
                                        "truth, metadata; docs/guide/logs.md)")
    rec.add_argument("scenario", help="built-in name or TOML path")
    rec.add_argument("--out", type=Path, required=True, help="the log folder to write (must not exist)")
    rec.add_argument("--seed", type=int, default=None, help="override the scenario seed")
    rec.add_argument("--navigator", default=None, help="override the navigator flown")
    rec.add_argument("--duration", type=float, default=None, help="override the time limit, seconds")
    rec.add_argument("--set", action="append", default=[], metavar="PATH=VALUE",
                     help="set a scenario field by dotted path (as fly's --set)")
    rec.add_argument("--quiet", action="store_true", help="no progress bar")
    rep_ = sub.add_parser("replay", help="run a navigator open loop over a sensor log; write a run folder "
                                         "as fly does (metrics when the log holds truth)")
    rep_.add_argument("log", type=Path, help="a sensor-log folder (trn-env record, trn_env.logs.LogBuilder)")
    rep_.add_argument("--navigator", default=None, help="navigator name (default: the log's)")
    rep_.add_argument("--monitor", action="append", default=[], metavar="NAME",
                      help="run this monitor beside the navigator (repeatable)")
    rep_.add_argument("--map", default=None, metavar="DEM",
                      help="the navigator's map: a DEM path or bundled name (default: the log's map)")
    rep_.add_argument("--out", type=Path, default=None, help="run folder (default runs/replay-<log>-<time>)")
    rep_.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    rep_.add_argument("--overwrite", action="store_true",
                      help="replace a run folder --out that holds a previous run, as a whole")
    rep_.add_argument("--seed", type=int, default=None,
                      help="the navigator's random stream (default: the log's seed)")
    rep_.add_argument("--set", action="append", default=[], metavar="navigator.settings.NAME=VALUE",
                      help="a navigator setting, VALUE a TOML literal (repeatable)")
    sub.add_parser("scenarios", help="list the built-in scenarios")
    navs = sub.add_parser("navigators", help="list the built-in and installed navigators and monitors with "
                                             "their settings (name, type, unit, default, meaning)")
    navs.add_argument("names", nargs="*", metavar="NAME",
                      help="only these (names or package.module:Name references; default: all)")
    navs.add_argument("--json", action="store_true", help="one JSON object instead of tables")
    val = sub.add_parser("validate", help="check a scenario file and list every problem")
    val.add_argument("scenario")
    pre = sub.add_parser("precompile", help="compile the numba kernels of every built-in navigator once, "
                                            "on all cores (after an install; later runs load the cache)")
    pre.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    bench = sub.add_parser("bench", help="print throughput figures, each beside its same-run reference")
    bench.add_argument("--quick", action="store_true", help="shorter measurements (less precise)")
    bench.add_argument("--json", action="store_true",
                       help="print the figures as one JSON object instead of the table")
    camp = sub.add_parser("campaign", help="fly a Monte Carlo campaign (seeds x navigators x sweeps)")
    camp.add_argument("file", type=Path, help="campaign TOML file")
    camp.add_argument("--out", type=Path, default=None,
                      help="output folder (default campaigns/<name>-<time>)")
    camp.add_argument("--workers", type=int, default=None, help="worker processes / Ray CPUs (default: all)")
    camp.add_argument("--backend", choices=("local", "ray"), default="local")
    camp.add_argument("--address", default=None,
                      help="Ray cluster address (HOST:PORT, ray://HOST:PORT, auto)")
    camp.add_argument("--resume", action="store_true", help="fly only the runs missing from --out")
    camp.add_argument("--check", type=Path, default=None, metavar="BASELINE",
                      help="compare with a baseline: exit 1 if a figure is worse than its tolerance")
    camp.add_argument("--write-baseline", type=Path, default=None, metavar="BASELINE",
                      help="write the campaign's figures as a baseline")
    camp.add_argument("--quiet", action="store_true", help="no progress bar")
    rep = sub.add_parser("report", help="summary table and plots of a campaign folder (PNGs + report.html)")
    rep.add_argument("dir", type=Path, help="campaign output folder")
    rep.add_argument("--out", type=Path, default=None, help="report folder (default DIR/report)")
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
    plan.add_argument("--climb-rate", type=float, default=5.0, metavar="M/S",
                      help="climb rate the route's ground profile must allow at the route's airspeed "
                           "(default 5 m/s, a margin under the King Air's; see --no-climb-limit)")
    plan.add_argument("--no-climb-limit", action="store_true", help="plan without the climb limit")
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


def cmd_navigators(args) -> int:
    """Every navigator and monitor (or the NAMEs given) with its origin and settings; a plug-in that cannot
    be loaded is reported (exit 2) and the others are still listed."""
    from trn_env.navigators import catalogue, registry
    wanted = [(n, None) for n in args.names] or (
        [(n, "navigator") for n in registry.available()]
        + [(n, "monitor") for n in registry.available_monitors()])
    entries, errors = [], []
    for name, kind in wanted:
        plugin, err = None, None
        for k in ([kind] if kind else ["navigator", "monitor"]):
            try:
                plugin = registry.resolve(name, k)
                break
            except registry.PluginError as exc:
                err = str(exc)
                break
            except ValueError as exc:
                err = err or str(exc)
        if plugin is None:
            errors.append(err)
            continue
        origin = {"built-in": "built-in", "registered": "registered in this process",
                  "reference": f"reference {plugin.reference}"}.get(
            plugin.origin, f"plug-in {plugin.distribution or ''} ({plugin.reference})".replace("  ", " "))
        entries.append({"name": name, "kind": plugin.kind, "origin": origin,
                        "summary": catalogue.summary_of(plugin.factory),
                        "settings": [s.as_dict() for s in catalogue.settings_of(plugin.factory)]})
    if args.json:
        print(json.dumps({"plugins": entries, "errors": errors}, indent=2))
    else:
        from rich.console import Console
        from rich.table import Table
        console = Console(width=max(Console().width, 140))
        for e in entries:
            table = Table(title=f"{e['kind']} {e['name']}  [{e['origin']}]\n{e['summary']}",
                          title_justify="left")
            for col in ("setting", "type", "unit", "default", "meaning"):
                table.add_column(col, overflow="fold")
            for s in e["settings"]:
                table.add_row(s["name"], s["type"], s["unit"], s["default"], s["meaning"])
            console.print(table)
    for err in errors:
        print(f"error: {err}", file=sys.stderr)
    return 2 if errors else 0


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


def _at_loss(summary: dict) -> str:
    e, s = summary["horizontal_error_at_gnss_loss_m"], summary["horizontal_sigma_at_gnss_loss_m"]
    return f"{e:.1f} m / {s:.1f} m" if e == e else "no GNSS loss"


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
        ("wall time (flight)", f"{summary['wall_time_s']:.1f} s"),
        ("real-time factor", f"{summary['realtime_factor']:.1f} x"),
        ("distance flown", f"{summary['distance_flown_m'] / 1000:.1f} km"),
        ("GNSS-denied time", f"{summary['gnss_denied_time_s']:.0f} s"),
        ("horizontal error / 1-sigma at GNSS loss", _at_loss(summary)),
        ("horizontal error RMS", f"{summary['horizontal_error_rms_m']:.1f} m"),
        ("horizontal error final", f"{summary['horizontal_error_final_m']:.1f} m"),
        ("horizontal error max", f"{summary['horizontal_error_max_m']:.1f} m"),
        ("vertical error RMS", f"{summary['vertical_error_rms_m']:.1f} m"),
        ("final 1-sigma horizontal", f"{summary['horizontal_sigma_final_m']:.1f} m"),
        ("within 3 sigma (N and E)", f"{100 * summary['fraction_within_3sigma']:.0f} %"),
        ("horizontal CEP50 / CEP95", f"{summary['horizontal_error_cep50_m']:.1f} / "
                                     f"{summary['horizontal_error_cep95_m']:.1f} m"),
        ("ANEES, position (3 = consistent)", f"{summary['anees']:.2f}"),
        ("track lost", "yes" if summary["track_lost"] else "no"),
        ("min true height above ground", f"{summary['min_true_agl_m']:.0f} m"),
        ("fuel remaining", "n/a (kinematic truth)" if summary.get("truth_source") == "kinematic" else
         f"{summary['fuel_remaining_kg']:.1f} kg" + (" (held constant)" if summary["constant_fuel"] else "")),
        ("navigator status", summary["navigator_status"]),
    ]
    if "warm_up_wall_time_s" in summary:
        rows.insert(5, ("kernels ready (compile / cache load)", f"{summary['warm_up_wall_time_s']:.1f} s"))
    if summary.get("route_not_followed"):
        rows.insert(1, ("what happened", summary["route_not_followed"]))
    for name, mon in sorted(summary.get("monitors", {}).items()):
        first = mon.get("first_alarm_t_s")
        when = f" (first at {first:.0f} s)" if first is not None else ""
        rows.append((f"{name} alarms", f"{mon['alarm_count']}{when}"))
    for k, v in rows:
        table.add_row(k, v)
    return table


def out_dir_problem(out: Path, overwrite: bool = False) -> str | None:
    """Why the run folder `out` could not be written (checked before flying, nothing left behind), or None."""
    from trn_env.output.run_folder import target_problem
    return target_problem(out, overwrite)


def cmd_fly(args) -> int:
    from trn_env.scenario.loading import ScenarioError
    from trn_env.scenario.overrides import load_scenario_with, parse_assignment
    try:
        sets = [parse_assignment(s) for s in args.set]
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        scenario = load_scenario_with(args.scenario, sets, seed=args.seed, navigator=args.navigator,
                                      duration_s=args.duration)
    except ScenarioError as err:
        _print_problems(err)
        return 2
    if args.out is not None:
        problem = out_dir_problem(args.out, args.overwrite)
        if problem is not None:
            print(f"error: {problem} (nothing flown, nothing written)", file=sys.stderr)
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

    from trn_env.flight.core import TrimError
    from trn_env.logs.record import recording_metadata
    from trn_env.scenario.build import build_terrain
    from trn_env.sim.closed_loop import spawn_rngs
    from trn_env.sim.warm_up import warm_up

    loop = writer = log_path = result = None
    try:
        # the terrain once (the same map stream as the loop's own), the kernels compiled (first run) or
        # loaded from numba's cache before the flight, so neither stalls the progress bar nor counts in the
        # real-time factor; then the loop (and its worker process, forked from this one) before the bar
        if not args.quiet:
            print(f"preparing {scenario.name}: terrain, then the numba kernels it uses (compiled on the "
                  "first run only, about half a minute on an idle 2-core machine; cached afterwards) ...",
                  file=sys.stderr, flush=True)
        dems = build_terrain(scenario, scenario.extras, spawn_rngs(scenario.seed)["map"])
        try:
            warm_s = warm_up(scenario, dems)
            writer = _log_writer(out_dir)
            loop = ClosedLoop(scenario, progress=progress, pipeline=not args.no_pipeline, dems=dems,
                              log_sink=writer)
            writer.metadata = recording_metadata(scenario, loop.estimate)
        except TrimError as exc:
            print(f"error: scenario {scenario.source}: initial: {exc} (nothing written)", file=sys.stderr)
            return 2
        except ValueError as exc:         # a component refusing what the validation let through
            print(f"error: scenario {scenario.source}: {exc} (nothing written)", file=sys.stderr)
            return 2
        if not args.quiet:
            print(f"ready after {warm_s:.1f} s", file=sys.stderr, flush=True)
        bar = tqdm(total=round(scenario.duration_s, 1), unit="sim s", desc=f"fly {scenario.name}",
                   disable=args.quiet, mininterval=0.5,
                   bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} sim s [{elapsed}<{remaining}]")
        wall0 = time.perf_counter()
        while loop.termination is None:
            loop.tick()
        result = loop.result(time.perf_counter() - wall0)
        result.summary["warm_up_wall_time_s"] = warm_s
        if loop.termination != "time_limit":       # the run ended before the limit: the bar ends full
            bar.total = bar.n
            bar.refresh()
    except KeyboardInterrupt as exc:
        if bar is not None:
            bar.close()
        code, word = _interrupt_exit(exc)
        print(f"{word}: nothing written", file=sys.stderr)
        return code
    finally:
        if loop is not None:
            loop.close()              # (the worker stops writing frames before the log is removed)
        if writer is not None and result is None:
            writer.abort()
    bar.close()
    plot = None if args.no_plots else _plotter(result)
    from trn_env.scenario.resolved import resolved_toml
    command = _command_line(args)
    result.summary["trn_env_version"] = __version__
    result.summary["command_line"] = command
    try:
        writer.write_events(result.events)
        log_path = writer.commit({"termination": result.termination, "recorded_summary": result.summary})
        writer = None
        write_run(out_dir, result.summary, result.arrays, result.events, plot=plot, log_dir=log_path,
                  overwrite=args.overwrite, extra_files={"scenario.toml": resolved_toml(scenario, command)})
    except KeyboardInterrupt as exc:
        code, word = _interrupt_exit(exc)
        print(f"{word} while writing: no summary written", file=sys.stderr)
        return code
    except OSError as exc:             # the folder changed under us since the check before the flight
        print(f"error: {exc}", file=sys.stderr)
        return 2
    finally:
        if writer is not None:
            writer.abort()
        if log_path is not None and log_path.exists():
            import shutil
            shutil.rmtree(log_path, ignore_errors=True)
    console.print(_summary_table(result.summary, out_dir))
    return 0


def _command_line(args) -> str:
    """The command as typed (shell-quoted), for summary.json and the resolved scenario's header."""
    import shlex
    return shlex.join(["trn-env", *getattr(args, "argv", sys.argv[1:])])


def _log_writer(out_dir: Path):
    """A LogWriter streaming a run's log into a hidden partial folder beside out_dir (moved in as log/)."""
    import os

    from trn_env.logs.writer import LogWriter
    from trn_env.output.run_folder import PARTIAL_MARK
    parent = Path(out_dir).absolute().parent
    return LogWriter(parent / f".{Path(out_dir).name}{PARTIAL_MARK}{os.getpid()}-log", {})


def cmd_record(args) -> int:
    from trn_env.logs.format import LogError
    from trn_env.scenario.loading import ScenarioError
    from trn_env.scenario.overrides import load_scenario_with, parse_assignment
    try:
        sets = [parse_assignment(s) for s in args.set]
        scenario = load_scenario_with(args.scenario, sets, seed=args.seed, navigator=args.navigator,
                                      duration_s=args.duration)
    except ScenarioError as err:
        _print_problems(err)
        return 2
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out = args.out
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        print(f"error: --out {out}: exists and is not an empty folder (a log is written whole into a new "
              "folder; nothing flown)", file=sys.stderr)
        return 2
    problem = out_dir_problem(out)
    if problem is not None:
        print(f"error: {problem} (nothing flown, nothing written)", file=sys.stderr)
        return 2
    from tqdm import tqdm

    from trn_env.flight.core import TrimError
    from trn_env.logs.record import record
    bar = tqdm(total=round(scenario.duration_s, 1), unit="sim s", desc=f"record {scenario.name}",
               disable=args.quiet, mininterval=0.5,
               bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} sim s [{elapsed}<{remaining}]")

    def progress(t_s: float, _total: float) -> None:
        bar.update(max(0.0, round(t_s, 1) - bar.n))

    try:
        result, path = record(scenario, out, progress=progress)
    except KeyboardInterrupt:
        bar.close()
        print("interrupted: nothing written", file=sys.stderr)
        return 130
    except (TrimError, ValueError, LogError) as exc:
        bar.close()
        print(f"error: scenario {scenario.source}: {exc} (nothing written)", file=sys.stderr)
        return 2
    bar.close()
    from trn_env.logs import read_log
    meta = read_log(path, check=False).metadata
    tables = ", ".join(f"{k} {v}" for k, v in meta["tables"].items())
    print(f"recorded {path}: {result.termination} after {result.sim_time_s:.1f} s, navigator "
          f"{scenario.navigator_name}; rows: {tables}")
    return 0


def cmd_replay(args) -> int:
    from trn_env.logs.format import LogError
    from trn_env.logs.replay import replay, write_result_log
    from trn_env.output.run_folder import default_out_dir, write_run
    if args.out is not None:
        problem = out_dir_problem(args.out, args.overwrite)
        if problem is not None:
            print(f"error: {problem} (nothing replayed, nothing written)", file=sys.stderr)
            return 2
    from trn_env.scenario.overrides import parse_assignment
    settings = {}
    for text in args.set:
        try:
            path, value = parse_assignment(text)
        except ValueError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        if not path.startswith("navigator.settings.") or path.count(".") != 2:
            print(f"error: --set {text!r}: replay sets navigator settings only "
                  "(navigator.settings.NAME=VALUE)", file=sys.stderr)
            return 2
        settings[path.split(".", 2)[2]] = value
    try:
        res = replay(args.log, args.navigator, settings=settings or None, monitors=args.monitor,
                     map_path=args.map, seed=args.seed)
    except (LogError, ValueError) as exc:
        print(f"error: {exc} (nothing written)", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted: nothing written", file=sys.stderr)
        return 130
    out_dir = args.out or default_out_dir(f"replay-{Path(args.log).name}")
    arrays = _with_truth_columns(res.arrays)
    plot = None if (args.no_plots or not res.has_truth) else _plotter(res)
    writer = log_path = None
    try:
        writer = _log_writer(out_dir)
        log_path = write_result_log(writer, res)
        writer = None
        write_run(out_dir, res.summary, arrays, res.events, plot=plot, log_dir=log_path,
                  overwrite=args.overwrite)
    except KeyboardInterrupt:
        print("interrupted while writing: no summary written", file=sys.stderr)
        return 130
    finally:
        if writer is not None:
            writer.abort()
        if log_path is not None and log_path.exists():
            import shutil
            shutil.rmtree(log_path, ignore_errors=True)
    s = res.summary
    if res.has_truth:
        print(f"replayed {args.log} with {s['navigator']}: {s['termination']}, horizontal RMS "
              f"{s['horizontal_error_rms_m']:.1f} m, ANEES {s['anees']:.2f} -> {out_dir}")
    else:
        print(f"replayed {args.log} with {s['navigator']}: {s['termination']} (no truth in the log: no "
              f"metrics) -> {out_dir}")
    return 0


def _with_truth_columns(arrays: dict) -> dict:
    """A replay's arrays with NaN truth where the log holds none (timeline.csv's columns exist)."""
    import numpy as np
    if "err_ned_m" in arrays:
        return arrays
    a = dict(arrays)
    n = a["est_t_s"].shape[0]
    nan = np.full(n, np.nan)
    a["t_s"] = a["est_t_s"]
    for k in ("true_lat_rad", "true_lon_rad", "true_h_msl_m", "true_h_agl_m", "true_yaw_rad", "true_tas_mps"):
        a[k] = nan
    a["err_ned_m"] = np.full((n, 3), np.nan)
    a["est_cov_diag"] = np.diagonal(a["est_cov"], axis1=1, axis2=2).copy()
    a["gnss_available"] = np.zeros(n, bool)
    return a


def _plotter(result):
    import trn_env.output.plots as plots

    def plot(tmp: Path) -> list[str]:
        sc = result.scenario
        wps = [(w.lat_deg, w.lon_deg) for w in (sc.route.waypoints if sc.route is not None else ())]
        title = f"{sc.name} / {sc.navigator_name} / seed {sc.seed}: {result.termination}"
        plots.plot_track(tmp / "track.png", result.world_dem, result.arrays, title=title, waypoints_deg=wps)
        plots.plot_errors(tmp / "errors.png", result.arrays, title=title)
        files = ["track.png", "errors.png"]
        for name in sorted(result.summary.get("monitors", {})):      # seed 003-style statistic plots
            plots.plot_integrity(tmp / f"{name}.png", result.arrays, name, title=title)
            files.append(f"{name}.png")
        return files

    return plot


def cmd_precompile(args) -> int:
    from trn_env.sim.precompile import precompile
    wall_s = precompile(workers=args.workers, report=lambda line: print(line, file=sys.stderr, flush=True))
    print(f"kernels compiled and cached in {wall_s:.1f} s", file=sys.stderr)
    return 0


class _stdout_to_stderr:
    """Send this process's standard output (Python's and the C++ libraries' file descriptor 1) to standard
    error for the block, so `trn-env bench --json` prints nothing but the JSON on standard output."""

    def __enter__(self):
        import contextlib
        sys.stdout.flush()
        self._saved = None
        try:
            self._saved = os.dup(1)
            os.dup2(2, 1)
        except OSError:
            self._saved = None
        self._redirect = contextlib.redirect_stdout(sys.stderr)
        self._redirect.__enter__()
        return self

    def __exit__(self, *exc):
        self._redirect.__exit__(*exc)
        sys.stdout.flush()
        if self._saved is not None:
            os.dup2(self._saved, 1)
            os.close(self._saved)
        return False


def cmd_bench(args) -> int:
    from trn_env.bench.runner import run_all
    with _stdout_to_stderr():      # JSBSim's banners and any component's prints stay out of the JSON/table
        results = run_all(quick=args.quick)
    if args.json:
        print(json.dumps(results, indent=2))
        return 0
    from rich.console import Console

    from trn_env.bench.table import bench_table
    Console(width=max(Console().width, 140)).print(bench_table(results))
    return 0


def cmd_campaign(args) -> int:
    from trn_env.campaign import CampaignError, load_campaign, make_backend, run_campaign
    from trn_env.campaign.baseline import read_baseline
    from trn_env.campaign.ray_backend import BackendError
    try:
        backend = make_backend(args.backend, args.workers, args.address)
        backend.preflight()      # Ray importable, its address reachable: before the (slower) validation
        baseline = read_baseline(args.check) if args.check is not None else None
        campaign = load_campaign(args.file)
    except CampaignError as err:
        print(f"error: campaign {err.source} is invalid ({len(err.problems)} problem(s)):", file=sys.stderr)
        for prob in err.problems:
            print(f"  - {prob}", file=sys.stderr)
        return 2
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    from rich.console import Console

    from trn_env.campaign.driver import default_out_dir
    out_dir = args.out or default_out_dir(campaign.name)
    console = Console()
    if not console.is_terminal:            # a pipe or a CI log: rich would assume 80 columns
        console = Console(width=100)
    try:
        stats = run_campaign(campaign, out_dir, backend=backend, resume=args.resume, progress=not args.quiet)
    except CampaignError as err:
        for prob in err.problems:
            print(f"error: {prob}", file=sys.stderr)
        return 2
    except BackendError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        code, word = _interrupt_exit(exc)
        print(f"{word}: the finished runs' rows are in {out_dir}/runs (continue with --resume)",
              file=sys.stderr)
        return code
    return _campaign_outcome(campaign, out_dir, stats, baseline, args, console)


def _campaign_outcome(campaign, out_dir: Path, stats: dict, baseline, args, console) -> int:
    from trn_env.campaign.baseline import compare, comparison_table, make_baseline, write_baseline
    from trn_env.campaign.rows import read_rows
    from trn_env.campaign.stats import summary_table
    df = read_rows(out_dir)
    console.print(summary_table(df, f"campaign {campaign.name}: {len(df)} run(s) -> {out_dir}"))
    rate = f"{stats['runs_per_minute']:.1f} runs/min" if stats["flown"] else "nothing to fly"
    console.print(f"{stats['flown']} flown ({stats['failed']} failed), {stats['already_done']} already done; "
                  f"{rate} on {stats['backend']}")
    status = 0
    if args.write_baseline is not None:
        write_baseline(args.write_baseline, make_baseline(df, campaign.name, campaign.hash))
        console.print(f"baseline written: {args.write_baseline}")
    if baseline is not None:
        comps = compare(df, baseline)
        console.print(comparison_table(comps, f"regression gate against {args.check}"))
        worse = [c for c in comps if c.verdict in ("worse", "missing")]
        better = [c for c in comps if c.verdict == "better"]
        for c in better:
            print(f"warning: {c.group} {c.figure} is much better than the baseline ({c.value:.4g} vs "
                  f"{c.baseline:.4g}); refresh it on purpose with --write-baseline", file=sys.stderr)
        if worse:
            for c in worse:
                print(f"regression: {c.group} {c.figure}: {c.value:.4g} vs baseline {c.baseline:.4g} "
                      f"(band ±{c.limit:.3g}): {c.verdict}", file=sys.stderr)
            status = 1
        else:
            console.print(f"regression gate passed ({len(comps)} figure(s), {len(better)} much better)")
    return status


def cmd_report(args) -> int:
    from trn_env.campaign.report import write_report
    try:
        out = write_report(args.dir, args.out)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"report written: {out / 'report.html'}")
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
    sc = scenario
    try:
        if not all(math.isfinite(v) for v in args.goal):
            raise ValueError(f"--goal must be finite latitude and longitude, got {args.goal}")
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
    except ValueError as err:
        msg = str(err).replace("PlannerConfig.weight", "--weight").replace(
            "PlannerConfig.max_featureless_m", "--max-featureless").replace(
            "PlannerConfig.agl_m", "--agl").replace("PlannerConfig.climb_rate_mps", "--climb-rate")
        print(f"error: {msg}", file=sys.stderr)
        return 2
    out = args.out
    plot_path = args.plot or out.with_suffix(".png")
    header = (f"route for scenario {scenario.name!r} from ({sc.initial.lat_deg}, "
              f"{sc.initial.lon_deg}) "
              f"to ({args.goal[0]}, {args.goal[1]}) deg\n"
              f"trn-env plan {args.scenario} --goal {args.goal[0]} {args.goal[1]} --weight {args.weight:g}"
              + (f" --max-featureless {args.max_featureless:g}" if args.max_featureless else ""))
    text = route.toml(float(sc.route.tas_mps), header=header)
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
    print(_plan_reason(route, straight, sc, config))
    return 0


def _plan_reason(route, straight, sc, config) -> str:
    """Why the planned route is longer than the straight line: each one's featureless flight, the expected
    horizontal error at the end of its longest featureless stretch (where the navigator must find the
    terrain again) and at the goal (trn_env.guidance.goal_error, with the scenario's IMU)."""
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
        return (f"why +{100 * route.extra_distance_fraction:.0f} % distance: not featureless terrain (the "
                f"straight line crosses {straight.featureless_m / 1000:.1f} km of it, the planned route "
                f"{route.featureless_m / 1000:.1f} km); the extra distance comes from the planning grid "
                f"({config.cell_m:.0f} m cells, 8 directions) and the climb limit: try a smaller --cell or "
                f"--no-climb-limit")
    return (f"why +{100 * route.extra_distance_fraction:.0f} % distance: the straight line crosses "
            f"{describe(straight)}; the planned route {describe(route)} {model}")


def main(argv: list[str] | None = None) -> int:
    previous = _install_sigterm()
    try:
        return _main(argv)
    finally:                   # a caller's own SIGTERM handling (a test runner, a notebook) is restored
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _main(argv: list[str] | None) -> int:
    try:
        args = _parser().parse_args(argv)
        args.argv = list(sys.argv[1:] if argv is None else argv)
        if args.command == "scenarios":
            return cmd_scenarios()
        if args.command == "validate":
            return cmd_validate(args)
        if args.command == "navigators":
            return cmd_navigators(args)
        if args.command == "fly":
            return cmd_fly(args)
        if args.command == "record":
            return cmd_record(args)
        if args.command == "replay":
            return cmd_replay(args)
        if args.command == "bench":
            return cmd_bench(args)
        if args.command == "precompile":
            return cmd_precompile(args)
        if args.command == "campaign":
            return cmd_campaign(args)
        if args.command == "report":
            return cmd_report(args)
        if args.command == "plan":
            return cmd_plan(args)
        return 2
    except KeyboardInterrupt as exc:       # during the imports, the scenario's loading, a benchmark
        code, word = _interrupt_exit(exc)
        print(f"{word}: nothing written", file=sys.stderr)
        return code
    except SystemError as exc:
        # Ctrl-C inside a numba dispatcher (e.g. while it unpickles a cached kernel) surfaces as "returned a
        # result with an exception set", caused by the KeyboardInterrupt
        cause = _caused_by_interrupt(exc)
        if cause is None:
            raise
        code, word = _interrupt_exit(cause)
        print(f"{word}: nothing written", file=sys.stderr)
        return code


def _caused_by_interrupt(exc: BaseException) -> KeyboardInterrupt | None:
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


if __name__ == "__main__":
    sys.exit(main())
