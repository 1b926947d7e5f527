"""The DEM integrity monitor and the navigator's integrity in closed loop
(tests/scenarios/integrity_short.toml: 100 s over a 60 m map bias patch that appears at 30 s): the alarm
comes after the aircraft reaches the patch and within 50 epochs of it, never before; no alarm without the
fault; the pipelined and inline loops agree bit for bit; the EKF's innovation keys are consistent;
summary.json carries the figures."""

from __future__ import annotations

import math

import numpy as np
import pytest
from trn_env.navigators.integrity.dem_monitor import replay_log
from trn_env.navigators.protocol import (
    EXTRA_INNOVATION,
    EXTRA_INNOVATION_COV,
    EXTRA_LOG_LIKELIHOOD,
    EXTRA_MEASUREMENT_TIME,
    EXTRA_NIS,
    EXTRA_NIS_DOF,
)
from trn_env.navigators.registry import create_monitor
from trn_env.terrain.geodesy import latlon_to_ned_offset

from trn_env.scenario.build import monitor_settings
from trn_env.scenario.loading import load_scenario, read_scenario_file, validate
from trn_env.sim.closed_loop import ClosedLoop

SCENARIO = "tests/scenarios/integrity_short.toml"


@pytest.fixture(scope="module")
def faulted():
    sc = load_scenario(SCENARIO)
    loop = ClosedLoop(sc, pipeline=True)
    res = loop.run()
    return sc, res


def _entry_time(sc, res) -> float:
    """First logged time the true position is inside the fault's rectangle (from the scenario's numbers)."""
    f = sc.terrain.map.faults[0].to_dict()
    a = res.arrays
    inside = []
    for lat, lon in zip(a["true_lat_rad"], a["true_lon_rad"], strict=True):
        lat_c, lon_c = math.radians(f["center_lat_deg"]), math.radians(f["center_lon_deg"])
        dn, de = latlon_to_ned_offset(lat_c, lon_c, 0.0, lat, lon)
        inside.append(abs(dn) <= f["size_n_m"] / 2 and abs(de) <= f["size_e_m"] / 2)
    inside = np.array(inside) & (a["t_s"] >= f["start_s"])
    assert inside.any()
    return float(a["t_s"][np.argmax(inside)])


def test_alarm_after_reaching_the_fault_and_within_50_epochs(faulted):
    sc, res = faulted
    mon = res.summary["monitors"]["dem_integrity"]
    t_entry = _entry_time(sc, res)
    assert mon["first_alarm_t_s"] is not None
    assert t_entry <= mon["first_alarm_t_s"] <= t_entry + 50.0
    assert mon["alarm_count"] >= 1 and mon["fraction_source_gnss"] == 1.0
    t = res.arrays["monitor_dem_integrity_t_s"]
    alarm = res.arrays["monitor_dem_integrity_alarm"]
    assert not alarm[t < t_entry].any()
    assert any(src == "dem_integrity" and "alarm" in msg for _, src, msg in res.events)
    assert any(src == "map" for _, src, _ in res.events)
    assert res.summary["map_faults"][0]["kind"] == "bias" and res.summary["map_faults"][0]["bias_m"] == 60.0
    assert 0.0 <= res.summary["fraction_healthy"] <= 1.0
    assert 0.0 <= res.summary["status_ok_fraction"] <= res.summary["fraction_healthy"]
    assert res.summary["status_ok_misleading_time_s"] >= 0.0


def test_no_alarm_without_the_fault_and_pipelined_equals_inline(faulted):
    data, _ = read_scenario_file(SCENARIO)
    data["terrain"]["map"].pop("faults")
    clean = ClosedLoop(validate(data, source="clean"), pipeline=True).run()
    assert clean.summary["monitors"]["dem_integrity"]["alarm_count"] == 0
    assert np.nanmax(clean.arrays["monitor_dem_integrity_statistic"]) < 96.0
    assert clean.summary["map_faults"] == []
    sc, res = faulted
    loop = ClosedLoop(sc, pipeline=False)
    inline = loop.run()
    for k, v in res.arrays.items():
        if k.startswith("monitor_"):
            assert np.array_equal(v, inline.arrays[k], equal_nan=True), k
    # the monitor on the run's log (as on a real flight's), with the map as it is after the fault appeared
    mon = create_monitor("dem_integrity", dem=loop.map_dem, **monitor_settings(sc, "dem_integrity"))
    replay = replay_log(mon, inline.arrays)
    after = replay["t_s"] >= sc.terrain.map.faults[0].start_s
    np.testing.assert_array_equal(replay["disparity_m"][after],
                                  inline.arrays["monitor_dem_integrity_disparity_m"][after])


def test_ekf_reports_its_innovation_under_the_protocol_keys():
    """After a TERCOM fix the EKF's Estimate.extra holds innovation, S, NIS = z' S^-1 z (2 dof), the Gaussian
    log-likelihood and the fix time (recomputed here from z and S)."""
    data, _ = read_scenario_file(SCENARIO)
    data["duration_s"] = 46.0
    data["gnss"] = {"outages": [{"start_s": 2.0}]}    # (with GNSS the EKF fuses it and makes no fixes)
    loop = ClosedLoop(validate(data, source="no gnss"), pipeline=False)
    while loop.termination is None:
        loop.tick()
    ex = loop.estimate.extra
    z, S = np.asarray(ex[EXTRA_INNOVATION]), np.asarray(ex[EXTRA_INNOVATION_COV])
    assert z.shape == (2,) and S.shape == (2, 2) and ex[EXTRA_NIS_DOF] == 2
    assert ex[EXTRA_NIS] == pytest.approx(float(z @ np.linalg.inv(S) @ z), rel=1e-9)
    ll = -0.5 * (ex[EXTRA_NIS] + math.log(np.linalg.det(2 * math.pi * S)))
    assert ex[EXTRA_LOG_LIKELIHOOD] == pytest.approx(ll, rel=1e-9)
    assert 39.0 <= ex[EXTRA_MEASUREMENT_TIME] <= 46.0
