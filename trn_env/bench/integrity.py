"""The DEM integrity monitor's cost beside the closed loop it runs in (`trn-env bench`).

The default scenario with a radar altimeter fitted and `[monitors.dem_integrity]` (seed 003's monitor, the
beam model on: one exact cone query on the map per epoch) flies a warm-up, then a timed stretch, pipelined as
`trn-env fly` runs it and inline in one process. Figures: the monitor's wall time per navigator update and per
loop update, and their ratio `integrity_monitor_time_fraction` (target < 0.01), each from the same run.

The pmf's and pf's protection level (`weighted_mass_radius`) on a point-mass filter's 200 x 200 grid (40,000
cells, Gaussian weights about an off-grid mean): the kernel's time per call beside numpy's own sort-based
radius of the same cells (argsort, cumulative sum, search), `integrity_mass_radius_40k_ms` and its ratio.
"""

from __future__ import annotations

import time

WARM_S = 45.0


def _loop_figures(sim_s: float, pipeline: bool, segments: int = 3) -> dict:
    from trn_env.scenario.overrides import load_scenario_with
    from trn_env.sim.closed_loop import ClosedLoop

    sc = load_scenario_with("default", [("sensors.radar_altimeter", {}), ("monitors", {"dem_integrity": {}})],
                            duration_s=WARM_S + sim_s + 20.0)
    fractions, walls, mons, navs, updates = [], 0.0, 0.0, 0.0, 0
    with ClosedLoop(sc, log_sensors=False, pipeline=pipeline) as loop:
        while loop.t_s < WARM_S - 1e-9:
            loop.tick()
        loop.sync()
        for k in range(segments):       # the median segment: a slow spell of the machine spoils one
            st0 = dict(loop.stage_s)
            n0 = loop.n_ticks
            t0 = time.perf_counter()
            while loop.termination is None and loop.t_s < WARM_S + (k + 1) * sim_s / segments - 1e-9:
                loop.tick()
            loop.sync()
            wall = time.perf_counter() - t0
            mon = loop.stage_s["monitors"] - st0["monitors"]
            fractions.append(mon / wall)
            walls += wall
            mons += mon
            navs += loop.stage_s["navigator"] - st0["navigator"]
            updates += loop.n_ticks - n0
    return {"loop_ms_per_update": 1e3 * walls / updates, "monitor_ms_per_update": 1e3 * mons / updates,
            "navigator_ms_per_update": 1e3 * navs / updates,
            "fraction": float(sorted(fractions)[len(fractions) // 2]),
            "fractions": [round(f, 5) for f in fractions], "updates": updates, "pipelined": loop.pipelined}


def _best_ms(fn, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return 1e3 * best


def mass_radius_figures(quick: bool = False, risk: float = 1e-3) -> dict:
    """The HPL mass radius of 40,000 grid cells: the numba kernel and numpy's sort-based radius (ms per call,
    best of the repeats), which must agree."""
    import numpy as np

    from trn_env.navigators.integrity.protection_level import weighted_mass_radius
    g = (np.arange(200) - 99.5) * 5.0                      # 5 m cells
    dn, de = (a.ravel().copy() for a in np.meshgrid(g, g, indexing="ij"))
    rng = np.random.default_rng(0)
    w = np.exp(-0.5 * (((dn - 7.3) / 60.0) ** 2 + ((de + 2.1) / 90.0) ** 2)) * rng.uniform(0.5, 1.5, dn.size)

    def numpy_radius() -> float:
        tot = w.sum()
        d = np.hypot(dn - (w @ dn) / tot, de - (w @ de) / tot)
        order = np.argsort(d)
        k = int(np.searchsorted(np.cumsum(w[order]), (1.0 - risk) * tot * (1.0 - 1e-12)))
        return float(d[order[min(k, d.size - 1)]])

    kernel = float(weighted_mass_radius(dn, de, w, risk))
    reference = numpy_radius()
    if abs(kernel - reference) > 1e-9:
        raise RuntimeError(f"weighted_mass_radius {kernel} m differs from numpy's {reference} m")
    repeats = 20 if quick else 100
    kernel_ms = _best_ms(lambda: weighted_mass_radius(dn, de, w, risk), repeats)
    numpy_ms = _best_ms(numpy_radius, repeats)
    return {"integrity_mass_radius_40k_ms": kernel_ms, "integrity_mass_radius_numpy_sort_40k_ms": numpy_ms,
            "integrity_mass_radius_ratio_to_numpy_sort": kernel_ms / numpy_ms}


def benchmark(quick: bool = False) -> dict:
    """integrity_monitor_time_fraction: the monitor's time / the closed loop's wall time (pipelined, as
    `trn-env fly`; the median of three segments), beside the loop's and the navigator's ms per update;
    the same inline (one process)."""
    sim_s = 40.0 if quick else 120.0
    piped = _loop_figures(sim_s, True)
    inline = _loop_figures(sim_s, False)
    return {
        "integrity_monitor_time_fraction": piped["fraction"],
        "integrity_monitor_time_fraction_by_segment": piped["fractions"],
        "integrity_monitor_ms_per_update": piped["monitor_ms_per_update"],
        "integrity_loop_ms_per_update": piped["loop_ms_per_update"],
        "integrity_navigator_ms_per_update": piped["navigator_ms_per_update"],
        "integrity_loop_pipelined": piped["pipelined"],
        "integrity_monitor_time_fraction_inline": inline["fraction"],
        "integrity_monitor_ms_per_update_inline": inline["monitor_ms_per_update"],
        "integrity_loop_ms_per_update_inline": inline["loop_ms_per_update"],
        "integrity_updates_timed": piped["updates"],
        **mass_radius_figures(quick),
    }


if __name__ == "__main__":
    import json

    print(json.dumps(benchmark(quick=True), indent=1))
