"""Run outputs: summary.json, the time-series log (log/ or log.npz, + timeline.csv), events, and plots.

`trn-env fly` and `trn-env replay` hand over `log_dir`, a sensor log (trn_env.logs) already streamed to
disk during the run: it is moved in as `log/` (Parquet tables, read with trn_env.logs.read_log or
pandas.read_parquet). `log.npz` then holds the per-update arrays only (truth, estimates, errors, monitors);
the full-rate sensor arrays it held before are in `log/` (`read_log(run / "log").arrays()`).

Everything is written atomically: the files go into a temporary directory next to the target, and only
when all of them are complete is that directory renamed onto the target. A run folder holds one run only:
a target that already holds a previous run is replaced as a whole (`overwrite=True`: the old folder is
renamed aside, the new one renamed into place, then the old one removed), never mixed with the new files;
a non-empty target is refused without `overwrite`, and a non-empty folder that holds no run (no
summary.json) is refused always. A Ctrl-C, SIGTERM or a kill therefore leaves either the complete new run
directory or the previous one untouched - never a half-written file. The temporary directory is named
`.NAME.partial-<pid>-<random>`; a run that was killed while writing leaves one behind, and the next run
writing into the same parent folder removes every such leftover whose process is gone. A target another
process filled while this run was being written is never replaced unless `overwrite` was asked; with
`unique` (the CLI's default names, one per second) the run takes the next free `NAME-2`, `NAME-3`, ...
"""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from trn_env.output.chunked import write_npz

# The columns of timeline.csv (a subset of the log arrays, one row per logged tick).
TIMELINE_COLUMNS = [
    "t_s", "true_lat_deg", "true_lon_deg", "true_h_msl_m", "true_h_agl_m", "true_yaw_deg", "tas_mps",
    "est_lat_deg", "est_lon_deg", "est_h_msl_m", "est_yaw_deg",
    "err_n_m", "err_e_m", "err_d_m", "err_horizontal_m", "sigma_n_m", "sigma_e_m", "sigma_d_m",
    "gnss_available", "nav_ok",
]


def default_out_dir(scenario_name: str, now: str | None = None) -> Path:
    """runs/<scenario>-<UTC timestamp>."""
    import datetime as _dt
    stamp = now or _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    return Path("runs") / f"{scenario_name}-{stamp}"


