"""The end of a streamed run reads its per-update rows back from the log (trn_env.sim.log.SimLog.arrays):
that read-back must hold the result's arrays plus about one column, not whole tables beside them (a 10-hour
flight's 36,000 rows made the end of the run the process's peak). Measured here on 20,000 synthetic rows
written through the real writer: numpy's allocations (tracemalloc) plus Arrow's pool (its own peak)."""

from __future__ import annotations

import math
import tracemalloc

import numpy as np
import pyarrow as pa
from trn_env.terrain import Dem

from trn_env.logs.writer import LogWriter
from trn_env.sim.log import SimLog


def _log(tmp_path, n: int) -> SimLog:
    writer = LogWriter(tmp_path / "log", {})
    log = SimLog(sink=writer)
    rng = np.random.default_rng(1)
    lat0, lon0 = math.radians(36.45), math.radians(-84.35)
    for k in range(n):
        t = float(k)
        lat, lon = lat0 + 1e-6 * k, lon0 + 1e-6 * k
        log.truth_rows.append((t, lat, lon, 1500.0, 80.0, 1.0, 0.0, 0.0, 0.0, 0.1, 85.0, 0.02, 0.0,
                               1.0, 2.0, 0.0))
        log.est_rows.append((t, lat + 1e-7, lon - 1e-7, 1501.0, np.array([80.0, 1.0, 0.0]), 0.0, 0.0, 0.1,
                             np.diag(rng.uniform(1.0, 2.0, 9)), True, "ok", 25.0))
        if len(log.truth_rows) >= log.flush_ticks:
            log.flush()
    return log


def test_read_back_holds_the_result_once(tmp_path):
    n = 20_000
    log = _log(tmp_path, n)
    dem = Dem(np.full((50, 50), 300.0), math.radians(36.4), math.radians(-84.4), math.radians(0.01),
              math.radians(0.01))
    # the numba kernels the read-back calls load once per process first (not the read-back's memory)
    from trn_env.scenario.build import world_height
    from trn_env.sim.log import error_ned_m
    x = np.full(4, math.radians(36.45))
    error_ned_m(x, x, x, x, x, x)
    world_height(dem, x, x - math.radians(120.8))
    pool = pa.default_memory_pool()
    arrow0 = pool.max_memory() or 0
    tracemalloc.start()
    try:
        arrays = log.arrays(dem, [])
        _, numpy_peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    arrow_peak = max(0, (pool.max_memory() or 0) - arrow0)
    result = sum(a.nbytes for a in arrays.values())
    column = 8 * n
    # the result's own arrays (est_cov alone is 81 columns) plus the truth rows read as one (n, 16) array
    # and the other temporaries (40 columns' worth); the earlier read-back held the 94 estimate columns, the
    # 81 covariance columns again and Arrow's tables: numpy 22.2 MB + Arrow 31.8 MB against 19.4 MB here
    assert arrays["est_cov"].shape == (n, 9, 9) and result > 100 * column
    assert numpy_peak + arrow_peak < result + 40 * column, (numpy_peak, arrow_peak, result)
    # and the values are the rows written
    assert np.array_equal(arrays["t_s"], np.arange(n, dtype=float))
    assert np.all(np.diagonal(arrays["est_cov"], axis1=1, axis2=2) >= 1.0)
    assert np.array_equal(arrays["est_cov_diag"], np.diagonal(arrays["est_cov"], axis1=1, axis2=2))
