"""The validated scenario as typed sections (trn_env/scenario/sections.py): the round trip to the dict for
every bundled scenario, typed access, frozen sections, problems by field path, and no scenario-dict lookups
left in the components outside trn_env/scenario/."""

from __future__ import annotations

import copy
import dataclasses
import json
import pickle
import re
from pathlib import Path

import pytest

from trn_env.scenario import builtin_names, load_scenario, read_scenario_file, validate
from trn_env.scenario.loading import Scenario, ScenarioError, _fill_defaults
from trn_env.scenario.sections import (
    NavigatorSection,
    ScenarioSections,
    SectionsError,
    Table,
    from_dict,
)

ROOT = Path(__file__).resolve().parents[1]
FILES = [*builtin_names(), *sorted(str(p) for p in (ROOT / "tests" / "scenarios").glob("*.toml"))]


def _canonical(d: dict) -> str:
    """The campaign's scenario-hash text (trn_env.campaign.runs.scenario_hash): key order free, int and float
    told apart."""
    return json.dumps(d, sort_keys=True, default=str, separators=(",", ":"))


def _kitchen_sink() -> dict:
    """The default scenario with every optional table the schema knows filled in."""
    data, _ = read_scenario_file("default")
    data = copy.deepcopy(data)
    data["aircraft"] = {"fuel_kg": 900.0, "constant_fuel": True, "settings": {}}
    data["atmosphere"] = {"delta_T_K": 15.0, "p_sl_pa": 101000.0}
    data["wind"]["gusts"] = [{"start_time_s": 30.0, "magnitude_mps": 5.0, "direction": [1.0, 0.0, 0.0],
                              "startup_s": 1.0, "steady_s": 2.0, "end_s": 1.0, "frame": "ned"}]
    data["wind"]["turbulence"] = {"model": "milspec", "severity": 3, "windspeed_at_20ft_mps": 4.0}
    data["terrain"]["map"]["error_model"] = {"preset": "dted1", "bias_fraction": 0.3}
    data["terrain"]["map"]["faults"] = [{"kind": "bias", "center_lat_deg": 36.52, "center_lon_deg": -84.36,
                                         "size_n_m": 2000.0, "size_e_m": 2000.0, "bias_m": 40.0,
                                         "start_s": 20.0}]
    data["sensors"]["radar_altimeter"] = {"lever_arm_b_m": [0.0, 0.0, 1.5]}
    data["sensors"]["gnss"] = {"outages": [[100.0, 120.0]]}
    data["monitors"] = {"dem_integrity": {"n_window": 40}}
    data["limits"] = {"max_horizontal_sigma_m": 3000.0, "max_horizontal_error_m": 800.0}
    data["gnss"]["outages"] = [{"start_s": 10.0, "end_s": 50.0}, {"start_s": 60.0}]
    data["initial_errors"] = {"position_ned_m": [10, 10, 5]}
    data["route"]["settings"] = {}
    return data


@pytest.mark.parametrize("name", FILES, ids=lambda f: Path(f).stem)
def test_round_trip_of_every_bundled_scenario(name):
    """to_dict(from_dict(d)) == d for the validated dict of every built-in and regression scenario, with the
    same key set and number types (the same canonical JSON, hence the same campaign scenario hash)."""
    raw, _ = read_scenario_file(name)
    sc = load_scenario(name, check_components=False)
    expected = _fill_defaults(raw)
    assert sc.to_dict() == expected
    assert _canonical(sc.to_dict()) == _canonical(expected)
    again = from_dict(sc.to_dict())
    assert again == sc.sections
    assert _canonical(again.to_dict()) == _canonical(expected)


def test_round_trip_of_every_optional_table():
    data = _kitchen_sink()
    sc = validate(copy.deepcopy(data), source="test", check_components=False)
    assert _canonical(sc.to_dict()) == _canonical(_fill_defaults(data))
    assert sc.atmosphere.delta_T_K == 15.0 and sc.wind.gusts[0].direction == (1.0, 0.0, 0.0)
    assert sc.wind.turbulence.severity == 3
    assert sc.terrain.map.faults[0].kind == "bias" and sc.terrain.map.faults[0].start_s == 20.0
    assert sc.terrain.map.error_model.preset == "dted1" and sc.terrain.map.error_model.bias_fraction == 0.3
    assert sc.terrain.map.error_model.random_sigma_m is None
    assert sc.gnss.outages[0].end_s == 50.0 and sc.gnss.outages[1].end_s is None
    assert sc.limits.max_horizontal_error_m == 800.0 and sc.aircraft.fuel_kg == 900.0
    assert sc.sections.monitor("dem_integrity").settings["n_window"] == 40
    assert sc.initial_errors.position_ned_m == (10, 10, 5)


