"""The end of a streamed run reads its per-update rows back from the log (trn_env.sim.log.SimLog.arrays),
computes the summary's metrics and writes log.npz: that step must not hold the whole flight's 9 x 9
covariances (648 bytes a row, two thirds of a row's arrays; a 10-hour flight's 36,000 rows made the end of
the run the process's peak), nor whole Arrow tables beside the result. Measured here on synthetic rows
written through the real writer: numpy's allocations (tracemalloc) plus Arrow's pool (its own peak)."""

from __future__ import annotations

import math
import tracemalloc
import zipfile

import numpy as np
import pyarrow as pa
import pytest
from _child_processes import NEUTRAL_CWD
from trn_env.terrain import Dem

from trn_env.logs.writer import MAX_BUFFER_BYTES, LogWriter
from trn_env.output.chunked import ChunkedRows, write_npz
from trn_env.output.metrics import navigation_metrics
from trn_env.output.run_folder import write_log_npz
from trn_env.sim.log import SimLog

COV_ROW_BYTES = 81 * 8


def _log(tmp_path, n: int, sink: bool = True, dense: bool = False) -> SimLog:
    log = SimLog(sink=LogWriter(tmp_path / "log", {}) if sink else None)
    rng = np.random.default_rng(1)
    lat0, lon0 = math.radians(36.45), math.radians(-84.35)
    for k in range(n):
        t = float(k)
        lat, lon = lat0 + 1e-6 * k, lon0 + 1e-6 * k
        log.truth_rows.append((t, lat, lon, 1500.0, 80.0, 1.0, 0.0, 0.0, 0.0, 0.1, 85.0, 0.02, 0.0,
                               1.0, 2.0, 0.0))
        if dense:        # a full covariance (correlated, some rows not finite) and noisy estimates
            a = rng.normal(size=(9, 9))
            cov = a @ a.T + 0.1 * np.eye(9)
            if k % 97 == 0:
                cov[1, 1] = np.nan
            est = (t, lat + 1e-6 * rng.normal(), lon + 1e-6 * rng.normal(), 1501.0 + rng.normal(),
                   rng.normal(size=3), 0.0, 0.0, 0.1, cov, bool(k % 7), "ok", 25.0)
        else:
            est = (t, lat + 1e-7, lon - 1e-7, 1501.0, np.array([80.0, 1.0, 0.0]), 0.0, 0.0, 0.1,
                   np.diag(rng.uniform(1.0, 2.0, 9)), True, "ok", 25.0)
        log.est_rows.append(est)
        if sink and len(log.truth_rows) >= log.flush_ticks:
            log.flush()
    return log


@pytest.fixture(scope="module")
def dem(tmp_path_factory):
    dem = Dem(np.full((50, 50), 300.0), math.radians(36.4), math.radians(-84.4), math.radians(0.01),
              math.radians(0.01))
    # the numba kernels and the libraries the end of a run calls load once per process first (not its memory)
    from trn_env.scenario.build import world_height
    from trn_env.sim.log import error_ned_m
    x = np.full(4, math.radians(36.45))
    error_ned_m(x, x, x, x, x, x)
    world_height(dem, x, x - math.radians(120.8))
    warm = tmp_path_factory.mktemp("warm")
    _end_of_run(warm, _log(warm, 1_200), dem)          # (the first call's imports: scipy's chi2, ...)
    return dem


def _end_of_run(tmp_path, log: SimLog, dem) -> tuple[dict, int, int]:
    """arrays(), the metrics and log.npz, as the end of a streamed `trn-env fly`: (arrays, numpy's peak,
    Arrow's peak above its earlier one), bytes."""
    pool = pa.default_memory_pool()
    arrow0 = pool.max_memory() or 0
    tracemalloc.start()
    try:
        arrays = log.arrays(dem, [])
        navigation_metrics(arrays)
        write_log_npz(tmp_path / "log.npz", arrays)
        _, numpy_peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return arrays, numpy_peak, max(0, (pool.max_memory() or 0) - arrow0)


