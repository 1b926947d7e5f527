"""King Air C90-class JSBSim model against published C90 figures (POH-class numbers).

Published reference figures (Beechcraft King Air C90/C90A POH, performance section; MTOW 10,100 lb):
- stall speed, flaps up, power idle, MTOW: 88 KIAS = 45.3 m/s  -> accepted 40-50 m/s
- stall speed, flaps down (35 deg), MTOW: 76 KIAS = 39.1 m/s    -> accepted 35-43 m/s
- maximum cruise speed ~245 KTAS at 12,000-16,000 ft (~126 m/s) -> accepted 115-135 m/s at 5,000 m
- sea-level rate of climb, two engines, MTOW: 1,955 ft/min = 9.9 m/s -> accepted 8-12 m/s
- the seed-000 flight test (Table 1) flew at 1,500 m and 5,600 m at ~85 m/s.

Fuel (AOPA Pilot, "Turbine Pilot: King Air C90GTi", June 2008, Hawker Beechcraft spec sheet; fuel flows for
both engines; the C90GTi's PT6A-135A is flat rated at 550 shp like the C90's PT6A-21):
- usable fuel 384 US gal = 2,573 lb (1,454 L)
- max-cruise power, FL290: 272 KTAS, 612 lb/h (91 US gal/h) -> 306 lb/h per engine
- max-range power, FL260: 208 KTAS, 332 lb/h (50 US gal/h) -> 7.75 h on the full 2,573 lb
- PT6A-21 rated specific fuel consumption 0.63 lb/shp/h (the engine file's psfc; P&WC quote ~0.66 lb/eshp/h
  for the small PT6A class); at part power a turboshaft's SFC rises (fuel flow ~ linear in power).
(A figure of 60-75 US gal/h per side is sometimes quoted; the manufacturer's own numbers above are 45 US gal/h
per side at max cruise, 25 at max range.)
"""

from __future__ import annotations

import math

import jsbsim
import numpy as np
import pytest
from jsbsim_helpers import (
    G0_MPS2,
    LBS_PER_KG,
    MTOW_KG,
    WING_AREA_M2,
    engage_autopilot,
    fly,
    mass_kg,
    start_in_flight,
)

from trn_env.flight.aircraft_data import available_aircraft, new_fdm

ELEVATOR_MIN_RAD = -0.349  # 20 deg trailing edge up
ELEVATOR_MAX_RAD = 0.244  # 14 deg trailing edge down
RHO0_KGPM3 = 1.225


def _full_power_level_run(h_m: float, tas0_mps: float, n_steps: int) -> np.ndarray:
    """Trimmed at (h, TAS0), then both throttles at the stop with the autopilot holding altitude and
    heading (stall protection off); returns (n_steps, 3): TAS m/s, climb rate m/s, altitude m."""
    fdm = start_in_flight(h_m, tas0_mps)
    engage_autopilot(fdm, lateral_mode=1, vertical_mode=1, speed_mode=0)
    fdm["ap/min-eas-mps"] = 0.0
    for i in range(2):
        fdm[f"fcs/throttle-cmd-norm[{i}]"] = 1.0
    rec = fly(fdm, n_steps, ["velocities/vtrue-fps", "velocities/h-dot-fps", "position/h-sl-meters"])
    rec[:, :2] *= 0.3048
    return rec


def test_kingair_is_available_and_at_mtow_by_default() -> None:
    """The default loading (full fuel, crew, payload) is the C90 MTOW 4,580 kg within 1 %."""
    assert "kingair" in available_aircraft()
    fdm = start_in_flight(1500.0, 85.0, trim=False)
    assert mass_kg(fdm) == pytest.approx(MTOW_KG, rel=0.01)
    # 1,450 L usable Jet-A at 0.80 kg/L within 2 %
    fuel_kg = fdm["propulsion/total-fuel-lbs"] * 0.45359237
    assert fuel_kg == pytest.approx(1450 * 0.80, rel=0.02)


