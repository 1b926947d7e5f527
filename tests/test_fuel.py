"""Fuel: the scenario's initial fuel load, the run ended by an engine stop, constant fuel for long flights.

The model's fuel flow itself is validated against published C90 figures in test_aircraft_performance.py.
"""

from __future__ import annotations

import copy
import json
import math

import pytest

from trn_env import cli
from trn_env.flight.core import Flight, InitialCondition
from trn_env.scenario.loading import ScenarioError, read_scenario_file, validate
from trn_env.sim.closed_loop import TERMINATIONS, ClosedLoop

KG_PER_LB = 0.45359237
CAPACITY_KG = 2 * 582.0        # kingair.xml: two 582 kg wing tank groups (1,454 L of Jet-A)
# Bounds on how long fuel lasts, from the engine file alone: both PT6As at most at 550 shp x 1.3 (the top of
# EnginePowerVC) and 0.63 lb/shp/h, at least at flight idle (Willans intercept 0.2 x 347 lb/h each, x 0.5
# for the lowest EnginePowerVC).
MAX_BURN_KGPS = 2 * 550.0 * 1.3 * 0.63 * KG_PER_LB / 3600.0
MIN_BURN_KGPS = 2 * 0.2 * 347.0 * 0.5 * KG_PER_LB / 3600.0


def _data(duration_s: float, **aircraft) -> dict:
    """The default scenario, INS only, cut to duration_s, with `aircraft` keys added."""
    data, _ = read_scenario_file("default")
    data = copy.deepcopy(data)
    data["duration_s"] = duration_s
    data["navigator"] = {"name": "ins"}
    data.setdefault("aircraft", {}).update(aircraft)
    return data


@pytest.mark.parametrize("value", [float("nan"), float("inf"), -1.0, 0.0, CAPACITY_KG + 1.0, "full", True])
def test_fuel_kg_must_be_finite_positive_and_fit_the_tanks(value):
    with pytest.raises(ScenarioError) as err:
        validate(_data(60.0, fuel_kg=value), source="test", check_components=False)
    mine = [p for p in err.value.problems if p.startswith("aircraft.fuel_kg")]
    assert mine and not any("unknown key" in p for p in mine), err.value.problems


def test_fuel_kg_and_constant_fuel_are_checked_once_and_typed():
    with pytest.raises(ScenarioError, match=r"aircraft.fuel_kg: give the fuel load once"):
        validate(_data(60.0, fuel_kg=300.0, settings={"fuel_fraction": 0.5}), source="test",
                 check_components=False)
    with pytest.raises(ScenarioError, match=r"aircraft.constant_fuel"):
        validate(_data(60.0, constant_fuel="yes"), source="test", check_components=False)
    with pytest.raises(ValueError, match="InitialCondition.fuel_kg"):
        InitialCondition(0.6, -1.5, 1500.0, 85.0, fuel_kg=float("nan"))
    with pytest.raises(ValueError, match="InitialCondition.fuel_kg: 2000.0 kg is more than"):
        Flight(InitialCondition(0.6, -1.5, 1500.0, 85.0, fuel_kg=2000.0))


def test_initial_fuel_load_is_written_to_the_tanks():
    """aircraft.fuel_kg = 300: JSBSim's tanks hold 150 kg each, and the aircraft is lighter than the default
    (full, 1,164 kg) by exactly the fuel not loaded."""
    full = ClosedLoop(validate(_data(60.0), source="full"), pipeline=False)
    part = ClosedLoop(validate(_data(60.0, fuel_kg=300.0), source="part"), pipeline=False)
    try:
        fdm = part.flight.fdm
        for i in range(2):
            assert fdm[f"propulsion/tank[{i}]/contents-lbs"] * KG_PER_LB == pytest.approx(150.0, abs=1e-6)
        assert full.flight.fuel_kg == pytest.approx(CAPACITY_KG, abs=1e-6)
        dm_kg = (full.flight.fdm["inertia/weight-lbs"] - fdm["inertia/weight-lbs"]) * KG_PER_LB
        assert dm_kg == pytest.approx(CAPACITY_KG - 300.0, abs=0.01)
    finally:
        full.close()
        part.close()


