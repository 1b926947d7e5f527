"""Inertial navigation: the strapdown mechanisation and its error models.

strapdown  `StrapdownIns` (NED mechanisation, WGS84 + J2 gravity, baro-damped vertical channel)
"""

from .strapdown import (
    GRAVITY_MODELS,
    StrapdownIns,
    gravity_ned,
    quat_from_C_bn,
    quat_to_dcm,
)

__all__ = ["GRAVITY_MODELS", "StrapdownIns", "gravity_ned", "quat_from_C_bn", "quat_to_dcm"]
