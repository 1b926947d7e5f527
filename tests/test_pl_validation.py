"""A navigator says where its protection level is not validated (navigators.integrity.protection_level:
set_condition, EXTRA_PL_NOT_VALIDATED): the scenario's condition (IMU grade against the presets' error
terms, map class), the statement against the navigator's declared validated conditions, and the key in its
estimates."""

from __future__ import annotations

import pytest
from trn_env.navigators import registry
from trn_env.navigators.integrity import protection_level as pl

from trn_env.scenario.loading import read_scenario_file, validate
from trn_env.scenario.navigation import build_navigator, pl_condition


def _scenario(imu: dict, terrain_map: dict):
    data, _ = read_scenario_file("tests/scenarios/acq_track_short.toml")
    data["sensors"]["imu"] = imu
    data["terrain"]["map"] = terrain_map
    return validate(data, source="test")


@pytest.mark.parametrize("imu, terrain_map, expect", [
    ({"grade": "navigation"}, {"dem": "jacksboro"}, "navigation/as_published"),
    ({"grade": "tactical"}, {"dem": "jacksboro", "error_model": {"preset": "dted1"}}, "tactical/dted1"),
    # a navigation-grade IMU with one term worse than the navigation preset's is judged against tactical's
    ({"grade": "navigation", "gyro_bias_rps": 1e-6}, {"dem": "jacksboro"}, "tactical/as_published"),
    ({"grade": "consumer"}, {"dem": "jacksboro"}, "beyond_tactical/as_published"),
    ({"grade": "navigation"}, {"dem": "jacksboro", "error_model": {"preset": "dted1", "bias_fraction": 1.0}},
     "navigation/custom_error_model"),
])
def test_condition_of_a_scenario(imu, terrain_map, expect):
    assert pl_condition(_scenario(imu, terrain_map)) == expect


def test_statement_against_the_declared_conditions():
    class Nav:
        name = "x"
        integrity_risk = pl.DEFAULT_INTEGRITY_RISK
    nav = Nav()
    extra = pl.publish({}, 10.0, nav)
    assert pl.EXTRA_PL_NOT_VALIDATED not in extra            # no condition stated: no claim either way
    pl.set_condition(nav, "tactical/dted1", ("navigation/as_published",))
    msg = pl.publish({}, 10.0, nav)[pl.EXTRA_PL_NOT_VALIDATED]
    assert "not validated" in msg and "tactical/dted1" in msg and "navigation/as_published" in msg
    pl.set_condition(nav, "navigation/as_published", ("navigation/as_published",))
    assert pl.publish({}, 10.0, nav)[pl.EXTRA_PL_NOT_VALIDATED] == ""
    nav.integrity_risk = 1e-5
    pl.set_condition(nav, "navigation/as_published", ("navigation/as_published",))
    assert "not at 1e-05" in pl.publish({}, 10.0, nav)[pl.EXTRA_PL_NOT_VALIDATED]


@pytest.mark.parametrize("name", ["pmf", "pf", "rbpf", "ins_tercom", "acq_track"])
def test_built_navigator_states_its_condition(name):
    from trn_env import terrain
    data, _ = read_scenario_file("tests/scenarios/acq_track_short.toml")
    data["sensors"]["imu"] = {"grade": "consumer"}
    # the settings the campaign flew it with (its declaration's)
    data["navigator"] = {"name": name, "settings": dict(registry.capabilities(name).pl_settings)}
    dem = terrain.load("jacksboro")
    nav = build_navigator(validate(data, source="test"), dem)
    assert nav.pl_not_validated.startswith(f"{name}: protection level not validated under "
                                           "beyond_tactical/as_published")
    data["sensors"]["imu"] = {"grade": "navigation"}
    nav = build_navigator(validate(data, source="test"), dem)
    validated = "navigation/as_published" in registry.capabilities(name).pl_validated
    assert (nav.pl_not_validated == "") == validated


@pytest.mark.parametrize("name", ["pmf", "pf", "rbpf", "ins_tercom", "acq_track"])
def test_declared_conditions_are_the_campaigns(name):
    """A navigator declares a grade/map condition validated exactly when the campaign's report on the
    validation page (docs/validation/integrity_pl_campaign.json) bounds its misleading-information rate at or
    below the stated risk on every terrain flown under that condition."""
    import json
    from pathlib import Path
    doc = json.loads((Path(__file__).resolve().parents[1] / "docs" / "validation"
                      / "integrity_pl_campaign.json").read_text())
    assert any(key.startswith(name + "/") for key in doc["results"]), "no campaign rows for " + name
    assert set(registry.capabilities(name).pl_validated) == _met(doc, name)


def test_guide_accuracy_table_is_the_campaigns():
    """The navigators guide's accuracy table is the one the campaign script makes from the report on the
    validation page (docs/validation/integrity_pl_campaign.json), and every cell is a median over a
    90th percentile no smaller than it."""
    import json
    from pathlib import Path

    from _scripts import load_script
    root = Path(__file__).resolve().parents[1]
    doc = json.loads((root / "docs" / "validation" / "integrity_pl_campaign.json").read_text())
    table = load_script("protection_level_campaign").accuracy_table(doc)
    guide = (root / "docs" / "guide" / "navigators.md").read_text()
    assert guide.split("<!-- accuracy-table -->\n")[1].split("\n<!-- /accuracy-table -->")[0] == table
    for key, m in doc["results"].items():
        if not key.endswith("/all"):
            assert 0.0 < m["horizontal_rms_median_m"] <= m["horizontal_rms_p90_m"], key
    assert len(table.splitlines()) == 2 + len(doc["conditions"])


