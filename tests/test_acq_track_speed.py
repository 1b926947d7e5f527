"""acq_track's speed work checked against independent computations: the footprint dilation kernel against
scipy.ndimage.grey_dilation and a per-post brute force (voids and map edges included)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage
from trn_env.navigators.acquisition_tracking.footprint import BAND_M, FootprintMaps

from trn_env import terrain


@pytest.fixture(scope="module")
def dem():
    return terrain.load("jacksboro")


def _ndimage_footprint(heights, dn, de, tan_half, a):
    """The grey dilation of the footprint module's docstring by scipy.ndimage (edges: nearest)."""
    r = a * tan_half
    ki, kj = int(r // dn), int(r // de)
    ii, jj = np.mgrid[-ki : ki + 1, -kj : kj + 1]
    rho2 = (ii * dn) ** 2 + (jj * de) ** 2
    inside = rho2 <= r * r
    h = np.where(np.isfinite(heights), heights, -1e9)
    dil = ndimage.grey_dilation(
        h, footprint=inside, structure=np.where(inside, -rho2 / (2.0 * a), 0.0), mode="nearest"
    )
    return np.where(np.isfinite(heights), dil, np.nan)


@pytest.mark.parametrize("band", [11, 13, 20, 40])
def test_footprint_dilation_matches_ndimage(dem, band):
    """Real map with voids punched in (one on the edge): the numba dilation equals ndimage's to the bit."""
    h = np.array(dem.heights_m, float)
    rng = np.random.default_rng(band)
    h[rng.integers(0, h.shape[0], 40), rng.integers(0, h.shape[1], 40)] = np.nan
    h[0, 5] = np.nan
    fm = FootprintMaps(dem.with_heights(h, name="voids"), 17.0)
    a = band * BAND_M
    got = fm.grid(a)[0]
    want = _ndimage_footprint(h, fm.dn_m, fm.de_m, fm.tan_half, a)
    assert np.array_equal(got, want, equal_nan=True)
    assert fm.grid(a + 0.2 * BAND_M)[0] is got  # the same band: the cached map


def test_footprint_dilation_brute_force_at_edges(dem):
    """A few posts (corners, edges, next to a void) by the formula written out: max over the posts q within
    a tan(beam / 2) of h(q) - rho^2 / (2 a), q clamped onto the grid."""
    h = np.array(dem.heights_m, float)
    h[3, 4] = np.nan
    fm = FootprintMaps(dem.with_heights(h, name="void"), 17.0)
    a = 30 * BAND_M
    got = fm.grid(a)[0]
    r = a * math.tan(math.radians(8.5))
    n_i, n_j = h.shape
    for i, j in ((0, 0), (0, n_j - 1), (n_i - 1, 0), (n_i - 1, n_j - 1), (3, 5), (2, 4), (150, 200)):
        best = -math.inf
        for di in range(-5, 6):
            for dj in range(-5, 6):
                rho2 = (di * fm.dn_m) ** 2 + (dj * fm.de_m) ** 2
                if rho2 > r * r:
                    continue
                q = h[min(max(i + di, 0), n_i - 1), min(max(j + dj, 0), n_j - 1)]
                if np.isfinite(q):
                    best = max(best, q - rho2 / (2.0 * a))
        assert got[i, j] == pytest.approx(best, abs=1e-9)
    assert np.isnan(got[3, 4])


def test_footprint_cache_keeps_the_most_recently_used_bands(dem):
    from trn_env.navigators.acquisition_tracking.footprint import MAX_BANDS

    fm = FootprintMaps(dem, 17.0)
    bands = list(range(10, 10 + MAX_BANDS))
    first = {b: fm.grid(b * BAND_M)[0] for b in bands}
    assert fm.grid(bands[0] * BAND_M)[0] is first[bands[0]]  # used again: now the most recent
    fm.grid((bands[-1] + 1) * BAND_M)[0]  # one band more: the least recently used (bands[1]) goes
    assert len(fm._cache) == MAX_BANDS and bands[1] not in fm._cache and bands[0] in fm._cache
    again = fm.grid(bands[1] * BAND_M)[0]
    assert again is not first[bands[1]] and np.array_equal(again, first[bands[1]])
