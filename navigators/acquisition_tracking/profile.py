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

from ..measurements.baro import geometric_height_m  # noqa: F401 (re-exported)


def plumb_height_m(range_m, roll_rad, pitch_rad, beamwidth_deg: float):
    """Plumb-bob height of a pulse altimeter's shortest range R at the given attitude (level ground)."""
    if isinstance(roll_rad, float) and isinstance(pitch_rad, float):
        # one sample (the navigator's case), tilted well inside the half beam: excess 0, R cos 0 = R exactly
        # (the margin keeps the test off the boundary the numpy expression below decides)
        if math.cos(roll_rad) * math.cos(pitch_rad) > math.cos(math.radians(0.5 * beamwidth_deg)) + 1e-9:
            return range_m
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


class _Samples(deque):
    """A bounded deque that counts its changes (Transect.arrays caches its arrays by the count) and keeps
    the numeric fields of its samples as columns (t, d, m_v, m_psi, range, valid; oldest first)."""

    def __init__(self, maxlen: int):
        super().__init__(maxlen=maxlen)
        self.version = 0
        self.cols = np.zeros((6, maxlen))

    def __reduce__(self):
        return (_restore_samples, (self.maxlen, list(self), self.version))

    def _put(self, k: int, x) -> None:
        c = self.cols
        c[0, k], c[1, k], c[2, k], c[3, k], c[4, k] = x.t_s, x.d_m, x.m_v, x.m_psi, x.range_m
        c[5, k] = 1.0 if x.valid else 0.0

    def append(self, x) -> None:
        if len(self) == self.maxlen:  # the oldest drops out
            self.cols[:, :-1] = self.cols[:, 1:]
        super().append(x)
        self._put(len(self) - 1, x)
        self.version += 1

    def __setitem__(self, i, x) -> None:
        super().__setitem__(i, x)
        self._put(i % len(self), x)
        self.version += 1

    def clear(self) -> None:
        super().clear()
        self.version += 1

    def _changed(self, *_a, **_k):
        raise TypeError("Transect.samples: only append, item assignment and clear are supported")

    appendleft = extend = extendleft = insert = pop = popleft = remove = rotate = __delitem__ = _changed


def _restore_samples(maxlen: int, items: list, version: int) -> _Samples:
    s = _Samples(maxlen)
    for x in items:
        s.append(x)
    s.version = version
    return s


class Transect:
    """The sliding window of the newest N samples (append the newest, drop the oldest)."""

    def __init__(self, n: int):
        self.n = int(n)
        self.samples: deque[Sample] = _Samples(self.n)
        self._cache = (-1, None)

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
        """(t, d, valid, dt, m_v, m_psi, range) as arrays (dt[0] = 0). Cached until the samples change:
        callers must not write into them."""
        s = self.samples
        if self._cache[0] == s.version:
            return self._cache[1]
        cols = s.cols[:, : len(s)].copy()  # the samples' columns (copied: the buffer moves on)
        t = cols[0]
        dt = np.zeros(t.size)
        dt[1:] = t[1:] - t[:-1]
        out = (t, cols[1], cols[5] != 0.0, dt, cols[2], cols[3], cols[4])
        self._cache = (s.version, out)
        return out
