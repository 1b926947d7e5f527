"""Where a first run's numba compile time goes: fly a scenario in one process and sum numba's compile
events per kernel and per module (exclusive of the kernels compiled inside them).

    find . -name '*.nbi' -delete -o -name '*.nbc' -delete     # cold caches (else it measures cache loads)
    python scripts/compile_profile.py [SCENARIO]

Times are wall seconds of this process (on a shared machine, load stretches them; compare shares).
"""

from __future__ import annotations

import collections
import sys
import time

from numba.core import event


def main(argv: list[str]) -> None:
    stack: list[list] = []
    exclusive: collections.Counter = collections.Counter()

    class Listener(event.Listener):
        def on_start(self, ev):
            f = ev.data["dispatcher"].py_func
            stack.append([f"{f.__module__}.{f.__qualname__}", time.perf_counter(), 0.0])

        def on_end(self, ev):
            name, t0, inner = stack.pop()
            dt = time.perf_counter() - t0
            exclusive[name] += dt - inner
            if stack:
                stack[-1][2] += dt

    event.register("numba:compile", Listener())
    from trn_env.sim.closed_loop import run_scenario
    t0 = time.perf_counter()
    res = run_scenario(argv[1] if len(argv) > 1 else "default", pipeline=False)
    total = sum(exclusive.values())
    print(f"run {time.perf_counter() - t0:.1f} s (flight {res.wall_time_s:.1f} s), compile {total:.1f} s")
    modules: collections.Counter = collections.Counter()
    for name, dt in exclusive.items():
        modules[name.rsplit(".", 1)[0]] += dt
    for name, dt in modules.most_common(15):
        print(f"  {name:60s} {dt:7.1f} s  {100 * dt / max(total, 1e-9):5.1f} %")
    for name, dt in exclusive.most_common(15):
        print(f"  {name:80s} {dt:7.1f} s")


if __name__ == "__main__":
    main(sys.argv)
