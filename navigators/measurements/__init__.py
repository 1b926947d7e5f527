"""Terrain measurement models shared by the navigators.

ira_closest_point  seed 000's closest-point formulas: (R, theta) + attitude + velocity -> the IRA return's
                   position relative to the antenna (eqs 3-13)
"""

from navigators.measurements.ira_closest_point import FORMULAS, closest_point_ned, effective_look_angle

__all__ = ["FORMULAS", "closest_point_ned", "effective_look_angle"]
