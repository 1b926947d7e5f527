"""Wind: layer validation and interpolation, JSBSim turbulence on/off and severity ordering, gusts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trn_env.flight.core import AutopilotTargets, Flight, InitialCondition, LateralMode
from trn_env.flight.wind import CosineGust, Turbulence, WindConfig, WindLayer

LAT0, LON0 = math.radians(33.2), math.radians(-98.2)
TAS_MPS = 75.0


# ------------------------------------------------------------------------------------------ validation
def test_negative_wind_speed_names_the_field():
    with pytest.raises(ValueError, match=r"wind\.layers\[1\]\.speed_mps"):
        WindConfig(layers=[(0.0, 270.0, 5.0), (1000.0, 270.0, -3.0)])


def test_non_monotonic_layers_name_the_field():
    with pytest.raises(ValueError, match=r"wind\.layers\[2\]\.altitude_m.*monoton"):
        WindConfig(layers=[(0.0, 270.0, 5.0), (1000.0, 270.0, 8.0), (900.0, 270.0, 9.0)])
    with pytest.raises(ValueError, match=r"wind\.layers\[1\]\.altitude_m"):
        WindConfig(layers=[(500.0, 270.0, 5.0), (500.0, 270.0, 8.0)])


def test_unknown_turbulence_model_and_severity_are_rejected():
    with pytest.raises(ValueError, match=r"wind\.turbulence\.model"):
        WindConfig(turbulence=Turbulence(model="vonkarman"))
    with pytest.raises(ValueError, match=r"wind\.turbulence\.severity"):
        WindConfig(turbulence=Turbulence(model="milspec", severity="apocalyptic"))
    with pytest.raises(ValueError, match=r"wind\.turbulence\.severity"):
        WindConfig(turbulence=Turbulence(model="milspec", severity=9))


def test_bad_layer_and_gust_values_are_rejected():
    with pytest.raises(ValueError, match=r"wind\.layers\[0\]\.direction_from_deg"):
        WindConfig(layers=[(0.0, float("nan"), 5.0)])
    with pytest.raises(ValueError, match=r"wind\.layers\[0\] must be"):
        WindConfig(layers=[(0.0, 5.0)])
    with pytest.raises(ValueError, match=r"wind\.gusts\[0\]\.magnitude_mps"):
        WindConfig(gusts=[CosineGust(start_time_s=1.0, magnitude_mps=-2.0)])
    with pytest.raises(ValueError, match=r"wind\.gusts\[0\]\.frame"):
        WindConfig(gusts=[CosineGust(start_time_s=1.0, magnitude_mps=2.0, frame="ecef")])


# ------------------------------------------------------------------------------------------ steady wind
def test_direction_convention_is_meteorological_from():
    w = WindConfig(layers=[WindLayer(0.0, 270.0, 10.0)])      # from the west: the air moves east
    np.testing.assert_allclose(w.steady_wind_ned_mps(1000.0), [0.0, 10.0, 0.0], atol=1e-12)
    w = WindConfig.constant(0.0, 7.0)                         # from the north: moves south
    np.testing.assert_allclose(w.steady_wind_ned_mps(0.0), [-7.0, 0.0, 0.0], atol=1e-12)


def test_layers_interpolate_by_altitude_and_hold_beyond_the_ends():
    w = WindConfig(layers=[(0.0, 270.0, 10.0), (1000.0, 180.0, 20.0), (3000.0, 180.0, 40.0)])
    # component-wise linear interpolation, computed by hand
    np.testing.assert_allclose(w.steady_wind_ned_mps(500.0), [0.5 * 0.0 + 0.5 * 20.0, 0.5 * 10.0, 0.0])
    np.testing.assert_allclose(w.steady_wind_ned_mps(2000.0), [30.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(w.steady_wind_ned_mps(-100.0), [0.0, 10.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(w.steady_wind_ned_mps(9000.0), [40.0, 0.0, 0.0], atol=1e-12)
    for h in (-5.0, 0.0, 250.0, 999.0, 1500.0, 2999.9, 5000.0):
        np.testing.assert_allclose(w.steady_wind_ned_tuple(h), w.steady_wind_ned_mps(h), atol=1e-12)
    assert WindConfig().steady_wind_ned_tuple(100.0) == (0.0, 0.0, 0.0)


def test_steady_wind_follows_altitude_in_flight():
    """The flight core rewrites the steady wind for the current altitude at each advance."""
    wind = WindConfig(layers=[(0.0, 270.0, 4.0), (1400.0, 270.0, 6.0), (1600.0, 270.0, 16.0)])
    f = Flight(InitialCondition(LAT0, LON0, 1500.0, TAS_MPS, 0.0), wind=wind)
    c = f.advance(200)
    expected = wind.steady_wind_ned_mps(float(c.h_msl_m[-1]))
    np.testing.assert_allclose(c.wind_ned_mps[-1], wind.steady_wind_ned_mps(1500.0), atol=1e-9)
    f.advance(1)
    got = np.array([f.fdm[f"atmosphere/wind-{a}-fps"] for a in ("north", "east", "down")]) * 0.3048
    np.testing.assert_allclose(got, expected, atol=1e-9)
    # the trim starts in the wind: air-relative speed is the IC's TAS, ground speed includes the wind
    s = c.slice(0, 1)
    np.testing.assert_allclose(s.tas_mps, TAS_MPS, atol=0.2)
    assert s.v_ned_mps[0, 1] == pytest.approx(wind.steady_wind_ned_mps(1500.0)[1], abs=0.3)


# ------------------------------------------------------------------------------------------ turbulence
def _fly_turbulence(turbulence: Turbulence, seed: int = 11, n: int = 2000) -> dict[str, float]:
    """Fluctuation (std of the step-to-step change, last 15 s) of body rates, alpha, beta and wind."""
    f = Flight(InitialCondition(LAT0, LON0, 1500.0, TAS_MPS, 0.0), wind=WindConfig(turbulence=turbulence),
               seed=seed, targets=AutopilotTargets(lateral_mode=LateralMode.HEADING, heading_cmd_rad=0.0,
                                                   altitude_cmd_m=1500.0, tas_cmd_mps=TAS_MPS))
    c = f.advance(n).slice(n - 1500, n)

    def fluct(x):
        return float(np.std(np.diff(x, axis=0)))

    return {"p": fluct(c.omega_eb_b_rps[:, 0]), "q": fluct(c.omega_eb_b_rps[:, 1]),
            "alpha": fluct(c.alpha_rad), "beta": fluct(c.beta_rad), "wind": fluct(c.wind_ned_mps[:, 2])}


def test_turbulence_off_is_quiet_and_on_fluctuates_in_severity_order():
    off = _fly_turbulence(Turbulence(model="none"))
    light = _fly_turbulence(Turbulence(model="milspec", severity="light"))
    moderate = _fly_turbulence(Turbulence(model="milspec", severity="moderate"))
    severe = _fly_turbulence(Turbulence(model="milspec", severity="severe"))
    assert off["wind"] == 0.0
    for key in ("p", "q", "alpha", "beta"):
        assert 20.0 * off[key] < light[key] < moderate[key] < severe[key], key
    tustin = _fly_turbulence(Turbulence(model="tustin", severity="moderate"))
    for key in ("p", "alpha", "beta", "wind"):
        assert tustin[key] > 0.3 * moderate[key], key


def test_cosine_gust_profile_in_truth():
    gust = CosineGust(start_time_s=1.0, magnitude_mps=5.0, direction=(0.0, 0.0, -1.0), startup_s=1.0,
                      steady_s=1.0, end_s=1.0, frame="ned")
    f = Flight(InitialCondition(LAT0, LON0, 1500.0, TAS_MPS, 0.0), wind=WindConfig(gusts=[gust]))
    c = f.advance(450)
    w_up = -c.wind_ned_mps[:, 2]
    t = c.t_s
    assert np.all(w_up[t < 0.99] == 0.0)
    steady = (t > 2.1) & (t < 2.9)
    np.testing.assert_allclose(w_up[steady], 5.0, rtol=1e-9)
    assert np.all(w_up[t > 4.1] == 0.0)
    # half-way up the 1 - cos ramp the gust is half its magnitude
    k = int(np.argmin(np.abs(t - 1.5)))
    assert w_up[k] == pytest.approx(2.5, abs=0.2)
