"""The declarative settings system (navigators.core.settings) and what is generated from it: validation of
every problem at once by field path, the scenario schema's sections, the docs' tables; the registry's
declared capabilities; sensors a navigator or monitor requires refused before anything runs."""

from __future__ import annotations

import copy
import json
import math
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from trn_env.navigators import registry
from trn_env.navigators.core.capabilities import Capabilities
from trn_env.navigators.core.settings import (
    Settings,
    SettingsError,
    _coerce,
    json_schema,
    markdown_table,
    setting,
    settings_fields,
    table_rows,
)

from trn_env.scenario import build
from trn_env.scenario.loading import ScenarioError, load_scenario, validate
from trn_env.sensors.suite import SENSOR_MODELS

ROOT = Path(__file__).resolve().parents[1]
BUILTIN_NAVIGATORS = ("acq_track", "ins", "ins_tercom", "pf", "pmf", "rbpf")
BUILTIN_MONITORS = ("dem_integrity",)


@dataclass(frozen=True)
class Demo(Settings):
    """A settings class with one field of each kind."""

    count: int = setting(3, "a whole number", ge=1, le=10)
    gain: float = setting(0.5, "a ratio", "1", gt=0.0, lt=1.0)
    sigma_m: float = setting(2.0, "a sigma", "m", ge=0.0)
    step_m: float | str = setting("auto", "a number or auto", "m", gt=0.0, also=("auto",))
    mode: str = setting("a", "a choice", choices=("a", "b"))
    flag: bool = setting(True, "a switch")
    arm_m: tuple[float, ...] = setting((0.0, 0.0, 0.0), "a vector", "m", length=3)
    floor_m: float | None = setting(None, "optional", "m", gt=0.0)

    def check(self):
        return [("count", "must be even")] if self.count % 2 == 1 and self.mode == "b" else []


def all_settings_classes():
    out = {f"navigator {n}": registry.settings_class(n) for n in BUILTIN_NAVIGATORS}
    out.update({f"monitor {n}": registry.monitor_capabilities(n).settings for n in BUILTIN_MONITORS})
    out.update({f"sensor {n}": m.config_cls for n, m in SENSOR_MODELS.items()})
    return out


# ------------------------------------------------------------------------------------------ the helper

def test_every_problem_reported_at_once_by_field_path():
    with pytest.raises(SettingsError) as exc:
        Demo.from_mapping({"cuont": 2, "gain": 1.0, "sigma_m": -1, "arm_m": [0, "x", -1e400], "mode": "c",
                           "flag": "yes", "step_m": "fast"})
    paths = [p for p, _ in exc.value.problems]
    assert paths == ["cuont", "gain", "sigma_m", "step_m", "mode", "flag", "arm_m[1]", "arm_m[2]"], paths
    text = str(exc.value)
    assert "did you mean 'count'?" in text and "known: arm_m, count, flag" in text
    assert "gain: must be in (0, 1), got 1.0" in text
    assert "sigma_m: must be >= 0 m, got -1" in text
    assert isinstance(exc.value, ValueError)


def test_values_normalised_and_cross_checks_after_fields():
    s = Demo(count=4.0, gain=np.float32(0.25), arm_m=np.array([1, 2, 3]), flag=np.bool_(False), step_m=2)
    assert type(s.count) is int and s.count == 4
    assert type(s.gain) is float and s.arm_m == (1.0, 2.0, 3.0) and s.flag is False and s.step_m == 2.0
    with pytest.raises(SettingsError, match="count: must be even"):
        Demo(count=3, mode="b")
    for bad in (math.nan, math.inf, True, "3", 2.5):
        with pytest.raises(SettingsError, match="count"):
            Demo(count=bad)
    assert Demo(floor_m=None).floor_m is None
    with pytest.raises(SettingsError, match="floor_m: must be > 0 m"):
        Demo(floor_m=0.0)


