"""Scenario validation keeps the answers of its two costly checks (the JSBSim trim, the coarse terrain's
spectrum fit) for the inputs that fix them, so a campaign's many variants validate in a fraction of the
time; a kept answer must never stand in for a different input."""

from __future__ import annotations

import numpy as np
import pytest
from trn_env.terrain.dem import Dem

from trn_env import terrain
from trn_env.scenario import ScenarioError, load_scenario
from trn_env.scenario import build as scenario_build
from trn_env.scenario import maps as scenario_maps


def _problems(**fields) -> list[str]:
    try:
        load_scenario("default").with_fields(fields)
    except ScenarioError as err:
        return list(err.problems)
    return []


def test_the_trim_check_answers_each_start_by_its_own_arguments(monkeypatch):
    """Alternating a start JSBSim trims and one it cannot: each keeps its own answer, the second time
    without a new JSBSim trim; a start that differs in any argument of the flight (here the wind) trims
    anew."""
    from trn_env.flight import core
    monkeypatch.setattr(scenario_build, "_TRIM_CHECKED", {})
    built = []
    real_flight = core.Flight

    def counting_flight(*args, **kwargs):
        built.append(kwargs.get("wind"))
        return real_flight(*args, **kwargs)

    monkeypatch.setattr(core, "Flight", counting_flight)
    answers = [_problems(**{"initial.tas_mps": tas}) for tas in (85.0, 45.0, 85.0, 45.0)]
    assert answers[0] == answers[2] == []
    assert len(answers[1]) == 1 and answers[1] == answers[3]
    assert answers[1][0].startswith("initial: JSBSim cannot trim 'kingair' in level flight") \
        and "TAS = 45.0 m/s" in answers[1][0]
    assert len(built) == 2
    assert _problems(**{"initial.tas_mps": 85.0, "wind.layers.0.speed_mps": 6.0}) == []
    assert len(built) == 3 and built[-1].layers[0].speed_mps == 6.0


def test_the_trim_check_keeps_no_more_than_its_bound(monkeypatch):
    monkeypatch.setattr(scenario_build, "_TRIM_CHECKED", {})
    monkeypatch.setattr(scenario_build, "_TRIM_CHECKED_MAX", 2)
    for tas in (80.0, 85.0, 90.0):
        assert _problems(**{"initial.tas_mps": tas}) == []
    assert 1 <= len(scenario_build._TRIM_CHECKED) <= 2


def test_the_spectrum_fit_is_done_once_per_coarse_grid(monkeypatch):
    """The same heights and spacing (a DEM loaded again) are fitted once; other heights, a sub-region or
    a failing fit are fitted every time (a failure is never kept)."""
    from trn_env.terrain import refine
    monkeypatch.setattr(scenario_maps, "_SPECTRUM_FITTED", set())
    fitted = []
    real_fit = refine.fit_dem_spectrum

    def counting_fit(dem, *args, **kwargs):
        fitted.append(dem.heights_m.shape)
        return real_fit(dem, *args, **kwargs)

    monkeypatch.setattr(refine, "fit_dem_spectrum", counting_fit)
    settings = {"spacing_m": 30.0}
    scenario_maps.check_refinement(terrain.load("jacksboro"), settings)
    scenario_maps.check_refinement(terrain.load("jacksboro"), settings)
    assert len(fitted) == 1
    scenario_maps.check_refinement(terrain.load("jacksboro"),
                                   {"spacing_m": 30.0, "region_deg": [36.47, 36.56, -84.40, -84.33]})
    assert len(fitted) == 2 and fitted[1] != fitted[0]
    other = terrain.load("jacksboro")
    other = Dem(np.asarray(other.heights_m) * 1.5, other.lat0_rad, other.lon0_rad, other.dlat_rad,
                other.dlon_rad, name="jacksboro x 1.5")
    scenario_maps.check_refinement(other, settings)
    assert len(fitted) == 3

    def failing_fit(dem, *args, **kwargs):
        fitted.append("failed")
        raise ValueError("fit_power_law: fewer than 3 PSD bins")

    monkeypatch.setattr(scenario_maps, "_SPECTRUM_FITTED", set())
    monkeypatch.setattr(refine, "fit_dem_spectrum", failing_fit)
    for _ in range(2):
        with pytest.raises(ValueError, match="fewer than 3 PSD bins"):
            scenario_maps.check_refinement(terrain.load("jacksboro"), settings)
    assert fitted[-2:] == ["failed", "failed"]


def test_a_campaign_reads_each_dem_once(tmp_path, monkeypatch):
    """Validation reads a DEM per scenario; a campaign's variants share what the first read (the world and
    the map of every variant are the same Dem, as its flights share them). A file that cannot be read is a
    problem of every variant that names it, said once."""
    from trn_env.campaign import CampaignError, load_campaign
    from trn_env.scenario import validation
    reads = []
    real_load = validation._load_dem

    def counting_load(value, fill_voids):
        reads.append((value, fill_voids))
        return real_load(value, fill_voids)

    monkeypatch.setattr(validation, "_load_dem", counting_load)
    campaign = tmp_path / "c.toml"
    campaign.write_text('seeds = 1\nscenarios = ["default"]\nnavigators = ["ins", "pmf"]\n'
                        '[[sweeps]]\npath = "wind.layers.0.speed_mps"\nvalues = [2.0, 4.0, 6.0]\n')
    loaded = load_campaign(campaign)
    assert len(loaded.variants) == 6
    assert reads == [("jacksboro", False)]
    worlds = {id(v.dems[0]) for v in loaded.variants}
    assert len(worlds) == 1

    reads.clear()
    for _ in range(2):        # a scenario validated on its own reads its DEM each time (once for both)
        load_scenario("default")
    assert reads == [("jacksboro", False)] * 2

    reads.clear()
    campaign.write_text(f'seeds = 1\nscenarios = ["default"]\nnavigators = ["ins", "pmf"]\n'
                        f'[[sweeps]]\npath = "terrain.map.dem"\nvalues = ["{tmp_path / "missing.tif"}"]\n')
    with pytest.raises(CampaignError) as err:
        load_campaign(campaign)
    assert len(reads) == 3          # the world once; the missing map tried for each variant
    missing = [p for p in err.value.problems if "cannot load DEM" in p]
    assert len(missing) == 1 and missing[0].startswith("sweeps[0].values[0] (terrain.map.dem = "), missing


def test_the_validation_cost_script_measures_both_ways(capsys):
    """scripts/campaign_validation_cost.py (the figures in docs/validation/campaign_backends.md) on a
    two-point sweep, and its refusals."""
    import json

    from _scripts import load_script
    script = load_script("campaign_validation_cost")
    assert script.main(["--points", "2", "--alone", "2"]) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["variants"] == 6 and row["alone_variants"] == 2
    assert row["campaign_ms_per_variant"] > 0 and row["alone_ms_per_variant"] > 0
    for argv, field in ((["--points", "0"], "--points"), (["--points", "2", "--alone", "7"], "--alone"),
                        (["--path", "x.y", "--points", "2", "--alone", "1"], "--path x.y: sweeps[0]")):
        assert script.main(argv) == 2
        assert capsys.readouterr().err.startswith(f"error: {field}")
