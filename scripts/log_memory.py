"""Peak memory of a long closed-loop flight whose log streams to disk (issue 39, "Scale").

    python scripts/log_memory.py --hours 1 --out /tmp/mem1h            # streamed log (trn-env record)
    python scripts/log_memory.py --hours 1 --out /tmp/mem1h --in-memory # the old path: SimLog in memory,
                                                                        # then log.npz written at the end
The flight: the default scenario with `aircraft.constant_fuel = true`, its route's four waypoints repeated
until the route outlasts the flight, time limit HOURS. A thread samples the resident memory (VmRSS) of this
process and of its children (the estimation stage's worker) every 5 s; printed: the peak of each and of
their sum, and a line per sample in OUT.rss.csv (wall s, sim s, parent RSS, children RSS, total PSS MB;
PSS counts the pages the forked worker shares with its parent once; then each process's own peak so far,
VmHWM, which catches a peak between two samples).
"""

from __future__ import annotations

import argparse
import copy
import os
import threading
import time
from pathlib import Path

from trn_env.output.run_folder import folder_problem


def _rss_mb(pid: int) -> float:
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


def _hwm_mb(pid: int) -> float:
    """The process's peak resident memory so far (VmHWM): catches peaks between two samples."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


def _pss_mb(pid: int) -> float:
    """Proportional set size: shared (copy-on-write) pages split between the processes sharing them."""
    try:
        with open(f"/proc/{pid}/smaps_rollup") as f:
            for line in f:
                if line.startswith("Pss:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


def _children(pid: int) -> list[int]:
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            return [int(x) for x in f.read().split()]
    except OSError:
        return []


def scenario(hours: float):
    from trn_env.scenario.loading import read_scenario_file, validate
    data, _ = read_scenario_file("default")
    data = copy.deepcopy(data)
    data["duration_s"] = hours * 3600.0
    data.setdefault("aircraft", {})["constant_fuel"] = True
    wps = data["route"]["waypoints"]
    loop = wps[1:] + [wps[0]]
    n_loops = int(hours * 3600.0 / 500.0) + 2          # one loop of the route is ~ 60 km, ~ 700 s
    data["route"]["waypoints"] = [wps[0]] + loop * n_loops
    data["name"] = f"default_{hours:g}h"
    return validate(data, source=f"default, {hours:g} h")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--in-memory", action="store_true")
    args = ap.parse_args()
    if args.out is not None and (problem := folder_problem(args.out, "--out")):
        ap.error(problem)       # checked before the work, not after it
    sc = scenario(args.hours)
    samples = []
    sim_t = [0.0]
    stop = threading.Event()
    t0 = time.perf_counter()

    def sample():
        me = os.getpid()
        while not stop.is_set():
            kids = _children(me)
            samples.append((time.perf_counter() - t0, sim_t[0], _rss_mb(me), sum(_rss_mb(c) for c in kids),
                            _pss_mb(me) + sum(_pss_mb(c) for c in kids), _hwm_mb(me),
                            max((_hwm_mb(c) for c in kids), default=0.0)))
            stop.wait(5.0)

    th = threading.Thread(target=sample, daemon=True)
    th.start()

    def progress(t_s, _total):
        sim_t[0] = t_s

    if args.in_memory:
        import numpy as np

        from trn_env.sim.closed_loop import ClosedLoop
        res = ClosedLoop(sc, pipeline=True, progress=progress).run()
        args.out.mkdir(parents=True, exist_ok=True)
        with open(args.out / "log.npz", "wb") as f:
            np.savez_compressed(f, **res.arrays)
    else:
        from trn_env.logs.record import record
        res, _ = record(sc, args.out, progress=progress)
    stop.set()
    th.join()
    hwm_parent = _hwm_mb(os.getpid())              # exact: the kernel's own peak of this process
    hwm_worker = max(s[6] for s in samples)        # the worker's own peak, as of its last sample
    with open(str(args.out) + ".rss.csv", "w") as f:
        f.write("wall_s,sim_s,parent_rss_mb,children_rss_mb,total_pss_mb,parent_hwm_mb,worker_hwm_mb\n")
        for s in samples:
            f.write(",".join(f"{x:.1f}" for x in s) + "\n")
    peak_p = max(s[2] for s in samples)
    peak_c = max(s[3] for s in samples)
    peak_sum = max(s[4] for s in samples)
    at = {h: max((s[4] for s in samples if s[1] <= h * 3600.0), default=float("nan"))
          for h in (0.25, 1, 2, 5, 10) if h <= args.hours}
    print(f"{'in-memory' if args.in_memory else 'streamed'} {args.hours:g} h: termination {res.termination}, "
          f"sim {res.sim_time_s:.0f} s, wall {time.perf_counter() - t0:.0f} s; "
          f"peak RSS parent {peak_p:.0f} MB, "
          f"worker {peak_c:.0f} MB; peak PSS of both {peak_sum:.0f} MB; peak PSS up to sim hour: "
          + ", ".join(f"{h:g} h {v:.0f} MB" for h, v in at.items())
          + f"; peak RSS (VmHWM) parent {hwm_parent:.0f} MB, worker {hwm_worker:.0f} MB")


if __name__ == "__main__":
    main()
