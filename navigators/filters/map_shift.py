"""The share of the map's horizontal shift in a terrain filter's published position.

A map shifted by s (a feature at true position p appears at p + s; terrain.map_error) moves every terrain
fix by s: terrain samples pin the position relative to the map, not to the Earth, and no amount of them
shows the filter the shift. The point-mass and particle filters' belief is therefore the position's error
relative to the map; the published position's error, relative to the Earth, is

    e = e_f + A s,   A = diag(a_n, a_e),

e_f the part the belief describes (INS drift, sensor noise) and a_i in [0, 1] the share of the shift the
estimate has taken on along each axis. Per axis, a measurement update with gain k moves the estimate by k
times its residual, so (the fixed-gain error recursion, exact for a scalar Kalman update, where
k = 1 - P_post / P_prior):

- a terrain sample, which sees x + s:  a' = (1 - k) a + k;
- a GNSS fix, which sees x:            a' = (1 - k) a;
- prediction (the INS walk, the grid's convolution, re-spreading the belief around its mean) leaves a:
  the estimate keeps the shift it took while e_f grows.

A GNSS fix is a measurement of the position relative to the Earth, whose error holds a s: fused against the
belief alone (the error relative to the map, a few metres after terrain samples) a fix sigma_h away would
be an outlier to it. So before a fix the filters widen the belief by the share's covariance and set a to 0
(terrain_filter._shift_into_belief: the share becomes the belief's own, which the fix then narrows as a
Bayes update does), so the filters need no GNSS step of the recursion: it runs from 0 again. (`gnss`
states it for a filter that fuses fixes without the widening.)

The grid and particle updates are not linear: k is taken per axis from the belief's variance before and
after the update, clipped to [0, 1] (a multimodal posterior can be wider than its prior). s is independent
of e_f with variance sigma_h^2 per axis (the map's accuracy class: CE90 / 2.146), so the published
horizontal covariance adds diag(a_n^2, a_e^2) sigma_h^2 to the belief's. Navigators hold sigma_h as
`map_horizontal_sigma_m` (navigators.registry's published-integrity setting, which the protection level
already bounds separately: navigators.integrity.protection_level.publish); with it 0 nothing changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


def _gain(var_prior: float, var_post: float) -> float | None:
    """1 - var_post / var_prior clipped to [0, 1]; None when either is not a finite positive variance."""
    if not (math.isfinite(var_prior) and math.isfinite(var_post)) or var_prior <= 0.0 or var_post < 0.0:
        return None
    return min(max(1.0 - var_post / var_prior, 0.0), 1.0)


@dataclass
class MapShiftShare:
    """The shares (a_n, a_e) of the map's horizontal shift in the estimate (see the module)."""

    share: np.ndarray = field(default_factory=lambda: np.zeros(2))

    def terrain(self, cov_prior: np.ndarray, cov_post: np.ndarray) -> None:
        """A terrain update took the belief's horizontal covariance (2 x 2 or larger, m^2, north-east
        first) from cov_prior to cov_post."""
        self._update(cov_prior, cov_post, toward=1.0)

    def gnss(self, cov_prior: np.ndarray, cov_post: np.ndarray) -> None:
        """A GNSS position update took the belief's horizontal covariance from cov_prior to cov_post."""
        self._update(cov_prior, cov_post, toward=0.0)

    def _update(self, cov_prior: np.ndarray, cov_post: np.ndarray, toward: float) -> None:
        for i in range(2):
            k = _gain(float(cov_prior[i, i]), float(cov_post[i, i]))
            if k is not None:
                self.share[i] = (1.0 - k) * self.share[i] + k * toward

    def covariance(self, sigma_h_m: float) -> np.ndarray:
        """The shift's part of the published horizontal covariance (2 x 2, m^2) for a shift of sigma_h_m per
        axis."""
        return np.diag(self.share * self.share) * float(sigma_h_m) ** 2
