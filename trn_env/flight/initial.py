"""Where and how a flight starts: `InitialCondition` (position, airspeed, attitude, fuel, trim), each
field checked finite and in range when built."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from trn_env.flight.checks import finite


@dataclass(frozen=True)
class InitialCondition:
    """Where and how the flight starts.

    Parameters
    ----------
    lat_rad, lon_rad : float
        Start position (WGS84), rad.
    h_msl_m : float
        Start height above MSL, m (above -500 m).
    tas_mps : float
        True airspeed, m/s (> 0; the aircraft must trim there).
    heading_rad : float
        True heading, rad.
    flaps : float
        Flap setting, normalised 0..1.
    fuel_fraction : float, optional
        Every tank at this fraction of its capacity, 0..1.
    gamma_rad : float
        Initial flight-path angle, rad (0 = level).
    fuel_kg : float, optional
        Total fuel on board, kg (> 0, shared between the tanks in proportion to their capacity, at most
        their total capacity); give at most one of fuel_fraction and fuel_kg (neither: the tanks as in the
        aircraft file, full for the King Air).

    Raises
    ------
    ValueError
        Naming the field that is not finite or out of range.
    """

    lat_rad: float
    lon_rad: float
    h_msl_m: float
    tas_mps: float
    heading_rad: float = 0.0
    flaps: float = 0.0
    fuel_fraction: float | None = None
    gamma_rad: float = 0.0
    fuel_kg: float | None = None

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None and f.name in ("fuel_fraction", "fuel_kg"):
                continue
            finite(f"InitialCondition.{f.name}", v)
        if not -math.pi / 2 <= self.lat_rad <= math.pi / 2:
            raise ValueError(f"InitialCondition.lat_rad must be within +-pi/2, got {self.lat_rad}")
        if self.tas_mps <= 0.0:
            raise ValueError(f"InitialCondition.tas_mps must be > 0, got {self.tas_mps}")
        if self.h_msl_m < -500.0:
            raise ValueError(f"InitialCondition.h_msl_m must be above -500 m, got {self.h_msl_m}")
        if not 0.0 <= self.flaps <= 1.0:
            raise ValueError(f"InitialCondition.flaps must be within 0..1, got {self.flaps}")
        if self.fuel_fraction is not None and not 0.0 <= self.fuel_fraction <= 1.0:
            raise ValueError(f"InitialCondition.fuel_fraction must be within 0..1, got {self.fuel_fraction}")
        if self.fuel_kg is not None and not self.fuel_kg > 0.0:
            raise ValueError(f"InitialCondition.fuel_kg must be > 0 (no fuel, no flight), got {self.fuel_kg}")
        if self.fuel_kg is not None and self.fuel_fraction is not None:
            raise ValueError("InitialCondition.fuel_kg: give fuel_kg or fuel_fraction, not both")
        if abs(self.gamma_rad) > math.radians(30.0):
            raise ValueError(f"InitialCondition.gamma_rad must be within +-30 deg, got {self.gamma_rad}")