@pytest.mark.parametrize(
    ("h_m", "tas_mps"),
    [(1500.0, 85.0), (5600.0, 85.0), (5000.0, 115.0)],
    ids=["1500m_85mps", "5600m_85mps", "5000m_115mps"],
)
def test_trims_level_flight_alpha_0_to_8deg_throttle_below_1(h_m: float, tas_mps: float) -> None:
    """JSBSim trim succeeds; alpha 0-8 deg, throttle < 1, elevator inside its stops, and the trim is a
    real equilibrium: 5 s of hands-off flight change altitude < 3 m and TAS < 1 m/s (JSBSim restarts a
    turboprop's N1 from idle after a trim, which costs ~0.4 m/s while the engines spool back)."""
    fdm = start_in_flight(h_m, tas_mps)
    alpha_deg = fdm["aero/alpha-deg"]
    throttle = fdm["fcs/throttle-cmd-norm[0]"]
    elevator_rad = fdm["fcs/elevator-pos-rad"]
    print(f"trim {h_m:.0f} m {tas_mps:.0f} m/s: alpha {alpha_deg:.2f} deg, throttle {throttle:.3f}, "
          f"elevator {math.degrees(elevator_rad):.2f} deg")
    assert -0.5 < alpha_deg < 8.0
    assert 0.05 < throttle < 1.0
    assert ELEVATOR_MIN_RAD * 0.8 < elevator_rad < ELEVATOR_MAX_RAD * 0.8
    rec = fly(fdm, 500, ["position/h-sl-meters", "velocities/vtrue-fps"])
    assert np.abs(rec[:, 0] - h_m).max() < 3.0
    assert np.abs(rec[:, 1] * 0.3048 - tas_mps).max() < 1.0


@pytest.mark.parametrize(
    ("flaps_norm", "tas0_mps", "vs_min_mps", "vs_max_mps"),
    [(0.0, 58.0, 40.0, 50.0), (1.0, 50.0, 35.0, 43.0)],
    ids=["clean_40_to_50mps", "flaps35_35_to_43mps"],
)
def test_stall_speed_at_mtow(
    flaps_norm: float, tas0_mps: float, vs_min_mps: float, vs_max_mps: float
) -> None:
    """Idle-power deceleration in altitude hold at 1,000 m until the wing stalls; the 1-g stall speed
    Vs = sqrt(2 m g / (rho0 S CLmax)) (EAS) from the peak lift coefficient lies in the band
    (C90 POH: 88 KIAS = 45.3 m/s clean, 76 KIAS = 39.1 m/s flaps down), and lift really breaks down
    after the peak (a stall, not a speed floor)."""
    fdm = start_in_flight(1000.0, tas0_mps, flaps_norm=flaps_norm)
    engage_autopilot(fdm, lateral_mode=1, vertical_mode=1, speed_mode=0)
    fdm["ap/min-eas-mps"] = 0.0  # switch the autopilot's stall protection off for this test
    for i in range(2):
        fdm[f"fcs/throttle-cmd-norm[{i}]"] = 0.0
    rec = fly(fdm, 2500, ["aero/cl-squared", "aero/alpha-rad", "position/h-sl-meters"])
    cl = np.sqrt(rec[:, 0])
    k = int(np.argmax(cl))
    cl_max = cl[k]
    vs_eas_mps = math.sqrt(2.0 * mass_kg(fdm) * G0_MPS2 / (RHO0_KGPM3 * WING_AREA_M2 * cl_max))
    print(f"stall flaps {35 * flaps_norm:.0f} deg: CLmax {cl_max:.3f}, Vs {vs_eas_mps:.2f} m/s EAS")
    assert mass_kg(fdm) == pytest.approx(MTOW_KG, rel=0.01)
    assert vs_min_mps <= vs_eas_mps <= vs_max_mps
    assert k < len(cl) - 100, "lift coefficient still rising at the end: no stall reached"
    assert cl[k:].min() < 0.9 * cl_max
    assert abs(rec[k, 2] - 1000.0) < 15.0, "stall must be reached in level flight"


