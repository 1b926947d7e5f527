"""Plug-in navigators and monitors: entry points, module:Name references, their errors, the CLI's
`navigators` listing and exit status, gymnasium vector envs.

A plug-in package is simulated with a real `*.dist-info` folder (METADATA + entry_points.txt) on sys.path:
importlib.metadata finds its entry points exactly as those of a pip-installed package."""

from __future__ import annotations

import json
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib
from trn_env.navigators import registry
from trn_env.navigators.builtin import BUILTIN_MONITORS, BUILTIN_NAVIGATORS

ROOT = Path(__file__).resolve().parents[1]

PLUG = '''
from trn_env.navigators.builtin import ins as _ins


class PlugIns:
    """A plug-in navigator delegating to the built-in INS (its settings are the INS's)."""

    name = "plug_ins"

    def __init__(self, **settings):
        self._nav = _ins(**settings)

    def reset(self, initial):
        self._nav.reset(initial)

    def update(self, frames):
        return self._nav.update(frames)


def not_a_navigator_factory(**settings):
    return 42
'''


@pytest.fixture(scope="module")
def plugin_dir(tmp_path_factory):
    """A folder holding a plug-in package with its dist-info (entry points), a broken one and a class
    that is not a navigator; put on sys.path for the module's tests, registry caches refreshed."""
    d = tmp_path_factory.mktemp("plugins")
    (d / "plugtest_nav.py").write_text(PLUG)
    (d / "plugtest_broken.py").write_text("raise RuntimeError('boom: calibration table missing')\n")
    (d / "plugtest_thing.py").write_text("class Thing:\n    def update(self, frames):\n        return None\n")
    info = d / "plugtest-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: plugtest\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(textwrap.dedent("""\
        [trn_env.navigators]
        plug_ins = plugtest_nav:PlugIns
        plug_broken = plugtest_broken:Nav
        plug_thing = plugtest_thing:Thing

        [trn_env.monitors]
        plug_mon_broken = plugtest_broken:Mon
        """))
    sys.path.insert(0, str(d))
    registry.refresh()
    yield d
    sys.path.remove(str(d))
    registry.refresh()


def _cli(args: list[str], capsys):
    """trn-env in this process (the plug-in folder is on sys.path): (exit status, stdout, stderr)."""
    from trn_env import cli
    capsys.readouterr()
    code = cli.main(args)
    out = capsys.readouterr()
    return code, out.out, out.err


# ------------------------------------------------------------------------------------------ registry

def test_builtins_are_declared_as_entry_points_like_a_users():
    """pyproject.toml's entry points are navigators.builtin's table, and the installed metadata has them."""
    ep = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]
    assert ep["trn_env.navigators"] == BUILTIN_NAVIGATORS
    assert ep["trn_env.monitors"] == BUILTIN_MONITORS
    installed = {e.name: e.value for e in registry.metadata.entry_points(group="trn_env.navigators")}
    for name, ref in BUILTIN_NAVIGATORS.items():
        assert installed.get(name) == ref, f"reinstall trn-env (pip install -e .): entry point {name} missing"
    for name in BUILTIN_NAVIGATORS:
        p = registry.resolve(name)
        assert p.origin == "built-in" and p.reference == BUILTIN_NAVIGATORS[name]
    assert registry.resolve("pf").takes_rng and registry.resolve("rbpf").takes_rng
    assert not registry.resolve("pmf").takes_rng


def test_reference_creates_the_same_navigator_as_its_name():
    from trn_env.navigators.filters.pmf import PointMassFilter
    nav = registry.create("trn_env.navigators.filters.pmf:PointMassFilter", dem="jacksboro", grid_size=11)
    assert isinstance(nav, PointMassFilter)
    assert registry.resolve("trn_env.navigators.filters.pmf:PointMassFilter").origin == "reference"


@pytest.mark.parametrize("ref, words", [
    ("plugtest_missing_module:Nav", ["plugtest_missing_module", "ModuleNotFoundError"]),
    ("plugtest_broken:Nav", ["plugtest_broken", "RuntimeError", "boom: calibration table missing",
                             "plugtest_broken.py:1"]),
    ("plugtest_thing:Thing", ["not a navigator", "Thing lacks reset(initial: Estimate)"]),
    ("plugtest_nav:nothing_here", ["has no attribute 'nothing_here'"]),
    ("numpy:linalg", ["not a navigator", "module 'numpy.linalg'"]),
])
def test_bad_references_name_the_module_and_the_problem(plugin_dir, ref, words):
    with pytest.raises(registry.PluginError) as err:
        registry.create(ref)
    for w in words:
        assert w in str(err.value), (w, str(err.value))


def test_a_module_not_found_says_where_to_put_it(tmp_path, monkeypatch):
    """The command-line tool does not search the current directory: a module there is named with the fix;
    elsewhere the message says to install it or add its folder to PYTHONPATH; a module the plug-in itself
    imports that is missing is not confused with the plug-in (the plug-in's line is given)."""
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", ".", str(tmp_path))])
    monkeypatch.chdir(tmp_path)
    (tmp_path / "plugtest_here_nav.py").write_text("class Nav:\n    pass\n")
    with pytest.raises(registry.PluginError, match=r"plugtest_here_nav.py is in the current directory, which "
                                                   r"the trn-env command does not search.*PYTHONPATH=\."):
        registry.create("plugtest_here_nav:Nav")
    with pytest.raises(registry.PluginError, match=r"No module named 'plugtest_gone_nav'; install its "
                                                   r"package, or add the folder holding it to PYTHONPATH"):
        registry.create("plugtest_gone_nav:Nav")
    other = tmp_path / "elsewhere"
    other.mkdir()
    (other / "plugtest_dep_nav.py").write_text("import plugtest_missing_dependency\n")
    monkeypatch.syspath_prepend(str(other))
    with pytest.raises(registry.PluginError) as err:
        registry.create("plugtest_dep_nav:Nav")
    assert "No module named 'plugtest_missing_dependency' (at " in str(err.value)
    assert "plugtest_dep_nav.py:1" in str(err.value) and "PYTHONPATH" not in str(err.value)


def test_a_plugin_without_settings_gets_the_map_only_when_it_takes_it(plugin_dir, tmp_path, monkeypatch):
    """A plain class taking no arguments is built as it is (it was refused: 'dem: unknown setting'); one
    taking dem or **kwargs gets the scenario's navigator map."""
    from trn_env.scenario.navigation import navigator_settings
    from trn_env.scenario.overrides import load_scenario_with
    (tmp_path / "plugtest_plain_nav.py").write_text(textwrap.dedent("""\
        class Plain:
            name = "plain"
            def reset(self, initial): ...
            def update(self, frames): ...

        class WithMap(Plain):
            def __init__(self, dem):
                self.dem = dem
        """))
    monkeypatch.syspath_prepend(str(tmp_path))
    for ref, gets_map in [("plugtest_plain_nav:Plain", False), ("plugtest_plain_nav:WithMap", True),
                          ("plugtest_nav:PlugIns", True)]:
        sc = load_scenario_with("default", [], navigator=ref)
        settings = navigator_settings(sc, map_dem="the map")
        assert ("dem" in settings) == gets_map, ref
        if ref.endswith("Plain"):
            assert isinstance(registry.create(ref, **settings), object)


def test_factory_returning_a_non_navigator_is_refused(plugin_dir):
    with pytest.raises(registry.PluginError, match="lacks reset.*update"):
        registry.create("plugtest_nav:not_a_navigator_factory")


def test_unknown_name_lists_the_available_ones():
    with pytest.raises(ValueError, match=r"unknown navigator 'nosuch'.*'ins_tercom'.*package.module:Name"):
        registry.create("nosuch")


def test_entry_points_of_an_installed_package(plugin_dir):
    assert "plug_ins" in registry.available() and "plug_broken" in registry.available()
    p = registry.resolve("plug_ins")
    assert p.origin == "entry point" and p.distribution == "plugtest 0.1"
    nav = registry.create("plug_ins")
    assert nav.name == "plug_ins"
    with pytest.raises(registry.PluginError, match=r"entry point 'plugtest_broken:Nav' of plugtest 0.1.*"
                                                   r"cannot import module 'plugtest_broken'.*boom"):
        registry.create("plug_broken")
    with pytest.raises(registry.PluginError, match="plug_thing.*not a navigator.*lacks reset"):
        registry.create("plug_thing")
    with pytest.raises(registry.PluginError, match="plugtest_broken"):
        registry.create_monitor("plug_mon_broken")


def test_plugin_taking_a_builtin_name_is_refused(plugin_dir, tmp_path):
    info = plugin_dir / "plugclash-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: plugclash\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[trn_env.navigators]\npmf = plugtest_nav:PlugIns\n")
    registry.refresh()
    try:
        with pytest.raises(registry.PluginError, match="takes the name of a built-in navigator"):
            registry.create("pmf", dem="jacksboro")
    finally:
        for f in info.iterdir():
            f.unlink()
        info.rmdir()
        registry.refresh()


