"""Driver memory over a long campaign: peak RSS of the driver process after 100 and after 1,000 runs of very
short flights on the local backend (rows written to a temporary folder as they arrive).

    PYTHONPATH=. python scripts/campaign_memory.py [--runs 1000] [--sim-s 3] [--workers N] [--scenario S]

The default flight is tests/scenarios/ins_only_short.toml (no terrain refinement, so a run costs ~0.1 s
and the driver's per-run work - receiving, writing and forgetting a row - is what is measured).

Prints one JSON object: driver VmHWM (peak resident set) and VmRSS at the start (campaign validated, DEM
loaded), after 100 runs and at the end, in MiB, and the runs per minute. The workers' memory is not the
driver's (they are separate processes, forked once).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from trn_env.campaign import load_campaign, run_campaign
from trn_env.campaign.local import LocalBackend


def _status_mib(key: str) -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--sim-s", type=float, default=3.0)
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--scenario", default=str(Path(__file__).resolve().parent.parent / "tests" / "scenarios"
                                              / "ins_only_short.toml"))
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "memory.toml"
        p.write_text(f'name = "memory"\nseeds = {args.runs}\nscenarios = [{json.dumps(args.scenario)}]\n'
                     f'duration_s = {args.sim_s}\n', encoding="utf-8")
        camp = load_campaign(p)
        out = {"runs": args.runs, "sim_s": args.sim_s,
               "start_peak_rss_mib": _status_mib("VmHWM"), "start_rss_mib": _status_mib("VmRSS")}
        count = [0]

        def on_row(_row: dict) -> None:
            count[0] += 1
            if count[0] == 100:
                out["after_100_peak_rss_mib"] = _status_mib("VmHWM")
                out["after_100_rss_mib"] = _status_mib("VmRSS")

        t0 = time.perf_counter()
        stats = run_campaign(camp, Path(d) / "out", backend=LocalBackend(args.workers), progress=False,
                             on_row=on_row)
        out["wall_s"] = time.perf_counter() - t0
        out[f"after_{args.runs}_peak_rss_mib"] = _status_mib("VmHWM")
        out[f"after_{args.runs}_rss_mib"] = _status_mib("VmRSS")
        out["runs_per_minute"] = stats["runs_per_minute"]
        out["driver_cpu_ms_per_row"] = 1e3 * stats["driver_row_cpu_s"] / max(stats["flown"], 1)
        out["failed"] = stats["failed"]
        out["rows_folder_mib"] = sum(f.stat().st_size for f in (Path(d) / "out" / "runs").iterdir()) / 2**20
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
