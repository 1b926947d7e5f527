"""Shared parts of the subcommands: interrupts and SIGTERM (exit 130 / 143), problem printing, the run
folder check, the command line as typed, and standard output sent to standard error."""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path


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


def _print_problems(err, what: str = "scenario") -> None:
    """Every problem of a ScenarioError / CampaignError (`what` names the file's kind), one a line."""
    print(f"error: {what} {err.source} is invalid ({len(err.problems)} problem(s)):", file=sys.stderr)
    for prob in err.problems:
        print(f"  - {prob}", file=sys.stderr)


def _discard_partial_log(writer, log_path: Path | None) -> None:
    """After a run's log writing (finally): abort the writer if it did not finish (writer not None) and
    remove the log folder if the run did not hand it over (log_path not None): nothing half-written stays."""
    if writer is not None:
        writer.abort()
    if log_path is not None and log_path.exists():
        import shutil
        shutil.rmtree(log_path, ignore_errors=True)


def write_failure(exc: OSError, what: str, kept: str = "nothing written") -> str:
    """The one line for an OSError while a command writes its output (a full disk, a folder removed or made
    read-only meanwhile): `what` could not be written (the file when the error names one), the system's
    reason without Python's or pyarrow's wrapping, and what is `kept` (the callers remove partial output)."""
    reason = os.strerror(exc.errno) if isinstance(exc.errno, int) and exc.errno > 0 else (
        exc.strerror or str(exc))
    target = f"{what} ({exc.filename})" if exc.filename else what
    return f"error: cannot write {target}: {reason} ({kept})"


def scenario_from_args(args):
    """The scenario fly, record and validate build from their SCENARIO, --seed, --navigator, --duration and
    --set options; None after printing every problem (the caller exits 2)."""
    from trn_env.scenario.loading import ScenarioError
    from trn_env.scenario.overrides import load_scenario_with, parse_assignment
    try:
        sets = [parse_assignment(s) for s in args.set]
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return None
    try:
        return load_scenario_with(args.scenario, sets, seed=args.seed, navigator=args.navigator,
                                  duration_s=args.duration)
    except ScenarioError as err:
        _print_problems(err)
        return None


def out_dir_problem(out: Path, overwrite: bool = False) -> str | None:
    """Why the run folder `out` could not be written (checked before flying, nothing left behind), or None."""
    from trn_env.output.run_folder import target_problem
    return target_problem(out, overwrite)


def run_folder_target(args, default_name: str) -> tuple[Path, str | None]:
    """The run folder of `fly` or `replay` (`--out`, else runs/<default_name>-<UTC second>) and why it could
    not be written, or None. The default name may be taken by a run of the same second: write_run(unique=
    True) then takes NAME-2, so only its place is checked here."""
    from trn_env.output.run_folder import creatable_problem, default_out_dir
    if args.out is not None:
        return args.out, out_dir_problem(args.out, args.overwrite)
    out_dir = default_out_dir(default_name)
    problem = creatable_problem(out_dir, "the run folder")
    return out_dir, problem and f"{problem}; give --out"


def _command_line(args) -> str:
    """The command as typed (shell-quoted), for summary.json and the resolved scenario's header."""
    import shlex
    return shlex.join(["trn-env", *getattr(args, "argv", sys.argv[1:])])


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


class _ReaderGoneStdout:
    """Standard output that outlives its reader: once the pipe it writes to is closed (`trn-env campaign ...
    | head -1`), further output is dropped (file descriptor 1 goes to os.devnull, for the C++ libraries too)
    instead of raising BrokenPipeError from the next print, so the command finishes its work and its files
    and exits with its own status. Everything else is the wrapped stream's."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._drop()
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._drop()

    def _drop(self) -> None:
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(devnull, self._stream.fileno())
        finally:
            os.close(devnull)

    def __getattr__(self, name):
        return getattr(self._stream, name)
