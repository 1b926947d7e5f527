"""Route guidance: waypoints, leg following and the vertical profile, from a SUPPLIED position estimate.

    route = Route([Waypoint(lat0, lon0, 1500.0), Waypoint(lat1, lon1, 300.0, alt_ref="agl"), ...])
    guide = Guidance(route, tas_mps=85.0)
    targets = guide.command(estimate, t_s)     # AutopilotTargets for Flight.set_targets
    guide.done                                 # True once the last waypoint is reached

`estimate` is anything with lat_rad, lon_rad, h_m (and optionally v_ned_mps): a navigator's Estimate, or
`position_from_truth(chunk)`. Guidance never sees the truth unless it is handed the truth.

Lateral law: the straight-line vector field of Nelson et al. (2007) / Beard & McLain, "Small Unmanned
Aircraft" (2012) eq. 10.8: commanded ground track chi_c = chi_leg - chi_inf * (2/pi) * atan(k * e_y), with
e_y the signed cross-track error (positive right of the leg). The aircraft's autopilot holds chi_c in its
ground-track mode, so crosswind is handled by the autopilot's crab, and e_y -> 0 along the leg.

Geometry is on the WGS84 ellipsoid: the leg's end points are taken to ECEF and expressed in the local NED
tangent frame at the estimated position (terrain.geodesy.lla_to_ecef, C_en), so the cross-track error and
the leg direction are exact at the aircraft however long the leg is. A waypoint is passed when the
along-track distance reaches the leg length less the turn anticipation R tan(dchi / 2), R = V^2 / (g tan
bank_limit) (no anticipation for the last waypoint).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from terrain.geodesy import C_en, lla_to_ecef
from trn_env.flight import AutopilotTargets, LateralMode, SpeedMode, VerticalMode
from trn_env.truth import TruthChunk

G_MPS2 = 9.80665


def _wrap_pi(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


@dataclass(frozen=True)
class Waypoint:
    """A route point: geodetic latitude/longitude (rad) and altitude alt_m above MSL (alt_ref "msl") or
    above the ground (alt_ref "agl"), flown on the leg that ends at this waypoint."""

    lat_rad: float
    lon_rad: float
    alt_m: float
    alt_ref: str = "msl"

    def __post_init__(self):
        for name in ("lat_rad", "lon_rad", "alt_m"):
            v = getattr(self, name)
            if not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v):
                raise ValueError(f"Waypoint.{name} must be a finite number, got {v!r}")
        if abs(self.lat_rad) > math.pi / 2:
            raise ValueError(f"Waypoint.lat_rad must be within +-pi/2, got {self.lat_rad}")
        if self.alt_ref not in ("msl", "agl"):
            raise ValueError(f"Waypoint.alt_ref must be 'msl' or 'agl', got {self.alt_ref!r}")
        if self.alt_ref == "agl" and self.alt_m <= 0.0:
            raise ValueError(f"Waypoint.alt_m above ground must be > 0, got {self.alt_m}")

    @classmethod
    def from_deg(cls, lat_deg: float, lon_deg: float, alt_m: float, alt_ref: str = "msl") -> Waypoint:
        return cls(math.radians(lat_deg), math.radians(lon_deg), alt_m, alt_ref)


class Route:
    """An ordered list of at least two waypoints; legs join consecutive waypoints."""

    def __init__(self, waypoints: Sequence[Waypoint]):
        wps = list(waypoints)
        if len(wps) < 2:
            raise ValueError(f"a route needs at least 2 waypoints, got {len(wps)}")
        for i, w in enumerate(wps):
            if not isinstance(w, Waypoint):
                raise ValueError(f"route waypoint {i} must be a Waypoint, got {w!r}")
        self.waypoints: tuple[Waypoint, ...] = tuple(wps)
        self._ecef = np.array([lla_to_ecef(w.lat_rad, w.lon_rad, 0.0) for w in wps])
        for i in range(len(wps) - 1):
            d = float(np.linalg.norm(self._ecef[i + 1] - self._ecef[i]))
            if d < 1.0:
                raise ValueError(f"route waypoints {i} and {i + 1} coincide (leg {i} is {d:.2f} m long)")

    def __len__(self) -> int:
        return len(self.waypoints)

    @property
    def n_legs(self) -> int:
        return len(self.waypoints) - 1

    def leg_length_m(self, leg: int) -> float:
        return float(np.linalg.norm(self._ecef[leg + 1] - self._ecef[leg]))

    def length_m(self) -> float:
        return sum(self.leg_length_m(i) for i in range(self.n_legs))

    def local_ne_m(self, lat_rad: float, lon_rad: float, h_m: float) -> np.ndarray:
        """North/east coordinates (m, (n_waypoints, 2)) of the waypoints in the local tangent frame at the
        given position."""
        r0 = np.array(lla_to_ecef(lat_rad, lon_rad, 0.0))
        d_ned = (self._ecef - r0) @ C_en(lat_rad, lon_rad)   # rows: C_ne (r - r0)
        return d_ned[:, :2]


@dataclass
class PositionEstimate:
    """The minimum guidance needs: geodetic position and (optionally) NED velocity."""

    lat_rad: float
    lon_rad: float
    h_m: float
    v_ned_mps: np.ndarray | None = None
    t_s: float = 0.0


def position_from_truth(chunk: TruthChunk, i: int = -1) -> PositionEstimate:
    """Row i of a truth chunk as a PositionEstimate (for flying on the truth)."""
    return PositionEstimate(float(chunk.lat_rad[i]), float(chunk.lon_rad[i]), float(chunk.h_msl_m[i]),
                            np.array(chunk.v_ned_mps[i], float), float(chunk.t_s[i]))


@dataclass
class LegState:
    """Where the estimate is relative to the active leg (metres, rad)."""

    leg: int
    along_m: float
    cross_m: float          # positive: right of the leg
    length_m: float
    track_rad: float        # direction of the leg at the estimate


class Guidance:
    """Flies a Route leg by leg from supplied estimates, returning AutopilotTargets.

    tas_mps: commanded true airspeed; bank_limit_rad: passed to the autopilot and used for turn
    anticipation; k_per_m and chi_inf_rad: the vector-field gains (approach angle far from the leg
    chi_inf, slope k at the leg); vertical: "step" (each leg flies the altitude of its end waypoint) or
    "linear" (interpolated along the leg when both ends use the same reference).
    """

    def __init__(self, route: Route, *, tas_mps: float = 85.0, bank_limit_rad: float = math.radians(25.0),
                 k_per_m: float = 1.0 / 400.0, chi_inf_rad: float = math.radians(45.0),
                 vertical: str = "step"):
        if not isinstance(route, Route):
            raise ValueError(f"route must be a Route, got {type(route).__name__}")
        for name, v in (("tas_mps", tas_mps), ("bank_limit_rad", bank_limit_rad), ("k_per_m", k_per_m),
                        ("chi_inf_rad", chi_inf_rad)):
            if not math.isfinite(v) or v <= 0.0:
                raise ValueError(f"Guidance.{name} must be a positive finite number, got {v!r}")
        if chi_inf_rad > math.pi / 2:
            raise ValueError(f"Guidance.chi_inf_rad must be <= pi/2, got {chi_inf_rad}")
        if vertical not in ("step", "linear"):
            raise ValueError(f"Guidance.vertical must be 'step' or 'linear', got {vertical!r}")
        self.route = route
        self.tas_mps = float(tas_mps)
        self.bank_limit_rad = float(bank_limit_rad)
        self.k_per_m = float(k_per_m)
        self.chi_inf_rad = float(chi_inf_rad)
        self.vertical = vertical
        self.leg = 0
        self.done = False

    def leg_state(self, estimate) -> LegState:
        """Along/cross-track position of `estimate` on the active leg."""
        ne = self.route.local_ne_m(float(estimate.lat_rad), float(estimate.lon_rad), float(estimate.h_m))
        a, b = ne[self.leg], ne[self.leg + 1]
        ab = b - a
        length = float(math.hypot(ab[0], ab[1]))
        u = ab / length
        rel = -a                                    # the estimate is the origin of the local frame
        along = float(rel @ u)
        cross = float(u[0] * rel[1] - u[1] * rel[0])
        return LegState(self.leg, along, cross, length, math.atan2(u[1], u[0]))

    def _anticipation_m(self, state: LegState, estimate) -> float:
        if self.leg + 1 >= self.route.n_legs:
            return 0.0
        ne = self.route.local_ne_m(float(estimate.lat_rad), float(estimate.lon_rad), float(estimate.h_m))
        nxt = ne[self.leg + 2] - ne[self.leg + 1]
        dchi = abs(_wrap_pi(math.atan2(nxt[1], nxt[0]) - state.track_rad))
        radius = self.tas_mps ** 2 / (G_MPS2 * math.tan(self.bank_limit_rad))
        return min(radius * math.tan(0.5 * min(dchi, math.radians(150.0))), 0.5 * state.length_m)

    def command(self, estimate, t_s: float | None = None) -> AutopilotTargets:
        """Autopilot targets for the current estimate (switching legs as waypoints are passed)."""
        for name in ("lat_rad", "lon_rad", "h_m"):
            v = getattr(estimate, name, None)
            if v is None or not math.isfinite(float(v)):
                raise ValueError(f"guidance estimate.{name} must be a finite number, got {v!r}")
        state = self.leg_state(estimate)
        while not self.done and state.along_m >= state.length_m - self._anticipation_m(state, estimate):
            if self.leg + 1 >= self.route.n_legs:
                self.done = True
                break
            self.leg += 1
            state = self.leg_state(estimate)
        # Beard & McLain (2012) eq. 10.8: vector field for straight-line following.
        chi_c = state.track_rad - self.chi_inf_rad * (2.0 / math.pi) * math.atan(self.k_per_m * state.cross_m)
        chi_c = _wrap_pi(chi_c)
        wp_from, wp_to = self.route.waypoints[self.leg], self.route.waypoints[self.leg + 1]
        alt = wp_to.alt_m
        if self.vertical == "linear" and wp_from.alt_ref == wp_to.alt_ref:
            frac = min(max(state.along_m / state.length_m, 0.0), 1.0)
            alt = wp_from.alt_m + frac * (wp_to.alt_m - wp_from.alt_m)
        agl = wp_to.alt_ref == "agl"
        return AutopilotTargets(
            lateral_mode=LateralMode.TRACK, heading_cmd_rad=chi_c, track_cmd_rad=chi_c,
            bank_limit_rad=self.bank_limit_rad,
            vertical_mode=VerticalMode.HEIGHT_AGL if agl else VerticalMode.ALTITUDE_MSL,
            altitude_cmd_m=alt if not agl else float(estimate.h_m), agl_cmd_m=alt if agl else 300.0,
            vs_cmd_mps=0.0, speed_mode=SpeedMode.TAS, tas_cmd_mps=self.tas_mps)
