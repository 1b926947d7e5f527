"""The `trn-env` command line: fly a scenario, list scenarios, validate one, run the benchmarks.

    trn-env --version
    trn-env fly [SCENARIO] [--seed N] [--out DIR [--overwrite]] [--navigator NAME] [--duration S] [--no-plots]
    trn-env record SCENARIO --out LOG [--seed N] [--navigator NAME] [--duration S] [--set PATH=VALUE]
    trn-env replay LOG [--navigator NAME] [--monitor NAME] [--map DEM] [--out DIR] [--no-plots]
    trn-env scenarios
    trn-env navigators [NAME ...] [--json]
    trn-env validate SCENARIO [--seed N] [--navigator NAME] [--duration S] [--set PATH=VALUE]
    trn-env bench [--quick] [--json]
    trn-env precompile [--workers N]
    trn-env campaign FILE [--out DIR] [--workers N] [--backend local|ray] [--address ADDR] [--resume]
                     [--check BASELINE.json] [--write-baseline BASELINE.json]
    trn-env report DIR [--out DIR]
    trn-env plan SCENARIO --goal LAT LON [--weight W] [--max-featureless M] [--agl M] [--climb-rate M/S |
                 --no-climb-limit] --out route.toml

Exit status: 0 success, 1 regression gate failed (`campaign --check`), 2 invalid input (every problem
printed, nothing written), 130 interrupted (Ctrl-C at any point: a one-line message, no traceback), 143
terminated (SIGTERM, handled as Ctrl-C is: partial outputs removed, one line). A reader that closes the
output early (`| head`) stops nothing: the rest of the output is dropped and the command finishes.

One module a subcommand (or two close ones): `fly`, `record` (record, replay), `listing` (scenarios,
navigators, validate), `campaign` (campaign, report), `bench` (bench, precompile), `plan`; `parser` builds
the argument parser and `common` holds what they share. `main` dispatches through this package's names, so
`trn_env.cli.cmd_*` stay the commands' public entries.
"""

from __future__ import annotations

import errno
import os
import signal
import sys

from trn_env.cli.bench import cmd_bench, cmd_precompile
from trn_env.cli.campaign import cmd_campaign, cmd_report
from trn_env.cli.common import (
    Terminated,
    _install_sigterm,
    _interrupt_exit,
    _ReaderGoneStdout,
    out_dir_problem,
)
from trn_env.cli.fly import cmd_fly
from trn_env.cli.listing import cmd_navigators, cmd_scenarios, cmd_validate
from trn_env.cli.parser import _parser
from trn_env.cli.plan import cmd_plan
from trn_env.cli.record import cmd_record, cmd_replay

__all__ = ["main", "Terminated", "out_dir_problem", "cmd_bench", "cmd_campaign", "cmd_fly", "cmd_navigators",
           "cmd_plan", "cmd_precompile", "cmd_record", "cmd_replay", "cmd_report", "cmd_scenarios",
           "cmd_validate"]


def main(argv: list[str] | None = None) -> int:
    previous = _install_sigterm()
    # the process's own standard output (not a caller's capture) survives a reader that stops early
    wrapped = sys.stdout is sys.__stdout__ and sys.stdout is not None
    if wrapped:
        sys.stdout = _ReaderGoneStdout(sys.stdout)
    try:
        return _main(argv)
    finally:                   # a caller's own SIGTERM handling (a test runner, a notebook) is restored
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
        if wrapped:
            sys.stdout.flush()             # output still buffered meets a closed pipe here, not at exit
            sys.stdout = sys.__stdout__


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
    except OSError as exc:
        # a path the system will not even look up (a name longer than the file system takes), wherever a
        # command first touches it: one line; any other OSError is not bad input and keeps its traceback
        if exc.errno not in (errno.ENAMETOOLONG, errno.ELOOP):
            raise
        print(f"error: {exc.filename or 'a path'}: {os.strerror(exc.errno)} (nothing written)",
              file=sys.stderr)
        return 2
    except SystemError as exc:
        # Ctrl-C inside a numba dispatcher (e.g. while it unpickles a cached kernel) surfaces as "returned a
        # result with an exception set", caused by the KeyboardInterrupt
        cause = _caused_by_interrupt(exc)
        if cause is None:
            raise
        code, word = _interrupt_exit(cause)
        print(f"{word}: nothing written", file=sys.stderr)
        return code
    except Exception as exc:
        # a plug-in's output the loop cannot use: one line and its fix (imported here: the protocol's
        # numba imports would slow every command's start)
        from trn_env.navigators.protocol import NavigatorContractError
        if not isinstance(exc, NavigatorContractError):
            raise
        print(f"error: {exc} (nothing written)", file=sys.stderr)
        return 2


def _caused_by_interrupt(exc: BaseException) -> KeyboardInterrupt | None:
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None

