"""The aircraft autopilot's modes and targets: `AutopilotTargets` written to the JSBSim autopilot's ap/*
properties (`AP_PROPERTIES`), all SI, angles true."""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

from trn_env.flight.checks import finite


class LateralMode(IntEnum):
    WINGS_LEVEL = 0
    HEADING = 1
    TRACK = 2


class VerticalMode(IntEnum):
    PITCH_HOLD = 0
    ALTITUDE_MSL = 1
    HEIGHT_AGL = 2
    VERTICAL_SPEED = 3


class SpeedMode(IntEnum):
    MANUAL = 0
    TAS = 1


@dataclass
class AutopilotTargets:
    """Targets for the aircraft's JSBSim autopilot (all SI; angles true, radians).

    lateral_mode: 0 wings level, 1 heading hold (heading_cmd_rad), 2 ground-track hold (track_cmd_rad);
    vertical_mode: 0 pitch hold, 1 altitude MSL (altitude_cmd_m), 2 height above ground (agl_cmd_m),
    3 vertical speed (vs_cmd_mps, up positive); speed_mode: 0 manual throttle, 1 TAS hold (tas_cmd_mps).
    """

    lateral_mode: LateralMode = LateralMode.TRACK
    heading_cmd_rad: float = 0.0
    track_cmd_rad: float = 0.0
    bank_limit_rad: float = math.radians(25.0)
    vertical_mode: VerticalMode = VerticalMode.ALTITUDE_MSL
    altitude_cmd_m: float = 1500.0
    agl_cmd_m: float = 300.0
    vs_cmd_mps: float = 0.0
    speed_mode: SpeedMode = SpeedMode.TAS
    tas_cmd_mps: float = 85.0
    engage: bool = True

    def __post_init__(self):
        for name, enum in (("lateral_mode", LateralMode), ("vertical_mode", VerticalMode),
                           ("speed_mode", SpeedMode)):
            v = getattr(self, name)
            try:
                setattr(self, name, enum(v))
            except ValueError:
                raise ValueError(f"AutopilotTargets.{name} must be one of "
                                 f"{[int(m) for m in enum]}, got {v!r}") from None
        for name in ("heading_cmd_rad", "track_cmd_rad", "bank_limit_rad", "altitude_cmd_m", "agl_cmd_m",
                     "vs_cmd_mps", "tas_cmd_mps"):
            finite(f"AutopilotTargets.{name}", getattr(self, name))
        if not 0.0 < self.bank_limit_rad <= math.radians(60.0):
            raise ValueError(f"AutopilotTargets.bank_limit_rad must be within (0, 60 deg], "
                             f"got {self.bank_limit_rad}")
        if self.tas_cmd_mps <= 0.0:
            raise ValueError(f"AutopilotTargets.tas_cmd_mps must be > 0, got {self.tas_cmd_mps}")
        if self.agl_cmd_m <= 0.0:
            raise ValueError(f"AutopilotTargets.agl_cmd_m must be > 0, got {self.agl_cmd_m}")

    @classmethod
    def trusted(cls, lateral_mode: LateralMode, heading_cmd_rad: float, track_cmd_rad: float,
                bank_limit_rad: float, vertical_mode: VerticalMode, altitude_cmd_m: float, agl_cmd_m: float,
                vs_cmd_mps: float, speed_mode: SpeedMode, tas_cmd_mps: float,
                engage: bool = True) -> AutopilotTargets:
        """Targets from values the caller has already checked (enum modes, finite floats within the limits
        of __post_init__), without re-validating them: the guidance loop's per-tick constructor."""
        t = cls.__new__(cls)
        t.__dict__.update(lateral_mode=lateral_mode, heading_cmd_rad=heading_cmd_rad,
                          track_cmd_rad=track_cmd_rad, bank_limit_rad=bank_limit_rad,
                          vertical_mode=vertical_mode, altitude_cmd_m=altitude_cmd_m, agl_cmd_m=agl_cmd_m,
                          vs_cmd_mps=vs_cmd_mps, speed_mode=speed_mode, tas_cmd_mps=tas_cmd_mps,
                          engage=engage)
        return t

    def __reduce__(self):
        # plain numbers, the modes found again by value: the closed loop's second process sends ten targets
        # per update, and an enum's constructor is slow to unpickle
        return (_targets_from_values, (int(self.lateral_mode), self.heading_cmd_rad, self.track_cmd_rad,
                                       self.bank_limit_rad, int(self.vertical_mode), self.altitude_cmd_m,
                                       self.agl_cmd_m, self.vs_cmd_mps, int(self.speed_mode),
                                       self.tas_cmd_mps, self.engage))

    def property_values(self) -> tuple[float, ...]:
        """The ap/* values in AP_PROPERTIES order."""
        return (float(self.lateral_mode), float(self.heading_cmd_rad), float(self.track_cmd_rad),
                float(self.bank_limit_rad), float(self.vertical_mode), float(self.altitude_cmd_m),
                float(self.agl_cmd_m), float(self.vs_cmd_mps), float(self.speed_mode),
                float(self.tas_cmd_mps), 1.0 if self.engage else 0.0)

    def properties(self) -> dict[str, float]:
        """The ap/* property values these targets write."""
        return {
            "ap/lateral-mode": float(self.lateral_mode),
            "ap/heading-cmd-rad": float(self.heading_cmd_rad),
            "ap/track-cmd-rad": float(self.track_cmd_rad),
            "ap/bank-limit-rad": float(self.bank_limit_rad),
            "ap/vertical-mode": float(self.vertical_mode),
            "ap/altitude-cmd-m": float(self.altitude_cmd_m),
            "ap/agl-cmd-m": float(self.agl_cmd_m),
            "ap/vs-cmd-mps": float(self.vs_cmd_mps),
            "ap/speed-mode": float(self.speed_mode),
            "ap/tas-cmd-mps": float(self.tas_cmd_mps),
            "ap/engage": 1.0 if self.engage else 0.0,
        }


AP_PROPERTIES = ("ap/lateral-mode", "ap/heading-cmd-rad", "ap/track-cmd-rad", "ap/bank-limit-rad",
                 "ap/vertical-mode", "ap/altitude-cmd-m", "ap/agl-cmd-m", "ap/vs-cmd-mps", "ap/speed-mode",
                 "ap/tas-cmd-mps", "ap/engage")


_MODES_BY_VALUE = tuple({int(m): m for m in enum} for enum in (LateralMode, VerticalMode, SpeedMode))


def _targets_from_values(lateral, heading, track, bank, vertical, altitude, agl, vs, speed, tas, engage):
    """AutopilotTargets.__reduce__'s inverse."""
    lat_modes, vert_modes, speed_modes = _MODES_BY_VALUE
    return AutopilotTargets.trusted(lat_modes[lateral], heading, track, bank, vert_modes[vertical], altitude,
                                    agl, vs, speed_modes[speed], tas, engage)
