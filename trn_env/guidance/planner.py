"""Terrain-information route planner: from the navigator's MAP only, trade flight distance against the
expected navigation error at the goal.

    planner = TerrainInformationPlanner(map_dem, PlannerConfig(weight=3.0, max_featureless_m=6000.0))
    route = planner.plan(start_lat_rad, start_lon_rad, goal_lat_rad, goal_lon_rad)
    route.waypoints_deg          [(lat_deg, lon_deg, h_agl_m), ...] from the start to the goal
    route.as_route()             a trn_env.guidance.Route (AGL waypoints) for Guidance
    route.toml()                 a [route] table that scenario files accept

Why: a terrain-referenced navigator fixes over rough, distinctive terrain and drifts (INS error growth) over
featureless terrain, so the expected error at the goal grows with the featureless distance flown, most of
all the featureless stretch just before the goal (seed 001's remark on terrain SNR and re-routing). The
planner minimises, over 16-connected paths on the cost map of `trn_env.guidance.cost_map` (cells of
`cell_m`, CRLB of the map's terrain information),

    J = sum over edges of length_m * (1 + weight * u_edge)

with u_edge the mean featureless factor (0 informative .. 1 featureless) of the cells the edge touches:
`weight` is the one knob (0: the shortest path; W: a featureless metre costs 1 + W metres). Optionally no
featureless stretch (consecutive edges with u_edge > 0.5) may exceed `max_featureless_m`: the search then
runs on states (cell, featureless distance so far in half-cell bins), so the constraint is exact on the grid.
The search is A* (straight-line heuristic, admissible since every edge costs at least its length) in a numba
kernel (trn_env.guidance.astar). The grid path is then string-pulled (a shortcut is taken when its J along
the straight line is no larger and it keeps the featureless bound) and thinned for the turn radius: a
waypoint whose fillet (Beard & McLain 2012 ch. 11: turn anticipation R tan(|dchi| / 2), R = V^2 / (g tan(0.8
bank_limit))) needs more than half of an adjacent leg is removed when that keeps the bound and costs at most
`turn_cost_tolerance` more J. The route keeps `edge_margin_cells` away from the map's edge. Heights: every
waypoint is `agl_m` above the ground (guidance's height-above-ground hold, flown on the estimate and the map).
Climb: an edge is excluded when the map (cell mean heights) rises faster along it than the aircraft's climb
gradient (the hold could not follow it), and a string-pulled shortcut when the map sampled along it does;
the gradient is `climb_gradient_max` if given, else `climb_rate_mps / tas_mps` (on by default: 5 m/s, a
margin under the King Air's 9.9 m/s sea-level best rate of climb at MTOW - C90 POH, checked in
tests/test_aircraft_performance.py - and its autopilot's 7.5 m/s climb limit; at 85 m/s a gradient of
0.059). `climb_rate_mps=None` (and no `climb_gradient_max`) plans without a climb limit.

`RouteNotFoundError` (a ValueError) when no path meets the constraints; bad settings raise ValueError
naming the setting.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from trn_env.guidance.astar import (
    FEATURELESS_EDGE,
    MOVES,
    _featureless_runs,
    astar_kernel,
    edge_featureless,
    path_stretch_bins,
)
from trn_env.guidance.cost_map import InformationGrid, information_grid
from trn_env.guidance.route_following import Route, Waypoint
from trn_env.terrain.dem import Dem
from trn_env.terrain.geodesy import radii_m

# the search kernels (trn_env.guidance.astar) are re-exported: their names stay importable from here
__all__ = ["FEATURELESS_EDGE", "MOVES", "PlannedRoute", "PlannerConfig", "RouteNotFoundError",
           "TerrainInformationPlanner", "astar_kernel", "edge_featureless", "plot_route"]

G_MPS2 = 9.80665


def _leg_ne_m(lat0_rad: float, lon0_rad: float, lat1_rad: float, lon1_rad: float) -> tuple[float, float]:
    """North/east extent (m) of the leg from (lat0, lon0) to (lat1, lon1) (rad): seed 000 eq 2's small-offset
    form with the radii and the cosine taken at the leg's mid-latitude, so a leg is as long in either
    direction and collinear legs (the grid path's steps) add up to the leg they make to second order (within
    dlat^2 / 24 of it, relative; dlat the leg's latitude span in rad) instead of first (the form taken at the
    leg's start made a 1 km leg north 1.5e-5 longer than its two halves, so string pulling kept every grid
    step of a straight line)."""
    lat_mid = 0.5 * (lat0_rad + lat1_rad)
    r_n, r_e = radii_m(lat_mid)
    return (lat1_rad - lat0_rad) * r_n, (lon1_rad - lon0_rad) * r_e * math.cos(lat_mid)


def _check_finite_point(name: str, lat_rad, lon_rad) -> None:
    """ValueError naming the point unless both coordinates are finite numbers (rad)."""
    for v in (lat_rad, lon_rad):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating)) or not math.isfinite(v):
            raise ValueError(f"{name} must be finite latitude/longitude, got {lat_rad!r}, {lon_rad!r}")


class RouteNotFoundError(ValueError):
    """No route meets the planner's constraints (featureless bound, climb limit, map edge margin)."""


