"""The TRN signal: a sliding transect of N terrain-height samples (seed 001 ch. 3; spec section 1).

Measured terrain height = barometric height (ISA pressure altitude converted to geometric height) - the
radar altimeter's plumb height. Samples are taken on the absolute time grid k * sample_period_s (the radar
sample at or just after each grid instant). A sample whose range is a no-return, NaN, or whose barometric
height is missing keeps its slot (the positions still advance with the aiding) but drops out of the
correlation (valid False); the navigator notes it in Health.

Roll compensation (spec section 8, our formula): a pulse altimeter returns the shortest range in its cone;
over level ground and a body tilt t = acos(cos roll cos pitch) beyond the half beam b, that range lies along
the cone's edge nearest the vertical, so the plumb height is R cos(t - b); inside the half beam it is R.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

R0_GEOPOTENTIAL_M = 6356766.0  # US Standard Atmosphere 1976 Earth radius for geopotential height


def geometric_height_m(h_geopotential_m):
    """Geometric height from ISA geopotential (pressure) altitude, h = r0 H / (r0 - H)."""
    return R0_GEOPOTENTIAL_M * h_geopotential_m / (R0_GEOPOTENTIAL_M - h_geopotential_m)


def plumb_height_m(range_m, roll_rad, pitch_rad, beamwidth_deg: float):
    """Plumb-bob height of a pulse altimeter's shortest range R at the given attitude (level ground)."""
    tilt = np.arccos(np.clip(np.cos(roll_rad) * np.cos(pitch_rad), -1.0, 1.0))
    excess = np.maximum(tilt - 0.5 * math.radians(beamwidth_deg), 0.0)
    return range_m * np.cos(excess)


@dataclass
class Sample:
    """One transect sample: time, measured terrain height (m MSL; NaN when dropped), valid, range (m),
    aiding speed / heading (m/s, rad; 0 unaided), air vector (tas, compass heading; NaN without air data),
    GNSS position at its time (rad; NaN without), roll used in the compensation (rad)."""

    t_s: float
    d_m: float
    valid: bool
    range_m: float
    m_v: float
    m_psi: float
    tas_mps: float
    heading_rad: float
    gnss_lat: float
    gnss_lon: float
    gnss_v_ne: tuple[float, float]
    roll_rad: float


class Transect:
    """The sliding window of the newest N samples (append the newest, drop the oldest)."""

    def __init__(self, n: int):
        self.n = int(n)
        self.samples: deque[Sample] = deque(maxlen=self.n)

    def __len__(self) -> int:
        return len(self.samples)

    @property
    def full(self) -> bool:
        return len(self.samples) == self.n

    def clear(self) -> None:
        self.samples.clear()

    def append(self, s: Sample) -> None:
        self.samples.append(s)

    def arrays(self):
        """(t, d, valid, dt, m_v, m_psi, range) as arrays (dt[0] = 0)."""
        s = self.samples
        t = np.array([x.t_s for x in s])
        d = np.array([x.d_m for x in s])
        valid = np.array([x.valid for x in s], dtype=np.bool_)
        dt = np.zeros(t.size)
        dt[1:] = np.diff(t)
        m_v = np.array([x.m_v for x in s])
        m_psi = np.array([x.m_psi for x in s])
        rng = np.array([x.range_m for x in s])
        return t, d, valid, dt, m_v, m_psi, rng
