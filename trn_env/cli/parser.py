"""The argument parser of `trn-env`: every subcommand and option (the docs' CLI reference is generated from
it)."""

from __future__ import annotations

import argparse
from pathlib import Path

from trn_env import __version__


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
    rep_.add_argument("--out", type=Path, default=None,
                      help="run folder (default runs/replay-<log>-<time>; a run folder's log/ is named after "
                           "its run)")
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
    val = sub.add_parser("validate", help="check a scenario file and list every problem (with fly's "
                                          "overrides: the scenario fly would build from the same options)")
    val.add_argument("scenario", help="built-in name or TOML path")
    val.add_argument("--seed", type=int, default=None, help="override the scenario seed (as fly's)")
    val.add_argument("--navigator", default=None, help="override the navigator (as fly's)")
    val.add_argument("--duration", type=float, default=None,
                     help="override the time limit, seconds (as fly's)")
    val.add_argument("--set", action="append", default=[], metavar="PATH=VALUE",
                     help="set a scenario field by dotted path (as fly's --set)")
    pre = sub.add_parser("precompile", help="compile the numba kernels of every built-in navigator, the DEM "
                                            "monitor and both env tiers once, on all cores (after an install "
                                            "and on every node; later runs load the cache)")
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
