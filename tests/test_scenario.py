"""Scenario files: schema, semantic checks, every problem reported with its field path."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from trn_env.scenario.loading import (
    ScenarioError,
    builtin_names,
    list_scenarios,
    load_scenario,
    read_scenario_file,
    schema_problems,
    validate,
)

REPO_SCENARIOS = Path(__file__).parent / "scenarios"


def _default_data() -> dict:
    data, _ = read_scenario_file("default")
    return data


def test_builtins_listed_with_descriptions():
    names = builtin_names()
    for required in ("default", "crosswind_5km", "ins_only"):
        assert required in names
    rows = dict(list_scenarios())
    assert all(rows[n].strip() for n in names), rows


@pytest.mark.parametrize("name", ["default", "crosswind_5km", "ins_only"])
def test_builtin_scenarios_validate(name):
    sc = load_scenario(name)
    assert sc.name == name
    assert sc.initial_errors.position_ned_m == (30.0, 30.0, 15.0)  # seed 000 Table 2 default
    assert sc.duration_s > 0


def test_default_scenario_content_matches_issue():
    sc = load_scenario("default")
    assert sc.terrain.world.dem == "jacksboro"
    assert sc.navigator.name == "ins_tercom"
    assert {"imu", "baro", "ira"} <= set(sc.sensors.fitted)
    assert all(abs(w.h_agl_m - 1500.0) < 1e-9 for w in sc.route.waypoints)
    assert sc.gnss.outages[0].start_s < 60.0 and sc.gnss.outages[0].end_s is None


def test_regression_scenarios_validate():
    files = sorted(REPO_SCENARIOS.glob("*.toml"))
    assert len(files) >= 3
    for f in files:
        load_scenario(f)


def test_unknown_key_and_wrong_type_reported_with_paths():
    data = _default_data()
    data["bogus"] = 1
    data["initial"]["lat_deg"] = "north"
    data["route"]["waypoints"][1]["speed"] = 3
    data["route"]["waypoints"][2]["lat_deg"] = 95.0
    data["wind"]["turbulence"]["severity"] = "huge"
    probs = schema_problems(data)
    joined = "\n".join(probs)
    assert len(probs) == 5, joined
    assert any(p.startswith("bogus: unknown key") for p in probs)
    assert any(p.startswith("initial.lat_deg:") and "number" in p for p in probs)
    assert any(p.startswith("route.waypoints[1].speed: unknown key") for p in probs)
    assert any(p.startswith("route.waypoints[2].lat_deg:") and "90" in p for p in probs)
    assert any(p.startswith("wind.turbulence.severity:") for p in probs)


def test_every_problem_listed_at_once(tmp_path):
    """Unknown key, wrong type, unknown navigator, route outside the terrain, unreadable DEM: one error."""
    data = _default_data()
    data["surprise"] = True
    data["duration_s"] = "long"
    data["navigator"] = {"name": "no_such_navigator"}
    data["route"]["waypoints"][2]["lon_deg"] = -80.0          # ~370 km east of the Jacksboro DEM
    bad_dem = tmp_path / "broken.tif"
    bad_dem.write_bytes(b"this is not a GeoTIFF")
    data["terrain"]["map"] = {"dem": str(bad_dem)}
    with pytest.raises(ScenarioError) as exc:
        validate(data, source="test")
    probs = exc.value.problems
    joined = "\n".join(probs)
    assert any(p.startswith("surprise: unknown key") for p in probs), joined
    assert any(p.startswith("duration_s:") for p in probs), joined
    assert any(p.startswith("navigator.name:") and "no_such_navigator" in p for p in probs), joined
    assert any(p.startswith("route.waypoints[2]:") and "outside" in p for p in probs), joined
    assert any(p.startswith("terrain.map.dem:") and "broken.tif" in p for p in probs), joined
    assert len(probs) == 5, joined
    assert "5 problem(s)" in str(exc.value)


def test_missing_dem_file_and_altitude_rules(tmp_path):
    data = _default_data()
    data["terrain"]["world"]["dem"] = str(tmp_path / "missing.npz")
    data["route"]["waypoints"][0]["h_msl_m"] = 2000.0          # now has both h_msl_m and h_agl_m
    del data["route"]["waypoints"][1]["h_agl_m"]                # now has neither
    with pytest.raises(ScenarioError) as exc:
        validate(data, source="test")
    probs = exc.value.problems
    assert any(p.startswith("terrain.world.dem:") and "missing.npz" in p for p in probs), probs
    assert any(p.startswith("route.waypoints[0]:") and "exactly one" in p for p in probs), probs
    assert any(p.startswith("route.waypoints[1]:") and "exactly one" in p for p in probs), probs


def test_semantic_checks_on_valid_schema():
    data = _default_data()
    data["wind"]["layers"][1]["altitude_m"] = -100.0
    data["gnss"]["outages"] = [{"start_s": 50.0, "end_s": 20.0}]
    data["initial"]["lat_deg"] = 10.0
    with pytest.raises(ScenarioError) as exc:
        validate(data, source="test")
    probs = exc.value.problems
    assert any(p.startswith("wind.layers[1].altitude_m:") for p in probs), probs
    assert any(p.startswith("gnss.outages[0].end_s:") for p in probs), probs
    assert any(p.startswith("initial:") and "outside" in p for p in probs), probs


def test_below_terrain_msl_waypoint_rejected():
    data = _default_data()
    wp = data["route"]["waypoints"][1]
    del wp["h_agl_m"]
    wp["h_msl_m"] = 100.0       # the Jacksboro DEM is 236..1076 m
    with pytest.raises(ScenarioError) as exc:
        validate(data, source="test")
    assert any(p.startswith("route.waypoints[1].h_msl_m:") and "below the terrain" in p
               for p in exc.value.problems)


def test_component_settings_rejected_at_their_field():
    data = _default_data()
    data["sensors"]["imu"] = {"grade": "navigation", "gyro_bias_rps": -1.0, "no_such": 1}
    with pytest.raises(ScenarioError) as exc:
        validate(data, source="test")
    probs = exc.value.problems       # every problem at once, each at its field, no class name
    assert any(p.startswith("sensors.imu.gyro_bias_rps: ") for p in probs), probs
    assert any(p.startswith("sensors.imu.no_such: unknown") for p in probs), probs
    assert not any("ImuConfig" in p for p in probs), probs


def test_component_problems_reported_with_other_problems():
    data = _default_data()
    data["unexpected"] = 1
    data["sensors"]["imu"] = {"grade": "navigation", "no_such": 1}
    data["sensors"]["baro"] = {"bias_m": -3.0}
    data["wind"]["turbulence"]["severity"] = "apocalyptic"
    with pytest.raises(ScenarioError) as exc:
        validate(data, source="test")
    probs = exc.value.problems
    assert any(p.startswith("unexpected: unknown key") for p in probs), probs
    assert any(p.startswith("sensors.imu.no_such:") for p in probs), probs
    assert any(p.startswith("sensors.baro.bias_m:") for p in probs), probs
    assert sum(p.startswith("wind") for p in probs) == 1, probs       # schema only, no follow-on message


def test_overrides_revalidated():
    sc = load_scenario("default", seed=7, duration_s=30.0, navigator="ins")
    assert (sc.seed, sc.duration_s, sc.navigator_name) == (7, 30.0, "ins")
    with pytest.raises(ScenarioError) as exc:
        load_scenario("default", navigator="nope")
    assert any(p.startswith("navigator.name:") for p in exc.value.problems)
    assert load_scenario("default", seed=2**63 - 1, check_components=False).seed == 2**63 - 1
    with pytest.raises(ScenarioError, match=r"seed: 9223372036854775808 is greater than the maximum"):
        load_scenario("default", seed=2**63, check_components=False)    # TOML and Parquet hold 64 bits


def test_bad_toml_and_missing_file(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text("name = \n")
    with pytest.raises(ScenarioError) as exc:
        load_scenario(f)
    assert exc.value.problems[0].startswith("file: not valid TOML") and "JSON" not in exc.value.problems[0]
    as_json = tmp_path / "default.json"                 # the same scenario written as JSON
    as_json.write_text(json.dumps(read_scenario_file("default")[0]))
    with pytest.raises(ScenarioError) as exc:
        load_scenario(as_json)
    assert exc.value.problems[0].endswith("(it looks like JSON: a scenario file is TOML, e.g. a resolved "
                                          "scenario.toml of a run folder)"), exc.value.problems
    with pytest.raises(ScenarioError) as exc:
        load_scenario(tmp_path / "nope.toml")
    assert exc.value.problems[0].startswith("file: no such scenario")
    binary = tmp_path / "plot.toml"
    binary.write_bytes(b"\x89PNG\r\n\x1a\n")
    with pytest.raises(ScenarioError) as exc:
        load_scenario(binary)
    assert exc.value.problems == ["file: not a UTF-8 text file (invalid start byte at byte 0)"]


def test_a_byte_order_mark_is_accepted_in_scenario_and_campaign_files(tmp_path):
    """Editors on Windows save UTF-8 with a byte-order mark, which tomllib refuses ('Invalid statement at
    line 1, column 1'): the same file without it loads to the same scenario, and a campaign file too."""
    from importlib import resources

    from trn_env.campaign import load_campaign

    marked = tmp_path / "marked.toml"
    text = (resources.files("trn_env.scenario.builtin") / "default.toml").read_bytes()
    marked.write_bytes(b"\xef\xbb\xbf" + text)
    assert load_scenario(marked).to_dict() == load_scenario("default").to_dict()
    campaign = tmp_path / "c.toml"
    campaign.write_bytes(b"\xef\xbb\xbf" + f'name = "c"\nroot_seed = 1\nseeds = 1\nnavigators = ["ins"]\n'
                         f'scenarios = ["{marked.as_posix()}"]\n'.encode())
    assert load_campaign(campaign).name == "c"


def test_relative_dem_path_resolved_against_scenario_file(tmp_path):
    import numpy as np

    from trn_env import terrain
    dem = terrain.load("jacksboro")
    np.savez(tmp_path / "copy.npz", heights_m=dem.heights_m, lat0_deg=math.degrees(dem.lat0_rad),
             lon0_deg=math.degrees(dem.lon0_rad), dlat_deg=math.degrees(dem.dlat_rad),
             dlon_deg=math.degrees(dem.dlon_rad))
    data = _default_data()
    data["terrain"]["world"]["dem"] = "copy.npz"
    text = _to_toml(data)
    (tmp_path / "sc.toml").write_text(text)
    assert tomllib.loads(text)["terrain"]["world"]["dem"] == "copy.npz"
    sc = load_scenario(tmp_path / "sc.toml")
    assert Path(sc.terrain.world.dem).resolve() == (tmp_path / "copy.npz").resolve()


def _to_toml(data: dict) -> str:
    """Minimal TOML writer for the test (tables, arrays of inline tables, scalars)."""
    def val(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, dict):
            return "{ " + ", ".join(f"{k} = {val(x)}" for k, x in v.items()) + " }"
        if isinstance(v, list):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return repr(v)

    lines = [f"{k} = {val(v)}" for k, v in data.items() if not isinstance(v, dict)]
    for k, v in data.items():
        if isinstance(v, dict):
            lines.append(f"[{k}]")
            lines += [f"{kk} = {val(vv)}" for kk, vv in v.items()]
    return "\n".join(lines) + "\n"
