"""Barometric altimeter: the measured height the navigators use, and its measurement model.

The barometer reports the pressure altitude, an ISA geopotential height H (US Standard Atmosphere 1976);
the navigators' INS and maps are in geometric height h = r0 H / (r0 - H), r0 = 6,356,766 m (the standard's
Earth radius for geopotential height; its inverse H = r0 h / (r0 + h) is the integral of g(z) / g0 =
(r0 / (r0 + z))^2 from 0 to h). `geometric_height_m` works on floats and numpy arrays;
`geometric_height_kernel` is the same formula compiled for numba kernels (the same bits).

Measurement model, with the interface the radar altimeter's, the IRA's and GNSS's models have (`predict`,
`likelihood` over arrays of hypotheses):

- `predict(h_m, bias_m, geopotential)`: the reading a hypothesis of geometric height h_m (m) gives with a
  barometric bias bias_m (m, on the reading): h + b, or, for a barometer reporting the pressure altitude,
  r0 h / (r0 + h) + b;
- `likelihood(z_m, z_pred_m, sigma_m)`: the Gaussian log-likelihood of the reading z_m given each
  prediction, per-axis sigma_m, without the normalising constant (as gnss.likelihood):
  -(z - z_pred)^2 / (2 sigma^2).

The navigators slave their INS vertical channel to the barometric height (the third-order baro loop of
navigators.inertial.strapdown) rather than weighing hypotheses by it; these are the model for a filter that
does, and the terms a plug-in needs.
"""

from __future__ import annotations

from numba import njit

R0_GEOPOTENTIAL_M = 6356766.0  # US Standard Atmosphere 1976 Earth radius for geopotential height


def geometric_height_m(h_geopotential_m):
    """Geometric height (m) from ISA geopotential (pressure) altitude (m): h = r0 H / (r0 - H)."""
    return R0_GEOPOTENTIAL_M * h_geopotential_m / (R0_GEOPOTENTIAL_M - h_geopotential_m)


def geopotential_height_m(h_geometric_m):
    """ISA geopotential (pressure) altitude (m) of a geometric height (m): H = r0 h / (r0 + h)."""
    return R0_GEOPOTENTIAL_M * h_geometric_m / (R0_GEOPOTENTIAL_M + h_geometric_m)


geometric_height_kernel = njit(cache=True, fastmath=False, error_model="numpy")(geometric_height_m)


def predict(h_m, bias_m=0.0, geopotential: bool = False):
    """The barometer's reading (m) for hypotheses of geometric height h_m (m; float or array) and a
    barometric bias bias_m (m, added to the reading): h + b, or H(h) + b when the barometer reports the
    pressure altitude (geopotential)."""
    return (geopotential_height_m(h_m) if geopotential else h_m) + bias_m


def likelihood(z_m, z_pred_m, sigma_m):
    """log N of the reading z_m (m) given each predicted reading z_pred_m (m), sigma sigma_m (m), without
    the constant: -(z - z_pred)^2 / (2 sigma^2) (float or array)."""
    return -0.5 * (z_m - z_pred_m) ** 2 / sigma_m**2


__all__ = [
    "R0_GEOPOTENTIAL_M",
    "geometric_height_kernel",
    "geometric_height_m",
    "geopotential_height_m",
    "likelihood",
    "predict",
]
