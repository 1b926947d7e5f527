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

Turns: waypoints are joined by fillets, the path manager of Beard & McLain (2012) ch. 11. A turn by dchi
starts where the incoming leg touches a circle of radius R tangent to both legs, R tan(|dchi| / 2) before the
waypoint (the turn anticipation); the aircraft then follows that circle with the orbit vector field
(Beard & McLain 2012 sec. 10.3: chi_c = phi + lambda (pi/2 + atan(k_orbit (d - R) / R)), phi the bearing
from the centre, d the distance to it, lambda +1 for a right turn), plus a feed-forward lead for the
autopilot's lag, until it crosses the half-plane where the circle touches the outgoing leg, and then follows
that leg. R = V^2 / (g tan(0.8 bank_limit)) with V the largest ground speed of the turn, TAS + |wind|, so
the ground-track circle is flyable within the bank limit even with a tailwind (0.8:
Guidance.turn_bank_fraction, a margin for roll-in). The wind is estimated from the estimate's ground
velocity and heading (v_ned - TAS along yaw) when the estimate has both, else taken as calm. The active leg
(`leg`) switches to the outgoing leg when the turn starts. The anticipation is capped by the legs (half of
a leg shared by two turns, all of the first and last legs; the circle shrinks to fit, so a near-reversal
turn still overshoots); there is no anticipation for the last waypoint, which is passed when the
along-track distance reaches the leg length.

Geometry is on the WGS84 ellipsoid: the leg's end points (and a turn's centre) are taken to ECEF and
expressed in the local NED tangent frame at the estimated position (terrain.geodesy.lla_to_ecef, C_en), so
the cross-track error and the leg direction are exact at the aircraft however long the leg is.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from trn_env.flight.core import AutopilotTargets, LateralMode, SpeedMode, VerticalMode
from trn_env.flight.truth import TruthChunk
from trn_env.terrain.geodesy import WGS84_A_M, WGS84_E2, C_en, lla_to_ecef, ned_offset_to_latlon

G_MPS2 = 9.80665


def _wrap_pi(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def _local_ne(points_ecef, lat_rad: float, lon_rad: float) -> list[tuple[float, float]]:
    """North/east (m) of ECEF points (sequence of 3-tuples) in the tangent frame at (lat, lon, h = 0):
    C_ne (r - r0), as Route.local_ne_m, in scalar math (this runs every guidance tick)."""
    sl, cl = math.sin(lat_rad), math.cos(lat_rad)
    so, co = math.sin(lon_rad), math.cos(lon_rad)
    r_e = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * sl * sl)
    x0, y0, z0 = r_e * cl * co, r_e * cl * so, r_e * (1.0 - WGS84_E2) * sl
    c00, c10, c01 = -sl * co, -sl * so, -so
    out = []
    for x, y, z in points_ecef:
        dx, dy, dz = x - x0, y - y0, z - z0
        out.append((dx * c00 + dy * c10 + dz * cl, dx * c01 + dy * co))
    return out


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
        self._ecef_t = tuple(tuple(float(x) for x in r) for r in self._ecef)
        self._leg_lengths_m = tuple(float(np.linalg.norm(self._ecef[i + 1] - self._ecef[i]))
                                    for i in range(len(wps) - 1))
        for i, d in enumerate(self._leg_lengths_m):
            if d < 1.0:
                raise ValueError(f"route waypoints {i} and {i + 1} coincide (leg {i} is {d:.2f} m long)")

    def __len__(self) -> int:
        return len(self.waypoints)

    @property
    def n_legs(self) -> int:
        return len(self.waypoints) - 1

    def leg_length_m(self, leg: int) -> float:
        return self._leg_lengths_m[leg]

    def length_m(self) -> float:
        return sum(self.leg_length_m(i) for i in range(self.n_legs))

    def local_ne_m(self, lat_rad: float, lon_rad: float, h_m: float) -> np.ndarray:
        """North/east coordinates (m, (n_waypoints, 2)) of the waypoints in the local tangent frame at the
        given position."""
        r0 = np.array(lla_to_ecef(lat_rad, lon_rad, 0.0))
        d_ned = (self._ecef - r0) @ C_en(lat_rad, lon_rad)   # rows: C_ne (r - r0)
        return d_ned[:, :2]

    def local_ne_m_with(self, extra_ecef: np.ndarray, lat_rad: float, lon_rad: float) -> np.ndarray:
        """As local_ne_m, for the waypoints followed by extra ECEF points (rows of extra_ecef)."""
        r0 = np.array(lla_to_ecef(lat_rad, lon_rad, 0.0))
        pts = np.vstack([self._ecef, extra_ecef])
        return ((pts - r0) @ C_en(lat_rad, lon_rad))[:, :2]