def test_run_out_of_fuel_ends_fuel_exhausted_in_summary_and_table(tmp_path, capsys):
    """2 kg of fuel: `trn-env fly` ends the run `fuel_exhausted` (not a glide to terrain_collision) once the
    engines stop, within the time 2 kg lasts between the engines' highest and lowest possible burn; the
    summary, the summary table and events.csv say so."""
    scen = tmp_path / "dry.toml"
    scen.write_text(_toml_of_default_with("fuel_kg = 2.0"))
    out = tmp_path / "run"
    code = cli.main(["fly", str(scen), "--out", str(out), "--navigator", "ins", "--duration", "300",
                     "--no-pipeline"])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["termination"] == "fuel_exhausted" and "fuel_exhausted" in TERMINATIONS
    t_end = summary["sim_time_s"]
    assert 2.0 / MAX_BURN_KGPS - 1.0 <= t_end <= 2.0 / MIN_BURN_KGPS + 1.0
    assert summary["fuel_remaining_kg"] == 0.0
    assert summary["min_true_agl_m"] > 500.0     # ended at the engine stop, not on the ground
    printed = capsys.readouterr().out
    assert "termination" in printed and "fuel_exhausted" in printed
    events = (out / "events.csv").read_text()
    assert "fuel tank 0, 1 empty" in events and "termination: fuel_exhausted" in events


def _toml_of_default_with(aircraft_line: str) -> str:
    """The built-in default scenario's TOML with one line added to its [aircraft] table."""
    from importlib import resources
    text = (resources.files("trn_env.scenario.builtin") / "default.toml").read_text(encoding="utf-8")
    assert "\n[aircraft]\n" in text
    return text.replace("\n[aircraft]\n", f"\n[aircraft]\n{aircraft_line}\n", 1)


def test_engine_cut_off_with_fuel_on_board_ends_engine_failure():
    loop = ClosedLoop(validate(_data(60.0), source="cut"), pipeline=False)
    try:
        assert loop.tick() is None
        loop.flight.fdm["propulsion/active_engine"] = 1
        loop.flight.fdm["propulsion/cutoff_cmd"] = 1
        reason = None
        while reason is None:
            reason = loop.tick()
        assert reason == "engine_failure" and loop.t_s <= 3.0
        assert any("engine 1 stopped" in msg for _, src, msg in loop.log.events if src == "flight")
    finally:
        loop.close()


def test_constant_fuel_keeps_the_tanks_full_where_they_would_run_dry():
    """2 kg with aircraft.constant_fuel = true: 100 s (the same flight without it runs dry in ~40 s: the
    next test) flown to the time limit with the tank contents unchanged to the bit at every update."""
    loop = ClosedLoop(validate(_data(100.0, fuel_kg=2.0, constant_fuel=True), source="const"),
                      pipeline=False)
    try:
        fdm = loop.flight.fdm
        tanks0 = [fdm[f"propulsion/tank[{i}]/contents-lbs"] for i in range(2)]
        reason = None
        while reason is None:
            reason = loop.tick()
            assert [fdm[f"propulsion/tank[{i}]/contents-lbs"] for i in range(2)] == tanks0
        assert reason == "time_limit"
        assert all(fdm[f"propulsion/engine[{i}]/set-running"] == 1.0 for i in range(2))
    finally:
        loop.close()


def test_without_constant_fuel_the_same_flight_runs_dry():
    """The control for the test above: the same 2 kg, fuel not held, burns out inside the 100 s."""
    loop = ClosedLoop(validate(_data(100.0, fuel_kg=2.0), source="dry"), pipeline=False)
    try:
        reason = None
        while reason is None:
            reason = loop.tick()
        assert reason == "fuel_exhausted" and math.isclose(loop.flight.fuel_kg, 0.0, abs_tol=1e-9)
    finally:
        loop.close()


def test_env_episode_ends_terminated_when_the_fuel_runs_out():
    """TerrainNav-v0 on 2 kg of fuel: the episode is terminated (not truncated) with info termination
    fuel_exhausted, well inside max_episode_s."""
    import numpy as np

    from trn_env.env.terrain_nav import TerrainNavEnv
    e = TerrainNavEnv(validate(_data(600.0, fuel_kg=2.0), source="dry"), decision_interval_s=5.0,
                      max_episode_s=300.0, navigator="ins")
    try:
        e.reset(seed=0)
        term = trunc = False
        info: dict = {}
        while not (term or trunc):
            _, _, term, trunc, info = e.step(np.zeros(2, np.float32))
        assert term and not trunc and info["termination"] == "fuel_exhausted"
        assert info["t_s"] < 2.0 / MIN_BURN_KGPS + 5.0
    finally:
        e.close()
