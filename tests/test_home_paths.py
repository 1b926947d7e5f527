"""File paths in scenario and campaign files: `~` is the user's home folder, and a relative path is taken
relative to the file that names it (a DEM, a stale fault's source DEM, a campaign's scenarios), whatever the
working folder."""

from __future__ import annotations

import copy
import re

import pytest
from trn_env.terrain.loaders import save_npz

from trn_env import terrain
from trn_env.scenario.loading import ScenarioError, load_scenario, read_scenario_file, validate


@pytest.fixture()
def home(tmp_path, monkeypatch):
    """A home folder of its own holding maps/j.npz (the bundled DEM written out), and a working folder
    elsewhere."""
    home = tmp_path / "home"
    (home / "maps").mkdir(parents=True)
    save_npz(terrain.load("jacksboro"), home / "maps" / "j.npz")
    monkeypatch.setenv("HOME", str(home))
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    return home


def _default() -> dict:
    data, _ = read_scenario_file("default")
    data = copy.deepcopy(data)
    data["terrain"]["world"].pop("refinement", None)
    return data


def test_a_dem_named_from_the_home_folder(home):
    data = _default()
    data["terrain"]["world"]["dem"] = "~/maps/j.npz"
    data["terrain"]["map"]["dem"] = "~/maps/j.npz"
    sc = validate(data, source="test")
    assert sc.terrain.world.dem == str(home / "maps" / "j.npz") == sc.terrain.map.dem
    assert terrain.load("~/maps/j.npz").heights_m.shape == terrain.load("jacksboro").heights_m.shape
    data["terrain"]["world"]["dem"] = "~/maps/missing.npz"
    with pytest.raises(ScenarioError, match=r"terrain\.world\.dem: cannot load DEM .*missing\.npz"):
        validate(data, source="test")


def _default_text(map_dem: str = "jacksboro", fault: str = "") -> str:
    """The built-in default scenario's text with its map (and a fault) changed."""
    from trn_env.scenario.loading import _builtin_dir

    text = (_builtin_dir() / "default.toml").read_text(encoding="utf-8")
    section = f'[terrain.map]\ndem = "{map_dem}"\n{fault}'
    new, n = re.subn(r'\[terrain\.map\][^\n]*\ndem = "jacksboro"\n', section, text)
    assert n == 1
    return new


def test_a_stale_faults_source_dem_is_relative_to_the_scenario_file(home, tmp_path):
    """The source DEM of a stale fault is found beside the scenario file as its map is, from any working
    folder (not relative to the working folder), or in the home folder by `~`."""
    folder = tmp_path / "scenarios"
    (folder / "maps").mkdir(parents=True)
    save_npz(terrain.load("jacksboro"), folder / "maps" / "old.npz")
    fault = ('faults = [{ kind = "stale", center_lat_deg = 36.52, center_lon_deg = -84.36, size_n_m = 900.0, '
             'size_e_m = 900.0, source_dem = "SRC" }]\n')
    (folder / "stale.toml").write_text(_default_text("maps/old.npz", fault.replace("SRC", "maps/old.npz")))
    sc = load_scenario(folder / "stale.toml")
    assert sc.terrain.map.dem == str(folder / "maps" / "old.npz")
    assert sc.terrain.map.faults[0].source_dem == str(folder / "maps" / "old.npz")
    (folder / "stale.toml").write_text(_default_text("~/maps/j.npz", fault.replace("SRC", "~/maps/j.npz")))
    sc = load_scenario(folder / "stale.toml")
    assert sc.terrain.map.dem == str(home / "maps" / "j.npz") == sc.terrain.map.faults[0].source_dem


def test_a_campaigns_scenario_from_the_home_folder(home):
    from trn_env.campaign.spec import load_campaign

    (home / "s.toml").write_text(_default_text())
    (home / "c.toml").write_text('name = "c"\nseeds = [0]\nscenarios = ["~/s.toml"]\nduration_s = 5.0\n')
    campaign = load_campaign(home / "c.toml")
    assert [v.scenario_source for v in campaign.variants] == [str(home / "s.toml")]
