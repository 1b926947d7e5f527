"""Navigator throughput figures for `trn-env bench` (each beside a same-run reference where one exists)."""

from __future__ import annotations

import time

import numpy as np

from terrain.geodesy import OMEGA_EARTH_RPS, euler_to_C_bn

from .ins import StrapdownIns, gravity_ned
from .tercom import correlate


def _best(fn, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def benchmark(
    n_imu: int = 100_000, half_cells: int = 50, n_tercom_samples: int = 2000, repeats: int = 3
) -> dict:
    """ins_steps_per_s (strapdown mechanisation, numba), tercom_fix_s (one 101 x 101 MAD fix of
    n_tercom_samples samples) and tercom_lookups_per_s (bilinear lookups inside the MAD kernel)."""
    lat = np.radians(36.8)
    C = euler_to_C_bn(0.0, 0.0, 0.3)
    g = gravity_ned(lat, 3000.0, 1)
    t = np.arange(n_imu) * 0.01
    f = np.tile(C.T @ (-g), (n_imu, 1))
    w = np.tile(
        C.T @ np.array([OMEGA_EARTH_RPS * np.cos(lat), 0.0, -OMEGA_EARTH_RPS * np.sin(lat)]), (n_imu, 1)
    )
    ins = StrapdownIns()

    def run_ins():
        ins.reset(0.0, lat, 0.0, 3000.0, [80.0, 0.0, 0.0], 0.0, 0.0, 0.3)
        ins.propagate(t, f, w)

    run_ins()
    t_ins = _best(run_ins, repeats)
    rng = np.random.default_rng(0)
    heights = 300.0 + 50.0 * rng.standard_normal((400, 400))
    d = np.radians(3.0 / 3600.0)
    grid = (heights, lat - 200 * d, -200 * d, d, d)
    la = lat + np.linspace(-0.002, 0.002, n_tercom_samples)
    lo = np.linspace(-0.002, 0.002, n_tercom_samples)
    hm = np.full(n_tercom_samples, 300.0)

    def run_fix():
        correlate(grid, 0.0, la, lo, hm, half=half_cells)

    run_fix()
    t_fix = _best(run_fix, repeats)
    cells = (2 * half_cells + 1) ** 2
    return {
        "ins_steps_per_s": n_imu / t_ins,
        "tercom_fix_s": t_fix,
        "tercom_lookups_per_s": cells * n_tercom_samples / t_fix,
    }


if __name__ == "__main__":
    import json

    print(json.dumps(benchmark(), indent=1))