def test_max_level_speed_5000m_between_115_and_135_mps() -> None:
    """Full power in level flight at 5,000 m from 115 m/s until the speed settles (400 s, ~5 speed time
    constants): the final TAS is 115-135 m/s (C90 max cruise ~245 KTAS = 126 m/s), steady (< 0.1 m/s change
    over the last 50 s) and reached at constant altitude (+-10 m)."""
    rec = _full_power_level_run(5000.0, 115.0, 40000)
    v_max = rec[-1, 0]
    print(f"max level speed at 5000 m: {v_max:.2f} m/s TAS")
    assert 115.0 <= v_max <= 135.0
    assert abs(rec[-1, 0] - rec[-5000, 0]) < 0.1
    assert np.abs(rec[:, 2] - 5000.0).max() < 10.0


def test_sea_level_climb_rate_at_mtow_between_8_and_12_mps() -> None:
    """Level-acceleration flight test at 30 m, MTOW, full power from 52 m/s: specific excess power
    Ps = V/g dV/dt + dh/dt (= steady rate of climb at that speed) peaks at 8-12 m/s
    (C90 POH 1,955 ft/min = 9.9 m/s), at a best-climb speed between 55 and 95 m/s."""
    rec = _full_power_level_run(30.0, 52.0, 4000)
    v = rec[:, 0]
    box = np.ones(100) / 100.0  # 1 s moving average
    dv_dt = np.convolve(np.gradient(v, 0.01), box, mode="same")
    h_dot = np.convolve(rec[:, 1], box, mode="same")
    ps = v * dv_dt / G0_MPS2 + h_dot
    window = slice(300, 3900)  # engines spooled up; away from the filter edges
    k = int(np.argmax(ps[window]))
    print(f"sea-level best climb: {ps[window][k]:.2f} m/s at {v[window][k]:.1f} m/s TAS")
    assert 8.0 <= ps[window][k] <= 12.0
    assert 55.0 < v[window][k] < 95.0


def test_inertia_at_mtow_matches_roskam_radii_of_gyration() -> None:
    """At MTOW the moments of inertia JSBSim assembles (empty + fuel tanks + point masses) equal Roskam's
    twin-engine-propeller estimate I = m (k R / 2)^2 (Rx 0.34 span, Ry 0.29 length, Rz 0.44 mean of span and
    length) within 3 %, and the centre of gravity sits within 0.1 m of the aerodynamic reference point."""
    fdm = start_in_flight(1500.0, 85.0, trim=False)
    m_kg, span_m, length_m = mass_kg(fdm), 15.3, 10.8
    expected = {
        "inertia/ixx-slugs_ft2": m_kg * (span_m * 0.34 / 2.0) ** 2,
        "inertia/iyy-slugs_ft2": m_kg * (length_m * 0.29 / 2.0) ** 2,
        "inertia/izz-slugs_ft2": m_kg * ((span_m + length_m) / 2.0 * 0.44 / 2.0) ** 2,
    }
    for prop, i_kgm2 in expected.items():
        assert fdm[prop] * 1.3558179 == pytest.approx(i_kgm2, rel=0.03), prop
    assert fdm["inertia/cg-x-in"] * 0.0254 == pytest.approx(4.80, abs=0.1)


def _first_two_peaks(x: np.ndarray, dt_s: float) -> tuple[float, float]:
    """Period (s) and damping ratio from the first two positive peaks of a decaying oscillation."""
    peaks = [k for k in range(1, len(x) - 1) if x[k] > x[k - 1] and x[k] >= x[k + 1] and x[k] > 0]
    assert len(peaks) >= 2, "no oscillation found"
    period_s = (peaks[1] - peaks[0]) * dt_s
    log_dec = math.log(x[peaks[0]] / x[peaks[1]])
    return period_s, log_dec / math.sqrt(4.0 * math.pi**2 + log_dec**2)


