"""A first estimate of the navigation error at a route's goal, for explaining a planned route.

A terrain-referenced navigator is held near the terrain's Cramer-Rao bound where the terrain is informative
and dead-reckons on its INS over featureless terrain. Over the final featureless stretch (flown for
t = final_featureless_m / tas_mps seconds, short against the 84.4 min Schuler period) the per-axis
horizontal error of a strapdown INS grows from the last fix as (Titterton & Weston 2004, sec. 12.3.2,
short-term error propagation; seed 000 eq 9's error model without its Schuler terms)

    sigma(t)^2 = sigma_fix^2 + (sigma_v t)^2 + (b_a t^2 / 2)^2 + (g b_g t^3 / 6)^2

with sigma_fix the position error at the last fix, sigma_v the velocity error left by it, b_a the
accelerometer bias and b_g the gyro bias (1 sigma; the tilt it builds up turns gravity into a growing
acceleration error). The horizontal (2-D) RMS error is sqrt(2) sigma(t). This is the planner's explanation,
not a prediction of a particular navigator: the closed loop (`trn-env fly`) measures the real one.
"""

from __future__ import annotations

import math

G_MPS2 = 9.80665


def expected_goal_error_m(final_featureless_m: float, tas_mps: float, accel_bias_mps2: float,
                          gyro_bias_rps: float, sigma_fix_m: float = 5.0, sigma_v_mps: float = 0.1) -> float:
    """Horizontal RMS error (m) at the goal after `final_featureless_m` metres of featureless flight at
    `tas_mps` (see the module docstring for the model and its source)."""
    t = max(0.0, float(final_featureless_m)) / float(tas_mps)
    var = (sigma_fix_m ** 2 + (sigma_v_mps * t) ** 2 + (0.5 * accel_bias_mps2 * t * t) ** 2
           + (G_MPS2 * gyro_bias_rps * t ** 3 / 6.0) ** 2)
    return math.sqrt(2.0 * var)