def test_end_of_run_keeps_the_covariances_on_disk(tmp_path, dem):
    n = 20_000
    arrays, numpy_peak, arrow_peak = _end_of_run(tmp_path, _log(tmp_path, n), dem)
    cov = arrays["est_cov"]
    assert isinstance(cov, ChunkedRows) and cov.shape == (n, 9, 9)
    held = sum(a.nbytes for a in arrays.values() if isinstance(a, np.ndarray))
    column = 8 * n
    # the result's own arrays (40 columns; the covariances alone are 81) plus temporaries of 40 columns and
    # of a bounded size whatever the flight's length: the writer's last buffers (truth and estimates, each
    # at most MAX_BUFFER_BYTES, joined when their tables close) and one row group's covariances read back
    # (at most MAX_BUFFER_BYTES of estimate rows); the earlier ends of run: docs/validation/logs.md
    assert held < 45 * column
    bound = held + 40 * column + 3 * MAX_BUFFER_BYTES
    assert numpy_peak + arrow_peak < bound, (numpy_peak, arrow_peak, held)
    # and the values are the rows written, read back whole on request
    assert np.array_equal(arrays["t_s"], np.arange(n, dtype=float))
    full = np.asarray(cov)
    assert full.shape == (n, 9, 9) and np.all(np.diagonal(full, axis1=1, axis2=2) >= 1.0)
    assert np.array_equal(arrays["est_cov_diag"], np.diagonal(full, axis1=1, axis2=2))
    assert np.array_equal(np.load(tmp_path / "log.npz")["est_cov"], full)


def test_end_of_run_memory_grows_by_less_than_a_covariance_per_row(tmp_path, dem):
    """The peak of the end of the run, for 8,000 and 32,000 rows (row groups of 6,000 estimate rows in both):
    what each further row adds is less than its 9 x 9 covariance (648 bytes). Holding the covariances whole
    (the earlier end of run) adds ~1,600 B a row (its arrays ~970 B, their temporaries the rest); here
    ~480 B (the ~320 B of the other arrays and their temporaries)."""
    peaks = {}
    for n in (8_000, 32_000):
        _, numpy_peak, arrow_peak = _end_of_run(tmp_path / str(n), _log(tmp_path / str(n), n), dem)
        peaks[n] = numpy_peak + arrow_peak
    per_row = (peaks[32_000] - peaks[8_000]) / 24_000
    print(f"end of run: {per_row:.0f} B per further row, peaks {peaks}")
    assert per_row < COV_ROW_BYTES, (per_row, peaks)


def test_streamed_end_of_run_equals_the_in_memory_one(tmp_path, dem):
    """Arrays, metrics and log.npz members of the streamed end of run are those of the in-memory one bit for
    bit (full covariances, non-finite rows included)."""
    n = 3_000
    a = _log(tmp_path / "s", n, sink=True, dense=True).arrays(dem, [])
    b = _log(tmp_path / "m", n, sink=False, dense=True).arrays(dem, [])
    assert isinstance(a["est_cov"], ChunkedRows) and isinstance(b["est_cov"], np.ndarray)
    assert set(a) == set(b)
    for k in b:
        got = np.asarray(a[k])
        assert got.dtype == b[k].dtype and np.array_equal(got, b[k], equal_nan=True), k
    ma, mb = navigation_metrics(a), navigation_metrics(b)
    assert np.isfinite(mb["anees"]) and all(repr(ma[k]) == repr(mb[k]) for k in mb), (ma, mb)
    write_npz(tmp_path / "a.npz", a)
    np.savez_compressed(tmp_path / "b.npz", **b)
    za, zb = zipfile.ZipFile(tmp_path / "a.npz"), zipfile.ZipFile(tmp_path / "b.npz")
    assert za.namelist() == zb.namelist()
    for name in zb.namelist():
        assert za.read(name) == zb.read(name), name           # the same .npy bytes (header and data)


@pytest.mark.parametrize("preset", [None, "mimalloc"])
def test_trn_env_chooses_arrow_s_system_pool_unless_told_otherwise(preset):
    """Importing trn_env before pyarrow's first allocation selects Arrow's system allocator (mimalloc, the
    default, keeps what a long run's read-back freed); ARROW_DEFAULT_MEMORY_POOL, when set, wins."""
    import os
    import subprocess
    import sys
    env = {k: v for k, v in os.environ.items() if k != "ARROW_DEFAULT_MEMORY_POOL"}
    if preset:
        env["ARROW_DEFAULT_MEMORY_POOL"] = preset
    code = "import trn_env, pyarrow as pa; print(pa.default_memory_pool().backend_name)"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True,
                         cwd=NEUTRAL_CWD)
    assert out.stdout.strip() == (preset or "system"), out