def _json_default(o: Any):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def _clean_json(o: Any):
    """NaN/inf are not JSON: write them as null."""
    if isinstance(o, dict):
        return {str(k): _clean_json(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean_json(v) for v in o]
    if isinstance(o, (float, np.floating)):
        return float(o) if math.isfinite(float(o)) else None
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    return o


def write_summary(path: Path, summary: dict) -> None:
    text = json.dumps(_clean_json(summary), indent=2, default=_json_default) + "\n"
    path.write_text(text, encoding="utf-8")


def write_log_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """`numpy.savez_compressed`; an on-disk ChunkedRows (a streamed run's est_cov) goes a chunk at a time."""
    with open(path, "wb") as f:
        write_npz(f, arrays)


def timeline_table(arrays: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The per-tick columns of the log in display units (degrees where named)."""
    a = arrays
    cov = a["est_cov_diag"]
    sig = np.sqrt(np.clip(cov[:, :3], 0.0, None))
    return {
        "t_s": a["t_s"],
        "true_lat_deg": np.degrees(a["true_lat_rad"]),
        "true_lon_deg": np.degrees(a["true_lon_rad"]),
        "true_h_msl_m": a["true_h_msl_m"],
        "true_h_agl_m": a["true_h_agl_m"],
        "true_yaw_deg": np.degrees(a["true_yaw_rad"]),
        "tas_mps": a["true_tas_mps"],
        "est_lat_deg": np.degrees(a["est_lat_rad"]),
        "est_lon_deg": np.degrees(a["est_lon_rad"]),
        "est_h_msl_m": a["est_h_m"],
        "est_yaw_deg": np.degrees(a["est_yaw_rad"]),
        "err_n_m": a["err_ned_m"][:, 0],
        "err_e_m": a["err_ned_m"][:, 1],
        "err_d_m": a["err_ned_m"][:, 2],
        "err_horizontal_m": np.hypot(a["err_ned_m"][:, 0], a["err_ned_m"][:, 1]),
        "sigma_n_m": sig[:, 0],
        "sigma_e_m": sig[:, 1],
        "sigma_d_m": sig[:, 2],
        "gnss_available": a["gnss_available"].astype(int),
        "nav_ok": a["nav_ok"].astype(int),
    }


def write_timeline_csv(path: Path, arrays: dict[str, np.ndarray]) -> None:
    table = timeline_table(arrays)
    cols = [table[c] for c in TIMELINE_COLUMNS]
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(TIMELINE_COLUMNS)
        for row in zip(*cols, strict=True):
            w.writerow([repr(float(v)) if isinstance(v, (float, np.floating)) else int(v) for v in row])


def write_events_csv(path: Path, events: list[tuple[float, str, str]]) -> None:
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(["t_s", "source", "message"])
        for t, src, msg in events:
            w.writerow([repr(float(t)), src, msg])


PARTIAL_MARK = ".partial-"


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:          # someone else's live process
        return True
    return True


def clean_partial_leftovers(parent: Path, stale_after_s: float = 3600.0) -> list[Path]:
    """Remove the temporary folders (`.NAME.partial-<pid>-*`) that killed runs left in `parent`: those
    whose process no longer runs, and (older layout, no pid) those untouched for stale_after_s."""
    import time
    removed = []
    try:
        entries = list(Path(parent).iterdir())
    except OSError:
        return removed
    now = time.time()
    for p in entries:
        name = p.name
        if not (name.startswith(".") and PARTIAL_MARK in name) or not p.is_dir() or p.is_symlink():
            continue
        tail = name.rsplit(PARTIAL_MARK, 1)[1]
        head = tail.split("-", 1)[0]
        try:
            if head.isdigit() and "-" in tail:
                stale = not _pid_alive(int(head))
            else:
                stale = now - p.stat().st_mtime > stale_after_s
        except OSError:
            continue
        if stale:
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
    return removed


def lookup_problem(path: Path, option: str) -> str | None:
    """Why the system refuses to look `path` up at all (a name longer than the file system takes, a path
    beyond PATH_MAX, a loop of links), or None; an absent path, or one under a file, is left to the
    callers' own checks."""
    try:
        os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        return None
    except OSError as exc:
        return f"{option} {path}: {exc.strerror or exc}"
    return None


def target_problem(out_dir: Path | str, overwrite: bool = False, *, option: str = "--out",
                   marker: str = "summary.json", what: str = "run") -> str | None:
    """Why `out_dir` cannot take a new run (checked before a flight; nothing is created), or None.

    An absent or empty folder is fine; a folder holding a previous run (a summary.json) is fine with
    `overwrite`; any other non-empty folder, or a file, is refused. The folder (or its nearest existing
    parent) must accept a new directory: a probe directory is made there and removed at once, which catches
    what permission bits do not (read-only or pseudo file systems such as /proc). `option` names the
    setting in the message; `marker` and `what` say which file marks a folder it may replace (a campaign's
    report folder: "report.html", "report").
    """
    out_dir = Path(out_dir)
    problem = lookup_problem(out_dir, option)
    if problem is not None:
        return problem
    if out_dir.exists() and not out_dir.is_dir():
        return f"{option} {out_dir}: exists and is not a directory"
    if out_dir.is_dir():
        here = Path.cwd().resolve()
        if out_dir.resolve() == here or out_dir.resolve() in here.parents:
            return f"{option} {out_dir}: is the current folder or holds it; give a folder for the {what}"
        try:
            names = sorted(p.name for p in out_dir.iterdir())
        except OSError as exc:
            return f"{option} {out_dir}: cannot read the folder ({exc.strerror or exc})"
        if names and not overwrite:
            return (f"{option} {out_dir}: the folder is not empty (it holds {', '.join(names[:3])}"
                    f"{', ...' if len(names) > 3 else ''}); give another folder, or --overwrite to replace "
                    f"a previous {what}'s folder as a whole")
        if names and marker not in names:
            advice = "--overwrite replaces only a run folder" if what == "run" else "give another folder"
            return (f"{option} {out_dir}: the folder is not empty and holds no previous {what} "
                    f"(no {marker}); {advice}")
    return creatable_problem(out_dir, option)


def file_target_problem(path: Path | str, option: str, suffixes: tuple[str, ...] | None = None) -> str | None:
    """Why the file `path` cannot be written (checked before the work that makes it; nothing is created),
    or None: a folder, a suffix not in `suffixes` (lower case, with the dot; None: any), or a place where
    no file can be made (creatable_problem). An existing file is fine: it is replaced whole."""
    path = Path(path)
    problem = lookup_problem(path, option)
    if problem is not None:
        return problem
    if path.is_dir():
        return f"{option} {path}: is a folder; give a file name"
    if suffixes is not None and path.suffix.lower() not in suffixes:
        return (f"{option} {path}: give a file name ending in one of {', '.join(sorted(suffixes))}"
                f"{'' if path.suffix else ' (it has no suffix)'}")
    return creatable_problem(path, option)


def folder_problem(path: Path | str, option: str) -> str | None:
    """Why `path` cannot be used as an output folder that may already hold earlier outputs (a training
    run's folder), or None: a file, or a place where no folder can be made (creatable_problem)."""
    path = Path(path)
    problem = lookup_problem(path, option)
    if problem is not None:
        return problem
    if path.exists() and not path.is_dir():
        return f"{option} {path}: exists and is not a folder"
    return None if path.is_dir() else creatable_problem(path, option)


def creatable_problem(path: Path | str, option: str) -> str | None:
    """Why `path` (a file or a folder) cannot be created where it is, or None: its nearest existing parent
    must be a folder that accepts a new entry (a probe directory is made there and removed at once) and its
    missing parents must be creatable (made and removed again). Nothing is left behind."""
    path = Path(path)
    parent = path.absolute().parent
    while not parent.exists() and parent.parent != parent:
        parent = parent.parent
    if not parent.is_dir():
        return f"{option} {path}: cannot create it, {parent} is not a directory"
    try:
        probe = tempfile.mkdtemp(prefix=f".{path.name}.probe-", dir=parent)
    except OSError as exc:
        return f"{option} {path}: cannot create it in {parent} ({exc.strerror or exc})"
    os.rmdir(probe)
    missing = path.absolute().parent
    if missing != parent:
        try:          # the missing parents: creatable? (made and removed again, deepest first)
            missing.mkdir(parents=True)
        except OSError as exc:
            return f"{option} {path}: cannot create {missing} ({exc.strerror or exc})"
        q = missing
        while q != parent:
            q.rmdir()
            q = q.parent
    return None


def write_run(out_dir: Path | str, summary: dict, arrays: dict[str, np.ndarray],
              events: list[tuple[float, str, str]] | None = None,
              plot: Callable[[Path], list[str]] | None = None, log_dir: Path | None = None,
              overwrite: bool = False, extra_files: dict[str, str] | None = None,
              unique: bool = False) -> Path:
    """Write a complete run directory atomically; returns the directory written.

    `plot(tmp_dir)` may add figures; it returns their file names (listed in summary['files']).
    `log_dir`: a finished log folder moved in as `log/` (beside log.npz of `arrays`).
    `extra_files`: name -> text of further files (e.g. the resolved scenario.toml). `overwrite`: replace a
    folder that holds a previous run as a whole (see the module docstring); without it a non-empty
    `out_dir` raises FileExistsError before anything is written, and so does one that another process
    filled while this run was being written (never replaced). `unique` (a name the caller chose, such as
    default_out_dir's, not the user): a taken `out_dir` gives way to the first free `out_dir-2`, `-3`, ...
    instead, checked when the finished folder is renamed into place, so runs started in the same second
    each keep their own folder.
    """
    out_dir = Path(out_dir)
    problem = target_problem(out_dir, overwrite)
    if problem is not None and unique and out_dir.is_dir():
        problem = None                          # _commit finds the next free name
    if problem is not None:
        raise FileExistsError(problem) if out_dir.is_dir() else OSError(problem)
    parent = out_dir.resolve().parent
    parent.mkdir(parents=True, exist_ok=True)
    clean_partial_leftovers(parent)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}{PARTIAL_MARK}{os.getpid()}-", dir=parent))
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)          # mkdtemp makes it private; the run directory should not be
    try:
        files = ["summary.json", "log.npz", "timeline.csv", "events.csv"]
        write_log_npz(tmp / "log.npz", arrays)
        if log_dir is not None:
            files.insert(2, "log")
            os.replace(log_dir, tmp / "log")
        for name, text in (extra_files or {}).items():
            (tmp / name).write_text(text, encoding="utf-8")
            files.append(name)
        write_timeline_csv(tmp / "timeline.csv", arrays)
        write_events_csv(tmp / "events.csv", events or [])
        if plot is not None:
            files += plot(tmp)
        summary = dict(summary)
        summary["files"] = files
        write_summary(tmp / "summary.json", summary)
        out_dir = _commit(tmp, out_dir, overwrite, unique)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return out_dir