@dataclass
class PositionEstimate:
    """The minimum guidance needs: geodetic position and (optionally) NED velocity and true heading (with
    both, guidance estimates the wind for its turns)."""

    lat_rad: float
    lon_rad: float
    h_m: float
    v_ned_mps: np.ndarray | None = None
    t_s: float = 0.0
    yaw_rad: float | None = None


def position_from_truth(chunk: TruthChunk, i: int = -1) -> PositionEstimate:
    """Row i of a truth chunk as a PositionEstimate (for flying on the truth)."""
    return PositionEstimate(float(chunk.lat_rad[i]), float(chunk.lon_rad[i]), float(chunk.h_msl_m[i]),
                            np.array(chunk.v_ned_mps[i], float), float(chunk.t_s[i]), float(chunk.yaw_rad[i]))


@dataclass
class LegState:
    """Where the estimate is relative to the active leg (metres, rad)."""

    leg: int
    along_m: float
    cross_m: float          # positive: right of the leg
    length_m: float
    track_rad: float        # direction of the leg at the estimate


@dataclass(frozen=True)
class Turn:
    """A fillet in progress onto leg `leg`: circle centre (ECEF, on the ellipsoid), radius, direction
    (+1 right / clockwise seen from above, -1 left), and the along-track distance on the new leg at which
    the circle touches it (the exit half-plane)."""

    leg: int
    centre_ecef_m: np.ndarray
    radius_m: float
    direction: int
    exit_along_m: float

    @property
    def centre_ecef_t(self) -> tuple[float, float, float]:
        c = self.centre_ecef_m
        return float(c[0]), float(c[1]), float(c[2])