# ------------------------------------------------------------------------------------------ scenarios, CLI

def test_scenario_accepts_plugins_and_reports_a_broken_one(plugin_dir):
    from trn_env.scenario.loading import ScenarioError, load_scenario
    sc = load_scenario("default", navigator="plug_ins")
    assert sc.navigator_name == "plug_ins"
    sc = load_scenario("default", navigator="plugtest_nav:PlugIns")
    assert sc.navigator_name == "plugtest_nav:PlugIns"
    with pytest.raises(ScenarioError) as err:
        load_scenario("default", navigator="plug_broken")
    assert any(p.startswith("navigator.name:") and "boom" in p for p in err.value.problems)


def test_cli_validate_and_fly_exit_2_on_a_broken_plugin(plugin_dir, tmp_path, capsys):
    sc = tmp_path / "broken.toml"
    text = (ROOT / "tests/scenarios/ins_only_short.toml").read_text()
    sc.write_text(text.replace('[navigator]\nname = "ins"', '[navigator]\nname = "plug_broken"'))
    assert "plug_broken" in sc.read_text()
    code, _, err = _cli(["validate", str(sc)], capsys)
    assert code == 2, err
    assert "navigator.name" in err and "plugtest_broken" in err and "boom" in err and "Traceback" not in err
    out_dir = str(tmp_path / "r")
    code, _, err = _cli(["fly", "default", "--navigator", "plug_broken", "--out", out_dir], capsys)
    assert code == 2 and "boom" in err and "Traceback" not in err
    code, _, err = _cli(["fly", "default", "--navigator", "plugtest_thing:Thing", "--out", out_dir], capsys)
    assert code == 2 and "lacks reset" in err and "Traceback" not in err
    assert not (tmp_path / "r").exists()


