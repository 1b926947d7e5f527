"""Independent geometry for the sim/CLI/env tests: exact NED vectors through ECEF (no small-offset radii)."""

from __future__ import annotations

import numpy as np
from trn_env.terrain.geodesy import C_en, lla_to_ecef


def ned_between(lat0, lon0, h0, lat1, lon1, h1) -> np.ndarray:
    """(n, 3) NED vectors, resolved at point 0, from geodetic points 0 to points 1 (metres)."""
    arrays = (np.atleast_1d(np.asarray(x, float)) for x in (lat0, lon0, h0, lat1, lon1, h1))
    lat0, lon0, h0, lat1, lon1, h1 = arrays
    lat0, lon0, h0, lat1, lon1, h1 = np.broadcast_arrays(lat0, lon0, h0, lat1, lon1, h1)
    out = np.empty(lat0.shape + (3,))
    for k in range(lat0.shape[0]):
        r0 = np.array(lla_to_ecef(lat0[k], lon0[k], h0[k]))
        r1 = np.array(lla_to_ecef(lat1[k], lon1[k], h1[k]))
        out[k] = C_en(lat0[k], lon0[k]).T @ (r1 - r0)
    return out
