"""The error of a terrain filter's published height when its vertical offset also carries the map's error.

The point-mass and particle filters (terrain_filter) estimate one vertical offset b, the offset a terrain
sample sees: b = b_ins + m_b + m_c, the INS height's error (baro bias and drift) plus the map's vertical
bias m_b and, when the map error model declares a correlation length, its correlated random error m_c.
The published height is h_INS - b_hat, so its error is e = b_ins - b_hat: terrain samples pin b, not b_ins,
and the map's error stays in the height. The filter's variance of b (P_b) is that of b's estimate, which
terrain samples shrink to metres; the height's error keeps the map's.

`HeightError` carries the covariance of e with the map's true errors under the filter's own gains (the
error covariance of a linear estimator with given gains, Joseph form; exact for the linear-Gaussian model).
The map's errors are the true processes, not estimates: m_b constant (variance var_bias), m_c stationary
(variance var_corr, correlation rho(d / L) over the d metres flown between steps, the map error model's
function: exact one-step correlation, an AR(1) chain; for the exponential function the process itself),
so their variances stay fixed while e's covariance with them follows the gains:

- a terrain sample z = b_ins + m + v (noise variance r) moving b_hat by K (z - b_hat):
  e' = (1 - K) e - K m - K v;
- a GNSS height y = b_ins + w (variance r) moving b_hat by K (y - b_hat): e' = (1 - K) e - K w;
- over a step the INS's walk adds to e, and m_c decorrelates: cov(e, m_c) times rho;
- anything else that widens P_b about the INS (the grid's convolution, the vertical specific-force error's
  shift) adds to e as it adds to P_b.

(The filter itself carries m_c as a random walk in b, `map_walk_variance_per_m`: the smallest
walk that covers its increments; the height's error is m_c itself, whose variance a walk would overstate
without bound.) Without a map error (both variances 0) it stays inactive and the filters publish P_b.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

VAR_FLOOR_M2 = 1e-9

# sup over x > 0 of (1 - rho(x)) / x for rho(x) = exp(-x^2 / 2) (terrain.map_error's "gaussian" covariance,
# x = distance / correlation length): attained at x ~ 1.585
_GAUSSIAN_WALK_FACTOR = float(np.max((1.0 - np.exp(-0.5 * np.linspace(1e-3, 6.0, 60001) ** 2))
                                     / np.linspace(1e-3, 6.0, 60001)))
MAP_WALK_FACTORS = {"exponential": 1.0, "gaussian": _GAUSSIAN_WALK_FACTOR}


def map_walk_variance_per_m(sigma_m: float, correlation_length_m: float, function: str = "exponential"
                            ) -> float:
    """Variance rate (m^2 per metre flown) of the random walk that covers a correlated map error's
    structure function at every distance: E[(e(s + d) - e(s))^2] = 2 sigma^2 (1 - rho(d / L)) <= q d for
    all d with q = 2 sigma^2 c / L, c = sup_x (1 - rho(x)) / x (1 for rho = exp(-x), ~0.451 for
    exp(-x^2 / 2)). 0 when sigma or L is 0 (a white map error)."""
    if not (sigma_m > 0.0 and correlation_length_m > 0.0):
        return 0.0
    return 2.0 * sigma_m ** 2 * MAP_WALK_FACTORS[function] / correlation_length_m


@dataclass
class HeightError:
    """Covariances (m^2) of the published height's error e with itself and the map's errors (see the
    module); var_bias, var_corr the map bias's and correlated error's variances, length_m and function
    the latter's correlation."""

    var_e: float
    cov_e_bias: float
    cov_e_corr: float
    var_bias: float
    var_corr: float
    length_m: float
    function: str = "exponential"

    @classmethod
    def start(cls, p_offset: float, var_bias: float, var_corr: float, length_m: float,
              function: str = "exponential") -> HeightError:
        """The prior: b_hat = 0, so e = b_ins (variance p_offset minus the map's) independent of the map."""
        var_bias, var_corr = max(float(var_bias), 0.0), max(float(var_corr), 0.0)
        return cls(max(float(p_offset) - var_bias - var_corr, VAR_FLOOR_M2), 0.0, 0.0, var_bias, var_corr,
                   float(length_m), function)

    @property
    def active(self) -> bool:
        return self.var_bias + self.var_corr > 0.0

    def step(self, q_ins: float, distance_m: float) -> None:
        """One prediction step: the INS height error's walk (q_ins, m^2) over `distance_m` flown."""
        self.var_e += q_ins
        if self.cov_e_corr != 0.0 and self.length_m > 0.0:
            x = distance_m / self.length_m
            self.cov_e_corr *= math.exp(-x) if self.function == "exponential" else math.exp(-0.5 * x * x)

    def widen(self, dvar: float) -> None:
        """P_b changed by dvar about the INS (convolution spread, vertical specific-force shift)."""
        self.var_e = max(self.var_e + dvar, VAR_FLOOR_M2)

    def terrain(self, gain: float, noise_var: float) -> None:
        """b_hat moved by `gain` times a terrain sample's residual (noise variance noise_var, m^2)."""
        a = 1.0 - gain
        var_e = (a * a * self.var_e - 2.0 * a * gain * (self.cov_e_bias + self.cov_e_corr)
                 + gain * gain * (self.var_bias + self.var_corr + noise_var))
        self.cov_e_bias = a * self.cov_e_bias - gain * self.var_bias
        self.cov_e_corr = a * self.cov_e_corr - gain * self.var_corr
        self.var_e = max(var_e, VAR_FLOOR_M2)

    def gnss(self, gain: float, noise_var: float) -> None:
        """b_hat moved by `gain` times a GNSS height's residual (noise variance noise_var, m^2)."""
        a = 1.0 - gain
        self.var_e = max(a * a * self.var_e + gain * gain * noise_var, VAR_FLOOR_M2)
        self.cov_e_bias *= a
        self.cov_e_corr *= a