def test_build_takes_an_instance_a_mapping_or_overrides():
    base = Demo(count=2)
    assert Demo.build(base, {"gain": 0.75}) == Demo(count=2, gain=0.75)
    assert Demo.build({"count": 5}) == Demo(count=5)
    assert Demo.build(None) == Demo()
    with pytest.raises(SettingsError, match="settings: must be a Demo"):
        Demo.build(42)


def test_jsonschema_agrees_with_the_validation_on_random_values():
    """Independent oracle: jsonschema's verdict on the generated schema equals the field validation's, value
    by value, for 400 random single-field assignments per built-in class (numbers around each bound, wrong
    types, strings, lists)."""
    rng = np.random.default_rng(5)
    for label, cls in list(all_settings_classes().items()) + [("demo", Demo)]:
        validator = jsonschema.Draft202012Validator(json_schema(cls))
        fields = settings_fields(cls)
        for _ in range(400):
            f = fields[rng.integers(len(fields))]
            spec = f.spec
            anchors = [b for b in (spec.ge, spec.gt, spec.le, spec.lt) if b is not None] or [0.0]
            pick = rng.integers(6)
            if pick == 0:
                value = float(rng.choice(anchors) + rng.choice([-1.0, -1e-3, 0.0, 1e-3, 1.0]))
            elif pick == 1:
                value = int(rng.choice(anchors)) + int(rng.integers(-2, 3))
            elif pick == 2:
                value = rng.choice(["auto", "x", *(spec.choices or ())]).item()
            elif pick == 3:
                value = bool(rng.integers(2))
            elif pick == 4 and f.default is not None:
                value = f.default
            else:
                value = [float(rng.normal(0.0, 2.0)) for _ in range(int(rng.integers(0, 4)))]
            if isinstance(value, list) and f.kind != "vector":
                continue
            if f.kind == "any" or f.name == "map_class":       # checked in check(), not by the schema
                continue
            if isinstance(value, tuple):
                value = list(value)
            schema_ok = validator.is_valid({f.name: value})
            ours_ok = not _coerce(f, value)[1]          # the field's own validation (check() aside)
            assert schema_ok == ours_ok, (label, f.name, value)


def test_every_builtin_default_valid_and_documented():
    for label, cls in all_settings_classes().items():
        cls()                                            # the defaults validate
        rows = table_rows(cls)
        assert [r["name"] for r in rows] == list(cls.names()), label
        for r in rows:
            assert r["meaning"] and r["type"], (label, r)
        assert markdown_table(cls).count("\n") == len(rows) + 1


# ------------------------------------------------------------------------------------------ the registry

@pytest.mark.parametrize("name", BUILTIN_NAVIGATORS)
def test_two_bad_navigator_settings_reported_together(name):
    cls = registry.settings_class(name)
    bad = next(f.name for f in settings_fields(cls) if f.kind == "float" and f.spec.ge == 0.0)
    with pytest.raises(ValueError) as exc:
        registry.create(name, dem="jacksboro", no_such_setting=1, **{bad: -1.0})
    assert isinstance(exc.value, SettingsError)
    paths = {p for p, _ in exc.value.problems}
    assert paths == {"no_such_setting", bad}, exc.value.problems
    assert str(exc.value).startswith(f"navigator {name!r}: ") and "known: " in str(exc.value)


def test_monitor_settings_reported_together():
    with pytest.raises(SettingsError) as exc:
        registry.create_monitor("dem_integrity", dem="jacksboro", n_windw=3, gnss_max_age_s=-1.0)
    assert {p for p, _ in exc.value.problems} == {"n_windw", "gnss_max_age_s"}


