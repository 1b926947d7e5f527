"""A void in the navigator's map (SRTM and DTED have them, over water and steep slopes): the terrain filters
skip a terrain sample while most of their belief lies where the map has no height, instead of scoring the
hypotheses that have a height alone (navigators.filters.terrain_filter.MAX_MASS_WITHOUT_MAP)."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_terrain import jacksboro_with_a_void
from trn_env.navigators.filters import terrain_filter

from trn_env.scenario.overrides import load_scenario_with
from trn_env.sim.closed_loop import ClosedLoop


def _fly(map_dem, navigator: str) -> tuple[float, dict]:
    """The built-in default flight for 240 s (the second waypoint, under the void, at ~200 s): the largest
    horizontal error from 150 s on, and the summary."""
    fields = [("terrain.map.dem", str(map_dem))] if map_dem is not None else []
    sc = load_scenario_with("default", fields, navigator=navigator, duration_s=240.0, seed=0)
    run = ClosedLoop(sc, pipeline=False).run()
    t, err = run.arrays["t_s"], run.arrays["err_ned_m"]
    return float(np.hypot(err[:, 0], err[:, 1])[t >= 150.0].max()), run.summary


@pytest.mark.slow
def test_a_void_under_the_route_does_not_move_the_pmf(tmp_path, monkeypatch):
    """An 11 x 11 post (~1 km) void around the second waypoint: the pmf's error over it stays within 10 m
    of the same flight's over the intact map; scoring the grid's cells that have a height alone (the rule
    switched off) took it 200 m off."""
    void = jacksboro_with_a_void(tmp_path / "map.npz", 36.64, -84.34)
    intact, _ = _fly(None, "pmf")
    over_void, summary = _fly(void, "pmf")
    assert over_void <= intact + 10.0, (over_void, intact)
    assert summary["navigator_skipped"].get("belief_over_map_void", 0) > 0
    monkeypatch.setattr(terrain_filter, "MAX_MASS_WITHOUT_MAP", 1.0)
    without_the_rule, _ = _fly(void, "pmf")
    assert without_the_rule > 100.0, without_the_rule
