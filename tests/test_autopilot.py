"""King Air autopilot (JSBSim systems XML): holds, captures and limits, checked in JSBSim flight.

Tolerances come from issue 2: calm air altitude +-10 m and heading +-1 deg for 10 min; 90 deg heading
change with < 5 deg overshoot; with a 20 m/s crosswind the ground track follows the command and the crab
angle and sideslip match the wind triangle within 0.5 deg.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from _scripts import load_script
from jsbsim_helpers import FT_PER_M, engage_autopilot, fly, start_in_flight

from trn_env.flight.aircraft_data import new_fdm

H0_M = 1500.0
TAS0_MPS = 85.0


def _wrap_rad(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def test_calm_air_holds_altitude_10m_and_heading_1deg_for_10_minutes() -> None:
    """60,000 steps (10 min at 100 Hz) at 1,500 m / 85 m/s in altitude, heading and TAS hold: altitude
    within +-10 m and heading within +-1 deg throughout, while fuel burn changes the weight. Without the
    autopilot the same aircraft leaves those bounds (the hold is doing the work)."""
    fdm = start_in_flight(H0_M, TAS0_MPS, math.radians(30.0))
    engage_autopilot(fdm)
    props = ["position/h-sl-meters", "attitude/psi-rad", "inertia/weight-lbs"]
    t0 = time.perf_counter()
    rec = fly(fdm, 60000, props)
    wall_s = time.perf_counter() - t0
    print(f"autopilot hold: {60000 / wall_s:.0f} JSBSim steps/s including recording")
    alt_err_m = np.abs(rec[:, 0] - H0_M)
    hdg_err_deg = np.degrees(np.abs(_wrap_rad(rec[:, 1] - math.radians(30.0))))
    print(f"10 min hold: max |dh| {alt_err_m.max():.3f} m, max |dpsi| {hdg_err_deg.max():.3f} deg")
    assert alt_err_m.max() < 10.0
    assert hdg_err_deg.max() < 1.0
    assert rec[0, 2] - rec[-1, 2] > 20.0, "fuel must burn during the hold (weight changes)"

    free = start_in_flight(H0_M, TAS0_MPS, math.radians(30.0))
    free["fcs/aileron-cmd-norm"] = 0.02  # a small out-of-trim input the autopilot would absorb
    rec_free = fly(free, 60000, props)
    free_hdg_err_deg = np.degrees(np.abs(_wrap_rad(rec_free[:, 1] - math.radians(30.0))))
    assert free_hdg_err_deg.max() > 1.0 or np.abs(rec_free[:, 0] - H0_M).max() > 10.0


@pytest.mark.parametrize(
    ("psi0_deg", "psi1_deg"),
    [(0.0, 90.0), (30.0, -60.0), (315.0, 45.0)],
    ids=["right_0_to_90", "left_30_to_300", "right_across_north_315_to_45"],
)
def test_heading_change_90deg_overshoot_below_5deg(psi0_deg: float, psi1_deg: float) -> None:
    """A 90 deg heading change is captured (within 1 deg after 60 s) with < 5 deg overshoot, the bank stays
    within the 25 deg limit + 3 deg, altitude within +-30 m; the shortest way round is taken even across
    north (error wrapped to +-pi)."""
    fdm = start_in_flight(H0_M, TAS0_MPS, math.radians(psi0_deg))
    engage_autopilot(fdm)
    fdm["ap/heading-cmd-rad"] = math.radians(psi1_deg)
    rec = fly(fdm, 9000, ["attitude/psi-rad", "attitude/phi-rad", "position/h-sl-meters"])
    err_deg = np.degrees(_wrap_rad(rec[:, 0] - math.radians(psi1_deg)))
    turn_sign = np.sign(_wrap_rad(np.radians(psi1_deg - psi0_deg)))
    # error seen along the turn direction: starts at -90, overshoot is a positive value
    along = turn_sign * err_deg
    print(f"turn {psi0_deg:.0f} -> {psi1_deg:.0f} deg: overshoot {max(0.0, along.max()):.2f} deg")
    assert along[0] == pytest.approx(-90.0, abs=0.5)
    assert along.max() < 5.0
    assert np.abs(err_deg[6000:]).max() < 1.0
    assert np.degrees(np.abs(rec[:, 1])).max() < 28.0
    assert np.sign(np.mean(rec[:1000, 1])) == turn_sign, "must bank towards the shorter turn"
    assert np.abs(rec[:, 2] - H0_M).max() < 30.0


def test_track_hold_in_20mps_crosswind_matches_wind_triangle() -> None:
    """Track hold (mode 2) due north with a 20 m/s wind blowing towards the east, TAS held at 85 m/s: the
    ground track stays within 0.5 deg of north, the crab angle (heading - track) matches the wind
    triangle -asin(20/85) = -13.6 deg within 0.5 deg, and the sideslip is within 0.5 deg of zero."""
    fdm = start_in_flight(H0_M, TAS0_MPS, 0.0)
    fdm["atmosphere/wind-north-fps"] = 0.0
    fdm["atmosphere/wind-east-fps"] = 20.0 * FT_PER_M  # steady wind set after the (calm-air) trim
    engage_autopilot(fdm, lateral_mode=2, tas_mps=TAS0_MPS)
    fdm["ap/track-cmd-rad"] = 0.0
    rec = fly(fdm, 15000, ["ap/track-rad", "attitude/psi-rad", "aero/beta-rad", "velocities/vtrue-fps"])
    assert rec[0, 3] * 0.3048 == pytest.approx(TAS0_MPS, abs=6.0)
    tail = rec[-2000:]
    track_deg = np.degrees(_wrap_rad(tail[:, 0]))
    crab_deg = np.degrees(_wrap_rad(tail[:, 1] - tail[:, 0]))
    tas_mps = tail[:, 3] * 0.3048
    expected_crab_deg = -np.degrees(np.arcsin(20.0 / tas_mps))
    beta_deg = np.degrees(np.abs(tail[:, 2]))
    print(f"crosswind: max |track err| {np.abs(track_deg).max():.3f} deg, crab {crab_deg.mean():.2f} deg "
          f"(wind triangle {expected_crab_deg.mean():.2f}), max |beta| {beta_deg.max():.3f} deg")
    assert np.abs(track_deg).max() < 0.5
    assert np.abs(crab_deg - expected_crab_deg).max() < 0.5
    assert beta_deg.max() < 0.5


def test_altitude_change_is_rate_limited_and_captured_without_overshoot() -> None:
    """1,500 -> 2,500 m with TAS hold: climb rate never above the 7.5 m/s limit by more than 25 %, the
    target captured within +-10 m with < 10 m overshoot, TAS within 5 m/s of the command."""
    fdm = start_in_flight(H0_M, TAS0_MPS)
    engage_autopilot(fdm, altitude_m=2500.0)
    rec = fly(fdm, 24000, ["position/h-sl-meters", "velocities/h-dot-fps", "velocities/vtrue-fps"])
    vs_mps = rec[:, 1] * 0.3048
    assert vs_mps.max() < 7.5 * 1.25
    assert vs_mps[2000:12000].mean() > 6.0, "climbs at close to the limit, not slower"
    assert rec[:, 0].max() - 2500.0 < 10.0
    assert np.abs(rec[-3000:, 0] - 2500.0).max() < 10.0
    assert np.abs(rec[:, 2] * 0.3048 - TAS0_MPS).max() < 5.0


def test_climb_beyond_available_power_protects_airspeed() -> None:
    """Commanding 1,500 -> 6,500 m at 85 m/s: full power cannot sustain 7.5 m/s up high, and the
    energy protection trades climb rate for airspeed: equivalent airspeed never below 56 m/s
    (~1.2 x the 46 m/s stall speed)."""
    fdm = start_in_flight(H0_M, TAS0_MPS)
    engage_autopilot(fdm, altitude_m=6500.0)
    rec = fly(fdm, 45000, ["velocities/ve-fps", "position/h-sl-meters"])
    assert (rec[:, 0] * 0.3048).min() > 56.0
    assert rec[-1, 1] > 4500.0, "still climbing"


def test_vertical_speed_mode_holds_minus_3mps() -> None:
    """Vertical-speed mode at -3 m/s: after 20 s the climb rate is -3 +- 0.3 m/s."""
    fdm = start_in_flight(H0_M, TAS0_MPS)
    engage_autopilot(fdm, vertical_mode=3)
    fdm["ap/vs-cmd-mps"] = -3.0
    rec = fly(fdm, 4000, ["velocities/h-dot-fps"])
    vs_mps = rec[2000:, 0] * 0.3048
    assert np.abs(vs_mps + 3.0).max() < 0.3


def test_height_above_ground_hold_follows_terrain_elevation() -> None:
    """AGL mode: terrain at 800 m under the aircraft at 1,500 m, AGL command 500 m: the aircraft
    descends to 1,300 m MSL and holds 500 +- 10 m above the terrain JSBSim was given."""
    fdm = start_in_flight(H0_M, TAS0_MPS)
    fdm["position/terrain-elevation-asl-ft"] = 800.0 * FT_PER_M
    engage_autopilot(fdm, vertical_mode=2)
    fdm["ap/agl-cmd-m"] = 500.0
    rec = fly(fdm, 9000, ["position/h-agl-ft", "position/h-sl-meters"])
    assert np.abs(rec[-2000:, 0] / FT_PER_M - 500.0).max() < 10.0
    assert rec[-1, 1] == pytest.approx(1300.0, abs=10.0)


def test_airspeed_hold_by_power_captures_100mps() -> None:
    """Speed mode 1: TAS command 85 -> 100 m/s at constant altitude; within 1 m/s after 60 s."""
    fdm = start_in_flight(H0_M, TAS0_MPS)
    engage_autopilot(fdm, tas_mps=100.0)
    rec = fly(fdm, 9000, ["velocities/vtrue-fps", "position/h-sl-meters"])
    assert np.abs(rec[6000:, 0] * 0.3048 - 100.0).max() < 1.0
    assert np.abs(rec[:, 1] - H0_M).max() < 10.0


def test_wings_leveller_rolls_out_of_a_20deg_bank() -> None:
    """Lateral mode 0 from a 20 deg bank: |bank| < 1 deg after 10 s."""
    fdm = start_in_flight(H0_M, TAS0_MPS)
    engage_autopilot(fdm, lateral_mode=1, heading_rad=fdm["attitude/psi-rad"] + 1.0)
    fly(fdm, 800, [])
    assert abs(math.degrees(fdm["attitude/phi-rad"])) > 15.0
    fdm["ap/lateral-mode"] = 0
    rec = fly(fdm, 1500, ["attitude/phi-rad"])
    assert np.degrees(np.abs(rec[1000:, 0])).max() < 1.0


def test_disengaged_autopilot_leaves_the_controls_alone() -> None:
    """ap/engage = 0: every autopilot increment is zero, so the surfaces stay at the trim values."""
    fdm = start_in_flight(H0_M, TAS0_MPS)
    engage_autopilot(fdm, altitude_m=2500.0, heading_rad=1.0, tas_mps=100.0)
    fly(fdm, 500, [])
    fdm["ap/engage"] = 0
    rec = fly(fdm, 10, ["ap/elevator-delta-norm", "ap/aileron-delta-norm", "ap/rudder-delta-norm",
                        "ap/throttle-delta-norm"])
    assert np.all(rec[-1] == 0.0)


@pytest.mark.parametrize("dt_s", [0.005, 0.01, 0.02, 0.04])
def test_autopilot_limits_hold_at_every_integration_step(dt_s: float) -> None:
    """The autopilot's FCS components run at the executive's step, whatever it is: after an altitude step
    the smoothed vertical-speed target moves at the XML's rate limit, 1.5 m/s per second (over 2 s, 3.0 m/s
    +- one step's 1.5 dt). A step set only after the model was loaded left them at JSBSim's default 1/120 s:
    0.625 m/s^2 at 0.02 s, 2.5 at 0.005 s."""
    fdm = start_in_flight(H0_M, TAS0_MPS, fdm=new_fdm("kingair", dt_s))
    assert fdm.get_delta_t() == pytest.approx(dt_s)
    engage_autopilot(fdm, altitude_m=H0_M)
    fly(fdm, int(round(5.0 / dt_s)), [])
    fdm["ap/altitude-cmd-m"] = H0_M + 400.0
    v0 = fdm["ap/vs-target-smooth-mps"]
    fly(fdm, int(round(2.0 / dt_s)), [])
    assert fdm["ap/vs-target-smooth-mps"] - v0 == pytest.approx(3.0, abs=1.5 * dt_s + 1e-9)


def test_flight_converges_as_the_integration_step_shrinks() -> None:
    """The flight core at 50 Hz flies the same manoeuvring flight (track changes and climbs, calm air) as at
    200 Hz, within 2 m horizontally and 0.5 m in height over 240 s (scripts/flight_step_check.py's
    schedule); with the autopilot's components on JSBSim's default step instead they parted by ~90 m and
    ~37 m over 480 s."""
    script = load_script("flight_step_check")
    ref = script.fly(0.005, 240)
    f = script.fly(0.02, 240)
    n = min(len(f), len(ref))
    dn = (f[:n, 0] - ref[:n, 0]) * script.R_EARTH_M
    de = (f[:n, 1] - ref[:n, 1]) * script.R_EARTH_M * np.cos(ref[:n, 0])
    assert n >= 240
    assert np.max(np.hypot(dn, de)) < 2.0
    assert np.max(np.abs(f[:n, 2] - ref[:n, 2])) < 0.5
    assert np.ptp(ref[:, 2]) > 150.0                                          # it climbed and descended
