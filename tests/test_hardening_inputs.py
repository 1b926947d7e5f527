"""Bad input refused before anything flies (issue 21 section 3) and the small things a user meets (section 5).

Every refusal: a problem naming the field (or file), and from the command line exit 2, no traceback,
nothing written.
"""

from __future__ import annotations

import copy
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from synthetic_terrain import jacksboro_with_a_void
from trn_env.navigators import registry

from trn_env import cli, terrain
from trn_env.scenario.loading import ScenarioError, read_scenario_file, validate

SCEN = Path(__file__).parent / "scenarios"
SHORT = (SCEN / "default_short.toml").read_text()
DEM = terrain.load("jacksboro")


def _data() -> dict:
    """default_short without its 30 m world refinement (beside the point here, and a test that builds the
    terrain or flies is quicker without it)."""
    data, _ = read_scenario_file(SCEN / "default_short.toml")
    data = copy.deepcopy(data)
    data["terrain"]["world"].pop("refinement", None)
    return data


def _problems(data: dict) -> list[str]:
    with pytest.raises(ScenarioError) as exc:
        validate(data, source="test")
    return exc.value.problems


def _set(data: dict, path: str, value):
    *head, last = path.split(".")
    node = data
    for key in head:
        node = node[int(key)] if isinstance(node, list) else node.setdefault(key, {})
    if isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value
    return data


@pytest.mark.parametrize("path,field", [
    ("duration_s", "duration_s"),                                   # flew with no limit
    ("gnss.outages.0.start_s", "gnss.outages[0].start_s"),          # dropped the outage
    ("limits.max_horizontal_sigma_m", "limits.max_horizontal_sigma_m"),   # turned divergence off
    ("guidance.rate_hz", "guidance.rate_hz"),                       # crashed validate itself
    ("initial.tas_mps", "initial.tas_mps"),                         # was reported as aircraft.settings
    ("initial_errors.position_ned_m.0", "initial_errors.position_ned_m[0]"),   # crashed in reset
    ("navigator.settings.fix_sigma_m", "navigator.settings.fix_sigma_m"),
    ("sensors.imu.gyro_bias_rps", "sensors.imu.gyro_bias_rps"),
    ("route.waypoints.1.lat_deg", "route.waypoints[1].lat_deg"),
])
def test_nan_and_infinity_refused_at_their_field(path, field):
    for value in (math.nan, math.inf, -math.inf):
        data = _data()
        if path.startswith("initial_errors"):
            data["initial_errors"] = {"position_ned_m": [30.0, 30.0, 15.0]}
        probs = _problems(_set(data, path, value))
        assert any(p.startswith(f"{field}:") for p in probs), (value, probs)
        assert not any(p.startswith("aircraft.settings") for p in probs), probs


@pytest.mark.parametrize("path,value", [
    ("initial.lat_deg", math.inf), ("initial.lon_deg", math.nan), ("initial.lat_deg", 95.0),
    ("initial.lon_deg", -181.0), ("route.waypoints.1.lat_deg", -91.0), ("route.waypoints.0.lon_deg", 181.0),
])
def test_a_position_off_the_earth_is_one_problem_at_its_field(path, value):
    """The schema's problem alone: it was followed by 'is outside the true terrain' and 'outside the
    navigator map' for the same place (with 'inf' or '95.00000' as its latitude)."""
    field = path.replace(".waypoints.1.", ".waypoints[1].").replace(".waypoints.0.", ".waypoints[0].")
    probs = _problems(_set(_data(), path, value))
    assert len(probs) == 1 and probs[0].startswith(f"{field}:"), probs


def test_a_position_on_the_earth_off_the_terrain_is_outside_both_dems():
    probs = _problems(_set(_data(), "initial.lat_deg", 40.0))
    assert [p.split(" deg is ", 1)[1].split(" terrain.")[0] for p in probs] == [
        "outside the true terrain", "outside the navigator map"], probs


