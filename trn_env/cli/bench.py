"""`trn-env bench` (throughput figures beside same-run references) and `trn-env precompile`."""

from __future__ import annotations

import json
import sys

from trn_env.cli.common import _stdout_to_stderr


def cmd_precompile(args) -> int:
    if args.workers is not None and args.workers < 1:
        print(f"error: --workers: must be a whole number >= 1 (got {args.workers})", file=sys.stderr)
        return 2
    from trn_env.bench.precompile import precompile
    wall_s = precompile(workers=args.workers, report=lambda line: print(line, file=sys.stderr, flush=True))
    print(f"kernels compiled and cached in {wall_s:.1f} s", file=sys.stderr)
    return 0


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
