"""Map faults (terrain.map_error.MapFault) against direct computations, the time-dependent map swap, and the
scenario's validation of faults and monitors (every problem names its field before the flight)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from trn_env.terrain import queries
from trn_env.terrain.dem import Dem
from trn_env.terrain.geodesy import euler_to_C_bn
from trn_env.terrain.map_error import MapFault, apply_fault, fault_schedule, set_heights

from trn_env import terrain
from trn_env.scenario.loading import ScenarioError, read_scenario_file, validate

CENTER = (36.55, -84.25)


@pytest.fixture(scope="module")
def dem():
    return terrain.load("jacksboro")


def _inside(dem: Dem, fault: MapFault) -> np.ndarray:
    """Posts inside the fault's rectangle, from its definition (north/east offsets at the centre)."""
    lat_c, lon_c = map(math.radians, (fault.center_lat_deg, fault.center_lon_deg))
    north, east = dem.latlon_to_offset(lat_c, lon_c, dem.lat_rad[:, None], dem.lon_rad[None, :])
    return (np.abs(north) <= fault.size_n_m / 2) & (np.abs(east) <= fault.size_e_m / 2)


def test_bias_patch_only_inside_its_region(dem):
    f = MapFault("bias", *CENTER, 3000.0, 2000.0, bias_m=40.0)
    h = dem.heights_m.copy()
    apply_fault(h, dem, f)
    d = h - dem.heights_m
    inside = _inside(dem, f)
    np.testing.assert_allclose(d[inside], 40.0)
    assert np.count_nonzero(d[~inside]) <= 2 * (inside.shape[0] + inside.shape[1])   # edge posts at most
    dn, de = dem.spacing_m
    assert np.count_nonzero(d) == pytest.approx(3000.0 * 2000.0 / (dn * de), rel=0.25)


