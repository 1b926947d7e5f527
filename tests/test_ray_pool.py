"""Warm Ray workers (trn_env.campaign.ray_pool) on a real 2-CPU local Ray instance: rows equal to the
serial ones bit for bit, an actor that dies mid-run has its run flown again elsewhere (attempts counts it),
a run that kills its actor every time ends as an error row, Ctrl-C then --resume completes the campaign."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest
from _child_processes import init_local_ray

from trn_env.campaign import load_campaign
from trn_env.campaign.ray_pool import WarmWorker
from trn_env.output.metrics import METRIC_KEYS

pytestmark = pytest.mark.slow             # a Ray instance and ten short flights: about a minute on 2 cores

HERE = Path(__file__).resolve().parent
DIE_ONCE = "v000-s0001"       # its actor dies during its first attempt
DIE_ALWAYS = "v000-s0002"     # its actor dies on every attempt


class DyingWorker(WarmWorker):
    """A WarmWorker whose process dies under two of the runs, as on a node lost mid-run: after counting the
    attempt (as fly does first), before flying."""

    def fly(self, task, run_key):
        from trn_env.campaign.ray_backend import _attempt_number, attempt_key
        if task.run_id in (DIE_ONCE, DIE_ALWAYS):
            n = _attempt_number(attempt_key(run_key, task))
            _record_pid(task.run_id, n)
            if task.run_id == DIE_ALWAYS or n == 1:
                os._exit(1)
            from trn_env.campaign.runs import fly_run
            row, log = fly_run(task)
            row["attempts"] = n
            return row, log
        return super().fly(task, run_key)


def _record_pid(run_id: str, attempt: int) -> None:
    from ray.experimental.internal_kv import _internal_kv_put
    _internal_kv_put(f"{run_id}:{attempt}".encode(), str(os.getpid()).encode(), namespace="test_ray_pool")


@pytest.fixture(scope="module")
def ray_session():
    ray = pytest.importorskip("ray", reason="the ray extra is installed in CI (pip install -e .[ray])")
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])     # the workers cannot import tests/
    init_local_ray()
    yield ray
    ray.shutdown()


def _campaign(tmp_path, seeds: int):
    p = tmp_path / "pool.toml"
    p.write_text(f'name = "pool"\nroot_seed = 3\nseeds = {seeds}\n'
                 f'scenarios = ["{HERE}/campaigns/ci_denied_short.toml"]\nduration_s = 6.0\n'
                 'navigators = ["ins"]\n', encoding="utf-8")
    return load_campaign(p)


def _serial(camp) -> dict[str, dict]:
    from trn_env.campaign.driver import tasks
    from trn_env.campaign.runs import fly_run, set_dems
    set_dems(camp.extra["dems"])
    return {t.run_id: fly_run(t)[0] for t in tasks(camp, set())}


def _assert_same_run(a: dict, b: dict) -> None:
    assert a["termination"] == b["termination"] == "time_limit"
    assert a["scenario_hash"] == b["scenario_hash"]
    for k in METRIC_KEYS:
        assert (a[k] == b[k]) or (not np.isfinite(a[k]) and not np.isfinite(b[k])), k
    assert np.array_equal(a["series_err_h_m"], b["series_err_h_m"])


def test_dead_actors_runs_are_flown_elsewhere_and_counted(ray_session, tmp_path):
    from ray.experimental.internal_kv import _internal_kv_get

    from trn_env.campaign.driver import tasks
    from trn_env.campaign.ray_pool import WarmPool
    camp = _campaign(tmp_path, 4)
    serial = _serial(camp)
    pool = WarmPool(ray_session, 2, max_retries=2, worker_cls=DyingWorker)
    rows: dict[str, dict] = {}
    try:
        pool.run(tasks(camp, set()), camp.extra["dems"],
                 lambda row, _log: rows.__setitem__(row["run_id"], row))
        live = len(pool.actors)
    finally:
        pool.close()
    assert sorted(rows) == sorted(serial)
    for run_id, row in rows.items():
        if run_id == DIE_ALWAYS:
            assert row["termination"] == "error" and row["attempts"] == 3      # max_retries + 1
            assert "actor died" in row["error"]
            continue
        _assert_same_run(row, serial[run_id])
        # a healthy run that had finished on an actor whose process died before its reply left is flown
        # again and counted, as on a node lost mid-reply: 1 or 2 attempts; DIE_ONCE at least 2
        if run_id == DIE_ONCE:
            assert row["attempts"] >= 2, run_id
        else:
            assert row["attempts"] in (1, 2), run_id
    n_last = rows[DIE_ONCE]["attempts"]
    pid = {n: int(_internal_kv_get(f"{DIE_ONCE}:{n}".encode(), namespace="test_ray_pool"))
           for n in (1, n_last)}
    assert pid[1] != pid[n_last] and rows[DIE_ONCE]["pid"] == pid[n_last]     # flown again in another process
    assert live == 2                          # every dead actor was replaced


def test_ctrl_c_then_resume_completes_the_campaign_with_the_serial_rows(ray_session, tmp_path):
    from trn_env.campaign import run_campaign
    from trn_env.campaign.ray_backend import RayBackend
    from trn_env.campaign.rows import read_rows
    camp = _campaign(tmp_path, 4)
    serial = _serial(camp)
    out = tmp_path / "out"
    seen: list[str] = []

    def interrupt(row):
        seen.append(row["run_id"])
        raise KeyboardInterrupt

    backend = RayBackend()
    with pytest.raises(KeyboardInterrupt):
        run_campaign(camp, out, backend=backend, progress=False, on_row=interrupt)
    assert backend._pool is None                     # the actors were killed on the way out
    assert len(read_rows(out)) == 1 == len(seen)
    stats = run_campaign(camp, out, backend=RayBackend(), resume=True, progress=False)
    assert stats["already_done"] == 1 and stats["flown"] == 3 and "warm actors" in stats["backend"]
    df = read_rows(out)
    assert sorted(df["run_id"]) == sorted(serial)
    for _, row in df.iterrows():
        _assert_same_run(row, serial[row["run_id"]])
        assert row["attempts"] == 1