def test_cli_navigators_lists_builtins_and_plugins_with_settings(plugin_dir, capsys):
    code, out, err = _cli(["navigators", "--json"], capsys)
    assert code == 2                       # the broken plug-ins are reported ...
    listing = json.loads(out)
    assert any("plugtest_broken" in e and "boom" in e for e in listing["errors"])
    assert "plugtest_broken" in err
    by = {e["name"]: e for e in listing["plugins"]}                 # ... and everything else is listed
    for name in [*BUILTIN_NAVIGATORS, *BUILTIN_MONITORS, "plug_ins"]:
        assert name in by, name
    assert by["plug_ins"]["origin"].startswith("plug-in plugtest 0.1")
    pmf = {s["name"]: s for s in by["pmf"]["settings"]}
    assert pmf["spacing_min_m"]["unit"] == "m" and pmf["spacing_min_m"]["default"] == "2.0"
    assert pmf["spacing_max_m"]["meaning"]
    acq = {s["name"] for s in by["acq_track"]["settings"]}
    assert {"transect_samples", "sample_period_s"} <= acq               # AcqTrackConfig's fields
    assert "aiding" not in {s["name"] for s in by["ins"]["settings"]}   # fixed by the "ins" factory
    # the settings registry.create takes for every navigator, listed once beside them
    assert [s["name"] for s in listing["every_navigator_settings"]] == list(registry.PUBLISHED_INTEGRITY_KEYS)
    code, out, _ = _cli(["navigators", "pmf", "dem_integrity"], capsys)
    assert code == 0 and "spacing_min_m" in out and "n_window" in out
    assert "every navigator also takes" in out and "integrity_risk" in out
    code, out, _ = _cli(["navigators", "dem_integrity"], capsys)
    assert code == 0 and "every navigator also takes" not in out            # a monitor alone: not shown


# ------------------------------------------------------------------------------------------ env

def test_plugin_reference_in_async_vector_env(plugin_dir):
    """make_vec's async envs (forked workers) fly a plug-in given by reference."""
    import gymnasium as gym

    import trn_env  # noqa: F401 - registers the ids
    venv = gym.make_vec("trn_env/TerrainNav-v0", num_envs=2, vectorization_mode="async",
                        decision_interval_s=1.0, max_episode_s=3.0, navigator="plugtest_nav:PlugIns")
    try:
        obs, _ = venv.reset(seed=[0, 1])
        obs, rew, term, trunc, info = venv.step(np.zeros((2, 2), np.float32))
        assert np.all(np.isfinite(obs)) and np.all(np.isfinite(rew))
    finally:
        venv.close()


@pytest.mark.slow
def test_plugin_reference_in_spawned_vector_env(plugin_dir):
    """Spawned workers start from nothing: they import the plug-in from its reference (sys.path passes)."""
    import gymnasium as gym

    import trn_env  # noqa: F401
    venv = gym.make_vec("trn_env/TerrainNav-v0", num_envs=2, vectorization_mode="async",
                        vector_kwargs={"context": "spawn"}, decision_interval_s=1.0, max_episode_s=3.0,
                        navigator="plugtest_nav:PlugIns")
    try:
        obs, _ = venv.reset(seed=[0, 1])
        obs, *_ = venv.step(np.zeros((2, 2), np.float32))
        assert np.all(np.isfinite(obs))
    finally:
        venv.close()
