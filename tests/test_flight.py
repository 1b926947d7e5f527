"""Flight core: truth in SI and WGS84 checked against JSBSim and independent physics; bad input; crosswind
wind triangle; determinism; the benchmark's figures."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from _child_processes import NEUTRAL_CWD
from trn_env.terrain.geodesy import (
    OMEGA_EARTH_RPS,
    WGS84_A_M,
    WGS84_E2,
    C_en,
    lla_to_ecef,
    meridian_radius_m,
    prime_vertical_radius_m,
)

from trn_env.bench.flight import benchmark
from trn_env.flight.aircraft_data import new_fdm
from trn_env.flight.core import (
    AutopilotTargets,
    Flight,
    FlightDiverged,
    InitialCondition,
    LateralMode,
    TrimError,
    VerticalMode,
    _std_atmosphere,
)
from trn_env.flight.truth import TRUTH_FIELDS
from trn_env.flight.wind import Turbulence, WindConfig

LAT0, LON0 = math.radians(33.2), math.radians(-98.2)
TAS_MPS = 75.0
FT = 0.3048
PSF = 47.88025898033584


def _ic(**kw) -> InitialCondition:
    args = dict(lat_rad=LAT0, lon_rad=LON0, h_msl_m=1500.0, tas_mps=TAS_MPS, heading_rad=0.3)
    args.update(kw)
    return InitialCondition(**args)


def _normal_gravity_mps2(lat_rad: float, h_m: float) -> float:
    """WGS84 normal gravity (Somigliana) and second-order free-air correction (NIMA TR8350.2 eq 4-1, 4-3)."""
    s2 = math.sin(lat_rad) ** 2
    g_e, k = 9.7803253359, 0.00193185265241
    f, m = 1.0 / 298.257223563, 0.00344978650684
    g0 = g_e * (1.0 + k * s2) / math.sqrt(1.0 - WGS84_E2 * s2)
    return g0 * (1.0 - 2.0 / WGS84_A_M * (1.0 + f + m - 2.0 * f * s2) * h_m + 3.0 / WGS84_A_M ** 2 * h_m ** 2)


def _transport_terms(lat: float, h: float, v: np.ndarray) -> np.ndarray:
    """(2 omega_ie + omega_en) x v in NED: the Coriolis and transport-rate acceleration terms."""
    r_n = meridian_radius_m(lat) + h
    r_e = prime_vertical_radius_m(lat) + h
    w_ie = OMEGA_EARTH_RPS * np.array([math.cos(lat), 0.0, -math.sin(lat)])
    w_en = np.array([v[1] / r_e, -v[0] / r_n, -v[1] * math.tan(lat) / r_e])
    return np.cross(2.0 * w_ie + w_en, v)


@pytest.fixture(scope="module")
def manoeuvre():
    """A climbing 30-degree-bank turn in a steady wind: the truth and the FDM at its end."""
    f = Flight(_ic(), wind=WindConfig.constant(250.0, 12.0), seed=3)
    start = f.snapshot()
    f.set_targets(AutopilotTargets(lateral_mode=LateralMode.HEADING, heading_cmd_rad=2.5,
                                   bank_limit_rad=math.radians(30.0),
                                   vertical_mode=VerticalMode.VERTICAL_SPEED, vs_cmd_mps=4.0,
                                   tas_cmd_mps=TAS_MPS))
    chunk = f.advance(1500)
    return f, start, chunk


# ------------------------------------------------------------------------------------------ truth
def test_truth_chunk_shapes_units_and_time(manoeuvre):
    f, start, c = manoeuvre
    assert len(c) == 1500
    for name, shape in TRUTH_FIELDS.items():
        arr = getattr(c, name)
        assert arr.shape == (1500,) + shape, name
        assert np.all(np.isfinite(arr)), name
    np.testing.assert_allclose(c.t_s, np.arange(1, 1501) * 0.01)
    assert start.t_s[0] == 0.0 and f.t_s == pytest.approx(15.0)
    assert np.all(np.abs(c.yaw_rad) <= math.pi)
    # it did turn and climb (so the checks below see a manoeuvre, not level flight)
    assert np.degrees(np.abs(c.roll_rad)).max() > 20.0
    assert c.h_msl_m[-1] - c.h_msl_m[0] > 20.0


def test_position_and_velocity_are_wgs84_geodetic(manoeuvre):
    f, _, c = manoeuvre
    fdm = f.fdm
    r_jsb = np.array([fdm[f"position/ecef-{a}-ft"] for a in "xyz"]) * FT
    r_ours = np.array(lla_to_ecef(c.lat_rad[-1], c.lon_rad[-1], c.h_msl_m[-1]))
    np.testing.assert_allclose(r_ours, r_jsb, atol=2e-3)          # geodetic lat + WGS84 height: mm
    v_jsb = np.array([fdm[f"velocities/ecef-{a}-fps"] for a in "xyz"]) * FT
    np.testing.assert_allclose(C_en(c.lat_rad[-1], c.lon_rad[-1]) @ c.v_ned_mps[-1], v_jsb, atol=1e-6)
    # body-axis velocity through our C_bn (built from the Euler angles) equals JSBSim's u, v, w
    uvw = [fdm[f"velocities/{a}-fps"] * FT for a in "uvw"]
    np.testing.assert_allclose(c.C_bn[-1].T @ c.v_ned_mps[-1], uvw, atol=1e-6)


def test_body_rates_and_air_data_match_jsbsim(manoeuvre):
    f, _, c = manoeuvre
    fdm = f.fdm
    pqr = [fdm[f"velocities/{a}-rad_sec"] for a in "pqr"]
    np.testing.assert_allclose(c.omega_eb_b_rps[-1], pqr, atol=1e-10)
    np.testing.assert_allclose(c.omega_ib_b_rps[-1], [fdm[f"velocities/{a}i-rad_sec"] for a in "pqr"], atol=0)
    # TAS, alpha, beta are recomputed from the row's velocity, attitude and wind; JSBSim's own agree.
    assert c.tas_mps[-1] == pytest.approx(fdm["velocities/vtrue-fps"] * FT, abs=1e-9)
    assert c.alpha_rad[-1] == pytest.approx(fdm["aero/alpha-rad"], abs=1e-12)
    assert c.beta_rad[-1] == pytest.approx(fdm["aero/beta-rad"], abs=1e-12)
    np.testing.assert_allclose(c.C_bn[-1] @ c.C_bn[-1].T, np.eye(3), atol=1e-12)


def test_static_pressure_and_temperature_are_jsbsims_atmosphere():
    """p and T are JSBSim's standard atmosphere evaluated at each row's altitude: equal to JSBSim's own
    atmosphere/P-psf and T-R at the same position, from sea level to 12 km."""
    f = Flight(_ic())
    s = f.snapshot()
    assert s.p_static_pa[0] == pytest.approx(f.fdm["atmosphere/P-psf"] * PSF, abs=1e-3)
    assert s.T_static_K[0] == pytest.approx(f.fdm["atmosphere/T-R"] / 1.8, abs=1e-6)
    fdm = new_fdm()
    for h in (0.0, 800.0, 3000.0, 5600.0, 9000.0, 12000.0):
        fdm["ic/h-sl-ft"] = h / FT
        fdm["ic/lat-geod-rad"] = LAT0
        fdm["ic/long-gc-rad"] = LON0
        fdm.run_ic()
        lat, h_geod = fdm["position/lat-geod-rad"], fdm["position/geod-alt-ft"] * FT
        p, t = _std_atmosphere(lat, LON0, h_geod)
        assert p == pytest.approx(fdm["atmosphere/P-psf"] * PSF, abs=1e-3), h
        assert t == pytest.approx(fdm["atmosphere/T-R"] / 1.8, abs=1e-6), h
        # textbook ISA 1976: 288.15 K - 6.5 K/km (geopotential) up to 11 km, 216.65 K above
        assert t == pytest.approx(max(288.15 - 0.0065 * h * 6356766.0 / (6356766.0 + h), 216.65), abs=1e-6)


def test_specific_force_in_trim_balances_gravity_and_coriolis():
    """Steady level unaccelerated flight: C_bn f_b = (2 w_ie + w_en) x v - g (NED), g from WGS84 normal
    gravity. Checks the sign, the frame (geodetic NED) and the units of f_b."""
    f = Flight(_ic(heading_rad=1.2))
    s = f.snapshot()
    f_n = s.C_bn[0] @ s.f_b_mps2[0]
    lat, h, v = float(s.lat_rad[0]), float(s.h_msl_m[0]), s.v_ned_mps[0]
    expected = _transport_terms(lat, h, v) - np.array([0.0, 0.0, _normal_gravity_mps2(lat, h)])
    np.testing.assert_allclose(f_n, expected, atol=2e-3)
    assert f_n[2] == pytest.approx(-9.79, abs=0.02)


def test_integrating_specific_force_reproduces_the_velocity_change(manoeuvre):
    """dv/dt = C_bn f_b + g - (2 w_ie + w_en) x v integrated over the 15 s manoeuvre equals JSBSim's own
    velocity change (rectangular integration of the accelerations at the start of each step)."""
    _, _, c = manoeuvre
    dt = 0.01
    dv = np.zeros(3)
    for k in range(1, len(c)):
        lat, h, v = float(c.lat_rad[k - 1]), float(c.h_msl_m[k - 1]), c.v_ned_mps[k - 1]
        a = c.C_bn[k - 1] @ c.f_b_mps2[k - 1] + np.array([0.0, 0.0, _normal_gravity_mps2(lat, h)]) \
            - _transport_terms(lat, h, v)
        dv += a * dt
    actual = c.v_ned_mps[-1] - c.v_ned_mps[0]
    assert np.linalg.norm(actual) > 30.0          # a real manoeuvre
    np.testing.assert_allclose(dv, actual, atol=0.05)


def test_terrain_elevation_sets_height_above_ground():
    f = Flight(_ic(), terrain_elevation_m=300.0)
    c = f.advance(5)
    np.testing.assert_allclose(c.h_agl_m, c.h_msl_m - 300.0)
    assert f.fdm["position/h-agl-ft"] * FT == pytest.approx(c.h_msl_m[-1] - 300.0, abs=0.2)
    f.set_terrain_elevation(450.0)
    c = f.advance(5)
    np.testing.assert_allclose(c.h_agl_m, c.h_msl_m - 450.0)
    assert f.fdm["position/terrain-elevation-asl-ft"] * FT == pytest.approx(450.0)


def test_set_targets_writes_the_autopilot_properties():
    f = Flight(_ic())
    t = AutopilotTargets(lateral_mode=LateralMode.HEADING, heading_cmd_rad=1.0, track_cmd_rad=-0.5,
                         bank_limit_rad=0.3, vertical_mode=VerticalMode.HEIGHT_AGL, altitude_cmd_m=1234.0,
                         agl_cmd_m=321.0, vs_cmd_mps=-2.0, tas_cmd_mps=77.0)
    f.set_targets(t)
    for name, value in t.properties().items():
        assert f.fdm[name] == pytest.approx(value), name
    assert f.targets is t


def test_same_seed_same_truth_bit_for_bit_with_turbulence():
    wind = WindConfig(layers=[(0.0, 200.0, 8.0), (3000.0, 260.0, 18.0)],
                      turbulence=Turbulence(model="milspec", severity="moderate"))
    runs = []
    for seed in (5, 5, 6):
        f = Flight(_ic(), wind=wind, seed=seed)
        runs.append([f.advance(150) for _ in range(3)])
    for name in TRUTH_FIELDS:
        a = np.concatenate([getattr(c, name) for c in runs[0]])
        b = np.concatenate([getattr(c, name) for c in runs[1]])
        assert np.array_equal(a, b), name
    assert not np.array_equal(runs[0][-1].wind_ned_mps, runs[2][-1].wind_ned_mps)


# ------------------------------------------------------------------------------------------ crosswind
def test_crosswind_track_hold_matches_the_wind_triangle():
    """20 m/s crosswind from the left of a 30-degree track: the ground track holds the command; the crab
    angle (heading - track) is -asin(w_perp / TAS) and the sideslip is zero (air velocity along the
    nose), each within 0.5 deg."""
    track = math.radians(30.0)
    wind = WindConfig.constant(math.degrees(track) - 90.0, 20.0)
    f = Flight(_ic(heading_rad=track), wind=wind)
    f.set_targets(AutopilotTargets(lateral_mode=LateralMode.TRACK, track_cmd_rad=track, altitude_cmd_m=1500.0,
                                   tas_cmd_mps=TAS_MPS))
    f.advance(3000)
    c = f.advance(3000)
    trk = np.arctan2(c.v_ned_mps[:, 1], c.v_ned_mps[:, 0])
    crab = np.angle(np.exp(1j * (c.yaw_rad - trk)))
    u_right = np.array([-math.sin(track), math.cos(track)])          # unit vector right of the track
    w_perp = c.wind_ned_mps[:, :2] @ u_right
    expected_crab = -np.arcsin(w_perp / c.tas_mps)
    assert np.degrees(np.abs(trk - track)).max() < 0.5
    assert np.degrees(np.abs(crab - expected_crab)).max() < 0.5
    assert np.degrees(np.abs(c.beta_rad)).max() < 0.5
    assert np.degrees(np.mean(crab)) == pytest.approx(-math.degrees(math.asin(20.0 / TAS_MPS)), abs=0.5)
    # ground speed from the wind triangle
    gs = np.hypot(c.v_ned_mps[:, 0], c.v_ned_mps[:, 1])
    np.testing.assert_allclose(gs, np.sqrt(c.tas_mps ** 2 - w_perp ** 2) * np.cos(c.pitch_rad - c.alpha_rad),
                               rtol=5e-3)


# ------------------------------------------------------------------------------------------ bad input
def test_unknown_aircraft_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown aircraft 'learjet'"):
        Flight(_ic(), aircraft="learjet")


def test_untrimmable_initial_condition_names_the_condition():
    with pytest.raises(TrimError, match=r"cannot trim 'kingair'.*TAS = 25\.0 m/s"):
        Flight(_ic(tas_mps=25.0))


@pytest.mark.parametrize("field, value", [("tas_mps", -5.0), ("flaps", 1.5), ("lat_rad", float("nan")),
                                          ("fuel_fraction", 2.0), ("gamma_rad", 1.0)])
def test_bad_initial_condition_fields_are_named(field, value):
    with pytest.raises(ValueError, match=f"InitialCondition.{field}"):
        _ic(**{field: value})


def test_bad_targets_and_arguments_are_named():
    with pytest.raises(ValueError, match="AutopilotTargets.lateral_mode"):
        AutopilotTargets(lateral_mode=7)
    with pytest.raises(ValueError, match="AutopilotTargets.bank_limit_rad"):
        AutopilotTargets(bank_limit_rad=2.0)
    with pytest.raises(ValueError, match="not above the terrain"):
        Flight(_ic(h_msl_m=500.0), terrain_elevation_m=600.0)


def test_nan_state_raises_flight_diverged_naming_quantity_and_time():
    f = Flight(_ic())
    f.advance(10)
    f.fdm["atmosphere/wind-north-fps"] = float("nan")    # corrupt the air mass: the state turns NaN
    with pytest.raises(FlightDiverged) as err:
        f.advance(50)
    assert err.value.quantity in str(err.value)
    assert "turned nan" in str(err.value).lower()
    assert 0.1 < err.value.t_s <= 0.6
    assert f"t = {err.value.t_s:.2f} s" in str(err.value)


def test_fuel_fraction_changes_the_mass():
    light = Flight(_ic(fuel_fraction=0.2))
    heavy = Flight(_ic(fuel_fraction=0.9))
    assert heavy.fdm["inertia/weight-lbs"] > light.fdm["inertia/weight-lbs"] + 100.0


# ------------------------------------------------------------------------------------------ benchmark
def test_benchmark_reports_its_figures():
    out = benchmark(n_steps=400, chunk_steps=10, long_chunk_steps=100, block_steps=200, ic=_ic())
    assert set(out) >= {"jsbsim_steps_per_s", "flight_steps_per_s", "flight_ratio"}
    assert out["jsbsim_steps_per_s"] > 0 and out["flight_steps_per_s"] > 0
    assert out["flight_ratio"] == pytest.approx(out["flight_steps_per_s"] / out["jsbsim_steps_per_s"],
                                                rel=1e-2)


# ------------------------------------------------------------------------------------------ chunk layout
def test_chunks_are_independent_block_views_equal_to_jsbsim_each_step():
    """Each advance returns its own memory (the reused raw buffer never leaks into a chunk): a chunk kept
    from earlier is unchanged by later advances; every row equals JSBSim's properties read at that step;
    the fields have the documented shapes and layouts and behave as an ordinary TruthChunk (slice, copy,
    concatenate, dataclasses.replace)."""
    import dataclasses

    from trn_env.flight.truth import TruthChunk
    f = Flight(_ic())
    rows = []
    chunks = []
    for _ in range(3):
        c = f.advance(4)
        chunks.append(c)
        fdm = f.fdm
        f_z = fdm["forces/fbz-total-lbs"] / fdm["inertia/mass-slugs"] * FT
        rows.append((fdm["position/geod-alt-ft"] * FT, fdm["attitude/phi-rad"], f_z))
    kept = chunks[0].copy()
    f.advance(50)
    for name in TRUTH_FIELDS:
        np.testing.assert_array_equal(getattr(chunks[0], name), getattr(kept, name), err_msg=name)
    for c, (h, phi, nz) in zip(chunks, rows, strict=True):
        assert c.h_msl_m[-1] == h and c.roll_rad[-1] == phi and c.f_b_mps2[-1, 2] == pytest.approx(nz)
    c = chunks[1]
    assert isinstance(c, TruthChunk) and len(c) == 4
    assert c.v_ned_mps.shape == (4, 3) and c.C_bn.shape == (4, 3, 3) and c.C_bn.flags.c_contiguous
    assert not np.shares_memory(chunks[0].t_s, chunks[1].t_s)
    np.testing.assert_allclose(c.t_s, [0.05, 0.06, 0.07, 0.08])
    both = TruthChunk.concatenate([chunks[0], chunks[1]])
    np.testing.assert_array_equal(both.slice(4, 8).wind_ned_mps, c.wind_ned_mps)
    moved = dataclasses.replace(c, h_msl_m=c.h_msl_m + 1.0)
    np.testing.assert_array_equal(moved.h_msl_m, c.h_msl_m + 1.0)
    np.testing.assert_array_equal(moved.C_bn, c.C_bn)
    with pytest.raises(AttributeError):
        _ = c.no_such_field


def test_gusts_split_the_recording_without_losing_rows():
    """A gust starting mid-chunk splits the recording loop into segments written at offsets of one buffer:
    the rows stay contiguous in time and the gust shows in the recorded total wind from its start."""
    from trn_env.flight.wind import CosineGust
    wind = WindConfig(gusts=[CosineGust(start_time_s=0.155, magnitude_mps=8.0, startup_s=0.2, steady_s=1.0,
                                        end_s=0.2, direction=(0.0, 1.0, 0.0), frame="ned")])
    f = Flight(_ic(), wind=wind)
    c = f.advance(60)
    np.testing.assert_allclose(np.diff(c.t_s), 0.01, atol=1e-12)
    gust = np.linalg.norm(c.wind_ned_mps, axis=1)
    assert np.all(gust[:15] == 0.0) and gust[-1] > 7.0
    assert f.fdm["atmosphere/total-wind-east-fps"] * FT == pytest.approx(c.wind_ned_mps[-1, 1], abs=1e-12)


@pytest.mark.parametrize("turbulence", ["none", "milspec"])
def test_record_then_take_equals_one_advance_bit_for_bit(turbulence):
    """record() in pieces (with targets, terrain elevation and layered wind changing between pieces, as the
    closed loop's guidance ticks do) then one take() gives the same truth as advance() with the same writes
    between equal pieces; each row keeps the steady wind and terrain elevation it was flown with."""
    wind = WindConfig(layers=[(0.0, 200.0, 8.0), (3000.0, 260.0, 18.0)],
                      turbulence=Turbulence(model=turbulence, severity="light"))
    pieces, chunks = Flight(_ic(), wind=wind, seed=3), []
    whole = Flight(_ic(), wind=wind, seed=3)
    for k in range(5):
        for f in (pieces, whole):
            f.set_terrain_elevation(100.0 + 10.0 * k)
            f.set_targets(AutopilotTargets(lateral_mode=LateralMode.TRACK, track_cmd_rad=0.1 * k,
                                           vertical_mode=VerticalMode.ALTITUDE_MSL,
                                           altitude_cmd_m=1000.0 + 50 * k, tas_cmd_mps=TAS_MPS))
        pieces.record(20)
        chunks.append(whole.advance(20))
    assert pieces.pending_steps == 100
    taken = pieces.take()
    assert pieces.pending_steps == 0
    for name in TRUTH_FIELDS:
        assert np.array_equal(getattr(taken, name), np.concatenate([getattr(c, name) for c in chunks])), name
    # the terrain elevation of each piece is the one its rows' height above ground refers to
    np.testing.assert_allclose(taken.h_msl_m[20:40] - taken.h_agl_m[20:40], 110.0, atol=1e-9)
    with pytest.raises(ValueError, match="no steps recorded"):
        pieces.take()
    pieces.record(3)
    with pytest.raises(RuntimeError, match="take"):
        pieces.set_wind(WindConfig())


def test_building_a_flight_prints_no_jsbsim_banner():
    """JSBSim prints its start-up banner on the C-level stdout from the FGFDMExec constructor unless its
    debug level is zero beforehand: a script that builds a Flight itself must not get it."""
    code = ("from trn_env.flight import Flight, InitialCondition\n"
            "Flight(InitialCondition(0.637, -1.472, 1500.0, 85.0, 0.0)).advance(10)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         cwd=NEUTRAL_CWD)       # the installed trn_env (_child_processes)
    assert out.returncode == 0, out.stderr
    assert out.stdout == "", out.stdout
