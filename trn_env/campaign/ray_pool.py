"""Warm Ray workers: a pool of Ray actors, one per CPU, that stay alive for the whole campaign.

A Ray task may land on any worker process, and a fresh one pays the cold start first: importing trn_env
and its dependencies, unpickling the campaign's DEMs, loading the numba kernels from the cache (compiling
them on a node whose cache is empty). A campaign of many short runs pays it again wherever Ray starts a new
worker. An actor pays it once: it is created with one CPU, imports the packages and limits BLAS to one
thread (as the local pool's workers), then, for each `WarmPool.run` call, takes the campaign's DEMs from
the object store once and flies `trn_env.sim.warm_up`'s three-update copy of the campaign's first run (the
kernels that run uses are loaded before the first row); from then on it only flies runs (`fly_run`, the
same function as every backend, so the rows are the same bit for bit).

Scheduling: each live actor has at most two runs queued (one flying, the next one waiting, so the hand-over is
hidden behind a flight); a row is taken as soon as it is ready. An actor that dies (its process killed, its
node lost) loses the runs it held: the pool starts a replacement actor and hands those runs to the next free
actor. The run it was flying (its earliest one: an actor flies in order) is handed on up to `max_retries`
times more; the run queued behind it never started, so the loss does not count against it. Every attempt
counts itself in Ray's key-value store (`ray_backend._attempt_number`), so the row of a run flown again says
`attempts = 2`, and a run that killed its actor on every attempt gets an error row with `attempts =
max_retries + 1`. A run's own exception is a row (fly_run catches it), never a retry. The actors are killed
when the backend closes (Ctrl-C included).
"""

from __future__ import annotations

import os
import time
import uuid
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

from trn_env.campaign.runs import RunTask, died_row


class WarmWorker:
    """The actor's class (wrapped by ray.remote in WarmPool): imports at creation, DEMs and the warm-up
    flight per campaign (`prepare`), then `fly`."""

    def __init__(self) -> None:
        t0 = time.perf_counter()
        from threadpoolctl import threadpool_limits

        import trn_env.campaign.ray_backend  # noqa: F401 - the imports of a run, paid here once
        import trn_env.sim.closed_loop  # noqa: F401
        threadpool_limits(limits=1, user_api="blas")
        self.import_s = time.perf_counter() - t0
        self.warmed: set = set()
        self.dems_id: str | None = None

    def prepare(self, dems_id: str, dems: dict[str, Any], warm_task: RunTask | None) -> dict:
        """Take the campaign's DEMs (`dems_id` names them: the same DEMs are not set twice) and fly the
        warm-up copy of `warm_task` once per (navigator, scenario, DEMs); returns this actor's timings."""
        from trn_env.campaign.runs import set_dems
        t0 = time.perf_counter()
        if dems_id != self.dems_id:
            set_dems(dems)
            self.dems_id = dems_id
        t1 = time.perf_counter()
        key = None if warm_task is None or getattr(warm_task, "kind", "flight") != "flight" else (
            str(warm_task.sections.navigator.name), warm_task.scenario_name, warm_task.dem_keys)
        if key is not None and key not in self.warmed:
            warm_run(warm_task)
            self.warmed.add(key)
        return {"pid": os.getpid(), "import_s": self.import_s, "dems_s": t1 - t0,
                "warm_up_s": time.perf_counter() - t1}

    def fly(self, task: RunTask, run_key: str) -> tuple[dict, bytes | None]:
        from trn_env.campaign.ray_backend import _fly
        return _fly(task, None, run_key)


def warm_run(task: RunTask) -> float:
    """Fly the three-update warm-up copy of `task`'s scenario (trn_env.sim.warm_up) over the DEMs set with
    set_dems, in this process; returns the wall seconds. Its objects and random streams are its own."""
    from trn_env.campaign.runs import task_scenario
    from trn_env.scenario.build import build_terrain, quiet_stdout
    from trn_env.sim.closed_loop import spawn_rngs
    from trn_env.sim.warm_up import warm_up
    scenario = task_scenario(task)
    dems = build_terrain(scenario.sections, scenario.extras, spawn_rngs(scenario.seed)["map"])
    with quiet_stdout():
        return warm_up(scenario, dems, parallel=False)