@dataclass(frozen=True)
class PlannerConfig:
    """Planner settings (units in the names). See the module docstring for what each does."""

    weight: float = 3.0
    cell_m: float = 500.0
    agl_m: float = 600.0
    max_featureless_m: float | None = None
    tas_mps: float = 85.0
    bank_limit_deg: float = 25.0
    climb_gradient_max: float | None = None
    climb_rate_mps: float | None = 5.0
    edge_margin_cells: int = 2
    turn_cost_tolerance: float = 0.02
    sigma_m: float = 5.0
    window_m: float = 2000.0
    informative_crlb_m: float = 5.0
    featureless_crlb_m: float = 50.0

    def __post_init__(self):
        def num(name, v, lo, lo_ok=True, none_ok=False):
            if v is None and none_ok:
                return
            if (
                isinstance(v, bool)
                or not isinstance(v, (int, float, np.floating, np.integer))
                or not math.isfinite(v)
                or (v < lo if lo_ok else v <= lo)
            ):
                rel = ">=" if lo_ok else ">"
                raise ValueError(f"PlannerConfig.{name} must be a finite number {rel} {lo:g}, got {v!r}")

        num("weight", self.weight, 0.0)
        num("cell_m", self.cell_m, 0.0, lo_ok=False)
        num("agl_m", self.agl_m, 0.0, lo_ok=False)
        num("max_featureless_m", self.max_featureless_m, 0.0, lo_ok=False, none_ok=True)
        num("tas_mps", self.tas_mps, 0.0, lo_ok=False)
        num("bank_limit_deg", self.bank_limit_deg, 0.0, lo_ok=False)
        if self.bank_limit_deg > 60.0:
            raise ValueError(f"PlannerConfig.bank_limit_deg must be <= 60, got {self.bank_limit_deg}")
        num("climb_gradient_max", self.climb_gradient_max, 0.0, lo_ok=False, none_ok=True)
        num("climb_rate_mps", self.climb_rate_mps, 0.0, lo_ok=False, none_ok=True)
        if (
            isinstance(self.edge_margin_cells, bool)
            or not isinstance(self.edge_margin_cells, (int, np.integer))
            or self.edge_margin_cells < 0
        ):
            raise ValueError(
                f"PlannerConfig.edge_margin_cells must be an integer >= 0, got {self.edge_margin_cells!r}"
            )
        num("turn_cost_tolerance", self.turn_cost_tolerance, 0.0)
        num("sigma_m", self.sigma_m, 0.0, lo_ok=False)
        num("window_m", self.window_m, 0.0, lo_ok=False)
        num("informative_crlb_m", self.informative_crlb_m, 0.0, lo_ok=False)
        num("featureless_crlb_m", self.featureless_crlb_m, 0.0, lo_ok=False)

    @property
    def climb_gradient(self) -> float | None:
        """The climb gradient (rise / ground distance) routes must keep to; None: no climb limit."""
        if self.climb_gradient_max is not None:
            return float(self.climb_gradient_max)
        if self.climb_rate_mps is not None:
            return float(self.climb_rate_mps) / float(self.tas_mps)
        return None

    @property
    def turn_radius_m(self) -> float:
        """Ground-track turn radius at TAS in calm air, planned at 0.8 of the bank limit (as Guidance)."""
        return self.tas_mps**2 / (G_MPS2 * math.tan(0.8 * math.radians(self.bank_limit_deg)))


