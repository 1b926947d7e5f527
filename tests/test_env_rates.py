"""TerrainNav-v0's rates: JSBSim's step (flight_dt_s), the guidance rate and the scenario's sensor and filter
rates (scenario_fields, the route task's opt-in DECISION_RATES), their checks, the goal geometry kernel
against the ECEF rotation, and the King Air's trajectory at 50 Hz and 100 Hz steps against 200 Hz
(independent runs of the flight core)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _scripts import load_script
from trn_env.navigators.frames import imu_gap_s

from trn_env.env.env_settings import goal_offset_ne
from trn_env.env.route_task import (
    DECISION_RATES,
    FULL_TIER_ONLY,
    TASK_RATES,
    env_kwargs,
    fast_tier_kwargs,
)
from trn_env.env.terrain_nav import TerrainNavEnv
from trn_env.flight.core import (
    AutopilotTargets,
    Flight,
    InitialCondition,
    LateralMode,
    SpeedMode,
    VerticalMode,
)

SMALL = dict(decision_interval_s=2.0, max_episode_s=8.0, navigator="ins")


def test_flight_dt_sets_jsbsim_step_and_imu_rate_and_halves_the_steps():
    e = TerrainNavEnv("basin_route", flight_dt_s=0.02, **SMALL)
    sc = e.scenario
    assert sc.aircraft.dt_s == 0.02
    assert sc.sensors.imu.rate_hz == pytest.approx(50.0)               # lowered from 100 Hz to the step rate
    assert sc.guidance.rate_hz == sc.navigator.rate_hz                 # once per navigator update
    e.reset(seed=3)
    e.step(np.zeros(2, np.float32))
    assert e._loop.jsbsim_steps == 100                                 # 2 s at 50 Hz
    ref = TerrainNavEnv("basin_route", **SMALL)                        # the scenario's own 100 Hz step
    assert ref.scenario.aircraft.dt_s == 0.01
    ref.reset(seed=3)
    ref.step(np.zeros(2, np.float32))
    assert ref._loop.jsbsim_steps == 200
    # same episode start, same aircraft: after 2 s both are within metres of each other
    a, b = e._truth_now(), ref._truth_now()
    assert math.hypot((a[0] - b[0]) * 6.371e6, (a[1] - b[1]) * 6.371e6 * math.cos(a[0])) < 5.0
    e.close()
    ref.close()


def test_flight_dt_one_seed_one_episode():
    def episode(seed):
        e = TerrainNavEnv("basin_route", flight_dt_s=0.02, **SMALL)
        obs = [e.reset(seed=seed)[0]]
        rewards = []
        for k in range(3):
            o, r, *_ = e.step(np.array([0.5 * (k - 1), 0.3], np.float32))
            obs.append(o)
            rewards.append(r)
        e.close()
        return np.array(obs), np.array(rewards)

    o1, r1 = episode(5)
    o2, r2 = episode(5)
    o3, _ = episode(6)
    assert np.array_equal(o1, o2) and np.array_equal(r1, r2)
    assert not np.array_equal(o1, o3)


@pytest.mark.parametrize("kw, field", [
    (dict(flight_dt_s=0.06), "flight_dt_s"),              # beyond JSBSim's step limit
    (dict(flight_dt_s=0.03), "flight_dt_s"),              # 1 s guidance tick is not whole 0.03 s steps
    (dict(flight_dt_s=float("nan")), "flight_dt_s"),
    (dict(flight_dt_s=-0.01), "flight_dt_s"),
    (dict(flight_dt_s="0.02"), "flight_dt_s"),
    (dict(guidance_rate_hz=0.3), "guidance_rate_hz"),     # not a whole multiple of the 1 Hz navigator
])
def test_bad_rates_name_the_argument(kw, field):
    with pytest.raises(ValueError, match=field):
        TerrainNavEnv("basin_route", **SMALL, **kw)


def test_route_task_flies_50_hz_and_the_fast_tier_drops_full_tier_settings():
    kw = env_kwargs("basin")
    assert kw["flight_dt_s"] == 0.02 and kw["guidance_rate_hz"] == 1.0
    assert kw["scenario_fields"] == TASK_RATES["scenario_fields"]
    assert kw["scenario_fields"] is not TASK_RATES["scenario_fields"]          # a copy
    e = TerrainNavEnv(**{**kw, "max_episode_s": 8.0})
    sc = e.scenario
    assert (sc.sensors.ira.rate_hz, sc.navigator.settings.ira_average, sc.navigator.settings.ekf_rate_hz,
            sc.navigator.rate_hz, sc.guidance.rate_hz) == (50.0, 3, 10.0, 0.5, 1.0)
    assert e.ticks_per_decision == 15
    e.close()
    rated = env_kwargs("basin", decision_rates=True)
    assert rated["scenario_fields"] == DECISION_RATES["scenario_fields"]
    assert rated["scenario_fields"] is not DECISION_RATES["scenario_fields"]      # a copy
    e = TerrainNavEnv(**{**rated, "max_episode_s": 8.0})
    sc = e.scenario
    assert (sc.sensors.ira.rate_hz, sc.navigator.settings.ekf_rate_hz, sc.navigator.rate_hz,
            sc.guidance.rate_hz) == (10.0, 10.0, 0.5, 1.0)
    assert e.ticks_per_decision == 15 and e.decision_interval_s == 30.0
    e.close()
    with pytest.raises(ValueError, match="decision_rates"):
        env_kwargs("basin", decision_rates="yes")
    assert not set(FULL_TIER_ONLY) & set(fast_tier_kwargs(rated))
    fast = fast_tier_kwargs({**kw, "guidance_rate_hz": 1.0, "pipeline": False})
    assert not set(FULL_TIER_ONLY) & set(fast)
    assert {k: v for k, v in kw.items() if k not in FULL_TIER_ONLY} == fast


def test_scenario_fields_set_the_scenario_and_bad_ones_name_the_field():
    e = TerrainNavEnv("basin_route", scenario_fields={"sensors.ira.rate_hz": 25.0}, log_sensors=True, **SMALL)
    assert e.scenario.sensors.ira.rate_hz == 25.0
    assert TerrainNavEnv("basin_route", **SMALL).scenario.sensors.ira.rate_hz == 50.0      # the scenario's
    e.reset(seed=1)
    e.step(np.zeros(2, np.float32))                 # 2 s: two 1 s navigator updates of 25 IRA samples each
    e._loop.sync()
    assert [f.ira.t_s.shape[0] for f in e._loop._stage.logged_frames()] == [25, 25]
    e.close()
    for bad, words in (({"sensors.foo.rate_hz": 3.0}, ("scenario_fields", "sensors.foo")),
                       ({"sensors.ira.rate_hz": -1.0}, ("scenario_fields", "sensors.ira.rate_hz")),
                       ([("sensors.ira.rate_hz", 10.0)], ("scenario_fields",)),
                       ({3: 10.0}, ("scenario_fields",))):
        with pytest.raises(ValueError) as err:
            TerrainNavEnv("basin_route", scenario_fields=bad, **SMALL)
        assert all(w in str(err.value) for w in words), str(err.value)


def test_scenario_fields_can_fit_the_sensor_a_navigator_requires():
    """The navigator and the fields are validated together: a navigator needing a sensor the scenario lacks
    builds when scenario_fields adds it (it was refused before the fields were applied); the same
    navigator without the fields is refused naming the sensor."""
    small = {**SMALL, "navigator": "acq_track", "max_episode_s": 60.0}
    e = TerrainNavEnv("basin_route", scenario_fields={"sensors.radar_altimeter": {}, "sensors.heading": {}},
                      **small)
    assert e.scenario.navigator_name == "acq_track" and e.scenario.sensors.radar_altimeter is not None
    e.reset(seed=1)
    e.close()
    with pytest.raises(ValueError, match=r"sensors.radar_altimeter: navigator 'acq_track' needs this sensor"):
        TerrainNavEnv("basin_route", **small)
    with pytest.raises(ValueError, match=r"(?s)scenario_fields: .*sensors.ira.rate_hz: -1.0"):
        TerrainNavEnv("basin_route", scenario_fields={"sensors.ira.rate_hz": -1.0},
                      **{**SMALL, "navigator": "pmf"})


def test_ira_average_reaches_the_navigators_tercom_batch():
    """scenario_fields' navigator.settings.ira_average: the INS + TERCOM navigator's batch enters each 5
    consecutive IRA samples as their mean (2 s of 50 Hz IRA: 100 samples, 20 batch rows; GNSS ignored, as
    its updates restart the batch)."""
    e = TerrainNavEnv("basin_route", scenario_fields={"navigator.settings.ira_average": 5,
                                                      "navigator.settings.use_gnss": False},
                      decision_interval_s=2.0, max_episode_s=8.0)
    e.reset(seed=0)
    nav = e._loop.navigator
    assert nav.batch.average == 5
    e.step(np.zeros(2, np.float32))
    e._loop.sync()
    assert 15 <= len(nav.batch) <= 20 and nav.batch._pending.shape[0] < 5
    e.close()


def test_goal_offset_kernel_is_the_ecef_rotation():
    """goal_offset_ne against numpy: C_en(lat, lon)^T (r_goal - r) with both points through lla_to_ecef, on
    random pairs 1-60 km apart at random heights; and against the small-offset form (latlon_to_ned_offset)
    within 0.2 % for pairs within 2 km."""
    from trn_env.terrain.geodesy import C_en, latlon_to_ned_offset, lla_to_ecef

    rng = np.random.default_rng(4)
    for _ in range(50):
        lat, lon = math.radians(rng.uniform(-60, 60)), math.radians(rng.uniform(-180, 180))
        h = rng.uniform(0, 4000)
        glat = lat + rng.uniform(-1, 1) * 60e3 / 6.4e6
        glon = lon + rng.uniform(-1, 1) * 60e3 / 6.4e6
        want = C_en(lat, lon).T @ (np.array(lla_to_ecef(glat, glon, h)) - np.array(lla_to_ecef(lat, lon, h)))
        got = goal_offset_ne(lat, lon, h, glat, glon)
        assert abs(got[0] - want[0]) < 1e-6 and abs(got[1] - want[1]) < 1e-6
        glat, glon = lat + (glat - lat) / 30, lon + (glon - lon) / 30
        near = goal_offset_ne(lat, lon, h, glat, glon)
        approx = latlon_to_ned_offset(lat, lon, h, glat, glon)
        assert math.hypot(near[0] - approx[0], near[1] - approx[1]) < 2e-3 * math.hypot(*approx) + 0.01


def test_imu_gap_skips_the_median_only_where_no_interval_can_be_long():
    """imu_gap_s against its definition (intervals longer than 1.5 x the median, less the median) computed
    directly, on regular, jittered and gapped sample times."""
    rng = np.random.default_rng(2)
    for _ in range(200):
        n = int(rng.integers(3, 60))
        d = np.full(n, 0.02) * rng.uniform(0.7, 1.3, n) ** rng.integers(0, 2)
        if rng.random() < 0.5:
            d[rng.integers(0, n)] *= rng.uniform(1.0, 5.0)
        t = 10.0 + np.cumsum(d)
        prev = float(t[0] - rng.uniform(0.01, 0.1)) if rng.random() < 0.5 else float("nan")
        tt = np.concatenate(([prev], t)) if math.isfinite(prev) else t
        dd = np.diff(tt)
        med = np.median(dd)
        want = float(np.sum(dd[dd > 1.5 * med] - med))
        assert imu_gap_s(t, prev) == pytest.approx(want, abs=1e-12)


def _fly(dt_s: float, duration_s: int) -> np.ndarray:
    """The King Air in calm air on a fixed autopilot schedule (a 45 deg track change at 20 s, a 200 m climb
    at 40 s); (lat, lon, h) once a second."""
    lat0, lon0 = math.radians(36.527), math.radians(-84.1325)
    fl = Flight(InitialCondition(lat0, lon0, 900.0, 85.0, 0.0), dt_s=dt_s, seed=1, terrain_elevation_m=300.0)
    out = []
    for k in range(duration_s):
        fl.set_targets(AutopilotTargets(
            lateral_mode=LateralMode.TRACK, track_cmd_rad=math.radians(45.0) if k >= 20 else 0.0,
            vertical_mode=VerticalMode.ALTITUDE_MSL, altitude_cmd_m=1100.0 if k >= 40 else 900.0,
            speed_mode=SpeedMode.TAS, tas_cmd_mps=85.0))
        c = fl.advance(int(round(1.0 / dt_s)))
        out.append((c.lat_rad[-1], c.lon_rad[-1], c.h_msl_m[-1]))
    return np.array(out)


def test_50_hz_trajectory_error_is_first_order_and_bounded():
    """JSBSim's step error, both steps judged against 200 Hz (90 s, a 45 deg turn and a 200 m climb, ~7.6 km
    flown): first order in the step, so the 50 Hz trajectory departs about 3x as far as the 100 Hz one
    ((0.02 - 0.005) / (0.01 - 0.005)), between 2x and 4x here, and by less than 1 m / 0.1 m. (With the
    autopilot's FCS components on JSBSim's default step, before December 7 2026, the departures were tens of
    metres and came from the autopilot, not the integration: docs/validation/fast_tier.md.)"""
    t = 90
    x200, x100, x50 = _fly(0.005, t), _fly(0.01, t), _fly(0.02, t)

    def dev(a, b):
        r = 6.371e6
        dn = (a[:, 0] - b[:, 0]) * r
        de = (a[:, 1] - b[:, 1]) * r * np.cos(b[:, 0])
        return float(np.max(np.hypot(dn, de))), float(np.max(np.abs(a[:, 2] - b[:, 2])))

    h100, v100 = dev(x100, x200)
    h50, v50 = dev(x50, x200)
    assert h100 > 0.01                                   # the comparison sees the step at all
    assert 2.0 * h100 < h50 < 4.0 * h100
    assert h50 < 1.0 and v50 < 0.1


def test_rates_check_script_bad_arguments_exit_2(tmp_path, capsys):
    """scripts/env_rates_check.py: every bad argument is a one-line error and exit 2, nothing flown or
    written (the configurations are built before anything flies)."""
    mod = load_script("env_rates_check")
    ok = 'a={"flight_dt_s": 0.02}'
    out = tmp_path / "out"
    for argv, words in (([ok], "two or more"),
                        ([ok, 'b={"flight_dt_s": '], "not JSON"),
                        ([ok, "b=[1]"], "JSON object"),
                        ([ok, 'b={"flight_dt_s": 0.06}'], "flight_dt_s"),
                        ([ok, 'b={"no_such_argument": 1}'], "no_such_argument"),
                        ([ok, 'b={"scenario_fields": {"sensors.foo.rate_hz": 1.0}}'], "sensors.foo"),
                        ([ok, ok.replace("a=", "b="), "--routes", "nowhere"], "nowhere"),
                        ([ok, ok.replace("a=", "b="), "--cpu-repeats", "-1"], "--cpu-repeats")):
        args = [x for c in argv[:2] for x in ("--config", c)] + argv[2:] + ["--seeds", "2", "--out", str(out)]
        assert mod.main(args) == 2
        err = capsys.readouterr().err
        assert err.startswith("error:") and words in err, err
    assert not out.exists()


def test_cpu_breakdown_script_bad_arguments_exit_2(capsys):
    """scripts/env_cpu_breakdown.py: a bad --decisions or --config is a one-line error and exit 2."""
    mod = load_script("env_cpu_breakdown")
    for argv, words in ((["--decisions", "0"], "--decisions"), (["--config", "{"], "not JSON"),
                        (["--config", "[1]"], "JSON object"),
                        (["--config", '{"flight_dt_s": 0.06}', "--decisions", "1"], "flight_dt_s")):
        assert mod.main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith("error:") and words in err, err
