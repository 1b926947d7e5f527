"""Measurement models shared by the navigators, by sensor.

baro               the barometric altimeter: geopotential (pressure) altitude to geometric height
gnss               GNSS position and velocity fix against the INS (z, H, R), loosely coupled
lever_arm          lever arms of the ranging antennas transferred to the IMU point
ira_seed002        seed 002's IRA model: range and look angle over the zero-Doppler line (eqs 23-26) and
                   their linearisation in velocity and attitude (eqs 24-25), map noise
ira_closest_point  seed 000's closest-point formulas: (R, theta) + attitude + velocity -> the IRA return's
                   position relative to the antenna (eqs 3-13)
terrain_models     the same over many hypotheses of one epoch (numba), map heights at hypothesis offsets,
                   the radar altimeter's shortest in-cone return, the heavy-tailed terrain likelihood
"""

from .ira_closest_point import (
    FORMULAS,
    closest_point_ned,
    effective_look_angle,
)
from .terrain_models import (
    IRA_FORMULA_CODES,
    ira_points_batch,
    map_heights_at_offsets,
    ra_cone_ranges,
    radii_m,
    robust_log_likelihood,
)

__all__ = ["FORMULAS", "IRA_FORMULA_CODES", "closest_point_ned", "effective_look_angle", "ira_points_batch",
           "map_heights_at_offsets", "ra_cone_ranges", "radii_m", "robust_log_likelihood"]
