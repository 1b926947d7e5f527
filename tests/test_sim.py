"""The closed loop: seeding, initial errors, GNSS gating, logging, terminations, determinism."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from _ecef import ned_between as ned_vector_between
from _runs import assert_same_run
from trn_env.navigators.frames import GnssFrame, SensorFrames
from trn_env.navigators.protocol import Estimate

import trn_env.scenario.build as components
from trn_env.flight.truth import TruthChunk
from trn_env.scenario.loading import ScenarioError, read_scenario_file, validate
from trn_env.sim.closed_loop import (
    ClosedLoop,
    perturbed_estimate,
    spawn_rngs,
)
from trn_env.sim.nav_stage import gate_gnss as _gate_gnss
from trn_env.sim.nav_stage import gnss_available_mask


def _data(**changes) -> dict:
    data, _ = read_scenario_file("default")
    data = copy.deepcopy(data)
    data.update(changes)
    return data


def _short(duration_s: float, navigator: str = "ins", **changes) -> dict:
    """The default scenario, cut to duration_s, INS-only unless told otherwise (cheap)."""
    data = _data(duration_s=duration_s, **changes)
    data["navigator"] = {"name": navigator}
    return data


def test_spawn_rngs_reproducible_and_independent():
    a, b, c = spawn_rngs(5), spawn_rngs(5), spawn_rngs(6)
    assert set(a) == {"flight", "sensors", "map", "initial_errors", "navigator"}
    draws_a = {k: g.standard_normal(4) for k, g in a.items()}
    draws_b = {k: g.standard_normal(4) for k, g in b.items()}
    draws_c = {k: g.standard_normal(4) for k, g in c.items()}
    for k in draws_a:
        assert np.array_equal(draws_a[k], draws_b[k])
        assert not np.array_equal(draws_a[k], draws_c[k])
    vals = list(draws_a.values())
    assert all(not np.array_equal(vals[0], v) for v in vals[1:])


def test_initial_estimate_errors_have_table2_sigmas():
    """Errors measured through ECEF (independent of the eq-2 radii used to apply them)."""
    chunk = TruthChunk.empty(1)
    chunk.t_s[:] = 0.0
    chunk.lat_rad[:] = math.radians(36.5)
    chunk.lon_rad[:] = math.radians(-84.3)
    chunk.h_msl_m[:] = 2000.0
    chunk.v_ned_mps[:] = [80.0, 10.0, 0.0]
    chunk.roll_rad[:] = 0.0
    chunk.pitch_rad[:] = 0.02
    chunk.yaw_rad[:] = 0.1
    sig = {"position_ned_m": [30.0, 30.0, 15.0], "velocity_ned_mps": [0.1, 0.1, 0.1],
           "attitude_mrad": [0.05, 0.05, 1.0]}
    rng = np.random.default_rng(1)
    n = 3000
    ests = [perturbed_estimate(chunk, 0, sig, rng) for _ in range(n)]
    lat = np.array([e.lat_rad for e in ests])
    lon = np.array([e.lon_rad for e in ests])
    h = np.array([e.h_m for e in ests])
    d = ned_vector_between(np.full(n, chunk.lat_rad[0]), np.full(n, chunk.lon_rad[0]), np.full(n, 2000.0),
                           lat, lon, h)
    std = d.std(axis=0)
    # sample std of n normal draws: relative standard error 1/sqrt(2n) = 1.3 %; allow 5 %
    assert np.allclose(std, [30.0, 30.0, 15.0], rtol=0.05), std
    dv = np.array([e.v_ned_mps for e in ests]) - chunk.v_ned_mps[0]
    assert np.allclose(dv.std(axis=0), 0.1, rtol=0.05)
    dyaw = np.array([e.yaw_rad for e in ests]) - 0.1
    assert np.isclose(dyaw.std(), 1e-3, rtol=0.05)
    assert np.allclose(np.diag(ests[0].covariance), [900, 900, 225, 0.01, 0.01, 0.01, 2.5e-9, 2.5e-9, 1e-6])


def test_gnss_gating():
    t = np.arange(0.0, 10.0, 1.0)
    outages = [{"start_s": 2.0, "end_s": 4.0}, {"start_s": 7.0}]
    assert gnss_available_mask(t, outages).tolist() == [1, 1, 0, 0, 1, 1, 1, 0, 0, 0]
    g = GnssFrame(t_s=t, lat_rad=t * 0, lon_rad=t * 0, h_m=t, v_ned_mps=np.zeros((10, 3)), valid=t >= 0)
    fr = _gate_gnss(SensorFrames(0.0, 10.0, gnss=g), outages)
    assert fr.gnss.t_s.tolist() == [0.0, 1.0, 4.0, 5.0, 6.0]
    assert fr.gnss.h_m.tolist() == [0.0, 1.0, 4.0, 5.0, 6.0]
    g2 = GnssFrame(t_s=t[8:], lat_rad=t[8:], lon_rad=t[8:], h_m=t[8:], v_ned_mps=np.zeros((2, 3)),
                   valid=t[8:] >= 0)
    assert _gate_gnss(SensorFrames(8.0, 10.0, gnss=g2), outages).gnss is None


@pytest.fixture(scope="module")
def short_run():
    sc = validate(_short(20.0, navigator="ins_tercom"), source="test")
    loop = ClosedLoop(sc)
    return loop, loop.run()


def test_short_run_log_and_summary(short_run):
    loop, res = short_run
    a = res.arrays
    assert res.termination == "time_limit"
    assert res.jsbsim_steps == 2000
    n = a["t_s"].shape[0]
    assert n == 21                                   # t = 0 and every 1 s navigator update
    assert np.allclose(np.diff(a["t_s"]), 1.0)
    assert np.allclose(a["est_t_s"], a["t_s"], atol=0.011)
    # errors recomputed independently through ECEF
    d = ned_vector_between(a["true_lat_rad"], a["true_lon_rad"], a["true_h_msl_m"], a["est_lat_rad"],
                           a["est_lon_rad"], a["est_h_m"])
    assert np.allclose(a["err_ned_m"], d, atol=0.05)
    h_err = np.hypot(d[:, 0], d[:, 1])
    assert np.isclose(res.summary["horizontal_error_rms_m"], np.sqrt(np.mean(h_err ** 2)), rtol=1e-3)
    assert np.isclose(res.summary["horizontal_error_final_m"], h_err[-1], rtol=1e-3)
    assert np.isclose(res.summary["vertical_error_rms_m"], np.sqrt(np.mean(d[:, 2] ** 2)), rtol=1e-3)
    assert h_err.min() > 0.0                         # the navigator never got the truth
    # true AGL against the DEM directly
    world = loop.world_dem
    ground = world.height(a["true_lat_rad"], a["true_lon_rad"])
    assert np.allclose(a["true_h_agl_m"], a["true_h_msl_m"] - ground)
    # sensor readings logged at their rates
    assert a["sensor_imu_t_s"].shape[0] == pytest.approx(2000, abs=2)
    assert a["sensor_ira_t_s"].shape[0] == pytest.approx(1000, abs=2)
    # GNSS is lost at 10 s in the default scenario
    assert a["gnss_available"][a["t_s"] < 10.0].all() and not a["gnss_available"][a["t_s"] >= 10.0].any()
    for key in ("scenario", "seed", "navigator", "sim_time_s", "wall_time_s", "realtime_factor",
                "horizontal_error_rms_m", "horizontal_error_final_m", "vertical_error_rms_m", "termination"):
        assert key in res.summary
    assert res.summary["sim_time_s"] == pytest.approx(20.0)


def test_same_seed_same_run_bit_for_bit(short_run):
    _, res = short_run
    sc = validate(_short(20.0, navigator="ins_tercom"), source="test")
    again = ClosedLoop(sc).run()
    for k, v in res.arrays.items():
        assert np.array_equal(v, again.arrays[k], equal_nan=True), k
    other = ClosedLoop(validate(_short(20.0, seed=1, navigator="ins_tercom"), source="t")).run()
    assert not np.array_equal(res.arrays["est_lat_rad"], other.arrays["est_lat_rad"])
    assert not np.array_equal(res.arrays["sensor_imu_f_b_mps2"], other.arrays["sensor_imu_f_b_mps2"])


def test_guidance_flies_on_estimate_and_follows_route(short_run):
    loop, res = short_run
    a = res.arrays
    # first leg of the default route is ~8 deg true; after 20 s the ground track is on it
    v = a["true_v_ned_mps"][-50:]
    track_deg = np.degrees(np.arctan2(v[:, 1], v[:, 0]))
    wp0, wp1 = loop.scenario.route.waypoints[:2]
    leg = ned_vector_between(math.radians(wp0.lat_deg), math.radians(wp0.lon_deg), 0.0,
                             math.radians(wp1.lat_deg), math.radians(wp1.lon_deg), 0.0)[0]
    leg_deg = math.degrees(math.atan2(leg[1], leg[0]))
    assert abs(np.mean(track_deg) - leg_deg) < 5.0
    # AGL hold at ~1500 m above the terrain
    assert np.all(np.abs(a["true_h_agl_m"][-50:] - 1500.0) < 300.0)   # (the full default run: 1,250 m min)


def test_terrain_collision_termination():
    """Level at 800 m MSL toward a 996 m summit 2.8 km ahead."""
    data = _short(120.0)
    data["initial"] = {"lat_deg": 36.5408, "lon_deg": -84.2725, "h_msl_m": 800.0, "tas_mps": 85.0,
                       "heading_deg": 0.0}
    data["route"]["waypoints"] = [{"lat_deg": 36.5408, "lon_deg": -84.2725, "h_msl_m": 800.0},
                                  {"lat_deg": 36.5660, "lon_deg": -84.2725, "h_msl_m": 1200.0}]
    data["route"]["settings"] = {"vertical": "step"}
    data["route"]["waypoints"][1]["h_msl_m"] = 1200.0
    # hold 800 m: the commander keeps the MSL altitude, flying north
    sc = validate(data, source="test")
    from trn_env.flight.core import AutopilotTargets, LateralMode, VerticalMode
    loop = ClosedLoop(sc, commander=lambda est, t: AutopilotTargets(
        lateral_mode=LateralMode.TRACK, track_cmd_rad=0.0, vertical_mode=VerticalMode.ALTITUDE_MSL,
        altitude_cmd_m=800.0, tas_cmd_mps=85.0))
    res = loop.run()
    assert res.termination == "terrain_collision"
    last = loop.last_truth
    ground = loop.world_dem.height(last.lat_rad, last.lon_rad)
    assert np.any(last.h_msl_m - ground < 0.0)
    assert 20.0 < res.sim_time_s < 60.0


def test_off_map_termination():
    data = _short(120.0)
    data["initial"] = {"lat_deg": 36.60, "lon_deg": -84.40, "h_agl_m": 1500.0, "tas_mps": 85.0,
                       "heading_deg": 270.0}
    sc = validate(data, source="test")
    loop = ClosedLoop(sc, commander=lambda est, t: components.track_agl_targets(-math.pi / 2, 1500.0, 85.0))
    res = loop.run()
    assert res.termination == "off_map"
    assert not loop.world_dem.contains(loop.last_truth.lat_rad[-1], loop.last_truth.lon_rad[-1])
    assert res.sim_time_s < 20.0


def test_completed_termination():
    data = _short(200.0)
    data["route"]["waypoints"] = data["route"]["waypoints"][:1] + [
        {"lat_deg": 36.515, "lon_deg": -84.365, "h_agl_m": 1500.0}]
    res = ClosedLoop(validate(data, source="test")).run()
    assert res.termination == "completed"
    # ~2.8 km at ~85 m/s plus the initial trim: about half a minute
    assert 20.0 < res.sim_time_s < 60.0


def test_diverged_on_covariance_and_on_nan():
    data = _short(30.0)
    data["limits"] = {"max_horizontal_sigma_m": 20.0}      # below the initial 30 m per axis
    data["gnss"] = {"outages": [{"start_s": 0.0}]}          # (GNSS would bring it to 2 m at the first update)
    res = ClosedLoop(validate(data, source="test")).run()
    assert res.termination == "diverged" and res.sim_time_s == pytest.approx(1.0)   # the first update

    loop = ClosedLoop(validate(_short(30.0), source="test"))
    real_update = loop.navigator.update
    calls = {"n": 0}

    def nan_after_5(frames):
        est = real_update(frames)
        calls["n"] += 1
        if calls["n"] >= 5:
            return Estimate(est.t_s, float("nan"), est.lon_rad, est.h_m, est.v_ned_mps, est.roll_rad,
                            est.pitch_rad, est.yaw_rad, est.covariance, est.health)
        return est

    loop.navigator.update = nan_after_5
    res = loop.run()
    assert res.termination == "diverged" and res.sim_time_s == pytest.approx(5.0)   # the fifth update


def test_map_error_model_and_refined_world():
    data = _short(3.0)
    data["terrain"]["world"]["refinement"] = {"spacing_m": 30.0, "region_deg": [36.47, 36.56, -84.40, -84.33]}
    data["terrain"]["map"] = {"dem": "world", "error_model": {"bias_m": 40.0, "tilt_n": 1e-3}}
    data["route"]["waypoints"] = data["route"]["waypoints"][:1] + [
        {"lat_deg": 36.55, "lon_deg": -84.36, "h_agl_m": 1500.0}]
    loop = ClosedLoop(validate(data, source="test"))
    world, the_map = loop.world_dem, loop.map_dem
    assert max(world.spacing_m) < 31.0 and min(world.spacing_m) > 15.0
    lat = np.radians(np.array([36.49, 36.50, 36.52]))
    lon = np.radians(np.array([-84.37, -84.36, -84.35]))
    lat_c = the_map.center_rad[0]
    north = (lat - lat_c) * 6.36e6                       # tilt over a few km: 0.1 % radius error is << 1 m
    assert np.allclose(the_map.height(lat, lon), world.height(lat, lon) + 40.0 + 1e-3 * north, atol=0.5)
    assert loop.run().termination == "time_limit"
    data["route"]["waypoints"][1]["lat_deg"] = 36.60     # outside the refined region
    with pytest.raises(Exception) as exc:
        validate(data, source="test")
    assert any(p.startswith("route.waypoints[1]:") and "region_deg" in p for p in exc.value.problems)


@pytest.mark.parametrize("latency", [0, 1])
def test_guidance_runs_at_its_rate_on_the_estimate_dead_reckoned_between_updates(latency):
    """Guidance is asked at 10 Hz; the navigator updates at 1 Hz; in between the guidance gets the navigator
    estimate `latency` updates before the interval's start (the first estimate before that) moved by its own
    velocity (checked through ECEF: the offset of the commanded position from that estimate equals
    v_ned * dt to millimetres)."""
    calls = []
    targets = components.track_agl_targets(0.2, 1500.0, 85.0)

    def commander(est, t_s):
        calls.append((t_s, est))
        return targets

    data = _short(4.0)
    data["navigator"]["latency_updates"] = latency
    loop = ClosedLoop(validate(data, source="test"), commander=commander)
    updates = [loop.estimate]
    while loop.tick() is None:
        loop.sync()                                   # every update's estimate, as soon as it exists
        updates.append(loop.estimate)
    times = np.array([t for t, _ in calls])
    assert np.allclose(np.diff(times), 0.1, atol=1e-9) and times[-1] == pytest.approx(3.9)   # none at the end
    assert [u.t_s for u in updates] == pytest.approx([0.0, 1.0, 2.0, 3.0])
    for t_s, est in calls:
        start = math.floor(t_s + 1e-9)                # the update interval [start, start + 1) the call is in
        base = updates[max(start - latency, 0)]
        dt = t_s - base.t_s
        assert est.t_s == pytest.approx(t_s) and 0.0 <= dt < 1.0 + latency - 1e-9
        d = ned_vector_between(np.array([base.lat_rad]), np.array([base.lon_rad]), np.array([base.h_m]),
                               np.array([est.lat_rad]), np.array([est.lon_rad]), np.array([est.h_m]))[0]
        # the small-offset radii leave the Earth's curvature out: d^2 / 2R below the local level (3 mm at 2 s)
        curvature_m = float(np.dot(d, d)) / (2 * 6.36e6)
        np.testing.assert_allclose(d, np.asarray(base.v_ned_mps) * dt, atol=2e-3 + curvature_m)
        if dt == 0.0:
            assert est is base                                  # at an update: the navigator's own estimate


def test_navigator_rate_must_divide_the_guidance_rate():
    data = _short(3.0)
    data["navigator"]["rate_hz"] = 3.0
    with pytest.raises(ScenarioError, match="navigator.rate_hz"):
        validate(data, source="test")
    data["navigator"]["rate_hz"] = 2.0
    data["guidance"] = {"log_rate_hz": 5.0}
    with pytest.raises(ScenarioError, match="guidance.log_rate_hz"):
        validate(data, source="test")
    data = _short(3.0)
    data["navigator"]["latency_updates"] = 2
    with pytest.raises(ScenarioError, match="latency_updates"):
        validate(data, source="test")


def test_run_scenario_takes_a_scenario_a_dict_and_dotted_path_sets():
    """run_scenario flies a loaded Scenario or a dict as it flies the name (same bits); `sets` edits any field
    as `fly --set` does, equal to editing the dict by hand; a misspelt override names the right ones."""
    from trn_env.scenario.loading import load_scenario
    from trn_env.sim import run_scenario

    base = dict(seed=1, duration_s=3.0, navigator="ins", pipeline=False)
    by_name = run_scenario("default", **base)
    kw = {k: v for k, v in base.items() if k != "pipeline"}
    by_object = run_scenario(load_scenario("default", **kw), pipeline=False)
    assert_same_run(by_object, by_name)
    by_set = run_scenario("default", sets={"wind.layers.0.speed_mps": 3.0, "initial.h_agl_m": 1400.0}, **base)
    data = _data(seed=1, duration_s=3.0)
    data["navigator"] = {"name": "ins"}
    data["wind"]["layers"][0]["speed_mps"] = 3.0
    data["initial"]["h_agl_m"] = 1400.0
    by_dict = run_scenario(data, pipeline=False)
    assert_same_run(by_set, by_dict, ignore=("scenario_source",))      # built-in 'default' / <dict>
    assert not np.array_equal(by_set.arrays["true_h_msl_m"], by_name.arrays["true_h_msl_m"])
    assert by_set.scenario.sections.wind.layers[0].speed_mps == 3.0
    with pytest.raises(TypeError, match=r"unknown scenario override\(s\) 'duration': the overrides are "
                                        r"seed=, duration_s= \(s\) and navigator=.*sets="):
        run_scenario("default", duration=5)
    with pytest.raises(TypeError, match="sets must be a mapping"):
        run_scenario("default", sets=[("seed", 1)])
    with pytest.raises(TypeError, match="a scenario is a built-in name, a TOML file's path, a Scenario or a "
                                        "scenario dict, got int"):
        run_scenario(3)
    with pytest.raises(ScenarioError, match=r"wind.layers\[0\].speed_mps: -3 is less than the minimum"):
        run_scenario("default", sets={"wind.layers.0.speed_mps": -3})