@dataclass
class PlannedRoute:
    """A planned route: waypoints (lat_deg, lon_deg, h_agl_m) from the start to the goal, and its figures
    measured along the legs on the cost map (sampled every quarter cell)."""

    waypoints_deg: list[tuple[float, float, float]]
    length_m: float
    straight_length_m: float
    featureless_m: float
    longest_featureless_m: float
    final_featureless_m: float  # featureless distance flown since the last informative sample
    cost: float
    weight: float
    grid_path: np.ndarray = field(repr=False, default_factory=lambda: np.zeros((0, 2), np.int64))

    @property
    def extra_distance_fraction(self) -> float:
        return self.length_m / self.straight_length_m - 1.0 if self.straight_length_m > 0 else 0.0

    def as_route(self) -> Route:
        return Route([Waypoint.from_deg(la, lo, h, "agl") for la, lo, h in self.waypoints_deg])

    def route_table(self, tas_mps: float) -> dict:
        """The scenario file's [route] table (dict) flying this route at tas_mps."""
        return {
            "tas_mps": float(tas_mps),
            "waypoints": [{"lat_deg": la, "lon_deg": lo, "h_agl_m": h} for la, lo, h in self.waypoints_deg],
        }

    def toml(self, tas_mps: float, header: str = "") -> str:
        """A TOML document with the [route] table (scenario files accept it) and the planner's figures."""
        lines = [f"# {ln}" for ln in header.splitlines()] if header else []
        lines += [
            f"# planned by trn_env.guidance.planner: weight {self.weight:g}, length {self.length_m:.0f} m "
            f"(straight {self.straight_length_m:.0f} m, +{100 * self.extra_distance_fraction:.1f} %), "
            f"featureless {self.featureless_m:.0f} m, longest featureless stretch "
            f"{self.longest_featureless_m:.0f} m, final {self.final_featureless_m:.0f} m",
            "[route]",
            f"tas_mps = {float(tas_mps):.1f}",
            "waypoints = [",
        ]
        for la, lo, h in self.waypoints_deg:
            lines.append(f"    {{ lat_deg = {la:.6f}, lon_deg = {lo:.6f}, h_agl_m = {h:.1f} }},")
        lines.append("]")
        return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------------------ planner


