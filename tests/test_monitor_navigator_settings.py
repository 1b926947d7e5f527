"""The scenario build gives the DEM integrity monitor the navigator's error time constants (its GNSS-denied
path models the navigator's error as first-order Gauss-Markov in time, navigators.integrity.dem_monitor):
from the navigator's declared capabilities, unless the monitor's table gives them; bad values named."""

from __future__ import annotations

import pytest
from trn_env.navigators import registry
from trn_env.navigators.integrity import dem_monitor as dm

from trn_env.scenario.build import monitor_settings
from trn_env.scenario.loading import read_scenario_file, validate

TAU_KEYS = {"navigator_error_time_constant_s": "error_time_constant_s",
            "navigator_height_time_constant_s": "height_time_constant_s"}


def _scenario(navigator: str, monitor_extra: dict | None = None):
    data, _ = read_scenario_file("tests/scenarios/integrity_short.toml")
    data["navigator"] = {"name": navigator, "settings": {}}
    data["sensors"].update(air_data={}, heading={})      # acq_track's aiding
    data["monitors"]["dem_integrity"].update(monitor_extra or {})
    return validate(data, source="test")


@pytest.mark.parametrize("navigator", ["ins_tercom", "pmf", "pf", "rbpf", "acq_track", "ins"])
def test_monitor_gets_the_navigators_declared_time_constants(navigator):
    caps = registry.capabilities(navigator)
    got = monitor_settings(_scenario(navigator), "dem_integrity")
    for key, cap_key in TAU_KEYS.items():
        declared = getattr(caps, cap_key)
        if declared > 0:
            assert got[key] == pytest.approx(declared)
        else:
            assert key not in got          # the monitor keeps its default (error constant over the window)


def test_terrain_navigators_declare_time_constants_and_the_ins_does_not():
    for name in ("ins_tercom", "pmf", "pf", "rbpf", "acq_track"):
        caps = registry.capabilities(name)
        assert caps.error_time_constant_s > 0.0 and caps.height_time_constant_s > 0.0, name
    assert registry.capabilities("ins").error_time_constant_s == 0.0


def test_monitor_table_wins_over_the_navigator():
    got = monitor_settings(_scenario("pmf", {"navigator_error_time_constant_s": 7.0}), "dem_integrity")
    assert got["navigator_error_time_constant_s"] == 7.0


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), "x"])
@pytest.mark.parametrize("name", list(TAU_KEYS))
def test_bad_time_constant_named(name, bad):
    from trn_env import terrain
    with pytest.raises(ValueError, match=name):
        dm.DemIntegrityMonitor(dem=terrain.load("synthetic:rolling"), **{name: bad})