def test_campaign_settings_option_refuses_bad_input(tmp_path, capsys):
    """--settings: not JSON, a navigator not flown, or a setting its navigator does not declare or refuses:
    exit 2 naming the option, before any work (no --out folder made)."""
    from _scripts import load_script
    mod = load_script("protection_level_campaign")
    for text in ("nojson", '["rbpf"]', '{"pmf": {}}', '{"rbpf": {"nosuch": 1}}',
                 '{"rbpf": {"map_error_in_height": "x"}}'):
        with pytest.raises(SystemExit) as exc:
            mod.main(["--navigators", "rbpf", "--settings", text, "--out", str(tmp_path / "out")])
        assert exc.value.code == 2
        assert "--settings" in capsys.readouterr().err
        assert not (tmp_path / "out").exists()


def test_settings_other_than_the_campaigns_are_named():
    """A navigator built with settings the campaign did not fly (ins_tercom's default remove_bias = false;
    the campaign's true) says so under a condition its declaration covers, naming the setting; with the
    campaign's it states nothing."""
    from trn_env import terrain
    data, _ = read_scenario_file("tests/scenarios/acq_track_short.toml")
    data["sensors"]["imu"] = {"grade": "navigation"}
    dem = terrain.load("jacksboro")
    data["navigator"] = {"name": "ins_tercom", "settings": {"remove_bias": False}}
    msg = build_navigator(validate(data, source="test"), dem).pl_not_validated
    assert msg.startswith("ins_tercom: protection level not validated under navigation/as_published with "
                          "remove_bias=False (validated with True)")
    data["navigator"] = {"name": "ins_tercom", "settings": {}}      # the default is not the campaign's
    assert "remove_bias=False" in build_navigator(validate(data, source="test"), dem).pl_not_validated
    data["navigator"] = {"name": "ins_tercom", "settings": {"remove_bias": True}}
    assert build_navigator(validate(data, source="test"), dem).pl_not_validated == ""


def test_rbpf_range_only_variant_states_its_own_condition():
    """The rbpf with look_angle = false: validated on navigation/as_published (its own campaign), not on
    navigation/dted1; its defaults the other way round; another setting beside it voids the variant."""
    from trn_env import terrain
    data, _ = read_scenario_file("tests/scenarios/acq_track_short.toml")
    dem = terrain.load("jacksboro")
    data["sensors"]["imu"] = {"grade": "navigation"}
    data["terrain"]["map"] = {"dem": "jacksboro"}
    data["navigator"] = {"name": "rbpf", "settings": {"look_angle": False}}
    assert build_navigator(validate(data, source="test"), dem).pl_not_validated == ""
    data["navigator"] = {"name": "rbpf", "settings": {"look_angle": False, "tempering": "none"}}
    msg = build_navigator(validate(data, source="test"), dem).pl_not_validated
    assert "tempering='none'" in msg and "look_angle=False" in msg
    data["navigator"] = {"name": "rbpf", "settings": {}}
    msg = build_navigator(validate(data, source="test"), dem).pl_not_validated
    assert msg.startswith("rbpf: protection level not validated under navigation/as_published")
    assert msg.endswith("on: navigation/dted1)")
    data["terrain"]["map"] = {"dem": "jacksboro", "error_model": {"preset": "dted1"}}
    assert build_navigator(validate(data, source="test"), dem).pl_not_validated == ""
    data["navigator"] = {"name": "rbpf", "settings": {"look_angle": False}}
    msg = build_navigator(validate(data, source="test"), dem).pl_not_validated
    assert msg.startswith("rbpf: protection level not validated under navigation/dted1")
    assert msg.endswith("on: navigation/as_published)")


def _met(doc: dict, name: str) -> set[str]:
    """The grade/map conditions on which a campaign report bounds `name`'s misleading-information rate at
    or below its integrity risk on every terrain."""
    met: dict[str, bool] = {}
    for key, m in doc["results"].items():
        nav, condition = key.split("/")
        if nav != name or condition == "all":
            continue
        _terrain, grade, map_class = condition.split("-")
        ok = m["pl_misleading_rate_upper95"] <= doc["integrity_risk"]
        met[f"{grade}/{map_class}"] = met.get(f"{grade}/{map_class}", True) and ok
    return {c for c, ok in met.items() if ok}


def test_declared_settings_are_the_campaign_scripts():
    """Each navigator's declared campaign settings (pl_settings) are the ones
    scripts/protection_level_campaign.py flies it with, and the rbpf's range-only variant's conditions are
    what its campaign's report (docs/validation/integrity_pl_campaign_rbpf_range.json) bounds."""
    import json
    from pathlib import Path

    from _scripts import load_script
    script = load_script("protection_level_campaign")
    for name, campaign in script.NAVIGATORS.items():
        assert dict(registry.capabilities(name).pl_settings) == campaign, name
    doc = json.loads((Path(__file__).resolve().parents[1] / "docs" / "validation"
                      / "integrity_pl_campaign_rbpf_range.json").read_text())
    variants = dict(registry.capabilities("rbpf").pl_variants)
    assert set(variants[(("look_angle", False),)]) == _met(doc, "rbpf") == {"navigation/as_published"}