class TerrainInformationPlanner:
    """Plans routes on one map (the cost map is built once, in the constructor). See the module docstring."""

    def __init__(self, map_dem: Dem, config: PlannerConfig | None = None):
        self.config = config if config is not None else PlannerConfig()
        if not isinstance(self.config, PlannerConfig):
            raise ValueError(f"config must be a PlannerConfig, got {type(self.config).__name__}")
        c = self.config
        self.map_dem = map_dem
        self.grid: InformationGrid = information_grid(
            map_dem, c.cell_m, c.sigma_m, c.window_m, c.informative_crlb_m, c.featureless_crlb_m
        )
        ni, nj = self.grid.shape
        k = c.edge_margin_cells
        self.blocked = np.zeros((ni, nj), np.bool_)
        if k:
            self.blocked[:k, :] = self.blocked[-k:, :] = True
            self.blocked[:, :k] = self.blocked[:, -k:] = True
        self.blocked |= ~np.isfinite(self.grid.height_m)
        self._height = np.where(np.isfinite(self.grid.height_m), self.grid.height_m, 0.0)
        self._bin_m = 0.5 * min(self.grid.cell_n_m, self.grid.cell_e_m)

    # ------------------------------------------------------------------------- checks and geometry
    def check_endpoint(self, name: str, lat_rad: float, lon_rad: float) -> tuple[int, int]:
        """The planning cell of a start or goal; ValueError naming it when it is off the map or too near the
        map's edge."""
        _check_finite_point(name, lat_rad, lon_rad)
        deg = (math.degrees(lat_rad), math.degrees(lon_rad))
        if not self.map_dem.contains(lat_rad, lon_rad):
            b = np.degrees(self.map_dem.bounds)
            raise ValueError(
                f"{name} ({deg[0]:.5f}, {deg[1]:.5f}) deg is off the map {self.map_dem.name!r} "
                f"(lat {b[0]:.4f}..{b[1]:.4f}, lon {b[2]:.4f}..{b[3]:.4f} deg)"
            )
        i, j = self.grid.cell_of(lat_rad, lon_rad)
        if not self.grid.contains_cell(i, j) or self.blocked[i, j]:
            raise ValueError(
                f"{name} ({deg[0]:.5f}, {deg[1]:.5f}) deg is within "
                f"{self.config.edge_margin_cells} planning cells ({self.config.cell_m:g} m) of "
                f"the map's edge (or over a void)"
            )
        return i, j

    def _samples(self, lats: np.ndarray, lons: np.ndarray):
        """(step lengths (m), featureless factor) of samples every quarter cell along the legs."""
        step_m = 0.25 * min(self.grid.cell_n_m, self.grid.cell_e_m)
        ds_all, u_all = [], []
        for k in range(len(lats) - 1):
            dn, de = _leg_ne_m(lats[k], lons[k], lats[k + 1], lons[k + 1])
            d = math.hypot(dn, de)
            n = max(1, int(math.ceil(d / step_m)))
            f = (np.arange(n) + 0.5) / n
            la = lats[k] + f * (lats[k + 1] - lats[k])     # a leg is straight in latitude/longitude
            lo = lons[k] + f * (lons[k + 1] - lons[k])
            ds_all.append(np.full(n, d / n))
            u_all.append(self.grid.featureless_at(la, lo))
        return np.concatenate(ds_all), np.concatenate(u_all)

    def evaluate(self, lats_rad, lons_rad) -> dict:
        """Figures of a polyline (rad arrays) on the cost map: length_m, featureless_m, longest and final
        featureless stretch (m), cost J (sampled every quarter cell)."""
        lats, lons = np.asarray(lats_rad, float), np.asarray(lons_rad, float)
        ds, u = self._samples(lats, lons)
        feat = u > FEATURELESS_EDGE
        longest, run = _featureless_runs(ds, feat)
        return {
            "length_m": float(ds.sum()),
            "featureless_m": float(ds[feat].sum()),
            "longest_featureless_m": float(longest),
            "final_featureless_m": float(run),
            "cost": float(np.sum(ds * (1.0 + self.config.weight * u))),
        }

    def _segment_ok(self, la0, lo0, la1, lo1, budget: float) -> bool:
        """A straight shortcut is allowed: J no larger than `budget`, featureless bound kept, not blocked."""
        ev = self.evaluate([la0, la1], [lo0, lo1])
        # the leg's length form is within dlat^2 / 24 of the path it replaces (_leg_ne_m): allow 3x that
        if ev["cost"] > budget * (1.0 + 1e-9 + (la1 - la0) ** 2 / 8.0):
            return False
        return not self._line_limits(la0, lo0, la1, lo1, ev, first_only=True)

    def straight_line_limits(self, lat0_rad: float, lon0_rad: float, lat1_rad: float,
                             lon1_rad: float) -> list[str]:
        """The search's constraints that the straight line between two points (rad) breaks, in this order:
        "featureless" (a featureless stretch longer than max_featureless_m), "map" (it passes over map
        voids or within edge_margin_cells of the map's edge), "climb" (the map rises along it faster than
        the climb gradient); empty when the straight line is a route the planner could fly. ValueError
        naming the point that is not a finite latitude/longitude."""
        _check_finite_point("start", lat0_rad, lon0_rad)
        _check_finite_point("goal", lat1_rad, lon1_rad)
        ev = self.evaluate([lat0_rad, lat1_rad], [lon0_rad, lon1_rad])
        return self._line_limits(lat0_rad, lon0_rad, lat1_rad, lon1_rad, ev, first_only=False)

    def _line_limits(self, la0, lo0, la1, lo1, ev: dict, first_only: bool) -> list[str]:
        """straight_line_limits (ev: evaluate() of the line); first_only: stop at the first one found."""
        c = self.config
        broken = []
        if c.max_featureless_m is not None and ev["longest_featureless_m"] > c.max_featureless_m:
            broken.append("featureless")
            if first_only:
                return broken
        n = max(2, int(math.ceil(ev["length_m"] / (0.25 * min(self.grid.cell_n_m, self.grid.cell_e_m)))))
        f = np.linspace(0.0, 1.0, n)
        la, lo = la0 + f * (la1 - la0), lo0 + f * (lo1 - lo0)
        i = np.floor((la - self.grid.lat0_rad) / self.grid.dlat_rad + 0.5).astype(int)
        j = np.floor((lo - self.grid.lon0_rad) / self.grid.dlon_rad + 0.5).astype(int)
        ni, nj = self.grid.shape
        outside = (i < 0) | (i >= ni) | (j < 0) | (j >= nj)
        if np.any(outside) or np.any(self.blocked[i, j]):
            broken.append("map")
            if first_only:
                return broken
        gamma = c.climb_gradient
        if gamma is not None and not self._climb_ok(la, lo, ev["length_m"] / (n - 1), gamma):
            broken.append("climb")
        return broken

    def _climb_ok(self, la, lo, step_m: float, gamma: float) -> bool:
        """The map, sampled at (la, lo) every step_m and averaged over a planning cell as the search's cell
        heights are, never rises faster than gamma along the samples."""
        h = np.asarray(self.map_dem.height(la, lo), float)
        h = np.where(np.isfinite(h), h, 0.0)
        k = max(1, int(round(min(self.grid.cell_n_m, self.grid.cell_e_m) / max(step_m, 1e-9))))
        if h.size > k:
            c = np.concatenate([[0.0], np.cumsum(h)])
            h = (c[k:] - c[:-k]) / k             # running mean over one cell
        if h.size < 2:
            return True
        return bool(np.all(np.diff(h) <= gamma * step_m + 1.0))

    def _string_pull(self, lats, lons):
        """Greedy shortcuts along the grid path (each keeps J and the bounds, see _segment_ok)."""
        seg_cost = np.array(
            [self.evaluate(lats[k : k + 2], lons[k : k + 2])["cost"] for k in range(len(lats) - 1)]
        )
        cum = np.concatenate([[0.0], np.cumsum(seg_cost)])
        keep = [0]
        a = 0
        bound = self.config.max_featureless_m
        while a < len(lats) - 1:
            b = a + 1
            for c in range(a + 2, len(lats)):
                if not self._segment_ok(lats[a], lons[a], lats[c], lons[c], cum[c] - cum[a]):
                    break
                # a featureless stretch may run on across waypoints: judge the whole route (a shortcut with
                # no featureless sample only breaks stretches, so it cannot lengthen one)
                seg = self.evaluate(lats[[a, c]], lons[[a, c]]) if bound is not None else None
                if seg is not None and seg["featureless_m"] > 0.0:
                    idx = keep + list(range(c, len(lats)))
                    if self.evaluate(lats[idx], lons[idx])["longest_featureless_m"] > bound:
                        break
                b = c
            keep.append(b)
            a = b
        return lats[keep], lons[keep]

    def _thin_turns(self, lats, lons):
        """Remove waypoints whose fillet does not fit half of an adjacent leg (see the module docstring)."""
        c = self.config
        R = c.turn_radius_m
        base = self.evaluate(lats, lons)
        limit = base["cost"] * (1.0 + c.turn_cost_tolerance)
        changed = True
        while changed and len(lats) > 2:
            changed = False
            for k in range(1, len(lats) - 1):
                n0, e0 = _leg_ne_m(lats[k - 1], lons[k - 1], lats[k], lons[k])
                n1, e1 = _leg_ne_m(lats[k], lons[k], lats[k + 1], lons[k + 1])
                dchi = abs(
                    math.atan2(
                        math.sin(math.atan2(e1, n1) - math.atan2(e0, n0)),
                        math.cos(math.atan2(e1, n1) - math.atan2(e0, n0)),
                    )
                )
                need = R * math.tan(min(dchi, math.radians(170.0)) / 2.0)
                if need <= 0.5 * min(math.hypot(n0, e0), math.hypot(n1, e1)):
                    continue
                la2, lo2 = np.delete(lats, k), np.delete(lons, k)
                ev = self.evaluate(la2, lo2)
                if ev["cost"] > limit:
                    continue
                if c.max_featureless_m is not None and ev["longest_featureless_m"] > c.max_featureless_m:
                    continue
                if not self._segment_ok(la2[k - 1], lo2[k - 1], la2[k], lo2[k], np.inf):
                    continue
                lats, lons = la2, lo2
                changed = True
                break
        return lats, lons

    def _search(self, start: tuple[int, int], goal: tuple[int, int], n_bins: int | None):
        """astar_kernel on this planner's grid: (cost, cell path); n_bins None searches without the
        featureless bound."""
        c = self.config
        climb = -1.0 if c.climb_gradient is None else float(c.climb_gradient)
        try:
            return astar_kernel(
                (self.grid.featureless, self._height, self.blocked, self.grid.cell_n_m, self.grid.cell_e_m),
                (MOVES, float(c.weight), n_bins is not None, 1 if n_bins is None else n_bins, self._bin_m,
                 climb),
                start,
                goal,
            )
        except MemoryError:
            ni, nj = self.grid.shape
            bins = "" if n_bins is None else f" x {n_bins} featureless-stretch bins"
            raise ValueError(
                f"PlannerConfig.cell_m: the search over {ni} x {nj} cells{bins} needs more memory than this "
                f"machine gives; plan with larger cells"
                + ("" if n_bins is None else " or a shorter PlannerConfig.max_featureless_m")
            ) from None

    # ------------------------------------------------------------------------------------ plan
    def plan(
        self, start_lat_rad: float, start_lon_rad: float, goal_lat_rad: float, goal_lon_rad: float
    ) -> PlannedRoute:
        """The route of least J from the start to the goal (see the module docstring)."""
        c = self.config
        si, sj = self.check_endpoint("start", start_lat_rad, start_lon_rad)
        gi, gj = self.check_endpoint("goal", goal_lat_rad, goal_lon_rad)
        cost, path = self._search((si, sj), (gi, gj), None)
        if c.max_featureless_m is not None and len(path):
            # The bound can only raise the least cost, so when the unbounded route keeps to it, it is the
            # bounded answer too. Searched only otherwise: its states grow with the bound (cells x bins), and
            # a bound above every route's stretch would size them by the bound alone.
            top_bin = path_stretch_bins(self.grid.featureless, path, self.grid.cell_n_m, self.grid.cell_e_m,
                                        self._bin_m)
            if top_bin > c.max_featureless_m / self._bin_m:      # top_bin >= the bounded search's n_bins
                n_bins = int(math.floor(c.max_featureless_m / self._bin_m)) + 1     # <= top_bin
                cost, path = self._search((si, sj), (gi, gj), n_bins)
        if len(path) == 0:
            bound = (
                ""
                if c.max_featureless_m is None
                else f" with no featureless stretch over {c.max_featureless_m:g} m"
            )
            climb_s = "" if c.climb_gradient is None else f", climb gradient <= {c.climb_gradient:.3g}"
            raise RouteNotFoundError(
                f"no route found from ({math.degrees(start_lat_rad):.5f}, "
                f"{math.degrees(start_lon_rad):.5f}) to ({math.degrees(goal_lat_rad):.5f}, "
                f"{math.degrees(goal_lon_rad):.5f}) deg{bound}{climb_s} on the map "
                f"{self.map_dem.name!r}"
            )
        la, lo = self.grid.latlon_of(path[:, 0], path[:, 1])
        la, lo = np.array(la, float), np.array(lo, float)
        la[0], lo[0], la[-1], lo[-1] = start_lat_rad, start_lon_rad, goal_lat_rad, goal_lon_rad
        if len(la) > 2:
            la, lo = self._string_pull(la, lo)
            la, lo = self._thin_turns(la, lo)
        ev = self.evaluate(la, lo)
        dn, de = _leg_ne_m(start_lat_rad, start_lon_rad, goal_lat_rad, goal_lon_rad)
        wps = [(math.degrees(a), math.degrees(b), float(c.agl_m)) for a, b in zip(la, lo, strict=False)]
        return PlannedRoute(
            wps,
            ev["length_m"],
            math.hypot(dn, de),
            ev["featureless_m"],
            ev["longest_featureless_m"],
            ev["final_featureless_m"],
            ev["cost"],
            float(c.weight),
            grid_path=path,
        )


