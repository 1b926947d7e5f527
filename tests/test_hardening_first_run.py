"""The first run is visible and its compile stays out of the figures (issue 21 section 2): a status line
before the flight, the kernels warmed up before the progress bar starts, the real-time factor over the
flight alone, the bar full when the route completes before the time limit, and the warm-up leaves the
flight's results bit for bit as they were."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np

from trn_env import cli
from trn_env.scenario.build import build_terrain
from trn_env.scenario.loading import read_scenario_file, validate
from trn_env.sim.closed_loop import ClosedLoop, spawn_rngs
from trn_env.sim.warm_up import warm_up

SCEN = Path(__file__).parent / "scenarios"


def test_status_line_full_bar_and_realtime_factor_of_the_flight(tmp_path, capsys):
    out = tmp_path / "run"
    text = (SCEN / "default_short.toml").read_text().replace("refinement = { spacing_m = 30.0 }", "")
    (tmp_path / "default_short.toml").write_text(text)       # (no 30 m world to build: quicker)
    code = cli.main(["fly", str(tmp_path / "default_short.toml"), "--out", str(out), "--no-plots"])
    err = capsys.readouterr().err
    assert code == 0
    assert "numba kernels" in err and "first run only" in err and "ready after" in err
    assert err.index("ready after") < err.index("fly default_short")      # before the bar starts
    s = json.loads((out / "summary.json").read_text())
    assert s["termination"] == "completed" and s["sim_time_s"] < 0.7 * s["duration_limit_s"]
    last = [ln for ln in err.replace("\r", "\n").splitlines() if ln.startswith("fly default_short")][-1]
    assert "100%" in last, last                                            # not 55 % of the time limit
    assert s["warm_up_wall_time_s"] > 0.0
    assert s["realtime_factor"] == s["sim_time_s"] / s["wall_time_s"]       # the flight's wall time alone


def test_warm_up_leaves_the_flight_bit_for_bit():
    data, _ = read_scenario_file(SCEN / "default_short.toml")
    data = copy.deepcopy(data)
    data["duration_s"] = 12.0
    data["terrain"]["world"].pop("refinement")
    sc = validate(data, source="test")
    plain = ClosedLoop(sc).run()
    dems = build_terrain(sc, sc.extras, spawn_rngs(sc.seed)["map"])
    assert warm_up(sc, dems) > 0.0
    warmed = ClosedLoop(sc, dems=dems).run()
    assert plain.arrays.keys() == warmed.arrays.keys()
    for k, v in plain.arrays.items():
        assert np.array_equal(v, warmed.arrays[k], equal_nan=True), k
    assert plain.events == warmed.events
