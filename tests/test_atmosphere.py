"""Non-standard day: the atmosphere JSBSim flies in, the truth's p/T, and the barometric altitude error it
causes, checked against JSBSim's own values and an independent hydrostatic integration."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

import trn_env.scenario.build as components
from trn_env.flight.aircraft_data import new_fdm
from trn_env.flight.atmosphere import Atmosphere, static_p_T
from trn_env.flight.core import Flight, InitialCondition
from trn_env.scenario.loading import ScenarioError, read_scenario_file, validate
from trn_env.sensors.baro import BaroConfig, sample_baro

LAT0, LON0 = math.radians(33.2), math.radians(-98.2)
FT = 0.3048
PSF = 47.88025898033584
R_AIR = 287.05287             # ISA specific gas constant (ISO 2533)
G0 = 9.80665
R_EARTH_GP = 6356766.0        # radius of the geopotential definition (US 1976)
SCENARIOS = Path(__file__).parent / "scenarios"


# ---------------------------------------------------------------------------------- independent model
def _hydrostatic_p_pa(h_m: float, delta_T_K: float, p_sl_pa: float) -> float:
    """Pressure at geometric height h_m by integrating dp/dz = -g(z) p / (R T(z)) numerically, with
    g(z) = g0 (r0 / (r0 + z))^2 and T = 288.15 K + delta_T - 6.5 K/km of geopotential height (below 11 km).
    Independent of every closed form in the code under test."""
    def rhs(z, y):
        hgp = R_EARTH_GP * z / (R_EARTH_GP + z)
        t = 288.15 + delta_T_K - 0.0065 * hgp
        g = G0 * (R_EARTH_GP / (R_EARTH_GP + z)) ** 2
        return [-g * y[0] / (R_AIR * t)]
    sol = solve_ivp(rhs, (0.0, h_m), [p_sl_pa], rtol=1e-12, atol=1e-9)
    return float(sol.y[0, -1])


def _isa_pressure_altitude_m(p_pa: float) -> float:
    """Geopotential pressure altitude: the H at which the standard day's pressure (integrated numerically
    over geopotential height, dp/dH = -g0 p / (R T_ISA(H))) equals p_pa."""
    def p_std(hgp):
        sol = solve_ivp(lambda h, y: [-G0 * y[0] / (R_AIR * (288.15 - 0.0065 * h))], (0.0, hgp), [101325.0],
                        rtol=1e-12, atol=1e-9)
        return float(sol.y[0, -1])
    return brentq(lambda h: p_std(h) - p_pa, -500.0, 10500.0, xtol=1e-4)


# ---------------------------------------------------------------------------------- JSBSim's atmosphere
@pytest.mark.parametrize("delta_T_K, p_sl_pa", [(20.0, 101325.0), (-15.0, 99500.0), (5.0, 103000.0)])
def test_static_p_T_matches_jsbsims_non_standard_atmosphere(delta_T_K, p_sl_pa):
    """Atmosphere.apply sets JSBSim's temperature bias and sea-level pressure; static_p_T gives JSBSim's own
    atmosphere/P-psf and T-R at the same position, from sea level into the stratosphere."""
    atm = Atmosphere(delta_T_K=delta_T_K, p_sl_pa=p_sl_pa)
    fdm = new_fdm()
    atm.apply(fdm)
    for h in (0.0, 1200.0, 3000.0, 7000.0, 12500.0):
        fdm["ic/h-sl-ft"] = h / FT
        fdm["ic/lat-geod-rad"] = LAT0
        fdm["ic/long-gc-rad"] = LON0
        fdm.run_ic()
        lat, h_geod = fdm["position/lat-geod-rad"], fdm["position/geod-alt-ft"] * FT
        p, t = static_p_T(lat, LON0, h_geod, delta_T_K, p_sl_pa)
        assert p == pytest.approx(fdm["atmosphere/P-psf"] * PSF, abs=2e-3), h
        assert t == pytest.approx(fdm["atmosphere/T-R"] / 1.8, abs=1e-6), h
    assert fdm["atmosphere/delta-T"] == pytest.approx(1.8 * delta_T_K)


def test_flight_flies_in_and_records_the_days_atmosphere():
    """A Flight on an ISA+20 / 1005 hPa day: JSBSim keeps the settings through trim and flight, the truth's
    p/T equal JSBSim's at the end of a chunk, the density the aircraft feels is p / (R T) of the truth, and
    the hotter (thinner) air needs a larger angle of attack at the same TAS."""
    ic = InitialCondition(LAT0, LON0, 3000.0, 80.0, 0.4)
    hot = Flight(ic, atmosphere=Atmosphere(delta_T_K=20.0, p_sl_pa=100500.0))
    std = Flight(ic)
    c = hot.advance(200)
    fdm = hot.fdm
    assert fdm["atmosphere/delta-T"] == pytest.approx(36.0)
    assert fdm["atmosphere/P-sl-psf"] * PSF == pytest.approx(100500.0, abs=1e-6)
    assert c.p_static_pa[-1] == pytest.approx(fdm["atmosphere/P-psf"] * PSF, abs=2e-3)
    assert c.T_static_K[-1] == pytest.approx(fdm["atmosphere/T-R"] / 1.8, abs=1e-6)
    rho_jsbsim = fdm["atmosphere/rho-slugs_ft3"] * 14.59390294 / FT ** 3
    assert rho_jsbsim == pytest.approx(c.p_static_pa[-1] / (8.31432 / 0.0289645 * c.T_static_K[-1]), rel=1e-6)
    assert c.T_static_K[-1] == pytest.approx(288.15 + 20.0 - 0.0065 * 3000.0, abs=0.2)
    s = std.snapshot()
    assert c.alpha_rad[-1] > s.alpha_rad[0] + math.radians(0.2)
    # a standard-day Flight still records JSBSim's standard atmosphere
    assert s.p_static_pa[0] == pytest.approx(std.fdm["atmosphere/P-psf"] * PSF, abs=2e-3)


def test_set_atmosphere_in_flight_changes_jsbsim_and_the_truth():
    f = Flight(InitialCondition(LAT0, LON0, 2000.0, 80.0, 0.0))
    before = f.advance(5)
    f.set_atmosphere(Atmosphere(delta_T_K=-10.0))
    after = f.advance(5)
    assert after.T_static_K[-1] == pytest.approx(before.T_static_K[-1] - 10.0, abs=0.05)
    assert after.T_static_K[-1] == pytest.approx(f.fdm["atmosphere/T-R"] / 1.8, abs=1e-6)
    assert after.p_static_pa[-1] == pytest.approx(f.fdm["atmosphere/P-psf"] * PSF, abs=2e-3)


def test_hot_day_pressure_altitude_reads_about_200_m_low_at_3000_m():
    """ISA+20 at true 3000 m: the truth's static pressure equals the independent hydrostatic integral, and
    the barometric altimeter (ISA pressure altitude, noise-free) reads the independent pressure altitude,
    about 200 m below the true height."""
    ic = InitialCondition(LAT0, LON0, 3000.0, 80.0, 0.0)
    f = Flight(ic, atmosphere=Atmosphere(delta_T_K=20.0))
    c = f.advance(100)
    h_true = float(c.h_msl_m[-1])
    assert h_true == pytest.approx(3000.0, abs=5.0)
    p_expected = _hydrostatic_p_pa(h_true, 20.0, 101325.0)
    assert c.p_static_pa[-1] == pytest.approx(p_expected, abs=0.5)      # 0.5 Pa ~ 5 cm
    hp_expected = _isa_pressure_altitude_m(p_expected)
    frame, _ = sample_baro(c, None, np.random.default_rng(0), BaroConfig.noise_free())
    assert frame.h_baro_m[-1] == pytest.approx(hp_expected, abs=0.1)
    # hydrostatics: the error is close to -h dT / T_ISA(sea level) ~ -208 m
    assert h_true - frame.h_baro_m[-1] == pytest.approx(200.0, abs=15.0)


# ---------------------------------------------------------------------------------------------- scenario
def _scenario(atmosphere: dict | None):
    data, _ = read_scenario_file(SCENARIOS / "default_short.toml")
    if atmosphere is not None:
        data["atmosphere"] = atmosphere
    return validate(data, source="test")


def _baro_error_m(sc) -> tuple[float, float, float]:
    """(mean baro - true height, true height, expected error from the independent model) over 2 s."""
    world = sc.extras["world_dem_raw"]
    flight = components.build_flight(sc, world, np.random.default_rng(0))
    c = flight.advance(200)
    frame, _ = sample_baro(c, None, np.random.default_rng(0), BaroConfig.noise_free())
    h_true = c.h_msl_m[-1]
    atm = sc.atmosphere.to_dict() if sc.atmosphere is not None else {}
    p = _hydrostatic_p_pa(h_true, atm.get("delta_T_K", 0.0), atm.get("p_sl_pa", 101325.0))
    return float(frame.h_baro_m[-1] - h_true), float(h_true), _isa_pressure_altitude_m(p) - h_true


def test_scenario_atmosphere_table_gives_the_baro_error():
    """A scenario's [atmosphere] table reaches the flight: ISA+20 with a high sea-level pressure makes the
    noise-free altimeter (set to standard pressure) read low by the independently computed amount; the
    standard day reads true (within the geopotential-versus-geometric metre)."""
    err_std, _, expected_std = _baro_error_m(_scenario(None))
    assert abs(err_std) < 2.0 and err_std == pytest.approx(expected_std, abs=0.1)
    err_hot, h_hot, expected_hot = _baro_error_m(_scenario({"delta_T_K": 20.0, "p_sl_pa": 102500.0}))
    assert err_hot == pytest.approx(expected_hot, abs=0.1)
    # ISA+20 (~ -h 20/288 ~ -140 m) and 1175 Pa above standard (~ -98 m at sea level) add up
    assert err_hot < -(h_hot * 20.0 / 288.15) - 80.0


def test_bad_atmosphere_is_named():
    with pytest.raises(ValueError, match="Atmosphere.delta_T_K"):
        Atmosphere(delta_T_K=80.0)
    with pytest.raises(ValueError, match="Atmosphere.p_sl_pa"):
        Atmosphere(p_sl_pa=float("nan"))
    with pytest.raises(ValueError, match="atmosphere must be an Atmosphere"):
        Flight(InitialCondition(LAT0, LON0, 1500.0, 80.0), atmosphere={"delta_T_K": 5.0})
    with pytest.raises(ScenarioError) as err:
        _scenario({"delta_T_K": 90.0, "qnh": 1013.0})
    text = str(err.value)
    assert "atmosphere.delta_T_K: 90.0 is greater than the maximum of 60" in text
    assert "atmosphere.qnh: unknown key" in text
