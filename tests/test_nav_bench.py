"""trn_env.bench.navigators returns finite throughput figures (sizes reduced)."""

import numpy as np

from trn_env.bench.navigators import benchmark


def test_benchmark_figures():
    b = benchmark(n_imu=2000, half_cells=5, n_tercom_samples=100, repeats=1)
    assert set(b) == {"ins_steps_per_s", "tercom_fix_s", "tercom_lookups_per_s", "tercom_fix_ms",
                      "tercom_fix_threads", "tercom_fix_ms_one_thread", "tercom_fix_ms_previous",
                      "tercom_fix_speedup"}
    assert all(np.isfinite(v) and v > 0 for v in b.values())
