"""Footprint replicas: the map as a pulse radar altimeter sees it (seed 001 ch. 4, spec section 5).

A pulse altimeter returns the shortest range in its beam, so over rough terrain the measured height above
ground is shorter than the plumb-bob height (the thesis: radar minus plumb-bob error mean 23 m, std 33 m).
With replica_model = "footprint" the replicas are taken from the map's grey dilation by the beam's footprint
at the transect's height above ground a: h_fp(p) = max over |q - p| <= a tan(beam / 2) of
h(q) - |q - p|^2 / (2 a) (the shortest range to a point q at horizontal distance rho and depth a is about
a + rho^2 / (2 a), so the return comes from the point maximising h - rho^2 / (2 a)). The dilated maps are
made once per 50 m band of height above ground and cached (scipy.ndimage.grey_dilation on the map grid).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

BAND_M = 50.0


class FootprintMaps:
    """Dilated copies of a map's height grid, one per band of height above ground."""

    def __init__(self, dem, beamwidth_deg: float):
        self.dem = dem
        self.tan_half = math.tan(math.radians(0.5 * beamwidth_deg))
        self.dn_m, self.de_m = (float(x) for x in dem.spacing_m)
        self._cache: dict[int, np.ndarray] = {}

    def grid(self, agl_m: float):
        """dem.grid with the heights dilated for a height above ground of agl_m (plain grid if not finite or
        the footprint is under half a post)."""
        heights, lat0, lon0, dlat, dlon = self.dem.grid
        if not (math.isfinite(agl_m) and agl_m > 0):
            return self.dem.grid
        band = int(round(agl_m / BAND_M))
        if band < 1:
            return self.dem.grid
        if band not in self._cache:
            a = band * BAND_M
            r = a * self.tan_half
            ki, kj = int(r // self.dn_m), int(r // self.de_m)
            if ki < 1 and kj < 1:
                self._cache[band] = heights
            else:
                ii, jj = np.mgrid[-ki : ki + 1, -kj : kj + 1]
                rho2 = (ii * self.dn_m) ** 2 + (jj * self.de_m) ** 2
                inside = rho2 <= r * r
                structure = np.where(inside, -rho2 / (2.0 * a), -np.inf)
                h = np.where(np.isfinite(heights), heights, -1e9)
                dil = ndimage.grey_dilation(
                    h, footprint=inside, structure=np.where(inside, structure, 0.0), mode="nearest"
                )
                dil = np.where(np.isfinite(heights), dil, np.nan)
                self._cache[band] = np.ascontiguousarray(dil)
        return self._cache[band], lat0, lon0, dlat, dlon
