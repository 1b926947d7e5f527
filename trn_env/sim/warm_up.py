"""Compile (or load from numba's cache) the kernels a scenario uses before its flight starts.

The numba kernels compile on their first call and are cached beside the package, so the first run after
an install spends its first seconds compiling; later runs load the cache in well under a second. Flown
as it is, that compile sits inside the flight: the progress bar stalls at the first simulated second and
the real-time factor counts it. `warm_up` flies a copy of the scenario for three navigator updates first
(one process, the same terrain objects, its own aircraft trim and random streams): GNSS (if fitted) in the
first update, none after it, and the navigator's declared warm-up settings (capabilities.warm_up_settings:
e.g. a TERCOM fix due at the third update). Every kernel the
flight will call - sensors, terrain queries, mechanisation, covariance propagation on the GNSS-aided and
the fused GNSS-denied paths, the fix's correlation - is compiled or loaded then, and only those: a kernel
the scenario does not use is never compiled. The flight itself is untouched (its objects and random
streams are separate), so its results are the same bit for bit.

Compilation is single-threaded, and a 2-core machine has a second core: while this process flies the
warm-up (whose flight core, sensors and terrain queries come first), a forked child runs the scenario's
navigator on synthetic frames of the same array types (level flight at the start, IMU, baro, IRA or
radar altimeter, GNSS as fitted), compiling the navigator's kernels into numba's cache; by the time the
warm-up flight reaches its navigator they load from there. The child's work is best effort (anything it
cannot do is compiled by the flight as before) and it never touches the flight's objects.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
import time

import numpy as np

from trn_env.scenario.loading import Scenario


def warm_up_scenario(scenario: Scenario) -> Scenario:
    """The three-update copy of `scenario` that warm_up flies (module docstring)."""
    from trn_env.navigators import registry
    from trn_env.scenario.sections import GnssSection, Outage
    sc = scenario.sections
    rate = float(sc.navigator.rate_hz)
    navigator = sc.navigator
    warm = registry.capabilities(navigator.name).warm_up_settings
    if warm is not None:                        # e.g. a TERCOM fix due at the third update
        navigator = navigator.with_settings(**warm(rate))
    sections = dataclasses.replace(sc, duration_s=3.0 / rate, navigator=navigator,
                                   gnss=GnssSection(outages=(Outage(start_s=1.5 / rate),)))
    return Scenario(name=f"{scenario.name}[warm-up]", source=scenario.source, sections=sections,
                    description=scenario.description, seed=scenario.seed, duration_s=sections.duration_s,
                    extras=scenario.extras)


def warm_navigator(scenario: Scenario, map_dem) -> None:
    """Run warm_up_scenario(scenario)'s navigator over three synthetic 1 s frames (its kernels compile)."""
    from trn_env.navigators.frames import (
        BaroFrame,
        GnssFrame,
        ImuFrame,
        IraFrame,
        RadarAltimeterFrame,
        SensorFrames,
    )
    from trn_env.navigators.protocol import Estimate
    from trn_env.scenario import build
    from trn_env.terrain.geodesy import meridian_radius_m
    sc = warm_up_scenario(scenario)
    nav = build.build_navigator(sc, map_dem, np.random.default_rng(0))
    init = sc.initial
    lat = math.radians(init.lat_deg)
    lon = math.radians(init.lon_deg)
    ground = build.map_height(map_dem, lat, lon)
    h = float(init.h_msl_m if init.h_msl_m is not None else
              (ground if math.isfinite(ground) else 0.0) + (1000.0 if init.h_agl_m is None else init.h_agl_m))
    v = float(init.tas_mps)
    cov = np.diag([30.0, 30.0, 15.0, 0.1, 0.1, 0.1, 5e-5, 5e-5, 1e-3]) ** 2
    nav.reset(Estimate(0.0, lat, lon, h, np.array([v, 0.0, 0.0]), 0.0, 0.0, 0.0, cov))
    sensors = sc.sensors.fitted
    r_n = meridian_radius_m(lat) + h
    for k in range(3):
        t = k + np.arange(1, 101) * 0.01
        n = t.shape[0]
        ones = np.ones(n, np.bool_)
        f_b = np.zeros((n, 3))
        f_b[:, 2] = -9.80665
        fr = SensorFrames(float(k), float(k + 1), imu=ImuFrame(t, f_b, np.zeros((n, 3)), ones))
        agl = h - ground if math.isfinite(ground) else 1000.0
        if "baro" in sensors:
            tb = t[::4].copy()
            fr.baro = BaroFrame(tb, np.full(tb.shape[0], h), np.ones(tb.shape[0], np.bool_))
        if "ira" in sensors:
            ti = t[1::2].copy()
            fr.ira = IraFrame(ti, np.full(ti.shape[0], agl / math.cos(0.1)), np.full(ti.shape[0], 0.1),
                              np.ones(ti.shape[0], np.bool_))
        if "radar_altimeter" in sensors:
            ti = t[4::5].copy()
            fr.radar_altimeter = RadarAltimeterFrame(ti, np.full(ti.shape[0], agl),
                                                     np.ones(ti.shape[0], np.bool_))
        if "gnss" in sensors and k == 0:
            tg = t[-1:].copy()
            fr.gnss = GnssFrame(tg, np.array([lat + v * tg[0] / r_n]), np.array([lon]), np.array([h]),
                                np.array([[v, 0.0, 0.0]]), np.ones(1, np.bool_))
        nav.update(fr)


def warm_up(scenario: Scenario, dems, parallel: bool = True) -> float:
    """Fly warm_up_scenario(scenario) over `dems` (world, map) in this process, with the navigator's kernels
    compiled beside it in a forked child (`parallel`, Linux); returns the wall seconds."""
    from trn_env.sim.closed_loop import ClosedLoop
    from trn_env.sim.nav_stage import fork_available
    t0 = time.perf_counter()
    child = 0
    if parallel and fork_available():
        sys.stdout.flush()
        sys.stderr.flush()
        child = os.fork()
        if child == 0:                      # the child: compile, then leave without any cleanup of ours
            code = 0
            try:
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, 1)
                os.dup2(devnull, 2)
                warm_navigator(scenario, dems[1])
            except BaseException:           # best effort: the flight compiles what this did not
                code = 1
            os._exit(code)
    try:
        loop = ClosedLoop(warm_up_scenario(scenario), dems=dems, log_sensors=False, pipeline=False)
        try:
            loop.run()
        finally:
            loop.close()
    finally:
        if child:
            os.waitpid(child, 0)
    return time.perf_counter() - t0