@pytest.mark.parametrize("height", ["h_agl_m", "h_msl_m"])
def test_a_start_over_a_void_of_the_true_terrain_is_one_problem_naming_the_fix(tmp_path, capsys, height):
    """Validation passed a start over a void (h_msl_m), and fly then failed on 'Flight.terrain_elevation_m
    must be finite'; with h_agl_m it said 'InitialCondition.h_msl_m must be finite, got nan'."""
    data = _data()
    init = data["initial"]
    init.pop("h_agl_m", None)
    init.pop("h_msl_m", None)
    init[height] = 1500.0 if height == "h_agl_m" else 2500.0
    dem = str(jacksboro_with_a_void(tmp_path / "voids.npz", init["lat_deg"], init["lon_deg"]))
    data["terrain"]["world"]["dem"] = dem
    probs = _problems(copy.deepcopy(data))
    place = f"({init['lat_deg']:.5f}, {init['lon_deg']:.5f}) deg"
    assert probs == [f"initial: {place} is over a void of the true terrain terrain.world.dem (no height "
                     "there, and the flight starts on the ground's height): move the start, or set "
                     "terrain.world.fill_voids = true"], probs
    data["terrain"]["world"]["fill_voids"] = True
    validate(data, source="test")
    if height == "h_agl_m":                 # default_short's own start: refused before anything flies
        assert cli.main(["fly", str(SCEN / "default_short.toml"), "--set", f"terrain.world.dem={dem!r}",
                         "--duration", "5", "--no-plots", "--quiet", "--out", str(tmp_path / "run")]) == 2
        assert "is over a void of the true terrain" in capsys.readouterr().err
        assert not (tmp_path / "run").exists()


def test_zero_step_is_reported_not_a_crash():
    probs = _problems(_set(_data(), "aircraft.dt_s", 0.0))
    assert any(p.startswith("aircraft.dt_s:") for p in probs), probs
    probs = _problems(_set(_data(), "navigator.rate_hz", 0.0))
    assert any(p.startswith("navigator.rate_hz:") for p in probs), probs


BAD_SETTINGS = [
    ("accel_noise_mps2_rthz", -1e-4), ("gyro_noise_rps_rthz", math.nan), ("accel_bias_mps2", math.inf),
    ("gate_chi2", -3.0), ("min_samples", -5), ("half_cells", 0), ("fix_period_s", 0.0),
    ("dem", 5), ("dem", "/no/such/map.tif"), ("remove_bias", "yes"), ("gnss_sigma_h_m", -1.0),
    ("gnss_gate_chi2", math.nan), ("ira_decimation", 2.5), ("ira_average", 0), ("ira_average", 1.5),
]


@pytest.mark.parametrize("name,value", BAD_SETTINGS)
def test_navigator_settings_range_checked(name, value):
    kw = {} if name == "dem" else {"dem": DEM}
    with pytest.raises(ValueError, match=name):
        registry.create("ins_tercom", **kw, **{name: value})
    data = _data()
    data["navigator"]["settings"][name] = value
    probs = _problems(data)
    assert any(p.startswith(f"navigator.settings.{name}:") for p in probs), probs


def test_unknown_navigator_setting_named():
    data = _data()
    data["navigator"]["settings"]["colour"] = "red"
    assert any(p.startswith("navigator.settings.colour:") for p in _problems(data))


def test_above_service_ceiling_refused_naming_the_field():
    data = _data()
    data["initial"] = {"lat_deg": 36.49, "lon_deg": -84.37, "h_msl_m": 9500.0, "tas_mps": 85.0,
                       "heading_deg": 8.0}
    probs = _problems(data)
    assert any(p.startswith("initial.h_msl_m:") and "ceiling" in p for p in probs), probs
    data = _data()
    data["route"]["waypoints"][1] = {"lat_deg": 36.553, "lon_deg": -84.357, "h_agl_m": 8900.0}  # + ~400 m
    probs = _problems(data)
    assert any(p.startswith("route.waypoints[1].h_agl_m:") and "ceiling" in p for p in probs), probs


