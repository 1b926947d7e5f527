"""`trn-env fly`: fly a scenario in closed loop with a progress bar and write its run folder (summary,
log, timeline, plots); the summary table printed at the end."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from trn_env import __version__
from trn_env.cli.common import (
    _command_line,
    _discard_partial_log,
    _interrupt_exit,
    run_folder_target,
    scenario_from_args,
    write_failure,
)


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


def cmd_fly(args) -> int:
    scenario = scenario_from_args(args)
    if scenario is None:
        return 2
    out_dir, problem = run_folder_target(args, scenario.name)
    if problem is not None:
        print(f"error: {problem} (nothing flown, nothing written)", file=sys.stderr)
        return 2
    import time

    from rich.console import Console

    from trn_env.output.progress import progress_bar
    from trn_env.output.run_folder import write_run
    from trn_env.sim.closed_loop import ClosedLoop

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
        bar = progress_bar(total=round(scenario.duration_s, 1), unit="sim s", desc=f"fly {scenario.name}",
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
    except OSError as exc:             # the log streamed during the flight (e.g. a full disk)
        if bar is not None:
            bar.close()
        print(write_failure(exc, f"the run's log beside {out_dir}"), file=sys.stderr)
        return 2
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
        out_dir = write_run(out_dir, result.summary, result.arrays, result.events, plot=plot,
                            log_dir=log_path, overwrite=args.overwrite, unique=args.out is None,
                            extra_files={"scenario.toml": resolved_toml(scenario, command)})
    except KeyboardInterrupt as exc:
        code, word = _interrupt_exit(exc)
        print(f"{word} while writing: no summary written", file=sys.stderr)
        return code
    except OSError as exc:             # a full disk, or the folder changed since the check before the flight
        print(write_failure(exc, f"the run folder {out_dir}"), file=sys.stderr)
        return 2
    finally:
        _discard_partial_log(writer, log_path)
    console.print(_summary_table(result.summary, out_dir))
    return 0


def _log_writer(out_dir: Path):
    """A LogWriter streaming a run's log into a hidden partial folder beside out_dir (moved in as log/)."""

    from trn_env.logs.writer import LogWriter
    from trn_env.output.run_folder import PARTIAL_MARK
    parent = Path(out_dir).absolute().parent
    return LogWriter(parent / f".{Path(out_dir).name}{PARTIAL_MARK}{os.getpid()}-log", {})


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