class WarmPool:
    """`n` WarmWorker actors on the connected Ray session (module docstring); `close()` kills them."""

    def __init__(self, ray, n: int, max_retries: int = 3, worker_cls: type = WarmWorker):
        self.ray = ray
        self.n = int(n)
        self.max_retries = int(max_retries)
        # Ray does not restart a dead actor or retry its calls: the pool does both (module docstring)
        self._cls = ray.remote(num_cpus=1, max_restarts=0, max_task_retries=0)(worker_cls)
        self.actors: list = []
        self.timings: list[dict] = []          # prepare()'s figures of the last run call, per actor

    def close(self) -> None:
        for actor in self.actors:
            try:
                self.ray.kill(actor)
            except Exception:  # noqa: BLE001 - already gone
                pass
        self.actors = []

    def run(self, tasks: Iterable[RunTask], dems: dict[str, Any],
            on_result: Callable[[dict, bytes | None], None]) -> None:
        ray = self.ray
        it = iter(tasks)
        first = next(it, None)
        if first is None:
            return
        dems_ref = ray.put(dems)
        dems_id = uuid.uuid4().hex
        run_key = uuid.uuid4().hex[:16]
        while len(self.actors) < self.n:
            self.actors.append(self._cls.remote())
        self.timings = []
        starting = {actor.prepare.remote(dems_id, dems_ref, first): actor for actor in self.actors}
        idle: deque = deque()                   # live actors with a free slot (one entry per free slot)
        held: dict = {}                         # fly ref -> (actor, task, submission number)
        submitted = 0
        flying_when_died: dict = {}             # dead actor -> submission number of the run it was flying
        todo: deque[RunTask] = deque([first])   # runs handed back by a dead actor come first
        lost: dict[str, int] = {}               # run id -> times its actor died under it
        exhausted = False

        def replace(actor) -> None:
            if actor in self.actors:
                self.actors.remove(actor)
                try:
                    ray.kill(actor)
                except Exception:  # noqa: BLE001 - already gone
                    pass
            while actor in idle:
                idle.remove(actor)
            new = self._cls.remote()
            self.actors.append(new)
            starting[new.prepare.remote(dems_id, dems_ref, first)] = new

        while True:
            while idle and (todo or not exhausted):
                if not todo:
                    task = next(it, None)
                    if task is None:
                        exhausted = True
                        break
                    todo.append(task)
                actor = idle.popleft()
                task = todo.popleft()
                held[actor.fly.remote(task, run_key)] = (actor, task, submitted)
                submitted += 1
            if not held and not starting and exhausted and not todo:
                break
            ready, _ = ray.wait(list(held) + list(starting), num_returns=1)
            ref = ready[0]
            if ref in starting:
                actor = starting.pop(ref)
                try:
                    self.timings.append(ray.get(ref))
                except ray.exceptions.RayActorError:
                    replace(actor)
                    continue
                except ray.exceptions.RayError as exc:     # the warm-up failed: fly without it
                    self.timings.append({"error": f"{type(exc).__name__}: {exc}"})
                idle.extend([actor, actor])
                continue
            actor, task, number = held.pop(ref)
            try:
                row, log = ray.get(ref)
            except ray.exceptions.RayActorError as exc:    # the actor died: its runs go elsewhere
                if actor not in flying_when_died:
                    # an actor flies its runs in order: the earliest one it still held was flying, the
                    # one queued behind it never started and is handed on without counting against it
                    flying_when_died[actor] = min([number] + [n for a, _, n in held.values() if a is actor])
                if number != flying_when_died[actor]:
                    todo.appendleft(task)
                    if actor in self.actors:
                        replace(actor)
                    continue
                n_lost = lost[task.run_id] = lost.get(task.run_id, 0) + 1
                if n_lost <= self.max_retries:
                    todo.appendleft(task)
                else:
                    row = died_row(task, f"Ray actor died on each of {n_lost} attempts: "
                                         f"{type(exc).__name__}: {exc}")
                    row["attempts"] = n_lost
                    on_result(row, None)
                if actor in self.actors:
                    replace(actor)
                continue
            except ray.exceptions.RayError as exc:         # not the run's own failure (fly_run catches it)
                row, log = died_row(task, f"Ray task failed: {type(exc).__name__}: {exc}"), None
            if actor in self.actors:
                idle.append(actor)
            on_result(row, log)