def test_capabilities_are_declared_not_guessed_from_names():
    assert not hasattr(registry, "MAP_NOISE_AWARE") and not hasattr(registry, "IMU_AWARE")
    caps = {n: registry.capabilities(n) for n in BUILTIN_NAVIGATORS}
    assert {n for n, c in caps.items() if c.takes_rng} == {"pf", "rbpf"}
    assert {n for n, c in caps.items() if c.uses_imu_spec} == {"acq_track", "ins", "ins_tercom", "pf", "pmf",
                                                                "rbpf"}
    assert {n for n, c in caps.items() if c.imu_bias_settings} == {"rbpf"}
    assert {n for n, c in caps.items() if c.needs_map} == {"acq_track", "ins_tercom", "pf", "pmf", "rbpf"}
    assert caps["ins_tercom"].warm_up_settings(1.0) == {"fix_period_s": 2.0, "min_samples": 1}
    assert registry.sensor_needs("ins_tercom", {"aiding": "radar_altimeter"}).required.keys() == \
        {"imu", "radar_altimeter"}
    assert set(registry.sensor_needs("acq_track", {"aiding_source": "ins"}).required) == \
        {"radar_altimeter", "baro", "imu"}


def test_plugin_without_settings_class_checked_against_its_signature():
    class Plugin:
        def __init__(self, dem=None, gain: float = 1.0):
            self.gain = gain

        def reset(self, initial):
            pass

        def update(self, frames):
            return None

    registry.register("test_settings_plugin", Plugin)
    try:
        assert registry.create("test_settings_plugin", gain=2.0).gain == 2.0
        with pytest.raises(SettingsError, match=r"gian: unknown setting \(did you mean 'gain'\?\); "
                                                r"known: gain"):
            registry.create("test_settings_plugin", gian=2.0)
        assert registry.capabilities("test_settings_plugin") == Capabilities()
    finally:
        registry.unregister("test_settings_plugin")


def test_free_inertial_refuses_aiding():
    with pytest.raises(SettingsError, match="aiding"):
        registry.create("ins", aiding="ira")


# ------------------------------------------------------------------------------------------ scenarios

@pytest.fixture(scope="module")
def default_data():
    return load_scenario("default", check_components=False).to_dict()


def _problems(data) -> list[str]:
    with pytest.raises(ScenarioError) as exc:
        validate(copy.deepcopy(data), source="test", check_components=False)
    return exc.value.problems


def test_scenario_reports_every_component_problem_by_path(default_data):
    d = copy.deepcopy(default_data)
    d["navigator"]["settings"] = {"fix_perod_s": 30.0, "gnss_sigma_h_m": -1.0}
    d["monitors"] = {"dem_integrity": {"n_window": 1, "variant": "x"}}
    d["sensors"]["radar_altimeter"] = {}
    d["sensors"]["baro"] = {"bias_m": -3.0, "rate_hz": 0}
    d["sensors"]["imu"] = {"grade": "tacticl"}
    probs = _problems(d)
    for path in ("navigator.settings.fix_perod_s", "navigator.settings.gnss_sigma_h_m",
                 "monitors.dem_integrity.n_window", "monitors.dem_integrity.variant", "sensors.baro.bias_m",
                 "sensors.baro.rate_hz", "sensors.imu.grade"):
        assert sum(p.startswith(path + ":") for p in probs) == 1, (path, probs)
    assert not any("Config" in p or "Settings" in p for p in probs), probs


def test_imu_grade_problem_at_its_field_without_class_name():
    with pytest.raises(SettingsError) as exc:
        SENSOR_MODELS["imu"].config_cls.from_mapping({"grade": "bogus", "rate_hz": -1})
    assert exc.value.at("sensors.imu") == [
        "sensors.imu.grade: unknown grade 'bogus'; known: navigation, tactical, consumer, noise_free",
        "sensors.imu.rate_hz: must be > 0 Hz, got -1"]


@pytest.mark.parametrize("navigator,missing", [("pmf", "ira"), ("pf", "ira"), ("rbpf", "ira"),
                                               ("ins_tercom", "ira"), ("ins", "imu")])
def test_missing_required_sensor_refused_naming_navigator_and_sensor(default_data, navigator, missing):
    d = copy.deepcopy(default_data)
    d["navigator"] = {**d["navigator"], "name": navigator, "settings": {}}
    del d["sensors"][missing]
    probs = _problems(d)
    want = f"sensors.{missing}: navigator {navigator!r} needs this sensor"
    assert any(p.startswith(want) for p in probs), probs


