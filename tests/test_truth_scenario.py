"""The kinematic truth as a scenario choice ([truth] source = "kinematic"): it flies through the CLI into the
same output folder, the INS follows it as closely as the profile's own check demands, and bad [truth]
fields exit 2 naming the field."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest
from _ecef import ned_between
from _ins_truth import noise_free_ins_errors

import trn_env.scenario.build as components
from trn_env import cli
from trn_env.flight.truth import TruthChunk
from trn_env.scenario.loading import read_scenario_file, validate

BUILTIN = Path(components.__file__).parent / "builtin" / "seed002.toml"


def test_kinematic_scenario_flies_through_the_cli(tmp_path):
    """seed002 (240 m/s, beyond the King Air) through `trn-env fly`: the same files as a JSBSim run, and the
    logged truth is the profile: 240 m/s level along 18.1575 deg (distance and direction through ECEF)."""
    out = tmp_path / "run"
    assert cli.main(["fly", "seed002", "--out", str(out), "--quiet", "--duration", "10"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["truth_source"] == "kinematic" and summary["navigator"] == "rbpf"
    assert summary["termination"] == "time_limit" and summary["sim_time_s"] == pytest.approx(10.0)
    assert set(summary["files"]) >= {"summary.json", "log.npz", "timeline.csv", "track.png", "errors.png"}
    assert math.isfinite(summary["horizontal_error_rms_m"]) and summary["horizontal_error_rms_m"] < 150.0
    log = np.load(out / "log.npz")
    d = ned_between(log["true_lat_rad"][0], log["true_lon_rad"][0], log["true_h_msl_m"][0],
                    log["true_lat_rad"][-1], log["true_lon_rad"][-1], log["true_h_msl_m"][-1])[0]
    assert math.hypot(d[0], d[1]) == pytest.approx(2400.0, abs=1.0)      # 240 m/s x 10 s
    assert math.degrees(math.atan2(d[1], d[0])) == pytest.approx(18.1575, abs=0.01)
    assert np.ptp(log["true_h_msl_m"]) < 0.5 and abs(log["true_h_msl_m"][0] - 2500.0) < 1e-6


def _manoeuvring_scenario() -> dict:
    """seed002 with turns, a climb and a descent in a 20 m/s wind from the west, 150 s."""
    data, _ = read_scenario_file(BUILTIN)
    data = copy.deepcopy(data)
    data["duration_s"] = 150.0
    data["truth"]["segments"] = [
        {"kind": "straight", "duration_s": 20.0},
        {"kind": "turn", "duration_s": 40.0, "bank_deg": 25.0},
        {"kind": "climb", "duration_s": 30.0, "flight_path_deg": 4.0},
        {"kind": "straight", "duration_s": 30.0},
        {"kind": "turn", "duration_s": 30.0, "bank_deg": -20.0, "flight_path_deg": -3.0},
    ]
    data["initial"].update(lat_deg=36.55, lon_deg=-84.30, heading_deg=0.0)
    data["route"]["waypoints"] = [{"lat_deg": 36.55, "lon_deg": -84.30, "h_msl_m": 2500.0},
                                  {"lat_deg": 36.60, "lon_deg": -84.30, "h_msl_m": 2500.0}]
    data["wind"] = {"layers": [{"altitude_m": 0.0, "direction_from_deg": 270.0, "speed_mps": 20.0}]}
    return data


def test_ins_follows_the_scenario_kinematic_truth():
    """The flight a kinematic scenario builds (recorded in guidance ticks, taken per second, as the closed
    loop does) drives a noise-free IMU and the INS along it to the profile check's standard
    (tests/test_kinematic_truth.py: < 0.2 m and < 4 mm/s over 150 s), wind included: the ground velocity is
    the airspeed along the heading plus the wind."""
    sc = validate(_manoeuvring_scenario(), source="kinematic-test")
    world = components.build_terrain(sc, sc.extras, np.random.default_rng(0))[0]
    flight = components.build_flight(sc, world, np.random.default_rng(0))
    first = flight.snapshot()
    chunks = [first]
    for _ in range(150):
        for _ in range(10):
            flight.record(10)
        chunks.append(flight.take())
    t_s = np.concatenate([c.t_s for c in chunks])
    assert np.allclose(np.diff(t_s), 0.01) and t_s[-1] == pytest.approx(150.0)
    tr = TruthChunk.concatenate(chunks)
    # the wind: v = 240 m/s along the heading + 20 m/s toward the east, at every row
    cp = np.cos(tr.pitch_rad)
    air = 240.0 * np.stack([cp * np.cos(tr.yaw_rad), cp * np.sin(tr.yaw_rad), -np.sin(tr.pitch_rad)], axis=1)
    assert np.allclose(tr.v_ned_mps - air, [0.0, 20.0, 0.0], atol=1e-6)
    assert math.degrees(math.atan2(tr.v_ned_mps[0, 1], tr.v_ned_mps[0, 0])) == pytest.approx(
        math.degrees(math.atan2(20.0, 240.0)), abs=1e-6)          # crab in the first straight leg
    dn, de, dd, dv, _ = noise_free_ins_errors(tr)
    err = np.sqrt(dn**2 + de**2 + dd**2)
    assert err.max() < 0.2, err.max()
    assert dv.max() < 4e-3, dv.max()
    assert np.ptp(np.unwrap(tr.yaw_rad)) > math.radians(35) and np.ptp(tr.h_msl_m) > 100.0


BAD = [
    ('source = "kinematic"', 'source = "warp"', "truth.source"),
    ("speed_mps = 240.0", "speed_mps = nan", "truth.speed_mps"),
    ("speed_mps = 240.0", "speed_mps = inf", "truth.speed_mps"),
    ("speed_mps = 240.0", "speed_mps = -5.0", "truth.speed_mps"),
    ("speed_mps = 240.0", "speed_mps = 15.0", "truth.speed_mps"),          # slower than the 20 m/s wind
    ('{ kind = "straight", duration_s = 120.0 }', '{ kind = "turn", duration_s = 120.0 }',
     "truth.segments[0].bank_deg"),
    ('{ kind = "straight", duration_s = 120.0 }',
     '{ kind = "straight", duration_s = 10.0, transition_s = 20.0 }', "truth.segments[0].transition_s"),
    ('{ kind = "straight", duration_s = 120.0 }', '{ kind = "loop", duration_s = 120.0 }',
     "truth.segments[0].kind"),
    ('{ kind = "straight", duration_s = 120.0 }', '{ kind = "straight", duration_s = nan }',
     "truth.segments[0].duration_s"),
    ("segments = [{ kind = \"straight\", duration_s = 120.0 }]", "", "truth.segments"),
    ('source = "kinematic"', 'source = "jsbsim"', "truth.segments"),        # kinematic fields on JSBSim
    ("[sensors.imu]", "[wind]\nturbulence = { model = \"milspec\" }\n\n[sensors.imu]", "wind.turbulence"),
]


@pytest.mark.parametrize("old,new,field", BAD, ids=[b[2] + "-" + str(i) for i, b in enumerate(BAD)])
def test_bad_truth_fields_exit_2_naming_the_field(tmp_path, capsys, old, new, field):
    text = BUILTIN.read_text()
    assert old in text
    text = text.replace(old, new, 1)
    if "speed_mps = 15.0" in new:
        text = text.replace("[sensors.imu]", "[wind]\nlayers = [{ altitude_m = 0.0, direction_from_deg = "
                                             "270.0, speed_mps = 20.0 }]\n\n[sensors.imu]")
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    out = tmp_path / "never"
    assert cli.main(["fly", str(bad), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"{field}:" in err, err
    assert "Traceback" not in err
    assert not out.exists()
