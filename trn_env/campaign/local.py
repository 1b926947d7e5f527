"""The local backend: a process pool over the machine's cores (embedded, nothing to start).

Workers are forked on Linux (they inherit the campaign's DEMs and the parent's compiled numba kernels)
and spawned elsewhere (they receive the DEMs once through the pool initializer). At most 2 x workers runs
are in flight, so a long campaign's tasks are made as they are needed and the driver holds only the rows
not yet written. A worker process that dies (killed, out of memory) breaks the pool: the pool is rebuilt
and the runs that were in flight are flown again one at a time (so a death is pinned on the run that
caused it), each up to `max_attempts` times; a run that raises is not retried (its row carries the error).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import sys
from collections import deque
from collections.abc import Callable, Iterable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from trn_env.campaign.runs import RunTask, died_row, fly_run, retry_task, set_dems


def default_workers() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


# Workers per usable core beyond which --workers is refused on this machine (the local pool, a local Ray
# instance): each worker is a process of its own, all started at once (a forked pool launches every worker
# at its start; a Ray pool starts one actor per worker), and the runs are CPU-bound, so workers beyond the
# cores add memory, not speed; a typo (--workers 200 for 20) would otherwise start hundreds of processes.
MAX_WORKERS_PER_CORE = 4


def check_local_workers(workers: int | None, option: str = "--workers") -> None:
    """ValueError naming `option` when `workers` is not a whole number >= 1 or exceeds MAX_WORKERS_PER_CORE
    per usable core of this machine."""
    if workers is None:
        return
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"{option}: must be a whole number >= 1 (got {workers!r})")
    cores = default_workers()
    if workers > MAX_WORKERS_PER_CORE * cores:
        raise ValueError(
            f"{option}: {workers} is more than {MAX_WORKERS_PER_CORE} per usable core of this machine "
            f"({cores} core(s), so at most {MAX_WORKERS_PER_CORE * cores}): each worker is a process started "
            "at once and the work is CPU-bound, so more workers add memory, not speed"
        )


class LocalBackend:
    name = "local"

    def __init__(self, workers: int | None = None, max_attempts: int = 3):
        check_local_workers(workers)
        self.workers = workers or default_workers()
        self.max_attempts = int(max_attempts)

    def preflight(self) -> None:
        """Nothing to check before the campaign starts."""

    def __enter__(self) -> LocalBackend:
        return self

    def __exit__(self, *exc) -> None:
        pass

    def describe(self) -> str:
        return f"local process pool, {self.workers} worker(s)"

    def _pool(self, dems: dict[str, Any]) -> ProcessPoolExecutor:
        method = "fork" if sys.platform.startswith("linux") else "spawn"
        set_dems(dems)     # forked workers see it at once; spawned ones through the initializer
        return ProcessPoolExecutor(self.workers, mp_context=mp.get_context(method),
                                   initializer=_worker_init, initargs=(dems,))

    def run(self, tasks: Iterable[RunTask], dems: dict[str, Any],
            on_result: Callable[[dict, bytes | None], None]) -> None:
        it = iter(tasks)
        window = 2 * self.workers
        pool = self._pool(dems)
        inflight: dict = {}
        suspects: deque[RunTask] = deque()   # in flight when a worker died: flown again one at a time
        exhausted = False
        try:
            while True:
                if suspects:
                    if not inflight:
                        task = suspects.popleft()
                        inflight[pool.submit(fly_run, task)] = task
                else:
                    while len(inflight) < window and not exhausted:
                        task = next(it, None)
                        if task is None:
                            exhausted = True
                            break
                        inflight[pool.submit(fly_run, task)] = task
                if not inflight:
                    break
                done, _ = wait(inflight, return_when=FIRST_COMPLETED)
                broken = False
                for fut in done:
                    task = inflight.pop(fut)
                    try:
                        row, log = fut.result()
                    except BrokenProcessPool:
                        broken = True
                        self._again(task, suspects, on_result, alone=not inflight and len(done) == 1)
                        continue
                    on_result(row, log)
                if broken:         # every run still in flight went down with the pool
                    for fut, task in list(inflight.items()):
                        if fut.done() and fut.exception() is None:
                            on_result(*fut.result())
                        else:
                            self._again(task, suspects, on_result, alone=False)
                    inflight.clear()
                    pool.shutdown(wait=False, cancel_futures=True)
                    pool = self._pool(dems)
        except KeyboardInterrupt:
            # Ctrl-C reaches the workers too (the terminal signals the process group), SIGTERM to the
            # driver alone does not: stop them, rather than wait for the runs in flight to finish
            for proc in list(getattr(pool, "_processes", {}).values()):
                if proc.is_alive():
                    proc.terminate()
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)

    def _again(self, task: RunTask, suspects: deque, on_result, alone: bool) -> None:
        """A run lost with a dead worker: counted as an attempt only if it was flying alone (then it is
        the one that killed the worker); flown again alone until it passes or dies max_attempts times."""
        if not alone:
            suspects.append(task)
        elif task.attempt < self.max_attempts:
            suspects.append(retry_task(task))
        else:
            on_result(died_row(task, f"worker process died on each of {task.attempt} attempts"), None)


def _worker_init(dems: dict[str, Any]) -> None:
    """A pool worker: the DEMs, and one BLAS thread. The pool already has a process per core; OpenBLAS's own
    threads on top of it made each run 1.25 times slower than alone (`python -m trn_env.bench.campaign`:
    parallel efficiency 0.74 with them, 0.81-0.87 without, on 2 cores). Ray's workers get the same from
    Ray, which sets OMP_NUM_THREADS to the task's CPUs."""
    from threadpoolctl import threadpool_limits

    set_dems(dems)
    threadpool_limits(limits=1, user_api="blas")