def test_monitor_missing_sensor_refused(default_data):
    d = copy.deepcopy(default_data)
    d["monitors"] = {"dem_integrity": {}}
    d["sensors"].pop("radar_altimeter", None)
    probs = _problems(d)
    assert any(p.startswith("sensors.radar_altimeter: monitor 'dem_integrity' needs this sensor")
               for p in probs), probs


def test_campaign_refuses_a_navigator_without_its_sensor(tmp_path, default_data):
    from trn_env.campaign.spec import CampaignError, load_campaign
    scen = (ROOT / "tests" / "campaigns" / "ci_denied_short.toml").read_text()
    (tmp_path / "noira.toml").write_text(scen.replace("[sensors.ira]", "[sensors.radar_altimeter]"))
    (tmp_path / "c.toml").write_text('name = "c"\nseeds = 1\nscenarios = ["noira.toml"]\n'
                                     'navigators = ["ins", "pmf"]\n')
    with pytest.raises(CampaignError) as exc:
        load_campaign(tmp_path / "c.toml")
    assert any("sensors.ira: navigator 'pmf' needs this sensor" in p for p in exc.value.problems), \
        exc.value.problems


def test_env_refuses_a_navigator_without_its_sensor():
    from trn_env.env.terrain_nav import TerrainNavEnv
    with pytest.raises(ScenarioError, match="sensors.radar_altimeter: navigator 'acq_track' needs"):
        TerrainNavEnv(navigator="acq_track")


def test_unused_sensors_and_warm_up_settings(default_data):
    from trn_env.scenario.loading import Scenario
    from trn_env.sim.warm_up import warm_up_scenario
    sc = Scenario.from_dict(copy.deepcopy(default_data))
    assert build.unused_sensors(sc) == ["air_data"]       # ins_tercom reads no air data
    assert warm_up_scenario(sc).navigator.table["min_samples"] == 1
    assert warm_up_scenario(sc).navigator.settings.min_samples == 1
    d = copy.deepcopy(default_data)
    d["navigator"] = {**d["navigator"], "name": "pmf", "settings": {}}
    assert warm_up_scenario(Scenario.from_dict(d)).navigator.table == {}


def test_schema_file_up_to_date():
    """scripts/generate_schema.py --check: the file holds the generated sections of the built-ins."""
    out = subprocess.run([sys.executable, str(ROOT / "scripts" / "generate_schema.py"), "--check"],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
    schema = json.loads((ROOT / "trn_env" / "scenario" / "schema.json").read_text())
    branches = {b["if"]["properties"]["name"]["const"] for b in schema["properties"]["navigator"]["allOf"]}
    assert branches == set(BUILTIN_NAVIGATORS)
    assert set(schema["properties"]["sensors"]["properties"]) == set(SENSOR_MODELS)


def test_replay_refuses_a_log_without_a_required_sensor():
    from types import SimpleNamespace

    from trn_env.logs.format import LogError
    from trn_env.logs.replay import check_sensors
    from trn_env.scenario.sections import MonitorSection, NavigatorSection
    log = SimpleNamespace(path="x.trnlog", sensors=("imu", "baro", "gnss"))
    d = SimpleNamespace(navigator=NavigatorSection.of("pmf"), monitors=(MonitorSection("dem_integrity"),))
    with pytest.raises(LogError, match=r"navigator 'pmf' needs sensor\(s\) the log does not hold: ira"):
        check_sensors(None, "pmf", log, d)
    log.sensors = ("imu", "ira")
    with pytest.raises(LogError, match="monitor 'dem_integrity' needs sensor.*radar_altimeter"):
        check_sensors(None, "pmf", log, d)
    check_sensors(None, "pmf", log, SimpleNamespace(navigator=NavigatorSection.of("pmf"), monitors=()))
