"""Run a validated campaign on a backend: prepare the output folder, make the run tasks, write each row as
it arrives, show progress.

Order (so that bad input leaves nothing behind): the campaign file is validated (spec.load_campaign), the
output folder checked (a folder of another campaign is refused; an existing one needs `resume`), the
backend started (Ray imported and connected); only then is the manifest written and the first run flown.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict
from pathlib import Path

from trn_env.campaign.rows import done_run_ids, read_manifest, write_log, write_manifest, write_row
from trn_env.campaign.runs import RunTask
from trn_env.campaign.spec import Campaign, CampaignError, replay_argv
from trn_env.output.run_folder import creatable_problem

try:
    import fcntl
except ImportError:         # Windows: no advisory folder locks; a campaign runs unguarded there, as on NFS
    fcntl = None


def default_out_dir(name: str) -> Path:
    stamp = dt.datetime.now(dt.timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    return Path("campaigns") / f"{name}-{stamp}"


def reserve_default_out_dir(name: str) -> Path:
    """A new, empty folder campaigns/<name>-<UTC second>, made here so that campaigns started in the same
    second never share one: a taken name gives way to `-2`, `-3`, ... (each an exclusive mkdir). OSError when
    no folder can be made there."""
    base = default_out_dir(name)
    base.parent.mkdir(parents=True, exist_ok=True)
    for k in range(1, 10_000):
        candidate = base if k == 1 else base.with_name(f"{base.name}-{k}")
        try:
            candidate.mkdir()
            return candidate
        except FileExistsError:
            continue
    raise FileExistsError(f"{base}: no free name up to {base.name}-9999")


def check_out_dir(campaign: Campaign, out_dir: Path, resume: bool) -> set[str]:
    """Run ids already done in `out_dir` (empty for a new folder); CampaignError if the folder is refused."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise CampaignError(campaign.source, [f"--out {out_dir}: exists and is not a folder"])
    try:
        manifest = read_manifest(out_dir) if out_dir.is_dir() else None
    except ValueError as exc:
        raise CampaignError(campaign.source, [f"--out: {exc}"]) from None
    if manifest is None:
        if out_dir.is_dir() and any(out_dir.iterdir()):
            raise CampaignError(campaign.source, [f"--out {out_dir}: folder is not empty and holds no "
                                                  "campaign (campaign.json); choose another folder"])
        if resume and not out_dir.is_dir():
            raise CampaignError(campaign.source, [f"--resume: {out_dir} does not exist (nothing to resume)"])
        problem = creatable_problem(out_dir, "--out") if not out_dir.is_dir() else None
        if problem is not None:
            raise CampaignError(campaign.source, [problem])
        return set()
    if manifest.get("campaign_hash") != campaign.hash:
        raise CampaignError(campaign.source, [
            f"--resume: {out_dir} holds campaign {manifest.get('campaign')!r} from "
            f"{manifest.get('source')} (hash {str(manifest.get('campaign_hash'))[:12]}), "
            f"but {campaign.source} "
            f"hashes {campaign.hash[:12]}: a different campaign file (or one of its scenario files changed); "
            "refusing to mix their runs - use another --out"])
    if not resume:
        raise CampaignError(campaign.source, [f"--out {out_dir}: already holds this campaign; pass --resume "
                                              "to fly the missing runs, or choose another folder"])
    return done_run_ids(out_dir)


def tasks(campaign: Campaign, skip: set[str]) -> Iterator[RunTask]:
    """The campaign's runs not in `skip`, seed-major (a partial campaign has every variant at the same
    seeds), made lazily."""
    import shlex
    settings = asdict(campaign.metric_settings)
    for index, si, seed, v, run_id in campaign.pending_runs(skip):
        yield RunTask(
            campaign=campaign.name, campaign_hash=campaign.hash, run_id=run_id, run_index=index,
            variant_index=v.index, seed_index=si, seed=int(seed), scenario_name=v.scenario_name,
            scenario_source=v.scenario_source, navigator_label=v.navigator.label, sweep=dict(v.sweep),
            sections=v.sections, dem_keys=v.dem_keys, metric_settings=settings, keep_logs=campaign.keep_logs,
            replay_command=shlex.join(replay_argv(v, int(seed))))


def make_backend(name: str, workers: int | None = None, address: str | None = None):
    if name == "local":
        if address:
            raise ValueError("--address: only with --backend ray")
        from trn_env.campaign.local import LocalBackend
        return LocalBackend(workers)
    if name == "ray":
        from trn_env.campaign.ray_backend import RayBackend
        return RayBackend(address=address, workers=workers)
    raise ValueError(f"--backend: unknown backend {name!r} (local or ray)")


