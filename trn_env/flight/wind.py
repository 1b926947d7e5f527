"""Wind: steady wind by altitude layers, JSBSim turbulence and discrete (1 - cosine) gusts.

Everything is written to JSBSim's atmosphere properties (FGWinds):
- steady wind: atmosphere/wind-{north,east,down}-fps, recomputed for the current altitude by the flight
  core at every guidance tick (layers are interpolated linearly in altitude, component by component);
- turbulence: atmosphere/turb-type (0 none, 3 Milspec, 4 Tustin; both Dryden spectra after MIL-F-8785C),
  atmosphere/turbulence/milspec/severity (probability-of-exceedance index 1..7 of MIL-F-8785C fig. 7;
  light = 3 (1e-2), moderate = 4 (1e-3), severe = 6 (1e-5)) and
  atmosphere/turbulence/milspec/windspeed_at_20ft_AGL-fps (drives the intensity below 2000 ft AGL);
- gusts: atmosphere/cosine-gust/* (startup, steady and end durations, magnitude, direction, frame), started
  by the flight core at the gust's start time.

Directions are meteorological: the direction the wind blows FROM, clockwise from true north.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from trn_env.flight.checks import finite

FT_PER_M = 1.0 / 0.3048
KT_TO_MPS = 1852.0 / 3600.0

TURBULENCE_MODELS = {"none": 0, "milspec": 3, "tustin": 4}
SEVERITY_INDEX = {"none": 0, "light": 3, "moderate": 4, "severe": 6, "extreme": 7}
# MIL-F-8785C low-altitude model: wind speed at 20 ft for light / moderate / severe turbulence.
DEFAULT_W20_MPS = {0: 0.0, 1: 15 * KT_TO_MPS, 2: 15 * KT_TO_MPS, 3: 15 * KT_TO_MPS, 4: 30 * KT_TO_MPS,
                   5: 45 * KT_TO_MPS, 6: 45 * KT_TO_MPS, 7: 45 * KT_TO_MPS}
GUST_FRAMES = {"body": 1, "wind": 2, "ned": 3}


@dataclass(frozen=True)
class WindLayer:
    """Steady wind at one altitude: blowing FROM direction_from_deg (true, clockwise), speed in m/s."""

    altitude_m: float
    direction_from_deg: float
    speed_mps: float

    def ned_mps(self) -> np.ndarray:
        d = math.radians(self.direction_from_deg)
        return np.array([-self.speed_mps * math.cos(d), -self.speed_mps * math.sin(d), 0.0])


@dataclass(frozen=True)
class Turbulence:
    """JSBSim turbulence: model "none" | "milspec" | "tustin"; severity "light" | "moderate" | "severe" |
    "extreme" or an index 0..7; windspeed_at_20ft_mps None = the MIL-F-8785C value for the severity."""

    model: str = "none"
    severity: str | int = "light"
    windspeed_at_20ft_mps: float | None = None

    @property
    def type_index(self) -> int:
        return TURBULENCE_MODELS[self.model]

    @property
    def severity_index(self) -> int:
        if isinstance(self.severity, str):
            return SEVERITY_INDEX[self.severity]
        return int(self.severity)

    @property
    def w20_mps(self) -> float:
        if self.windspeed_at_20ft_mps is not None:
            return float(self.windspeed_at_20ft_mps)
        return DEFAULT_W20_MPS[self.severity_index]


@dataclass(frozen=True)
class CosineGust:
    """A discrete 1 - cosine gust starting at start_time_s: ramps up over startup_s, holds for steady_s,
    ramps down over end_s. direction is a vector (normalised by JSBSim) in `frame` ("ned", "body", "wind")
    along which the air moves; magnitude_mps its peak speed."""

    start_time_s: float
    magnitude_mps: float
    direction: tuple[float, float, float] = (0.0, 0.0, -1.0)
    startup_s: float = 1.0
    steady_s: float = 2.0
    end_s: float = 1.0
    frame: str = "ned"


@dataclass
class WindConfig:
    """Steady wind layers (list of WindLayer or (altitude_m, direction_from_deg, speed_mps) tuples, altitude
    strictly increasing; constant beyond the first/last layer), turbulence and gusts."""

    layers: Sequence[WindLayer | tuple[float, float, float]] = ()
    turbulence: Turbulence = field(default_factory=Turbulence)
    gusts: Sequence[CosineGust] = ()

    def __post_init__(self):
        layers = []
        for i, lay in enumerate(self.layers):
            if not isinstance(lay, WindLayer):
                try:
                    alt, d, s = lay
                except (TypeError, ValueError):
                    raise ValueError(f"wind.layers[{i}] must be (altitude_m, direction_from_deg, speed_mps), "
                                     f"got {lay!r}") from None
                lay = WindLayer(alt, d, s)
            alt = finite(f"wind.layers[{i}].altitude_m", lay.altitude_m)
            d = finite(f"wind.layers[{i}].direction_from_deg", lay.direction_from_deg)
            s = finite(f"wind.layers[{i}].speed_mps", lay.speed_mps)
            if s < 0.0:
                raise ValueError(f"wind.layers[{i}].speed_mps must be >= 0, got {s}")
            if layers and alt <= layers[-1].altitude_m:
                raise ValueError(f"wind.layers[{i}].altitude_m must increase monotonically: {alt} m follows "
                                 f"{layers[-1].altitude_m} m")
            layers.append(WindLayer(alt, d, s))
        self.layers = tuple(layers)
        t = self.turbulence
        if not isinstance(t, Turbulence):
            raise ValueError(f"wind.turbulence must be a Turbulence, got {t!r}")
        if t.model not in TURBULENCE_MODELS:
            raise ValueError(f"wind.turbulence.model must be one of {sorted(TURBULENCE_MODELS)}, "
                             f"got {t.model!r}")
        if isinstance(t.severity, str):
            if t.severity not in SEVERITY_INDEX:
                raise ValueError(f"wind.turbulence.severity must be one of {list(SEVERITY_INDEX)} or 0..7, "
                                 f"got {t.severity!r}")
        elif isinstance(t.severity, bool) or not isinstance(t.severity, int) or not 0 <= t.severity <= 7:
            raise ValueError(f"wind.turbulence.severity must be one of {list(SEVERITY_INDEX)} or 0..7, "
                             f"got {t.severity!r}")
        if t.windspeed_at_20ft_mps is not None:
            w = finite("wind.turbulence.windspeed_at_20ft_mps", t.windspeed_at_20ft_mps)
            if w < 0.0:
                raise ValueError(f"wind.turbulence.windspeed_at_20ft_mps must be >= 0, got {w}")
        gusts = tuple(self.gusts)
        for i, g in enumerate(gusts):
            if not isinstance(g, CosineGust):
                raise ValueError(f"wind.gusts[{i}] must be a CosineGust, got {g!r}")
            for name in ("start_time_s", "magnitude_mps", "startup_s", "steady_s", "end_s"):
                v = finite(f"wind.gusts[{i}].{name}", getattr(g, name))
                if v < 0.0:
                    raise ValueError(f"wind.gusts[{i}].{name} must be >= 0, got {v}")
            if g.frame not in GUST_FRAMES:
                raise ValueError(f"wind.gusts[{i}].frame must be one of {sorted(GUST_FRAMES)}, "
                                 f"got {g.frame!r}")
            vec = np.asarray(g.direction, float)
            if vec.shape != (3,) or not np.all(np.isfinite(vec)) or not np.any(vec):
                raise ValueError(f"wind.gusts[{i}].direction must be a non-zero 3-vector, "
                                 f"got {g.direction!r}")
        self.gusts = tuple(sorted(gusts, key=lambda g: g.start_time_s))
        alts = np.array([lay.altitude_m for lay in self.layers])
        vecs = np.array([lay.ned_mps() for lay in self.layers]).reshape(-1, 3)
        self._alts_m = alts
        self._vecs_ned_mps = vecs
        self._alts_t = tuple(float(a) for a in alts)
        self._vecs_t = tuple((float(w[0]), float(w[1])) for w in vecs)

    @classmethod
    def calm(cls) -> WindConfig:
        return cls()

    @classmethod
    def constant(cls, direction_from_deg: float, speed_mps: float, turbulence: Turbulence | None = None
                 ) -> WindConfig:
        """The same steady wind at every altitude."""
        return cls(layers=[(0.0, direction_from_deg, speed_mps)], turbulence=turbulence or Turbulence())

    def steady_wind_ned_mps(self, h_msl_m: float) -> np.ndarray:
        """Steady wind vector (NED, m/s: the velocity of the air) at height h_msl_m."""
        if len(self._alts_m) == 0:
            return np.zeros(3)
        out = np.empty(3)
        for k in range(2):
            out[k] = np.interp(h_msl_m, self._alts_m, self._vecs_ned_mps[:, k])
        out[2] = 0.0
        return out

    def steady_wind_ned_tuple(self, h_msl_m: float) -> tuple[float, float, float]:
        """steady_wind_ned_mps as a tuple, in plain Python (cheap enough for every guidance tick)."""
        alts, vecs = self._alts_t, self._vecs_t
        if not alts:
            return (0.0, 0.0, 0.0)
        if h_msl_m <= alts[0]:
            return (vecs[0][0], vecs[0][1], 0.0)
        if h_msl_m >= alts[-1]:
            return (vecs[-1][0], vecs[-1][1], 0.0)
        k = bisect.bisect_right(alts, h_msl_m)
        a = (h_msl_m - alts[k - 1]) / (alts[k] - alts[k - 1])
        return (vecs[k - 1][0] + a * (vecs[k][0] - vecs[k - 1][0]),
                vecs[k - 1][1] + a * (vecs[k][1] - vecs[k - 1][1]), 0.0)

    def apply_turbulence(self, fdm) -> None:
        """Write the turbulence settings to JSBSim (once, before the flight starts)."""
        t = self.turbulence
        sev = t.severity_index if t.model != "none" else 0
        fdm["atmosphere/turb-type"] = float(t.type_index)
        fdm["atmosphere/turbulence/milspec/severity"] = float(sev)
        fdm["atmosphere/turbulence/milspec/windspeed_at_20ft_AGL-fps"] = t.w20_mps * FT_PER_M

    @staticmethod
    def start_gust(fdm, gust: CosineGust) -> None:
        """Configure and start one 1 - cosine gust now."""
        fdm["atmosphere/cosine-gust/startup-duration-sec"] = float(gust.startup_s)
        fdm["atmosphere/cosine-gust/steady-duration-sec"] = float(gust.steady_s)
        fdm["atmosphere/cosine-gust/end-duration-sec"] = float(gust.end_s)
        fdm["atmosphere/cosine-gust/magnitude-ft_sec"] = float(gust.magnitude_mps) * FT_PER_M
        fdm["atmosphere/cosine-gust/frame"] = float(GUST_FRAMES[gust.frame])
        fdm["atmosphere/cosine-gust/X-velocity-ft_sec"] = float(gust.direction[0])
        fdm["atmosphere/cosine-gust/Y-velocity-ft_sec"] = float(gust.direction[1])
        fdm["atmosphere/cosine-gust/Z-velocity-ft_sec"] = float(gust.direction[2])
        fdm["atmosphere/cosine-gust/start"] = 1.0