def test_ramp_spike_shift_stale(dem):
    ramp = MapFault("ramp", *CENTER, 2000.0, 4000.0, bias_m=50.0, direction_deg=90.0)   # rising eastward
    h = dem.heights_m.copy()
    apply_fault(h, dem, ramp)
    d = h - dem.heights_m
    rows = np.flatnonzero(d.any(axis=1))
    prof = d[rows[len(rows) // 2]]
    prof = prof[prof != 0]
    assert np.all(np.diff(prof) > 0) and prof.max() <= 50.0 + 1e-9 and prof.max() > 45.0

    spike = MapFault("spike", *CENTER, 600.0, 600.0, bias_m=120.0)
    h = dem.heights_m.copy()
    apply_fault(h, dem, spike)
    d = h - dem.heights_m
    assert 80.0 < d.max() <= 120.0 and d.min() >= 0.0

    shift = MapFault("shift", *CENTER, 2000.0, 2000.0, shift_n_m=300.0)
    h = dem.heights_m.copy()
    apply_fault(h, dem, shift)
    inside = _inside(dem, shift)
    i, j = np.argwhere(inside)[len(np.argwhere(inside)) // 2]
    lat, lon = dem.offset_to_latlon(dem.lat_rad[i], dem.lon_rad[j], -300.0, 0.0)
    assert h[i, j] == pytest.approx(float(dem.height(lat, lon)), abs=1e-6)

    other = terrain.load("synthetic:rolling")
    src = Dem(other.heights_m, dem.lat0_rad, dem.lon0_rad, other.dlat_rad, other.dlon_rad, "other")
    stale = MapFault("stale", *CENTER, 1500.0, 1500.0, source_dem=src)
    h = dem.heights_m.copy()
    apply_fault(h, dem, stale)
    inside = _inside(dem, stale)
    i, j = np.argwhere(inside)[0]
    assert h[i, j] == pytest.approx(float(src.height(dem.lat_rad[i], dem.lon_rad[j])), abs=1e-6)


def test_time_dependent_map_swap_rebuilds_the_query_tables(dem):
    """The schedule's heights swapped into a Dem (set_heights): lookups and the exact radar-altimeter query
    see the fault afterwards, equal to a fresh Dem built with those heights."""
    base = dem.with_heights(dem.heights_m.copy())
    faults = [MapFault("bias", *CENTER, 3000.0, 3000.0, bias_m=80.0, start_s=50.0)]
    sched = fault_schedule(base, faults)
    assert [t for t, _ in sched] == [-math.inf, 50.0]
    lat, lon = np.radians([CENTER[0]]), np.radians([CENTER[1]])
    h = np.array([float(base.height(lat[0], lon[0])) + 800.0])
    C = euler_to_C_bn(0.0, 0.0, 0.0)
    r0 = queries.radar_altimeter_return(base, lat, lon, h, C, math.radians(8.5), 5000.0).range_m[0]
    set_heights(base, sched[1][1])
    assert not base.heights_m.flags.writeable     # read-only as every Dem's: the kernels' one array type
    r1 = queries.radar_altimeter_return(base, lat, lon, h, C, math.radians(8.5), 5000.0).range_m[0]
    fresh = dem.with_heights(sched[1][1].copy())
    r_fresh = queries.radar_altimeter_return(fresh, lat, lon, h, C, math.radians(8.5), 5000.0).range_m[0]
    assert r1 == pytest.approx(r_fresh, abs=1e-9)
    # raising the terrain by 80 m shortens every range by at most 80 m (the cone's footprint shrinks too)
    assert 70.0 < r0 - r1 <= 80.0 + 1e-6


def test_fault_region_checks(dem):
    with pytest.raises(ValueError, match="size_n_m"):
        MapFault("bias", *CENTER, -10.0, 100.0)
    with pytest.raises(ValueError, match="center_lat_deg"):
        apply_fault(dem.heights_m.copy(), dem, MapFault("bias", 40.0, -84.25, 1000.0, 1000.0))
    with pytest.raises(ValueError, match="start_s"):
        MapFault("bias", *CENTER, 100.0, 100.0, start_s=-1.0)


def _scenario_data(**changes):
    data, _ = read_scenario_file("tests/scenarios/integrity_short.toml")
    for path, value in changes.items():
        node = data
        keys = path.split(".")
        for k in keys[:-1]:
            node = node[int(k)] if isinstance(node, list) else node.setdefault(k, {})
        if value is None:
            node.pop(keys[-1])
        else:
            node[keys[-1]] = value
    return data


def _problems(data) -> list[str]:
    with pytest.raises(ScenarioError) as err:
        validate(data, source="test")
    return err.value.problems


def test_scenario_with_faults_and_monitor_validates():
    sc = validate(_scenario_data(), source="test")
    assert sc.sections.monitor("dem_integrity").settings["n_window"] == 50


@pytest.mark.parametrize("changes, field", [
    ({"terrain.map.faults.0.center_lat_deg": 37.5}, "terrain.map.faults[0]: center_lat_deg"),
    ({"terrain.map.faults.0.size_n_m": -100.0}, "terrain.map.faults[0].size_n_m"),
    ({"terrain.map.faults.0.start_s": 500.0}, "terrain.map.faults[0].start_s"),
    ({"monitors.dem_integrity.n_window": 1}, "monitors.dem_integrity.n_window"),
    ({"monitors.dem_integrity.sigma_m": -2.0}, "monitors.dem_integrity.sigma_m"),
    ({"monitors.dem_integrity.threshold": 0.0}, "monitors.dem_integrity.threshold"),
    ({"monitors.dem_integrity.threshold": None,
      "monitors.dem_integrity.false_alarm_probability": 1.5},
     "monitors.dem_integrity.false_alarm_probability"),
    ({"sensors.radar_altimeter": None}, "sensors.radar_altimeter: monitor 'dem_integrity' needs this sensor"),
])
def test_bad_scenario_names_the_field(changes, field):
    problems = _problems(_scenario_data(**changes))
    assert any(p.startswith(field) for p in problems), problems
