"""King Air C90-class JSBSim model against published C90 figures (POH-class numbers).

Published reference figures (Beechcraft King Air C90/C90A POH, performance section; MTOW 10,100 lb):
- stall speed, flaps up, power idle, MTOW: 88 KIAS = 45.3 m/s  -> accepted 40-50 m/s
- maximum cruise speed ~245 KTAS at 12,000-16,000 ft (~126 m/s) -> accepted 115-135 m/s at 5,000 m
- sea-level rate of climb, two engines, MTOW: 1,955 ft/min = 9.9 m/s -> accepted 8-12 m/s
- the seed-000 flight test (Table 1) flew at 1,500 m and 5,600 m at ~85 m/s.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from jsbsim_helpers import (
    G0_MPS2,
    MTOW_KG,
    WING_AREA_M2,
    engage_autopilot,
    fly,
    mass_kg,
    start_in_flight,
)

from trn_env.aircraft_data import available_aircraft

ELEVATOR_MIN_RAD = -0.349  # 20 deg trailing edge up
ELEVATOR_MAX_RAD = 0.244  # 14 deg trailing edge down
RHO0_KGPM3 = 1.225


def _trim_succeeds_below_full_power(h_m: float, tas_mps: float, gamma_rad: float = 0.0) -> bool:
    """True when JSBSim trims the aircraft at (h, TAS, gamma) with the throttle below the stop."""
    try:
        fdm = start_in_flight(h_m, tas_mps, gamma_rad=gamma_rad)
    except RuntimeError:
        return False
    return fdm["fcs/throttle-cmd-norm[0]"] < 0.999


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
    real equilibrium: 5 s of hands-off flight change altitude < 3 m and TAS < 0.5 m/s."""
    fdm = start_in_flight(h_m, tas_mps)
    alpha_deg = fdm["aero/alpha-deg"]
    throttle = fdm["fcs/throttle-cmd-norm[0]"]
    elevator_rad = fdm["fcs/elevator-pos-rad"]
    assert -0.5 < alpha_deg < 8.0
    assert 0.05 < throttle < 1.0
    assert ELEVATOR_MIN_RAD * 0.8 < elevator_rad < ELEVATOR_MAX_RAD * 0.8
    rec = fly(fdm, 500, ["position/h-sl-meters", "velocities/vtrue-fps"])
    assert np.abs(rec[:, 0] - h_m).max() < 3.0
    assert np.abs(rec[:, 1] * 0.3048 - tas_mps).max() < 0.5


def test_clean_stall_speed_at_mtow_between_40_and_50_mps() -> None:
    """Idle-power deceleration in altitude hold at 1,000 m until the wing stalls; the 1-g stall speed
    Vs = sqrt(2 m g / (rho0 S CLmax)) (EAS) from the peak lift coefficient lies in 40-50 m/s
    (C90 POH: 88 KIAS = 45.3 m/s), and lift really breaks down after the peak (a stall, not a
    speed floor)."""
    fdm = start_in_flight(1000.0, 58.0)
    engage_autopilot(fdm, lateral_mode=1, vertical_mode=1, speed_mode=0)
    fdm["ap/min-eas-mps"] = 0.0  # switch the autopilot's stall protection off for this test
    for i in range(2):
        fdm[f"fcs/throttle-cmd-norm[{i}]"] = 0.0
    rec = fly(fdm, 2500, ["aero/cl-squared", "aero/alpha-rad", "position/h-sl-meters"])
    cl = np.sqrt(rec[:, 0])
    k = int(np.argmax(cl))
    cl_max = cl[k]
    vs_eas_mps = math.sqrt(2.0 * mass_kg(fdm) * G0_MPS2 / (RHO0_KGPM3 * WING_AREA_M2 * cl_max))
    assert mass_kg(fdm) == pytest.approx(MTOW_KG, rel=0.01)
    assert 40.0 <= vs_eas_mps <= 50.0
    assert k < len(cl) - 100, "lift coefficient still rising at the end: no stall reached"
    assert cl[k:].min() < 0.9 * cl_max
    assert abs(rec[k, 2] - 1000.0) < 15.0, "stall must be reached in level flight"


def test_max_level_speed_5000m_between_115_and_135_mps() -> None:
    """Highest TAS at 5,000 m that JSBSim trims level below full throttle (bisection, 0.2 m/s):
    115-135 m/s (C90 max cruise ~245 KTAS = 126 m/s)."""
    lo, hi = 100.0, 150.0
    assert _trim_succeeds_below_full_power(5000.0, lo)
    assert not _trim_succeeds_below_full_power(5000.0, hi)
    while hi - lo > 0.2:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _trim_succeeds_below_full_power(5000.0, mid) else (lo, mid)
    assert 115.0 <= lo <= 135.0


def test_sea_level_climb_rate_at_mtow_between_8_and_12_mps() -> None:
    """Best steady climb at 30 m, MTOW, full power: for each speed the steepest flight-path angle that
    JSBSim trims below full throttle (bisection, 0.05 deg); the best V sin(gamma) is 8-12 m/s
    (C90 POH 1,955 ft/min = 9.9 m/s)."""
    rates = []
    for tas_mps in (60.0, 65.0, 70.0, 75.0, 80.0):
        lo, hi = 0.0, math.radians(20.0)
        while hi - lo > math.radians(0.05):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if _trim_succeeds_below_full_power(30.0, tas_mps, mid) else (lo, mid)
        rates.append(tas_mps * math.sin(lo))
    best = max(rates)
    assert 8.0 <= best <= 12.0
