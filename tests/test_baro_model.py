"""The barometer's measurement model (navigators.measurements.baro: predict, likelihood) against
independent computations: the geopotential altitude as the integral of gravity's fall with height
(scipy quad), the US 1976 table by geometric height through the simulator's ISA pressure, and scipy's normal
log-density."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate, stats
from trn_env.navigators.measurements import baro

from trn_env.sensors.baro import isa_pressure_pa


def test_predict_geopotential_is_the_integral_of_gravity_with_height():
    """H(h) = integral_0^h (r0 / (r0 + z))^2 dz (inverse-square gravity over g0); plus the bias."""
    r0 = baro.R0_GEOPOTENTIAL_M
    h = np.array([-300.0, 0.0, 850.0, 4200.0, 11000.0])
    ref = np.array([integrate.quad(lambda z: (r0 / (r0 + z)) ** 2, 0.0, x, epsabs=1e-10)[0] for x in h])
    np.testing.assert_allclose(baro.predict(h, 0.0, geopotential=True), ref, rtol=0, atol=1e-6)
    np.testing.assert_allclose(baro.predict(h, 7.5, geopotential=True), ref + 7.5, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(baro.predict(h, -3.0), h - 3.0)  # a geometric-height barometer
    # round trip through the conversion the navigators apply to the readings
    np.testing.assert_allclose(baro.geometric_height_m(baro.predict(h, 0.0, True)), h, rtol=0, atol=1e-7)


def test_predict_matches_the_us1976_table_by_geometric_height():
    """US 1976 by geometric height: 1500 m -> 84.56 kPa, 5000 m -> 54.05 kPa (the simulator's ISA)."""
    for z, p in ((1500.0, 84560.0), (5000.0, 54048.0)):
        assert isa_pressure_pa(baro.predict(z, 0.0, geopotential=True)) == pytest.approx(p, rel=3e-4)


def test_likelihood_is_the_normal_log_density_without_its_constant():
    rng = np.random.default_rng(3)
    z = 512.3
    pred = rng.normal(500.0, 20.0, 50)
    sigma = 6.0
    ref = stats.norm.logpdf(z, loc=pred, scale=sigma) + np.log(sigma * np.sqrt(2.0 * np.pi))
    np.testing.assert_allclose(baro.likelihood(z, pred, sigma), ref, rtol=0, atol=1e-9)
    assert int(np.argmax(baro.likelihood(z, pred, sigma))) == int(np.argmin(np.abs(pred - z)))
