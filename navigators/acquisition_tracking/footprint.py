"""Footprint replicas: the map as a pulse radar altimeter sees it (seed 001 ch. 4, spec section 5).

A pulse altimeter returns the shortest range in its beam, so over rough terrain the measured height above
ground is shorter than the plumb-bob height (the thesis: radar minus plumb-bob error mean 23 m, std 33 m).
With replica_model = "footprint" the replicas are taken from the map's grey dilation by the beam's footprint
at the transect's height above ground a: h_fp(p) = max over |q - p| <= a tan(beam / 2) of
h(q) - |q - p|^2 / (2 a) (the shortest range to a point q at horizontal distance rho and depth a is about
a + rho^2 / (2 a), so the return comes from the point maximising h - rho^2 / (2 a)). The dilated maps are
made once per 50 m band of height above ground and cached, the MAX_BANDS most recently used (`dilate`, a
numba kernel over the grid: edge posts repeat outward, a void post neither contributes nor is filled).
"""

from __future__ import annotations

import math
from collections import OrderedDict

import numpy as np
from numba import njit

BAND_M = 50.0
MAX_BANDS = 16  # maps kept (least recently used dropped): a map's size each, 1.1 MB for the bundled DEM
_VOID_M = -1e9  # a void post's height inside the dilation: never the maximum next to a valid post


@njit(cache=True)
def dilate(heights, di, dj, s, out):
    """out[i, j] = max over k of h[i + di[k], j + dj[k]] + s[k] (indices clamped to the grid: edge posts
    repeat outward; a void (NaN) post counts as _VOID_M), NaN where heights[i, j] is void. Heights in m;
    di, dj: post offsets of the footprint; s: its structure (m, <= 0)."""
    n_i, n_j = heights.shape
    voids = False
    for i in range(n_i):
        for j in range(n_j):
            if not np.isfinite(heights[i, j]):
                voids = True
    h = heights
    if voids:
        h = np.empty((n_i, n_j))
        for i in range(n_i):
            for j in range(n_j):
                x = heights[i, j]
                h[i, j] = x if np.isfinite(x) else _VOID_M
    out[:, :] = -np.inf
    for k in range(di.shape[0]):  # one footprint post at a time over whole rows (vectorises)
        sk = s[k]
        dk = dj[k]
        j_lo = min(max(-dk, 0), n_j)  # the columns whose neighbour j + dk needs no clamping
        j_hi = max(min(n_j - dk, n_j), j_lo)
        for i in range(n_i):
            src = h[min(max(i + di[k], 0), n_i - 1)]
            row = out[i]
            for j in range(j_lo):
                v = src[min(max(j + dk, 0), n_j - 1)] + sk
                if v > row[j]:
                    row[j] = v
            for j in range(j_lo, j_hi):
                v = src[j + dk] + sk
                row[j] = max(row[j], v)
            for j in range(j_hi, n_j):
                v = src[min(max(j + dk, 0), n_j - 1)] + sk
                if v > row[j]:
                    row[j] = v
    if voids:
        for i in range(n_i):
            for j in range(n_j):
                if not np.isfinite(heights[i, j]):
                    out[i, j] = np.nan


class FootprintMaps:
    """Dilated copies of a map's height grid, one per band of height above ground."""

    def __init__(self, dem, beamwidth_deg: float):
        self.dem = dem
        self.tan_half = math.tan(math.radians(0.5 * beamwidth_deg))
        self.dn_m, self.de_m = (float(x) for x in dem.spacing_m)
        self._cache: OrderedDict[int, np.ndarray] = OrderedDict()

    def footprint(self, a_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(di, dj, structure m) of the posts within the beam's footprint at a height above ground a_m."""
        r = a_m * self.tan_half
        ki, kj = int(r // self.dn_m), int(r // self.de_m)
        ii, jj = np.mgrid[-ki : ki + 1, -kj : kj + 1]
        rho2 = (ii * self.dn_m) ** 2 + (jj * self.de_m) ** 2
        inside = rho2 <= r * r
        return (
            np.ascontiguousarray(ii[inside], np.int64),
            np.ascontiguousarray(jj[inside], np.int64),
            np.ascontiguousarray(-rho2[inside] / (2.0 * a_m)),
        )

    def grid(self, agl_m: float):
        """dem.grid with the heights dilated for a height above ground of agl_m (plain grid if not finite or
        the footprint is under half a post)."""
        heights, lat0, lon0, dlat, dlon = self.dem.grid
        if not (math.isfinite(agl_m) and agl_m > 0):
            return self.dem.grid
        band = int(round(agl_m / BAND_M))
        if band < 1:
            return self.dem.grid
        if band in self._cache:
            self._cache.move_to_end(band)
        else:
            if len(self._cache) >= MAX_BANDS:
                self._cache.popitem(last=False)
            a = band * BAND_M
            r = a * self.tan_half
            if int(r // self.dn_m) < 1 and int(r // self.de_m) < 1:
                self._cache[band] = heights
            else:
                di, dj, s = self.footprint(a)
                dil = np.empty(heights.shape)
                dilate(np.ascontiguousarray(heights, float), di, dj, s, dil)
                self._cache[band] = dil
        return self._cache[band], lat0, lon0, dlat, dlon