def test_dutch_roll_and_phugoid_meet_mil_f_8785c_level_1() -> None:
    """Bare airframe (autopilot off) at 1,500 m / 85 m/s. Rudder doublet: Dutch roll damping ratio
    >= 0.08 and natural frequency >= 0.4 rad/s (MIL-F-8785C Level 1, Class II). Elevator doublet: the
    phugoid is stable with damping ratio >= 0.04 and a period of 20-90 s (light twins: ~30-60 s)."""
    fdm = start_in_flight(1500.0, 85.0)
    r0 = fdm["fcs/rudder-cmd-norm"]
    for dr, n in ((0.3, 100), (-0.3, 100), (0.0, 1)):
        fdm["fcs/rudder-cmd-norm"] = r0 + dr
        fly(fdm, n, [])
    beta = fly(fdm, 2000, ["aero/beta-rad"])[:, 0]
    period_s, zeta = _first_two_peaks(beta, 0.01)
    omega_n = 2.0 * math.pi / period_s / math.sqrt(1.0 - zeta**2)
    print(f"dutch roll: zeta {zeta:.3f}, omega_n {omega_n:.2f} rad/s")
    assert zeta >= 0.08
    assert omega_n >= 0.4

    fdm = start_in_flight(1500.0, 85.0)
    e0 = fdm["fcs/elevator-cmd-norm"]
    for de, n in ((-0.1, 50), (0.1, 50), (0.0, 1)):
        fdm["fcs/elevator-cmd-norm"] = e0 + de
        fly(fdm, n, [])
    tas = fly(fdm, 30000, ["velocities/vtrue-fps"])[:, 0]
    period_s, zeta = _first_two_peaks(tas - tas.mean(), 0.01)
    print(f"phugoid: period {period_s:.1f} s, zeta {zeta:.3f}")
    assert 20.0 <= period_s <= 90.0
    assert zeta >= 0.04


def test_sits_level_on_tricycle_gear_with_8_to_16_percent_on_the_nose_wheel() -> None:
    """Parked at MTOW: all three wheels on the ground, attitude within 1 deg of level, the gear carries
    the weight, and the nose wheel 8-16 % of it (spring force = compression x stiffness; the statics of the
    CG 3.35 m behind the nose wheel and 0.45 m ahead of the mains give 11.8 %)."""
    fdm = new_fdm("kingair", 0.01)
    fdm["ic/terrain-elevation-ft"] = 500.0
    fdm["ic/h-agl-ft"] = 0.0
    fdm["ic/vt-kts"] = 0.0
    fdm.run_ic()
    fly(fdm, 500, [])
    weight_n = mass_kg(fdm) * G0_MPS2
    stiffness_npm = (60000.0, 200000.0, 200000.0)
    loads_n = [fdm[f"gear/unit[{i}]/compression-ft"] * 0.3048 * stiffness_npm[i] for i in range(3)]
    assert all(fdm[f"gear/unit[{i}]/WOW"] == 1 for i in range(3))
    assert abs(fdm["attitude/theta-deg"]) < 1.0 and abs(fdm["attitude/phi-deg"]) < 1.0
    assert sum(loads_n) == pytest.approx(weight_n, rel=0.03)
    assert 0.08 <= loads_n[0] / weight_n <= 0.16


def _fuel_burn_lbph(fdm: jsbsim.FGFDMExec, n_steps: int) -> tuple[float, float]:
    """Fly n_steps (autopilot as engaged by the caller) and return (fuel burn of both engines from the drop in
    tank contents, lb/h; mean shaft power per engine, hp). The burn is a mass balance on the tanks, not
    JSBSim's fuel-flow output."""
    fuel0_lbs = fdm["propulsion/total-fuel-lbs"]
    t0_s = fdm["simulation/sim-time-sec"]
    rec = fly(fdm, n_steps, ["propulsion/engine[0]/power-hp", "propulsion/engine[1]/power-hp"])
    dt_h = (fdm["simulation/sim-time-sec"] - t0_s) / 3600.0
    burn_lbph = (fuel0_lbs - fdm["propulsion/total-fuel-lbs"]) / dt_h
    return burn_lbph, float(rec.mean())


