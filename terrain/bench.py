"""Terrain throughput benchmark: `benchmark() -> dict` (run `python -m terrain.bench`).

Figures (one thread; numba kernels compiled before timing):
  bilinear_lookups_per_s        numba batch bilinear (terrain.kernels.bilinear_batch)
  numpy_bilinear_lookups_per_s  numpy's vectorised bilinear formula on the same points (reference)
  ira_queries_per_s             terrain.queries.ira_return on a level-to-banked flight sample (1500 m AGL)
  radar_altimeter_queries_per_s terrain.queries.radar_altimeter_return on the same sample
  *_5km_agl                     the same two queries with the sample at 5 km AGL
  *_refined_10m                 the same two queries (1500 m AGL) on a 10 m world refined from the DEM
                                (terrain.refine.refine, central 12 x 12 km; refined_10m_posts gives its size)
  ira_queries_per_s_default_world  IRA queries (1500 m AGL, 45 deg window, 10 km) on the whole DEM refined to
                                30 m, as the default scenario's true world (refined_30m_posts: its size)
  ira_50_queries_us_default_world  one ira_return call of 50 such queries (one second of IRA at 50 Hz), us
  ira_call_overhead_us          the fixed cost of an ira_return call (one query without a valid height), us
"""

from __future__ import annotations

import json
import time

import numpy as np

from . import geodesy, kernels, queries
from .dem import Dem


def _numpy_bilinear(heights, lat0, lon0, dlat, dlon, lat, lon):
    fi = (lat - lat0) / dlat
    fj = (lon - lon0) / dlon
    ok = (fi >= 0) & (fj >= 0) & (fi <= heights.shape[0] - 1) & (fj <= heights.shape[1] - 1)
    i = np.clip(fi.astype(np.int64), 0, heights.shape[0] - 2)
    j = np.clip(fj.astype(np.int64), 0, heights.shape[1] - 2)
    u = fi - i
    v = fj - j
    a = heights[i, j] + v * (heights[i, j + 1] - heights[i, j])
    b = heights[i + 1, j] + v * (heights[i + 1, j + 1] - heights[i + 1, j])
    return np.where(ok, a + u * (b - a), np.nan)