def test_an_empty_error_model_is_no_error_model():
    """`error_model = {}` leaves the map as published, as the table did before the sections (no draw)."""
    from trn_env.scenario.sections import MapErrorModel
    assert not MapErrorModel() and MapErrorModel(bias_m=0.0)
    data = load_scenario("default", check_components=False).to_dict()
    data["terrain"]["map"]["error_model"] = {}
    sc = validate(data, source="test", check_components=False)
    assert sc.to_dict()["terrain"]["map"]["error_model"] == {} and not sc.terrain.map.error_model


def test_sections_are_typed_and_frozen():
    from trn_env.navigators import registry

    from trn_env.sensors.imu import ImuConfig
    from trn_env.sensors.ira import IraConfig
    sc = load_scenario("default", check_components=False)
    assert isinstance(sc.sections, ScenarioSections)
    assert isinstance(sc.sensors.imu, ImuConfig) and isinstance(sc.sensors.ira, IraConfig)
    assert sc.sensors.radar_altimeter is None and "radar_altimeter" not in sc.sensors.fitted
    assert isinstance(sc.navigator.settings, registry.settings_class("ins_tercom"))
    assert sc.navigator.settings.remove_bias is True            # the file's value, typed
    assert sc.navigator.settings.fix_period_s == 40.0           # the Settings class's default
    assert sc.route.waypoints[0].altitude == ("agl", 1500.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        sc.route.tas_mps = 10.0
    with pytest.raises(TypeError):
        sc.navigator.table["remove_bias"] = False
    assert isinstance(sc.aircraft.settings, Table)
    # the Settings objects are what the sensors get: equal to the configs built from the tables
    from trn_env.scenario.build import sensor_configs
    from trn_env.sensors.suite import _make_config
    assert sensor_configs(sc) == {n: _make_config(n, dict(t)) for n, t in sc.sensors.tables.items()}


def test_scenario_travels_to_worker_processes():
    """Campaign and pipelined workers get the scenario pickled (Ray: cloudpickle): the sections survive."""
    sc = load_scenario("default", check_components=False)
    again = pickle.loads(pickle.dumps(sc.sections))
    assert again == sc.sections and again.to_dict() == sc.to_dict()


def test_building_reports_every_problem_by_field_path():
    data = load_scenario("default", check_components=False).to_dict()
    data["navigator"]["settings"] = {"fix_perod_s": 30.0, "half_cells": 0}
    data["sensors"]["baro"] = {"bias_m": -3.0}
    data["route"]["waypoints"][1]["alt"] = 3.0
    with pytest.raises(SectionsError) as exc:
        from_dict(data)
    paths = [p.split(": ", 1)[0] for p in exc.value.problems]
    assert "navigator.settings.fix_perod_s" in paths and "navigator.settings.half_cells" in paths
    assert "sensors.baro.bias_m" in paths and "route.waypoints[1].alt" in paths
    # the loader reports the same fields (from the schema first, each once)
    with pytest.raises(ScenarioError) as exc:
        validate(data, source="test", check_components=False)
    got = [p.split(": ", 1)[0] for p in exc.value.problems]
    for path in ("navigator.settings.fix_perod_s", "navigator.settings.half_cells", "sensors.baro.bias_m",
                 "route.waypoints[1].alt"):
        assert got.count(path) == 1, (path, exc.value.problems)


def test_component_checks_run_beside_a_refused_setting():
    """A navigator setting refused while the sections are built does not hide the other components'
    problems: the start the aircraft cannot trim is reported with it."""
    data = load_scenario("default", check_components=False).to_dict()
    data["navigator"]["settings"] = {"half_cells": 0}
    data["initial"]["tas_mps"] = 30.0
    with pytest.raises(ScenarioError) as exc:
        validate(data, source="test")
    got = [p.split(": ", 1)[0] for p in exc.value.problems]
    assert "navigator.settings.half_cells" in got and "initial" in got, exc.value.problems


def test_edits_of_a_validated_scenario():
    sc = load_scenario("default", check_components=False)
    nav = sc.navigator.with_settings(fix_period_s=20.0)
    assert nav.settings.fix_period_s == 20.0 and nav.table.to_dict() == {"remove_bias": True,
                                                                         "fix_period_s": 20.0}
    assert sc.navigator.with_name("pmf").table.to_dict() == {}
    with pytest.raises(SectionsError, match="navigator.settings.fix_period_s"):
        sc.navigator.with_settings(fix_period_s=-1.0)
    with pytest.raises(SectionsError, match="navigator.settings.no_such"):
        NavigatorSection.of("ins_tercom", {"no_such": 1})
    assert NavigatorSection.of("ins_tercom", {"no_such": 1}, strict=False).settings is None
    faster = sc.with_fields({"guidance.rate_hz": 20.0})
    assert faster.guidance.rate_hz == 20.0 and sc.guidance.rate_hz == 10.0
    with pytest.raises(ScenarioError, match="guidance.rate_hz"):
        sc.with_fields({"guidance.rate_hz": 3.0})          # not a whole number of JSBSim steps
    again = Scenario.from_dict(sc.to_dict(), seed=7)
    assert again.seed == 7 and again.sections == sc.sections


# ---------------------------------------------------------------------------------- no dict lookups

_SECTIONS = ("aircraft", "truth", "initial", "initial_errors", "route", "wind", "atmosphere", "terrain",
             "sensors", "gnss", "navigator", "monitors", "guidance", "limits", "waypoints", "world", "map",
             "settings", "outages", "layers", "turbulence", "gusts", "faults", "error_model", "refinement")
_NAMES = "|".join(_SECTIONS)
_KEY = rf"""\[\s*["'](?:{_NAMES})["']\s*\]"""
_GET = rf"""\.get\(\s*["'](?:{_NAMES})["']"""
# (1) the old attribute; (2) a lookup by a section's key chained into another lookup; (3) a section key on a
# variable named like the old scenario dict
_OTHER = r"(?<!meta)(?<!metadata)(?<!summary)(?<!row)"   # log metadata, summary.json and campaign rows
_PATTERNS = [re.compile(r"\b(?:scenario|sc|task|variant|rec)\.data\b|\.data\[\s*[\"']"),
             re.compile(rf"{_OTHER}(?:{_KEY}|{_GET}[^)]*\))\s*(?:\[|\.get\(|\.setdefault\(|\.pop\()"),
             re.compile(rf"\b(?:d|data|scenario_data)\s*(?:{_KEY}|{_GET})")]


def _dict_lookups(text: str) -> list[str]:
    return [line.strip() for line in text.splitlines()
            if not line.lstrip().startswith("#") and any(p.search(line) for p in _PATTERNS)]


def test_the_lookup_patterns_catch_the_old_style():
    old = '''
    rate = float(d["navigator"]["rate_hz"])
    wp = self.scenario.data["route"]["waypoints"][-1]
    src = sc.data.get("truth", {}).get("source", "jsbsim")
    settings = dict(data["navigator"].get("settings") or {})
    imu = imu_spec(d.get("sensors", {}).get("imu"))
    outages = list(d["gnss"]["outages"])
    '''
    assert len(_dict_lookups(old)) == 6
    assert _dict_lookups('summary["navigator"] = name\nrow["sensors"] = 3\nx = meta.get("navigator")\n'
                         'summary["monitors"][name] = 1\nm = meta["map"]["dem"]') == []


def test_no_scenario_dict_lookups_outside_the_scenario_stage():
    """Components read the typed sections: no `d["navigator"]["settings"]`-style lookup on a scenario dict
    in trn_env outside trn_env/scenario/ (where the dict lives until it is validated)."""
    offenders = []
    for path in sorted((ROOT / "trn_env").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith("trn_env/scenario/"):
            continue
        offenders += [f"{rel}: {line}" for line in _dict_lookups(path.read_text(encoding="utf-8"))]
    assert not offenders, "scenario dict lookups (read the typed sections instead):\n" + "\n".join(offenders)
