"""Navigator throughput figures for `trn-env bench` (each beside a same-run reference where one exists)."""

from __future__ import annotations

import time

import numpy as np

from trn_env import terrain
from trn_env.navigators.inertial.strapdown import StrapdownIns, gravity_ned
from trn_env.navigators.tercom.mad import TERCOM_THREADS, _mad_surface_separable, correlate, mad_surface
from trn_env.terrain.geodesy import OMEGA_EARTH_RPS, euler_to_C_bn, meridian_radius_m, prime_vertical_radius_m


def _best(fn, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _default_fix_inputs(n_samples: int, half_cells: int) -> tuple:
    """mad_surface arguments of a fix like the default scenario's: the bundled jacksboro DEM, n_samples
    IRA samples along a 4 km straight leg across its middle, 5 m cells, bias removed."""
    dem = terrain.load("jacksboro")
    lat_min, lat_max, lon_min, lon_max = dem.bounds
    lat_c = 0.5 * (lat_min + lat_max)
    r_ns = meridian_radius_m(lat_c)
    r_ew = prime_vertical_radius_m(lat_c) * np.cos(lat_c)
    s_m = np.linspace(-2000.0, 2000.0, n_samples)
    lat_k = lat_c + s_m * np.cos(0.5) / r_ns
    lon_k = 0.5 * (lon_min + lon_max) + s_m * np.sin(0.5) / r_ew
    h_meas = dem.height(lat_k, lon_k) + 3.0 + np.random.default_rng(1).normal(0.0, 2.0, n_samples)
    return (dem.record(), lat_k, lon_k, h_meas, 5.0 / r_ns, 5.0 / r_ew, half_cells, True)


def benchmark(
    n_imu: int = 100_000, half_cells: int = 50, n_tercom_samples: int = 2000, repeats: int = 3
) -> dict:
    """ins_steps_per_s (strapdown mechanisation, numba), tercom_fix_s (one 101 x 101 MAD fix of
    n_tercom_samples samples) and tercom_lookups_per_s (bilinear lookups inside the MAD kernel);
    tercom_fix_ms: one default-scenario-like MAD surface (jacksboro, 2000 samples, 101 x 101 cells, bias
    removed), beside tercom_fix_ms_previous (the previous separable kernel, still the void path, on the
    same inputs) and their ratio tercom_fix_speedup."""
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
    args = _default_fix_inputs(n_tercom_samples, half_cells)
    mad_surface(*args)
    _mad_surface_separable(*args)
    t_new = _best(lambda: mad_surface(*args), repeats)
    t_one = _best(lambda: mad_surface(*args, threads=1), repeats)
    t_prev = _best(lambda: _mad_surface_separable(*args), repeats)
    return {
        "ins_steps_per_s": n_imu / t_ins,
        "tercom_fix_s": t_fix,
        "tercom_lookups_per_s": cells * n_tercom_samples / t_fix,
        "tercom_fix_ms": 1e3 * t_new,
        "tercom_fix_threads": TERCOM_THREADS,
        "tercom_fix_ms_one_thread": 1e3 * t_one,
        "tercom_fix_ms_previous": 1e3 * t_prev,
        "tercom_fix_speedup": t_prev / t_new,
    }


if __name__ == "__main__":
    import json

    print(json.dumps(benchmark(), indent=1))