class Guidance:
    """Flies a Route leg by leg from supplied estimates, returning AutopilotTargets.

    Parameters
    ----------
    route : Route
        The waypoints to fly.
    tas_mps : float
        Commanded true airspeed, m/s.
    bank_limit_rad : float
        Bank limit passed to the autopilot and used for the turn radius, rad (at most 60 deg).
    k_per_m, chi_inf_rad : float
        The straight-line vector-field gains: slope k at the leg (1/m) and approach angle far from the leg
        (rad, at most pi/2).
    vertical : {"step", "linear"}
        Each leg flies the altitude of its end waypoint ("step"), or one interpolated along the leg when
        both ends use the same reference ("linear").
    k_orbit : float
        The orbit vector-field gain (turns).
    turn_lead_s : float
        Feed-forward of the turns, s in [0, 60): the autopilot's track-error -> turn-rate time constant (5 s
        in the King Air's autopilot), so the orbit command leads the circle's tangent by
        turn_lead_s * V_ground / R and the aircraft turns at the circle's rate without a standing offset
        (0 = no feed-forward).
    wind_tau_s : float
        Time constant of the wind estimate's low-pass filter, s.
    turn_bank_fraction : float
        Turns are planned at this fraction of the bank limit, in [0.3, 1] (margin for roll-in and gusts).

    Raises
    ------
    ValueError
        Naming the argument that is out of range.
    """

    def __init__(self, route: Route, *, tas_mps: float = 85.0, bank_limit_rad: float = math.radians(25.0),
                 k_per_m: float = 1.0 / 400.0, chi_inf_rad: float = math.radians(45.0),
                 vertical: str = "step", k_orbit: float = 4.0, turn_lead_s: float = 5.0,
                 wind_tau_s: float = 5.0, turn_bank_fraction: float = 0.8):
        if not isinstance(route, Route):
            raise ValueError(f"route must be a Route, got {type(route).__name__}")
        for name, v in (("tas_mps", tas_mps), ("bank_limit_rad", bank_limit_rad), ("k_per_m", k_per_m),
                        ("chi_inf_rad", chi_inf_rad), ("k_orbit", k_orbit), ("wind_tau_s", wind_tau_s)):
            if not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v) or v <= 0.0:
                raise ValueError(f"Guidance.{name} must be a positive finite number, got {v!r}")
        if not isinstance(turn_lead_s, (int, float, np.floating, np.integer)) or not 0 <= turn_lead_s < 60:
            raise ValueError(f"Guidance.turn_lead_s must be within [0, 60) s, got {turn_lead_s!r}")
        frac = turn_bank_fraction
        if not isinstance(frac, (int, float, np.floating)) or not 0.3 <= frac <= 1:
            raise ValueError(f"Guidance.turn_bank_fraction must be within [0.3, 1], got {frac!r}")
        if bank_limit_rad > math.radians(60.0):
            raise ValueError(f"Guidance.bank_limit_rad must be <= 60 deg, got {bank_limit_rad}")
        if chi_inf_rad > math.pi / 2:
            raise ValueError(f"Guidance.chi_inf_rad must be <= pi/2, got {chi_inf_rad}")
        if vertical not in ("step", "linear"):
            raise ValueError(f"Guidance.vertical must be 'step' or 'linear', got {vertical!r}")
        self.route = route
        self.tas_mps = float(tas_mps)
        self.bank_limit_rad = float(bank_limit_rad)
        self.k_per_m = float(k_per_m)
        self.chi_inf_rad = float(chi_inf_rad)
        self.k_orbit = float(k_orbit)
        self.turn_lead_s = float(turn_lead_s)
        self.turn_bank_fraction = float(turn_bank_fraction)
        self.wind_tau_s = float(wind_tau_s)
        self.vertical = vertical
        self.leg = 0
        self.done = False
        self.turn: Turn | None = None
        self._wind_n = 0.0                      # low-pass wind estimate (north, east), m/s
        self._wind_e = 0.0
        self._wind_t_s: float | None = None

    @property
    def wind_ne_mps(self) -> np.ndarray:
        """The low-pass wind estimate (north, east), m/s."""
        return np.array([self._wind_n, self._wind_e])

    @wind_ne_mps.setter
    def wind_ne_mps(self, value) -> None:
        self._wind_n, self._wind_e = float(value[0]), float(value[1])

    # ------------------------------------------------------------------------------------------ geometry
    def _leg_state_ne(self, ne, leg: int) -> LegState:
        """ne: the waypoints' local north/east (rows of an array or 2-tuples)."""
        a_n, a_e = float(ne[leg][0]), float(ne[leg][1])
        ab_n, ab_e = float(ne[leg + 1][0]) - a_n, float(ne[leg + 1][1]) - a_e
        length = math.hypot(ab_n, ab_e)
        u_n, u_e = ab_n / length, ab_e / length
        rel_n, rel_e = -a_n, -a_e                   # the estimate is the origin of the local frame
        along = rel_n * u_n + rel_e * u_e
        cross = u_n * rel_e - u_e * rel_n
        return LegState(leg, along, cross, length, math.atan2(u_e, u_n))

    def leg_state(self, estimate) -> LegState:
        """Along/cross-track position of `estimate` on the active leg."""
        ne = self.route.local_ne_m(float(estimate.lat_rad), float(estimate.lon_rad), float(estimate.h_m))
        return self._leg_state_ne(ne, self.leg)

    def turn_radius_m(self) -> float:
        """Radius of the ground-track circle flyable at turn_bank_fraction of the bank limit.

        R = V^2 / (g tan(turn_bank_fraction * bank_limit)) at the turn's largest ground speed
        V = TAS + ``|wind|``.

        Returns
        -------
        float
            The radius, m.
        """
        # the wind estimate is capped at 0.6 TAS (a bad heading estimate must not blow the circle up)
        v = self.tas_mps + min(math.hypot(self._wind_n, self._wind_e), 0.6 * self.tas_mps)
        return v * v / (G_MPS2 * math.tan(self.turn_bank_fraction * self.bank_limit_rad))

    @staticmethod
    def _unit_legs(ne, leg: int):
        """Unit vectors (n, e) of legs `leg` and leg + 1 in the local frame ne, and the waypoint between."""
        a, w, b = ne[leg], ne[leg + 1], ne[leg + 2]
        w_n, w_e = float(w[0]), float(w[1])
        i_n, i_e = w_n - float(a[0]), w_e - float(a[1])
        o_n, o_e = float(b[0]) - w_n, float(b[1]) - w_e
        li, lo = math.hypot(i_n, i_e), math.hypot(o_n, o_e)
        return (i_n / li, i_e / li), (o_n / lo, o_e / lo), (w_n, w_e)

    def _turn_geometry(self, ne, leg: int) -> tuple[float, float, int]:
        """(anticipation distance, radius, direction) of the fillet from leg `leg` onto leg + 1, in the
        local frame ne; (0, 0, 0) for the last waypoint or a turn below 1 deg."""
        if leg + 1 >= self.route.n_legs:
            return 0.0, 0.0, 0
        q_in, q_out, _ = self._unit_legs(ne, leg)
        cross = q_in[0] * q_out[1] - q_in[1] * q_out[0]
        dchi = abs(math.atan2(cross, q_in[0] * q_out[0] + q_in[1] * q_out[1]))
        if dchi < math.radians(1.0):
            return 0.0, 0.0, 0
        radius = self.turn_radius_m()
        half = math.tan(0.5 * dchi)
        # each leg shared by two turns gives each half of its length; the first and last legs all of it
        share_in = 1.0 if leg == 0 else 0.5
        share_out = 1.0 if leg + 2 >= self.route.n_legs else 0.5
        d_max = min(share_in * self.route.leg_length_m(leg), share_out * self.route.leg_length_m(leg + 1))
        if radius * half > d_max:
            radius = d_max / half              # the circle shrinks to fit the legs
        return radius * half, radius, 1 if cross > 0.0 else -1

    def _start_turn(self, ne: np.ndarray, leg: int, estimate) -> Turn | None:
        """The fillet from leg onto leg + 1 (Beard & McLain 2012 ch. 11): centre on the bisector at
        R / cos(dchi / 2) from the waypoint."""
        d_turn, radius, direction = self._turn_geometry(ne, leg)
        if direction == 0:
            return None
        q_in, q_out, w = self._unit_legs(ne, leg)
        bis_n, bis_e = q_out[0] - q_in[0], q_out[1] - q_in[1]
        dchi = math.acos(max(-1.0, min(1.0, q_in[0] * q_out[0] + q_in[1] * q_out[1])))
        k = radius / math.cos(0.5 * dchi) / math.hypot(bis_n, bis_e)
        lat_c, lon_c = ned_offset_to_latlon(float(estimate.lat_rad), float(estimate.lon_rad), 0.0,
                                            w[0] + k * bis_n, w[1] + k * bis_e)
        return Turn(leg + 1, np.array(lla_to_ecef(lat_c, lon_c, 0.0)), radius, direction, d_turn)

    def _update_wind(self, estimate, t_s: float | None) -> None:
        v = getattr(estimate, "v_ned_mps", None)
        yaw = getattr(estimate, "yaw_rad", None)
        if v is None or yaw is None:
            return
        yaw = float(yaw)
        if not math.isfinite(yaw):
            return
        w_n = float(v[0]) - self.tas_mps * math.cos(yaw)
        w_e = float(v[1]) - self.tas_mps * math.sin(yaw)
        if not (math.isfinite(w_n) and math.isfinite(w_e)):
            return
        if self._wind_t_s is None or t_s is None:
            gain = 1.0 if self._wind_t_s is None else 0.1
        else:
            gain = 1.0 - math.exp(-max(t_s - self._wind_t_s, 0.0) / self.wind_tau_s)
        self._wind_n += gain * (w_n - self._wind_n)
        self._wind_e += gain * (w_e - self._wind_e)
        self._wind_t_s = t_s if t_s is not None else (self._wind_t_s or 0.0)

    # ------------------------------------------------------------------------------------------- command
    def command(self, estimate, t_s: float | None = None) -> AutopilotTargets:
        """Autopilot targets for the current estimate (switching legs and flying turns as waypoints come)."""
        lat = getattr(estimate, "lat_rad", None)
        lon = getattr(estimate, "lon_rad", None)
        h = getattr(estimate, "h_m", None)
        for name, v in (("lat_rad", lat), ("lon_rad", lon), ("h_m", h)):
            if v is None or not math.isfinite(float(v)):
                raise ValueError(f"guidance estimate.{name} must be a finite number, got {v!r}")
        self._update_wind(estimate, t_s)
        lat, lon = float(lat), float(lon)
        route = self.route
        n_wp = len(route.waypoints)
        if self.turn is not None:
            ne = _local_ne(route._ecef_t + (self.turn.centre_ecef_t,), lat, lon)
        else:
            ne = _local_ne(route._ecef_t, lat, lon)
        state = self._leg_state_ne(ne, self.leg)
        if self.turn is not None and state.along_m >= self.turn.exit_along_m:
            self.turn = None                          # crossed the exit half-plane: follow the leg
        while self.turn is None and not self.done:
            d_turn = self._turn_geometry(ne, self.leg)[0]
            if state.along_m < state.length_m - d_turn:
                break
            if self.leg + 1 >= route.n_legs:
                self.done = True
                break
            turn = self._start_turn(ne, self.leg, estimate)
            self.leg += 1
            state = self._leg_state_ne(ne, self.leg)
            if turn is not None and state.along_m < turn.exit_along_m:
                self.turn = turn
                ne = ne[:n_wp] + _local_ne((turn.centre_ecef_t,), lat, lon)
        if self.turn is not None:
            # Beard & McLain (2012) sec. 10.3: orbit vector field around the fillet's centre.
            c_n, c_e = ne[-1]
            rel_n, rel_e = -c_n, -c_e                 # estimate relative to the centre
            d = math.hypot(rel_n, rel_e)
            phi = math.atan2(rel_e, rel_n)
            r = self.turn.radius_m
            v = getattr(estimate, "v_ned_mps", None)
            v_g = math.hypot(float(v[0]), float(v[1])) if v is not None else self.tas_mps
            if not math.isfinite(v_g) or v_g <= 0.0:
                v_g = self.tas_mps
            lead = min(self.turn_lead_s * v_g / r, math.radians(60.0))   # feed-forward of the turn rate
            chi_c = phi + self.turn.direction * (0.5 * math.pi + math.atan(self.k_orbit * (d - r) / r) + lead)
        else:
            # Beard & McLain (2012) eq. 10.8: vector field for straight-line following.
            chi_c = state.track_rad - self.chi_inf_rad * (2.0 / math.pi) * math.atan(
                self.k_per_m * state.cross_m)
        chi_c = _wrap_pi(chi_c)
        wp_from, wp_to = self.route.waypoints[self.leg], self.route.waypoints[self.leg + 1]
        alt = wp_to.alt_m
        if self.vertical == "linear" and wp_from.alt_ref == wp_to.alt_ref:
            frac = min(max(state.along_m / state.length_m, 0.0), 1.0)
            alt = wp_from.alt_m + frac * (wp_to.alt_m - wp_from.alt_m)
        agl = wp_to.alt_ref == "agl"
        # every value is checked already (finite estimate, positive TAS and bank limit, waypoint heights)
        return AutopilotTargets.trusted(
            LateralMode.TRACK, chi_c, chi_c, self.bank_limit_rad,
            VerticalMode.HEIGHT_AGL if agl else VerticalMode.ALTITUDE_MSL,
            float(alt) if not agl else float(h), float(alt) if agl else 300.0,
            0.0, SpeedMode.TAS, self.tas_mps)
