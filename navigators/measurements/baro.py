"""Barometric altimeter: the measured height the navigators use.

The barometer reports the pressure altitude, an ISA geopotential height H (US Standard Atmosphere 1976);
the navigators' INS and maps are in geometric height h = r0 H / (r0 - H), r0 = 6,356,766 m (the standard's
Earth radius for geopotential height). `geometric_height_m` works on floats and numpy arrays;
`geometric_height_kernel` is the same formula compiled for numba kernels (the same bits).
"""

from __future__ import annotations

from numba import njit

R0_GEOPOTENTIAL_M = 6356766.0  # US Standard Atmosphere 1976 Earth radius for geopotential height


def geometric_height_m(h_geopotential_m):
    """Geometric height (m) from ISA geopotential (pressure) altitude (m): h = r0 H / (r0 - H)."""
    return R0_GEOPOTENTIAL_M * h_geopotential_m / (R0_GEOPOTENTIAL_M - h_geopotential_m)


geometric_height_kernel = njit(cache=True, fastmath=False, error_model="numpy")(geometric_height_m)

__all__ = ["R0_GEOPOTENTIAL_M", "geometric_height_kernel", "geometric_height_m"]
