"""Guidance stage: route following on a supplied estimate (never on truth).

route_following  `Route` of `Waypoint`s, `Guidance` (vector field with fillet turns, vertical profile)
"""

from trn_env.guidance.route_following import Guidance, PositionEstimate, Route, Waypoint, position_from_truth

__all__ = ["Guidance", "PositionEstimate", "Route", "Waypoint", "position_from_truth"]