def test_sensor_faster_than_the_truth_step_refused_at_its_field():
    # a coarser JSBSim step leaves the IMU's default 100 Hz faster than the truth's 50 Hz steps: the flight
    # refused it only once the first sensor frame was sampled, and `validate` passed it
    data = _data()
    data["aircraft"] = {"dt_s": 0.02}
    probs = _problems(data)
    imu = [p for p in probs if p.startswith("sensors.imu.rate_hz:")]
    assert len(imu) == 1 and "100 Hz (the sensor's default)" in imu[0] and "50 Hz" in imu[0], probs
    ira_rate = data["sensors"]["ira"].get("rate_hz", 50.0)
    assert not any(p.startswith("sensors.ira") for p in probs) and ira_rate * 0.02 <= 1.0
    data["sensors"]["imu"]["rate_hz"] = 50.0          # exactly the truth's rate: accepted
    validate(data, source="test")
    data["sensors"]["imu"]["rate_hz"] = 50.5
    assert [p.split(":")[0] for p in _problems(data)] == ["sensors.imu.rate_hz"]


def test_sensor_faster_than_the_kinematic_truth_step_refused():
    data, _ = read_scenario_file("seed002")
    data = copy.deepcopy(data)
    data["aircraft"] = {**data.get("aircraft", {}), "dt_s": 0.05}
    probs = _problems(data)
    assert {p.split(":")[0] for p in probs} == {"sensors.imu.rate_hz", "sensors.ira.rate_hz"}, probs


def test_cli_sensor_rate_refused_before_flying(tmp_path, capsys):
    out = tmp_path / "out"
    code = cli.main(["fly", str(SCEN / "default_short.toml"), "--quiet", "--no-plots", "--out", str(out),
                     "--set", "sensors.ira.rate_hz=1e9"])
    err = capsys.readouterr().err
    assert code == 2 and "sensors.ira.rate_hz: 1e+09 Hz" in err and "Traceback" not in err
    assert not out.exists()
    assert cli.main(["validate", "default", "--set", "aircraft.dt_s=0.02"]) == 2
    assert "sensors.imu.rate_hz" in capsys.readouterr().err


def test_initial_estimate_nan_refused_by_the_navigator():
    from trn_env.navigators.filters.ins_trn_ekf import initial_covariance
    from trn_env.navigators.protocol import Estimate
    nav = registry.create("ins")
    with pytest.raises(ValueError, match="initial"):
        nav.reset(Estimate(0.0, 0.6, -1.4, math.nan, np.zeros(3), 0.0, 0.0, 0.0, initial_covariance()))


# ------------------------------------------------------------------------------------- command line

def _cli(tmp_path, *args, scenario_text: str | None = None, scenario: str | None = None, capsys=None):
    if scenario is None:
        p = tmp_path / "s.toml"
        p.write_text(scenario_text if scenario_text is not None else SHORT)
        scenario = str(p)
    code = cli.main(["fly", scenario, "--quiet", "--no-plots", *args])
    err = capsys.readouterr().err if capsys is not None else ""
    return code, err


@pytest.mark.parametrize("old,new,field", [
    ("duration_s = 150.0", "duration_s = nan", "duration_s"),
    ("outages = [{ start_s = 10.0 }]", "outages = [{ start_s = nan }]", "gnss.outages[0].start_s"),
    ("[aircraft]", "", ""),     # placeholder replaced below
])
def test_cli_refuses_with_exit_2_nothing_written(tmp_path, capsys, old, new, field):
    text = SHORT.replace(old, new) if old != "[aircraft]" else SHORT + "\n[aircraft]\ndt_s = 0.0\n"
    field = field or "aircraft.dt_s"
    out = tmp_path / "out"
    code, err = _cli(tmp_path, "--out", str(out), scenario_text=text, capsys=capsys)
    assert code == 2 and field in err and "Traceback" not in err
    assert not out.exists() and not list(tmp_path.glob(".out*"))


def test_cli_out_checked_before_flying(tmp_path, capsys):
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    for out in (a_file, a_file / "sub" / "run"):
        code, err = _cli(tmp_path, "--out", str(out), capsys=capsys)
        assert code == 2 and "--out" in err and "nothing flown" in err
    assert a_file.read_text() == "x"


def test_cli_directory_as_scenario(tmp_path, capsys):
    code, err = _cli(tmp_path, "--out", str(tmp_path / "o"), scenario=str(tmp_path), capsys=capsys)
    assert code == 2 and "is a directory" in err and "no such" not in err


