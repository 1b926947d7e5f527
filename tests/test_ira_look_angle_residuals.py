"""scripts/ira_look_angle_residuals.py on a recorded flight: its residuals at the truth on the world are the
IRA simulator's own noise (the sensor's samples come from terrain.queries' exact closest point, the script's
prediction from ira_seed002's search), and bad input exits 2 before anything is written."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from _scripts import load_script

from trn_env.logs.record import record
from trn_env.scenario.overrides import load_scenario_with

SCEN = Path(__file__).parent / "scenarios"
LOOK_ANGLE_NOISE_DEG = 0.5   # five times the default, so that the check sees the simulator's noise alone

residuals = load_script("ira_look_angle_residuals")


@pytest.fixture(scope="module")
def log_path(tmp_path_factory):
    """45 s of the default route with the IRA's look-angle noise at 0.5 deg and a lever arm (compensated
    by the script as a replay does)."""
    sc = load_scenario_with(SCEN / "default_short.toml",
                            [("sensors.ira.look_angle_noise_deg", LOOK_ANGLE_NOISE_DEG),
                             ("sensors.ira.lever_arm_b_m", [0.5, 0.3, 1.2])],
                            navigator="ins_tercom", duration_s=45.0, seed=3)
    _, path = record(sc, tmp_path_factory.mktemp("ira_res") / "flight.trnlog", pipeline=False)
    return path


def test_residuals_on_the_world_are_the_sensors_noise(log_path):
    """44 epochs: the look angle's robust sigma on the world within 0.7-1.3 times the sensor's 0.5 deg (its
    standard error over 44 samples ~0.12 sigma); on the map larger (the map lacks the world's 30 m detail);
    the flight's ranges (~1,500 m) keep the 1,500 m calibration, so --calibration-height-m 1500 gives the
    same figures, and another height other model figures."""
    m = residuals.residuals(log_path)
    assert m["epochs"] >= 40
    assert 0.7 < m["theta_robust_sigma_world_deg"] / LOOK_ANGLE_NOISE_DEG < 1.3, m
    assert m["theta_robust_sigma_map_deg"] > m["theta_robust_sigma_world_deg"]
    assert residuals.residuals(log_path, 1500.0) == m
    other = residuals.residuals(log_path, 600.0)
    assert other["theta_model_sigma_deg"] > m["theta_model_sigma_deg"]
    assert other["theta_robust_sigma_map_deg"] == m["theta_robust_sigma_map_deg"]
    assert all(math.isfinite(v) for v in m.values() if isinstance(v, float))


def test_the_command_writes_its_json_and_refuses_bad_input(log_path, tmp_path, capsys):
    out = tmp_path / "res.json"
    assert residuals.main([str(log_path), "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert len(doc) == 1 and doc[0]["epochs"] >= 40
    for argv, what in (([str(tmp_path / "missing")], "no such folder"),
                       ([str(log_path), "--calibration-height-m", "-5"], "--calibration-height-m"),
                       ([str(log_path), "--calibration-height-m", "nan"], "--calibration-height-m"),
                       ([str(log_path), "--json", str(tmp_path)], "--json"),
                       ([str(log_path), "--json", str(tmp_path / "x.txt")], "--json")):
        with pytest.raises(SystemExit) as exc:
            residuals.main(argv + (["--json", str(tmp_path / "bad.json")] if "--json" not in argv else []))
        assert exc.value.code == 2
        assert what in capsys.readouterr().err
        assert not (tmp_path / "bad.json").exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    assert residuals.main([str(empty), "--json", str(tmp_path / "bad.json")]) == 2
    assert "error:" in capsys.readouterr().err and not (tmp_path / "bad.json").exists()
