"""The scenario build gives the DEM integrity monitor the navigator's error time constants (its GNSS-denied
path models the navigator's error as first-order Gauss-Markov in time, navigators.integrity.dem_monitor):
from the navigator's declared capabilities, unless the monitor's table gives them; bad values named."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
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


def _two_significant(x: float) -> float:
    return round(x, 1 - math.floor(math.log10(abs(x))))


def test_declared_time_constants_are_the_campaigns_fits():
    """Each terrain navigator declares the Gauss-Markov time constants fitted to its GNSS-denied error over
    the protection-level campaign's flights (docs/validation/integrity_error_time_constants.json, written by
    scripts/navigator_error_time_constants.py), to two significant figures."""
    doc = json.loads((Path(__file__).resolve().parents[1] / "docs" / "validation"
                      / "integrity_error_time_constants.json").read_text())
    assert set(doc) == {"ins_tercom", "pmf", "pf", "rbpf", "acq_track"}
    for name, fit in doc.items():
        caps = registry.capabilities(name)
        assert caps.error_time_constant_s == _two_significant(fit["tau_horizontal_s"]), name
        assert caps.height_time_constant_s == _two_significant(fit["tau_vertical_s"]), name


@pytest.mark.parametrize("tau_s", [8.0, 40.0, 150.0])
def test_time_constant_fit_recovers_a_gauss_markov_process(tau_s):
    """The script's autocorrelation and fit on simulated first-order Gauss-Markov series (the exact
    discrete recursion x' = exp(-1 / tau) x + sqrt(1 - exp(-2 / tau)) w at 1 s, stationary start): tau
    within 10 %."""
    from _scripts import load_script
    mod = load_script("navigator_error_time_constants")
    rng = np.random.default_rng(3)
    a = math.exp(-1.0 / tau_s)
    runs = []
    for _ in range(200):
        x = np.empty((390, 3))
        x[0] = rng.standard_normal(3)
        w = rng.standard_normal((390, 3)) * math.sqrt(1.0 - a * a)
        for k in range(1, 390):
            x[k] = a * x[k - 1] + w[k]
        runs.append(x)
    rho = mod.autocorrelation(runs, (0, 1), 60)
    assert mod.fit_tau(rho) == pytest.approx(tau_s, rel=0.1)