def _contour_step_m(relief_m: float) -> float:
    """A round contour interval (1, 2 or 5 x 10^k m) giving 5-12 contours over `relief_m`."""
    raw = relief_m / 12.0
    base = 10.0 ** math.floor(math.log10(raw))
    return next(m * base for m in (1.0, 2.0, 5.0, 10.0) if m * base >= raw)


def plot_route(
    path, planner: TerrainInformationPlanner, routes: dict[str, PlannedRoute], title: str = ""
) -> None:
    """PNG of routes over the planner's information map (log10 CRLB of the cells; featureless bright), with
    the cells' mean heights as contours."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    g = planner.grid
    ni, nj = g.shape
    lat = np.degrees(g.lat0_rad + np.array([-0.5, ni - 0.5]) * g.dlat_rad)
    lon = np.degrees(g.lon0_rad + np.array([-0.5, nj - 0.5]) * g.dlon_rad)
    fig, ax = plt.subplots(figsize=(7.5, 6.5))
    crlb = np.log10(np.clip(np.where(np.isfinite(g.crlb_m), g.crlb_m, 1e4), 0.1, 1e4))
    im = ax.imshow(
        crlb,
        origin="lower",
        extent=(lon[0], lon[1], lat[0], lat[1]),
        cmap="magma_r",
        aspect="auto",
        vmin=0.0,
        vmax=max(3.0, float(np.nanmax(crlb))),
    )
    fig.colorbar(im, ax=ax, label="log10 position CRLB of the map's terrain (m)")
    # the cells' mean heights as contours: where the climb limit bends a route, the rise it avoids shows
    h = g.height_m
    if np.isfinite(h).sum() >= 4 and np.nanmax(h) - np.nanmin(h) > 1.0:
        step = _contour_step_m(float(np.nanmax(h) - np.nanmin(h)))
        levels = np.arange(np.ceil(np.nanmin(h) / step) * step, np.nanmax(h), step)
        if levels.size:
            lat_c = np.degrees(g.lat0_rad + np.arange(ni) * g.dlat_rad)
            lon_c = np.degrees(g.lon0_rad + np.arange(nj) * g.dlon_rad)
            cs = ax.contour(lon_c, lat_c, np.ma.masked_invalid(h), levels=levels, colors="0.35",
                            linewidths=0.5, alpha=0.7)
            ax.clabel(cs, levels[::2], fontsize=6, fmt="%.0f m")
    colours = ["tab:cyan", "tab:green", "tab:blue", "white"]
    for k, (name, r) in enumerate(routes.items()):
        w = np.array(r.waypoints_deg)
        ax.plot(
            w[:, 1],
            w[:, 0],
            "-o",
            ms=3,
            color=colours[k % len(colours)],
            label=f"{name}: {r.length_m / 1000:.1f} km, featureless {r.featureless_m / 1000:.1f} km",
        )
    if routes:
        w = np.array(next(iter(routes.values())).waypoints_deg)
        ax.plot(w[0, 1], w[0, 0], "k^", ms=9, label="start")
        ax.plot(w[-1, 1], w[-1, 0], "k*", ms=12, label="goal")
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")
    ax.set_title(title or "planned route over the terrain information of the map")
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