@contextlib.contextmanager
def folder_lock(campaign: Campaign, out_dir: Path) -> Iterator[None]:
    """Hold `out_dir` (made here if absent) for one campaign process: a second campaign into the same folder
    at the same time (the same file resumed twice, or another file given the same --out) is refused with a
    CampaignError instead of mixing its rows and manifest into this one's. An advisory lock (flock) on the
    folder itself: the system drops it when the process ends, however it ends, and it leaves no file. A
    folder made here and still empty afterwards is removed."""
    out_dir = Path(out_dir)
    made = not out_dir.exists()
    out_dir.mkdir(parents=True, exist_ok=True)
    fd = None
    try:
        if fcntl is not None:           # (Windows has none: the campaign runs unguarded there)
            fd = os.open(out_dir, os.O_RDONLY)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise CampaignError(campaign.source, [
                    f"--out {out_dir}: another campaign is writing into this folder now (it holds the "
                    "folder's lock); wait for it to end (then --resume flies what it left), or choose "
                    "another folder"]) from None
            except OSError:
                pass        # a file system without flock on folders (NFS emulates it, for writers only)
        yield
    finally:
        if fd is not None:
            os.close(fd)                 # releases the lock
        if made and out_dir.is_dir() and not any(out_dir.iterdir()):
            out_dir.rmdir()


def folder_busy(out_dir: Path) -> bool:
    """True while a campaign holds `out_dir` (folder_lock): it is still flying runs into it. False when no
    process holds it, or on a file system (or a system) without folder locks."""
    if fcntl is None:
        return False
    try:
        fd = os.open(out_dir, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:
        return False
    finally:
        os.close(fd)                     # (releases a lock taken here)
    return False


def run_campaign(campaign: Campaign, out_dir: Path, *, backend=None, resume: bool = False,
                 progress: bool = True, on_row: Callable[[dict], None] | None = None) -> dict:
    """Fly the campaign's missing runs into `out_dir`; returns counts and timing (`driver_row_cpu_s`: the
    driver's CPU time writing rows). `backend`: a backend object (default: the local pool on every core).
    The folder is held for this process while it runs (folder_lock)."""
    out_dir = Path(out_dir)
    check_out_dir(campaign, out_dir, resume)         # refusals before anything is made
    with folder_lock(campaign, out_dir):
        # again under the lock: a campaign that held the folder until now may have written into it
        done = check_out_dir(campaign, out_dir, resume)
        return _run_campaign(campaign, out_dir, done, backend, progress, on_row)


def _run_campaign(campaign: Campaign, out_dir: Path, done: set[str], backend, progress: bool,
                  on_row: Callable[[dict], None] | None) -> dict:
    if backend is None:
        backend = make_backend("local")
    todo = campaign.n_runs - len(done & {campaign.run_id(v.index, s) for v in campaign.variants
                                         for s in range(len(campaign.seeds))})
    with backend:
        write_manifest(out_dir, {
            "campaign": campaign.name, "campaign_hash": campaign.hash, "source": campaign.source,
            "description": campaign.description, "n_runs": campaign.n_runs, "seeds": campaign.seeds,
            "sweep_paths": campaign.sweep_paths, "navigators": sorted({v.navigator.label
                                                                       for v in campaign.variants}),
            "created": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        }, campaign.text)
        stats = {"runs": campaign.n_runs, "already_done": campaign.n_runs - todo, "flown": 0, "failed": 0,
                 "backend": backend.describe(), "driver_row_cpu_s": 0.0}
        bar = None
        if progress:
            from trn_env.output.progress import progress_bar
            bar = progress_bar(total=todo, unit="run", desc=f"campaign {campaign.name}", mininterval=0.5)
        t0 = time.perf_counter()

        def on_result(row: dict, log_bytes: bytes | None) -> None:
            t_row = time.thread_time()
            if log_bytes is not None:
                write_log(out_dir, row["run_id"], log_bytes)
            write_row(out_dir, row)          # the row last: its file means the run is complete
            stats["flown"] += 1
            stats["failed"] += row["termination"] == "error"
            stats["driver_row_cpu_s"] += time.thread_time() - t_row
            if bar is not None:
                minutes = (time.perf_counter() - t0) / 60.0
                bar.set_postfix(failed=stats["failed"], rpm=f"{stats['flown'] / max(minutes, 1e-9):.1f}",
                                refresh=False)
                bar.update(1)
            if on_row is not None:
                on_row(row)

        try:
            if todo:
                # a campaign kind with its own runs (trn_env.campaign.episodes) makes its own tasks
                todo_tasks = campaign.tasks(done) if hasattr(campaign, "tasks") else tasks(campaign, done)
                backend.run(todo_tasks, campaign.extra.get("dems", {}), on_result)
        finally:
            if bar is not None:
                bar.close()
        stats["wall_time_s"] = time.perf_counter() - t0
        stats["runs_per_minute"] = 60.0 * stats["flown"] / stats["wall_time_s"] if stats["flown"] else 0.0
    return stats