def test_cli_device_or_pipe_as_scenario_is_not_called_missing(tmp_path, capsys):
    fifo = tmp_path / "pipe.toml"
    os.mkfifo(fifo)
    for path in (os.devnull, str(fifo)):
        code, err = _cli(tmp_path, "--out", str(tmp_path / "o"), scenario=path, capsys=capsys)
        assert code == 2 and "file: not a regular file" in err and "no such" not in err
    assert not (tmp_path / "o").exists()


def test_cli_subprocess_nan_exit_2_no_traceback(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(SHORT.replace("duration_s = 150.0", "duration_s = inf"))
    r = subprocess.run([sys.executable, "-m", "trn_env.cli", "validate", str(p)], capture_output=True,
                       text=True, cwd=tmp_path, timeout=120)
    assert r.returncode == 2 and "duration_s" in r.stderr and "Traceback" not in r.stderr


# ------------------------------------------------------------------------------------- section 5

def test_dem_and_load_input_errors():
    h = DEM.heights_m.copy()
    h[3, 4] = np.inf
    with pytest.raises(ValueError, match="infinite"):
        terrain.Dem(h, DEM.lat0_rad, DEM.lon0_rad, DEM.dlat_rad, DEM.dlon_rad)
    with pytest.raises(ValueError, match="lat_rad"):
        DEM.height(None, None)
    with pytest.raises(ValueError, match="DEM name"):
        terrain.load(None)
    assert math.isfinite(DEM.height(*DEM.center_rad))


def test_route_the_aircraft_cannot_climb_to_is_not_completed():
    """The 7 km leg ends at 8,500 m MSL (below the ceiling) from 1,800 m: ~6.7 km of climb in ~80 s is
    beyond the King Air (sea-level climb ~10 m/s), so the route's guidance finishes with the aircraft far
    below: route_not_followed, and the summary says what happened."""
    from trn_env.sim.closed_loop import ClosedLoop
    data = _data()
    data["navigator"] = {"name": "ins"}
    data["route"]["waypoints"][1] = {"lat_deg": 36.553, "lon_deg": -84.357, "h_msl_m": 8500.0}
    res = ClosedLoop(validate(data, source="test")).run()
    assert res.termination == "route_not_followed"
    assert "8500 m" in res.summary["route_not_followed"] and "route.waypoints[1]" in res.summary[
        "route_not_followed"]
    assert any(src == "sim" and "could not follow" in msg for _, src, msg in res.events)


def test_timeline_columns_say_what_they_are():
    from trn_env.output.run_folder import TIMELINE_COLUMNS
    assert "est_h_msl_m" in TIMELINE_COLUMNS and "err_horizontal_m" in TIMELINE_COLUMNS
    assert "est_h_m" not in TIMELINE_COLUMNS and "err_h_m" not in TIMELINE_COLUMNS


def test_plot_helpers():
    from trn_env.output import plots
    assert [plots._nice(x) for x in (0.7, 3.0, 7.4, 19.0, 6800.0)] == [0.5, 2.0, 5.0, 10.0, 5000.0]
    src = Path(plots.__file__).read_text()
    assert "3 hypot(sigma_N, sigma_E)" in src and "_scale_bar(ax" in src


def test_interp_one_matches_numpy():
    from trn_env.navigators.filters._ekf_kernels import interp_one
    rng = np.random.default_rng(1)
    xp = np.cumsum(rng.uniform(0.1, 1.0, 50))
    fp = rng.standard_normal(50)
    xs = np.concatenate([rng.uniform(xp[0] - 2, xp[-1] + 2, 500), xp, [np.nan]])
    got = np.array([interp_one(x, xp, fp) for x in xs])
    assert np.array_equal(got, np.interp(xs, xp, fp), equal_nan=True)


def test_perfectly_known_start_is_accepted_negative_variance_refused():
    """Zero initial sigmas (legal) used to crash the EKF reset; a negative eigenvalue is refused."""
    from trn_env.navigators.filters.ins_trn_ekf import initial_covariance
    from trn_env.navigators.protocol import Estimate
    nav = registry.create("ins")
    nav.reset(Estimate(0.0, 0.6, -1.4, 1000.0, np.zeros(3), 0.0, 0.0, 0.0, np.zeros((9, 9))))
    assert np.all(np.isfinite(nav.estimate().covariance))
    bad = initial_covariance()
    bad[0, 0] = -1.0
    with pytest.raises(ValueError, match="semi-definite"):
        nav.reset(Estimate(0.0, 0.6, -1.4, 1000.0, np.zeros(3), 0.0, 0.0, 0.0, bad))


def _data_over_the_antimeridian(tmp_path) -> dict:
    """default_short over the bundled DEM's heights moved to 0.10 S-0.19 N, 179.90-180.24 deg E (a DEM
    crossing the antimeridian), as world and map."""
    from trn_env.terrain.dem import Dem
    from trn_env.terrain.loaders import save_npz

    jacks = terrain.load("jacksboro")
    across = Dem(np.array(jacks.heights_m), math.radians(-0.1), math.radians(179.9), jacks.dlat_rad,
                 jacks.dlon_rad, "across 180")
    data = _data()
    data["terrain"]["world"]["dem"] = str(save_npz(across, tmp_path / "across.npz"))
    data["terrain"]["map"]["dem"] = "world"
    return data


def test_a_place_across_the_antimeridian_of_a_dem_crossing_it_is_named_so(tmp_path):
    """A DEM crossing 180 deg is read at longitudes beyond 180; a place on its other side (written, as the
    schema wants, at -179.x) was only 'outside the true terrain (lon 179.9..180.1 deg)'."""
    data = _data_over_the_antimeridian(tmp_path)
    data["initial"].update(lat_deg=0.0, lon_deg=179.95)
    data["route"]["waypoints"] = [{**wp, "lat_deg": 0.01 * k, "lon_deg": 179.96 + 0.01 * k}
                                  for k, wp in enumerate(data["route"]["waypoints"][:2])]
    validate(copy.deepcopy(data), source="test")                            # all on the DEM's 179.x side
    data["route"]["waypoints"][1]["lon_deg"] = -179.97
    probs = _problems(copy.deepcopy(data))
    assert len(probs) == 1 and probs[0].startswith("route.waypoints[1]: (0.01000, -179.97000) deg is outside "
                                                   "the true terrain"), probs
    assert "the DEM crosses the antimeridian and this place lies on its other side" in probs[0]
    data["route"]["waypoints"][1].update(lat_deg=1.0, lon_deg=179.97)       # merely off the DEM
    assert "antimeridian" not in " ".join(_problems(copy.deepcopy(data)))


def test_a_flight_reaching_the_antimeridian_ends_off_map_said_so_with_sound_metrics(tmp_path):
    """The aircraft flying east across 180 deg over a DEM crossing it: JSBSim's longitude wraps to -180 and
    the flight ends off the map. Its summary said a 40,088 km final error, an ANEES of 1e12 and a distance
    flown as long; the error is now taken the short way round (checked against the ECEF chord), and an
    event says why the flight ended."""
    from trn_env.terrain.geodesy import lla_to_ecef

    from trn_env.sim import error_ned_m, run_scenario

    data = _data_over_the_antimeridian(tmp_path)
    # eastbound 550 m short of 180 deg, the route back west: the turn (radius ~1.5 km) crosses it
    data["initial"].update(lat_deg=0.0, lon_deg=179.995, heading_deg=90.0)
    data["route"]["waypoints"] = [{**wp, "lat_deg": 0.0, "lon_deg": lon}
                                  for wp, lon in zip(data["route"]["waypoints"][:2], (179.995, 179.95),
                                                     strict=True)]
    data["duration_s"] = 120.0
    result = run_scenario(data, pipeline=False)
    s = result.summary
    assert s["termination"] == "off_map"
    assert any("crossed the antimeridian" in str(e) for e in result.events), result.events
    assert s["horizontal_error_max_m"] < 200.0 and s["distance_flown_m"] < 10_000.0, s

    lat, lon = math.radians(0.01), math.radians(179.9999)
    est_lat, est_lon = math.radians(0.0101), math.radians(-179.9998)        # ~33 m east, 11 m north
    err = error_ned_m(np.array([lat]), np.array([lon]), np.array([1000.0]), est_lat, est_lon, 1000.0)[0]
    chord = np.subtract(lla_to_ecef(est_lat, est_lon, 1000.0), lla_to_ecef(lat, lon, 1000.0))
    assert math.hypot(err[0], err[1]) == pytest.approx(np.linalg.norm(chord), rel=1e-4)
    assert err[1] > 0.0
