"""The loop's log and monitors get the sensor frames as measured, whatever a navigator or a monitor changes
in them in place (trn_env.sim.nav_stage: each reader gets arrays of its own while others read the frames).

Before, a navigator correcting its barometer in place (`frames.baro.h_baro_m += bias`) wrote the correction
into the recorded log (a replay then applied it twice) and into what the monitors saw."""

from __future__ import annotations

import numpy as np
from trn_env.navigators import registry
from trn_env.navigators.builtin import ins as _ins

SEEN: dict[str, list[np.ndarray]] = {"navigator": [], "monitor": []}


class BaroCorrectingIns:
    """The built-in INS, adding 100 m to the barometer's heights in the frames it is given."""

    name = "baro_correcting_ins"

    def __init__(self, **settings):
        self.nav = _ins(**settings)

    def reset(self, initial):
        self.nav.reset(initial)

    def update(self, frames):
        if frames.baro is not None:
            SEEN["navigator"].append(frames.baro.h_baro_m.copy())
            frames.baro.h_baro_m += 100.0
        return self.nav.update(frames)


class BaroCorrectingMonitor:
    """The DEM monitor, adding 50 m to the barometer's heights in the frames it is given."""

    def __init__(self, **settings):
        self.inner = registry.create_monitor("dem_integrity", **settings)

    def reset(self):
        self.inner.reset()

    def update(self, frames, estimate):
        if frames.baro is not None:
            SEEN["monitor"].append(frames.baro.h_baro_m.copy())
            frames.baro.h_baro_m += 50.0
        return self.inner.update(frames, estimate)


def test_log_and_monitors_get_the_frames_as_measured():
    from trn_env.scenario.overrides import load_scenario_with
    from trn_env.sim.closed_loop import ClosedLoop

    for seen in SEEN.values():
        seen.clear()
    sc = load_scenario_with("default", [("monitors", {f"{__name__}:BaroCorrectingMonitor": {}})], seed=3,
                            duration_s=6.0, navigator=f"{__name__}:BaroCorrectingIns")
    loop = ClosedLoop(sc, log_sensors=True, pipeline=False)
    try:
        while loop.termination is None:
            loop.tick()
    finally:
        loop.close()
    logged = [fr.baro.h_baro_m for fr in loop.log.frames if fr.baro is not None]
    assert len(logged) == len(SEEN["navigator"]) == len(SEEN["monitor"]) >= 5
    for log_h, nav_h, mon_h in zip(logged, SEEN["navigator"], SEEN["monitor"], strict=True):
        assert np.array_equal(log_h, nav_h) and np.array_equal(log_h, mon_h)