def _commit(tmp: Path, out_dir: Path, overwrite: bool, unique: bool) -> Path:
    """Put the finished folder in place; returns where. A rename onto an absent or empty target; a target
    that holds a run by now: with `unique`, the first free `NAME-2`, `NAME-3`, ... (each try one atomic
    rename); with `overwrite`, the old folder is renamed aside first and removed after the new one is in
    place (a kill between the two renames leaves the old run under `.NAME.partial-<pid>-old`, cleaned like
    any leftover); else FileExistsError, the other run untouched."""
    try:
        os.replace(tmp, out_dir)          # absent, or an empty directory: one atomic rename
        return out_dir
    except OSError:
        if not out_dir.is_dir():
            raise
    if unique:
        for k in range(2, 10_000):
            candidate = out_dir.with_name(f"{out_dir.name}-{k}")
            try:
                os.replace(tmp, candidate)
                return candidate
            except OSError:
                if not candidate.is_dir():
                    raise
        raise FileExistsError(f"{out_dir}: no free name up to {out_dir.name}-9999")
    if not overwrite:
        raise FileExistsError(f"--out {out_dir}: another run was written there while this one was "
                              "being written; give another folder")
    aside = out_dir.parent / f".{out_dir.name}{PARTIAL_MARK}{os.getpid()}-old"
    os.replace(out_dir, aside)
    os.replace(tmp, out_dir)
    shutil.rmtree(aside, ignore_errors=True)
    return out_dir