def _best_rate(fn, n_items: int, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return n_items / best


def flight_sample(dem: Dem, n: int, seed: int = 0, agl_m: float = 1500.0):
    """Antenna states for query benchmarks/tests: positions over the DEM, headings, +-30 deg bank,
    -5..10 deg pitch, 110 m/s with up to 20 m/s crosswind. Returns (lat, lon, h, v_ned, C_bn)."""
    rng = np.random.default_rng(seed)
    dn_m, de_m = dem.extent_m
    lat_c, lon_c = dem.center_rad
    lat, lon = dem.offset_to_latlon(
        lat_c, lon_c, rng.uniform(-0.3, 0.3, n) * dn_m, rng.uniform(-0.3, 0.3, n) * de_m
    )
    h = dem.height(lat, lon) + agl_m * rng.uniform(0.5, 1.5, n)
    yaw = rng.uniform(0, 2 * np.pi, n)
    roll = np.radians(rng.uniform(-30, 30, n))
    pitch = np.radians(rng.uniform(-5, 10, n))
    C = geodesy.euler_to_C_bn(roll, pitch, yaw)
    cross = rng.uniform(-20, 20, n)
    v = np.stack(
        [
            110 * np.cos(yaw) - cross * np.sin(yaw),
            110 * np.sin(yaw) + cross * np.cos(yaw),
            rng.uniform(-3, 3, n),
        ],
        axis=1,
    )
    return lat, lon, h, v, C


def _query_rates(dem, n, half_beamwidth_rad, half_window_rad, repeats, agl_m):
    """(IRA, radar altimeter) queries per second on a flight_sample of n states at agl_m."""
    qlat, qlon, qh, qv, qC = flight_sample(dem, n, agl_m=agl_m)
    queries.ira_return(dem, qlat[:4], qlon[:4], qh[:4], qv[:4], qC[:4], half_window_rad)
    queries.radar_altimeter_return(dem, qlat[:4], qlon[:4], qh[:4], qC[:4], half_beamwidth_rad)
    ira = _best_rate(lambda: queries.ira_return(dem, qlat, qlon, qh, qv, qC, half_window_rad), n, repeats)
    ra = _best_rate(
        lambda: queries.radar_altimeter_return(dem, qlat, qlon, qh, qC, half_beamwidth_rad), n, repeats
    )
    return ira, ra


def _ira_world_figures(world: Dem, n: int, half_window_rad: float, repeats: int):
    """(IRA queries/s, us per call of 50 queries, us per call of one query without a valid height) on
    `world` at 1500 m AGL, 10 km maximum range."""
    qlat, qlon, qh, qv, qC = flight_sample(world, n, seed=3, agl_m=1500.0)

    def call(sl, h=None):
        return lambda: queries.ira_return(
            world, qlat[sl], qlon[sl], qh[sl] if h is None else h, qv[sl], qC[sl], half_window_rad, 10000.0
        )

    call(slice(0, 4))()
    rate = _best_rate(call(slice(None)), n, repeats)
    per_50 = min(1.0 / _best_rate(call(slice(k, k + 50)), 1, repeats) for k in range(0, min(n, 500) - 49, 50))
    void_h = np.full(1, np.nan)
    overhead = 1.0 / _best_rate(call(slice(0, 1), void_h), 1, 20 * repeats)
    return rate, per_50 * 1e6, overhead * 1e6


def benchmark(
    dem: Dem | None = None,
    n_lookups: int = 2_000_000,
    n_queries: int = 20_000,
    half_beamwidth_rad: float = np.radians(20.0),
    half_window_rad: float = np.radians(45.0),
    repeats: int = 3,
) -> dict:
    """Throughput figures (see the module docstring) on `dem` (default: the bundled jacksboro DEM)."""
    if dem is None:
        from . import load

        dem = load("jacksboro")
    heights, lat0, lon0, dlat, dlon = dem.grid
    rng = np.random.default_rng(1)
    b = dem.bounds
    lat = rng.uniform(b[0], b[1], n_lookups)
    lon = rng.uniform(b[2], b[3], n_lookups)
    out = np.empty(n_lookups)
    kernels.bilinear_batch(heights, lat0, lon0, dlat, dlon, lat[:10], lon[:10], out[:10])
    nb = _best_rate(
        lambda: kernels.bilinear_batch(heights, lat0, lon0, dlat, dlon, lat, lon, out), n_lookups, repeats
    )
    npb = _best_rate(lambda: _numpy_bilinear(heights, lat0, lon0, dlat, dlon, lat, lon), n_lookups, repeats)
    ref = _numpy_bilinear(heights, lat0, lon0, dlat, dlon, lat, lon)
    if not np.allclose(out, ref, equal_nan=True):
        raise RuntimeError("benchmark: numba and numpy bilinear disagree")
    ira, ra = _query_rates(dem, n_queries, half_beamwidth_rad, half_window_rad, repeats, 1500.0)
    ira5, ra5 = _query_rates(dem, n_queries, half_beamwidth_rad, half_window_rad, repeats, 5000.0)
    from . import refine

    lat_c, lon_c = dem.center_rad
    dn_m, de_m = dem.extent_m
    half_lat = min(6000.0 / dn_m, 0.5) * (dem.bounds[1] - dem.bounds[0])
    half_lon = min(6000.0 / de_m, 0.5) * (dem.bounds[3] - dem.bounds[2])
    fine = refine.refine(dem, 10.0, seed=0, region=(lat_c - half_lat, lat_c + half_lat, lon_c - half_lon,
                                                    lon_c + half_lon))
    n_fine = max(n_queries // 4, 100)
    ira10, ra10 = _query_rates(fine, n_fine, half_beamwidth_rad, half_window_rad, repeats, 1500.0)
    world = refine.refine(dem, 30.0, seed=0)
    ira_world, us50, overhead = _ira_world_figures(world, n_fine, half_window_rad, repeats)
    return {
        "terrain_dem": dem.name,
        "bilinear_lookups_per_s": float(nb),
        "numpy_bilinear_lookups_per_s": float(npb),
        "ira_queries_per_s": float(ira),
        "radar_altimeter_queries_per_s": float(ra),
        "ira_queries_per_s_5km_agl": float(ira5),
        "radar_altimeter_queries_per_s_5km_agl": float(ra5),
        "ira_queries_per_s_refined_10m": float(ira10),
        "radar_altimeter_queries_per_s_refined_10m": float(ra10),
        "refined_10m_posts": int(fine.heights_m.size),
        "ira_queries_per_s_default_world": float(ira_world),
        "ira_50_queries_us_default_world": float(us50),
        "ira_call_overhead_us": float(overhead),
        "refined_30m_posts": int(world.heights_m.size),
    }


if __name__ == "__main__":
    print(json.dumps(benchmark(), indent=2))
