"""`trn-env record` (fly and write a sensor log) and `trn-env replay` (a navigator open loop over a log,
written as a run folder)."""

from __future__ import annotations

import sys
from pathlib import Path

from trn_env.cli.common import (
    _discard_partial_log,
    out_dir_problem,
    run_folder_target,
    scenario_from_args,
    write_failure,
)
from trn_env.cli.fly import _log_writer, _plotter


def cmd_record(args) -> int:
    from trn_env.logs.format import LogError
    scenario = scenario_from_args(args)
    if scenario is None:
        return 2
    out = args.out
    from trn_env.output.run_folder import lookup_problem
    if (problem := lookup_problem(out, "--out")) is not None:
        print(f"error: {problem} (nothing flown, nothing written)", file=sys.stderr)
        return 2
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        print(f"error: --out {out}: exists and is not an empty folder (a log is written whole into a new "
              "folder; nothing flown)", file=sys.stderr)
        return 2
    problem = out_dir_problem(out)
    if problem is not None:
        print(f"error: {problem} (nothing flown, nothing written)", file=sys.stderr)
        return 2
    from trn_env.flight.core import TrimError
    from trn_env.logs.record import record
    from trn_env.output.progress import progress_bar
    bar = progress_bar(total=round(scenario.duration_s, 1), unit="sim s", desc=f"record {scenario.name}",
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
    except OSError as exc:             # the log streamed during the flight (e.g. a full disk)
        bar.close()
        print(write_failure(exc, f"the log {out}"), file=sys.stderr)
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
    from trn_env.output.run_folder import lookup_problem, write_run
    log = Path(args.log).absolute()
    problem = lookup_problem(Path(args.log), "log")     # before the folder named after it is judged
    if problem is not None:
        print(f"error: {problem} (nothing replayed, nothing written)", file=sys.stderr)
        return 2
    # a run folder's log/ is named after its run (runs/replay-<run>-<time>, not replay-log-<time>)
    out_dir, problem = run_folder_target(args, f"replay-{log.parent.name if log.name == 'log' else log.name}")
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
    arrays = _with_truth_columns(res.arrays)
    plot = None if (args.no_plots or not res.has_truth) else _plotter(res)
    writer = log_path = None
    try:
        writer = _log_writer(out_dir)
        log_path = write_result_log(writer, res)
        writer = None
        out_dir = write_run(out_dir, res.summary, arrays, res.events, plot=plot, log_dir=log_path,
                            overwrite=args.overwrite, unique=args.out is None)
    except KeyboardInterrupt:
        print("interrupted while writing: no summary written", file=sys.stderr)
        return 130
    except OSError as exc:             # a full disk, or the folder changed since the check before the replay
        print(write_failure(exc, f"the run folder {out_dir}"), file=sys.stderr)
        return 2
    finally:
        _discard_partial_log(writer, log_path)
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