def test_max_cruise_fuel_flow_and_sfc_match_c90_figures() -> None:
    """Max-cruise power (both throttles at the stop) in level flight at 5,000 m (16,400 ft, the C90's
    max-cruise band) from 120 m/s: after 10 s of spool-up, the burn measured over 20 s from the tanks is
    306 lb/h per engine +-15 % (C90GTi max cruise 612 lb/h for both) and the specific fuel consumption
    0.60-0.70 lb/shp/h (PT6A-21 0.63 rated; the issue: 5.2 at part power)."""
    fdm = start_in_flight(5000.0, 120.0)
    engage_autopilot(fdm, lateral_mode=1, vertical_mode=1, speed_mode=0)
    for i in range(2):
        fdm[f"fcs/throttle-cmd-norm[{i}]"] = 1.0
    fly(fdm, 1000, [])
    burn_lbph, hp = _fuel_burn_lbph(fdm, 2000)
    sfc = burn_lbph / 2.0 / hp
    print(f"max cruise 5000 m: {burn_lbph / 2:.0f} lb/h per engine at {hp:.0f} shp, SFC {sfc:.3f} lb/shp/h")
    assert burn_lbph / 2.0 == pytest.approx(306.0, rel=0.15)
    assert 0.60 <= sfc <= 0.70


def _cruise_burn_lbph(fuel_fraction: float) -> float:
    """Both tanks at `fuel_fraction` of capacity, trimmed at the seed-000 cruise point 2,000 m / 85 m/s, the
    autopilot holding altitude, heading and TAS: burn of both engines over 30 s after 10 s settling (lb/h)."""
    fdm = new_fdm("kingair", 0.01)
    for i in range(2):
        fdm[f"propulsion/tank[{i}]/contents-lbs"] = fuel_fraction * 582.0 * LBS_PER_KG
    start_in_flight(2000.0, 85.0, fdm=fdm)
    engage_autopilot(fdm)
    fly(fdm, 1000, [])
    burn_lbph, hp = _fuel_burn_lbph(fdm, 3000)
    print(f"cruise 2000 m 85 m/s, fuel {fuel_fraction:.0%}: {burn_lbph:.0f} lb/h both engines at {hp:.0f} shp"
          f" each, SFC {burn_lbph / 2 / hp:.3f}")
    return burn_lbph


def test_low_level_cruise_fuel_flow_and_full_fuel_endurance_match_c90_max_range() -> None:
    """At the TRN cruise point (2,000 m, 85 m/s = 165 KTAS, MTOW) the burn is 332 lb/h for both engines
    +-20 % (C90GTi max-range setting, 50 US gal/h), and the endurance on the full 1,164 kg (1,450 L) load,
    flying this cruise from full tanks to empty, is 7.75 h +-20 % (2,573 lb / 332 lb/h). Endurance: the burn
    is measured at full tanks (F1) and at 3 % (F2); with burn linear in weight,
    t = fuel (ln F1 - ln F2) / (F1 - F2). The issue's model burned 2,000 lb/h here (1.3 h)."""
    f_full = _cruise_burn_lbph(1.0)
    f_empty = _cruise_burn_lbph(0.03)
    fuel_lbs = 0.97 * 2 * 582.0 * LBS_PER_KG
    endurance_h = fuel_lbs * math.log(f_full / f_empty) / (f_full - f_empty)
    print(f"endurance on {fuel_lbs:.0f} lb: {endurance_h:.2f} h")
    assert f_full == pytest.approx(332.0, rel=0.20)
    assert f_empty < f_full  # lighter aircraft, less power, less fuel
    assert endurance_h == pytest.approx(7.75, rel=0.20)
