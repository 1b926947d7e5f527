"""The terrain-information planner: its A* against scipy's Dijkstra on independently built graphs, the
featureless bound, routes on the basin terrain and the real DEM, the route TOML in a scenario, bad input,
and `trn-env plan`."""

from __future__ import annotations

import math
import shlex
import sys

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from trn_env.terrain import metrics

from trn_env import terrain
from trn_env.guidance.astar import path_stretch_bins
from trn_env.guidance.planner import (
    MOVES,
    PlannerConfig,
    RouteNotFoundError,
    TerrainInformationPlanner,
    astar_kernel,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def _edge_u(u, i, j, di, dj):
    """Mean featureless factor of the cells an edge touches (written here from the planner's docstring:
    both ends; for a knight move also the two cells beside its midpoint)."""
    cells = [(i, j), (i + di, j + dj)]
    if abs(di) == 2:
        cells += [(i + di // 2, j), (i + di // 2, j + dj)]
    elif abs(dj) == 2:
        cells += [(i, j + dj // 2), (i + di, j + dj // 2)]
    return float(np.mean([u[a, b] for a, b in cells]))


def _moves():
    m8 = [(di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1) if (di, dj) != (0, 0)]
    knights = [(a * p, b * q) for a, b in ((1, 2), (2, 1)) for p in (1, -1) for q in (1, -1)]
    return m8 + knights


def _scipy_cost(u, cn, ce, w, start, goal, bound_bins=None, bin_m=None):
    """Least cost by scipy's Dijkstra on a graph built here: nodes = cells (or cells x featureless bins)."""
    ni, nj = u.shape
    nb = 1 if bound_bins is None else bound_bins
    rows, cols, vals = [], [], []
    for i in range(ni):
        for j in range(nj):
            for di, dj in _moves():
                ii, jj = i + di, j + dj
                if not (0 <= ii < ni and 0 <= jj < nj):
                    continue
                L = math.hypot(di * cn, dj * ce)
                ue = _edge_u(u, i, j, di, dj)
                for b in range(nb):
                    if bound_bins is not None and ue > 0.5:
                        b2 = int(round(b + L / bin_m))
                        if b2 >= nb:
                            continue
                    else:
                        b2 = 0
                    rows.append((i * nj + j) * nb + b)
                    cols.append((ii * nj + jj) * nb + b2)
                    vals.append(L * (1.0 + w * ue))
    n = ni * nj * nb
    g = coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()
    d = dijkstra(g, indices=(start[0] * nj + start[1]) * nb)
    return float(np.min(d[(goal[0] * nj + goal[1]) * nb : (goal[0] * nj + goal[1]) * nb + nb]))


def test_moves_are_the_16_connected_set():
    assert sorted(map(tuple, MOVES.tolist())) == sorted(_moves())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_astar_matches_scipy_dijkstra(seed):
    rng = np.random.default_rng(seed)
    u = (rng.random((14, 11)) > 0.6).astype(float) * rng.random((14, 11))
    h = np.zeros_like(u)
    blocked = np.zeros(u.shape, np.bool_)
    for w in (0.0, 1.5, 6.0):
        grid = (u, h, blocked, 480.0, 530.0)
        cost, path = astar_kernel(grid, (MOVES, w, False, 1, 240.0, -1.0), (1, 2), (12, 9))
        assert cost == pytest.approx(_scipy_cost(u, 480.0, 530.0, w, (1, 2), (12, 9)), rel=1e-9)
        assert tuple(path[0]) == (1, 2) and tuple(path[-1]) == (12, 9)
        # the path's own cost adds up to the reported cost
        c = sum(
            math.hypot((b[0] - a[0]) * 480.0, (b[1] - a[1]) * 530.0)
            * (1 + w * _edge_u(u, a[0], a[1], b[0] - a[0], b[1] - a[1]))
            for a, b in zip(path[:-1], path[1:], strict=False)
        )
        assert c == pytest.approx(cost, rel=1e-9)


def test_featureless_bound_matches_the_augmented_graph():
    """A featureless band across the grid with one informative gap far to the side: the bound forces the
    detour; the least cost equals scipy's Dijkstra on the (cell, bin) graph built in the test."""
    u = np.zeros((16, 12))
    u[6:10, :] = 1.0
    u[6:10, 0] = 0.0  # the gap
    h = np.zeros_like(u)
    blocked = np.zeros(u.shape, np.bool_)
    grid = (u, h, blocked, 500.0, 500.0)
    bin_m = 250.0
    for max_m in (600.0, 1200.0, 5000.0):
        nb = int(math.floor(max_m / bin_m)) + 1
        cost, path = astar_kernel(grid, (MOVES, 0.0, True, nb, bin_m, -1.0), (1, 8), (14, 8))
        ref = _scipy_cost(u, 500.0, 500.0, 0.0, (1, 8), (14, 8), bound_bins=nb, bin_m=bin_m)
        assert cost == pytest.approx(ref, rel=1e-9)
        # the stretch over featureless edges along the returned path respects the bound
        run = longest = 0.0
        for a, b in zip(path[:-1], path[1:], strict=False):
            d = b - a
            L = math.hypot(d[0] * 500.0, d[1] * 500.0)
            run = run + L if _edge_u(u, a[0], a[1], d[0], d[1]) > 0.5 else 0.0
            longest = max(longest, run)
        assert longest <= max_m + 0.5 * bin_m
    straight, _ = astar_kernel(grid, (MOVES, 0.0, False, 1, bin_m, -1.0), (1, 8), (14, 8))
    assert straight == pytest.approx(13 * 500.0)
    assert cost == pytest.approx(straight)  # 5 km allows crossing the 2 km band straight


@pytest.fixture(scope="module")
def basin():
    return terrain.load("synthetic:basin")


def _start_goal(dem, fs=(0.1, 0.5), fg=(0.8, 0.5)):
    la0, la1, lo0, lo1 = dem.bounds
    return (
        la0 + fs[0] * (la1 - la0),
        lo0 + fs[1] * (lo1 - lo0),
        la0 + fg[0] * (la1 - la0),
        lo0 + fg[1] * (lo1 - lo0),
    )


def _independent_featureless_run_m(dem, route, crlb_bad_m=30.0, n_per_leg=200):
    """Longest stretch (m) of a route whose points have a CRLB (terrain.metrics on the DEM posts, nearest
    post) above crlb_bad_m: computed from the DEM, not from the planner's grid."""
    crlb = metrics.terrain_information(dem, 5.0, 2000.0).crlb_sigma_h_m
    w = np.radians(np.array(route.waypoints_deg)[:, :2])
    run = longest = 0.0
    for (a0, b0), (a1, b1) in zip(w[:-1], w[1:], strict=False):
        la, lo = np.linspace(a0, a1, n_per_leg), np.linspace(b0, b1, n_per_leg)
        i = np.clip(np.round((la - dem.lat0_rad) / dem.dlat_rad).astype(int), 0, dem.n_lat - 1)
        j = np.clip(np.round((lo - dem.lon0_rad) / dem.dlon_rad).astype(int), 0, dem.n_lon - 1)
        seg_m = math.hypot((a1 - a0) * 6.37e6, (b1 - b0) * 6.37e6 * math.cos(a0))
        for bad in ~(crlb[i, j] <= crlb_bad_m):
            run = run + seg_m / n_per_leg if bad else 0.0
            longest = max(longest, run)
    return longest


def test_basin_routes_trade_distance_for_information(basin):
    s_lat, s_lon, g_lat, g_lon = _start_goal(basin)
    straight = TerrainInformationPlanner(basin, PlannerConfig(weight=0.0, climb_rate_mps=None)).plan(
        s_lat, s_lon, g_lat, g_lon)
    assert straight.length_m == pytest.approx(straight.straight_length_m, rel=0.01)
    assert len(straight.waypoints_deg) == 2
    # the climb limit (on by default) bends the shortest route round the steepest hills, by little here
    shortest = TerrainInformationPlanner(basin, PlannerConfig(weight=0.0)).plan(s_lat, s_lon, g_lat, g_lon)
    assert straight.length_m <= shortest.length_m < 1.05 * straight.length_m
    assert _independent_featureless_run_m(basin, straight) > 9000.0  # it crosses the 12 km basin
    planned = TerrainInformationPlanner(basin, PlannerConfig(weight=1.0)).plan(s_lat, s_lon, g_lat, g_lon)
    assert planned.featureless_m < 500.0 and planned.extra_distance_fraction < 0.25
    assert _independent_featureless_run_m(basin, planned) < 1500.0
    bounded = TerrainInformationPlanner(basin, PlannerConfig(weight=0.0, max_featureless_m=2000.0)).plan(
        s_lat, s_lon, g_lat, g_lon
    )
    assert bounded.longest_featureless_m <= 2000.0
    assert straight.length_m < bounded.length_m < planned.length_m * 1.02
    # the waypoints are the start and the goal at the ends, at the planner's height above ground
    assert bounded.waypoints_deg[0][:2] == pytest.approx((math.degrees(s_lat), math.degrees(s_lon)))
    assert bounded.waypoints_deg[-1][:2] == pytest.approx((math.degrees(g_lat), math.degrees(g_lon)))
    assert all(h == 600.0 for *_, h in bounded.waypoints_deg)
    # no fillet needs more than half of an adjacent leg, or the waypoint could not be removed cheaply
    route = planned.as_route()
    assert route.n_legs == len(planned.waypoints_deg) - 1


def test_bounded_plan_is_the_bounded_searchs_least_cost_at_any_bound(basin):
    """The planner searches with the bound only when the unbounded route breaks it: its route's grid cost is
    the least cost of the bounded search on the (cell, bin) states at every bound, and a bound far above
    any route's stretch (1e308 m overflowed; 1e8 m sized the states by the bound: a MemoryError) plans the
    unbounded route."""
    s_lat, s_lon, g_lat, g_lon = _start_goal(basin)
    free = TerrainInformationPlanner(basin, PlannerConfig(weight=0.0))
    si, sj = free.check_endpoint("start", s_lat, s_lon)
    gi, gj = free.check_endpoint("goal", g_lat, g_lon)
    grid = (free.grid.featureless, free._height, free.blocked, free.grid.cell_n_m, free.grid.cell_e_m)
    climb = free.config.climb_gradient
    free_cost, free_path = astar_kernel(grid, (MOVES, 0.0, False, 1, free._bin_m, climb), (si, sj), (gi, gj))
    top = path_stretch_bins(grid[0], free_path, grid[3], grid[4], free._bin_m)
    assert top * free._bin_m > 9000.0          # the unbounded route crosses the basin
    searched = []
    for bound_m in (1000.0, 2000.0, 6000.0, top * free._bin_m - 1.0, top * free._bin_m, 5e4, 1e8, 1e308):
        planner = TerrainInformationPlanner(basin, PlannerConfig(weight=0.0, max_featureless_m=bound_m))
        calls = []
        kernel = planner._search
        planner._search = lambda *a, _k=kernel, _c=calls: _c.append(a[2]) or _k(*a)
        route = planner.plan(s_lat, s_lon, g_lat, g_lon)
        searched.append(calls)
        if bound_m < 1e5:
            n_bins = int(math.floor(bound_m / free._bin_m)) + 1
            ref, _ = astar_kernel(grid, (MOVES, 0.0, True, n_bins, free._bin_m, climb), (si, sj), (gi, gj))
        else:
            ref = free_cost
        d = np.diff(route.grid_path, axis=0) * np.array([free.grid.cell_n_m, free.grid.cell_e_m])
        assert np.hypot(d[:, 0], d[:, 1]).sum() == pytest.approx(ref, rel=1e-12), bound_m   # weight 0
    # the bounded search ran exactly where the unbounded route breaks the bound
    assert [len(c) for c in searched] == [2, 2, 2, 2, 1, 1, 1, 1]


def test_path_stretch_bins_counts_as_the_kernel():
    """path_stretch_bins against an independent count on the featureless band of the test above, and
    against the kernel: a bounded search's path stays below its n_bins."""
    u = np.zeros((16, 12))
    u[6:10, :] = 1.0
    grid = (u, np.zeros_like(u), np.zeros(u.shape, np.bool_), 500.0, 500.0)
    straight = np.array([[i, 8] for i in range(1, 15)], np.int64)
    # edges entering, inside and leaving the band are featureless (mean u of both ends > 0.5 only when
    # both ends are in the band): 3 edges of 500 m, bins of 250 m
    assert path_stretch_bins(u, straight, 500.0, 500.0, 250.0) == 6
    for nb in (2, 3, 5, 9):
        u2 = u.copy()
        u2[6:10, 0] = 0.0
        _, path = astar_kernel((u2, *grid[1:]), (MOVES, 0.0, True, nb, 250.0, -1.0), (1, 8), (14, 8))
        assert path_stretch_bins(u2, path, 500.0, 500.0, 250.0) < nb


def test_route_toml_is_accepted_by_a_scenario(basin, tmp_path):
    from trn_env.scenario.loading import load_scenario, validate

    s_lat, s_lon, g_lat, g_lon = _start_goal(basin, fs=(0.1, 0.5))
    sc = load_scenario("basin_route")
    s_lat, s_lon = math.radians(sc.initial.lat_deg), math.radians(sc.initial.lon_deg)
    r = TerrainInformationPlanner(basin).plan(s_lat, s_lon, g_lat, g_lon)
    table = tomllib.loads(r.toml(85.0))["route"]
    data = sc.to_dict()
    data["route"] = table
    checked = validate(data, source="planned")
    assert len(checked.route.waypoints) == len(r.waypoints_deg)


def test_forty_km_route_on_the_bundled_dem():
    dem = terrain.load("jacksboro")
    s_lat, s_lon, g_lat, g_lon = _start_goal(dem, fs=(0.025, 0.03), fg=(0.97, 0.965))
    r = TerrainInformationPlanner(
        dem, PlannerConfig(weight=1.0, max_featureless_m=3000.0, edge_margin_cells=1)
    ).plan(s_lat, s_lon, g_lat, g_lon)
    assert r.straight_length_m > 40_000.0
    assert r.length_m >= r.straight_length_m * (1 - 1e-6)


def test_bad_input(basin):
    for kw, field in (
        (dict(weight=-1.0), "weight"),
        (dict(weight=float("nan")), "weight"),
        (dict(max_featureless_m=0.0), "max_featureless_m"),
        (dict(cell_m=-5.0), "cell_m"),
        (dict(agl_m="600"), "agl_m"),
        (dict(bank_limit_deg=80.0), "bank_limit_deg"),
    ):
        with pytest.raises(ValueError, match=field):
            PlannerConfig(**kw)
    p = TerrainInformationPlanner(basin)
    s_lat, s_lon, g_lat, g_lon = _start_goal(basin)
    with pytest.raises(ValueError, match="goal .* off the map"):
        p.plan(s_lat, s_lon, g_lat + 0.01, g_lon)
    with pytest.raises(ValueError, match="start .* edge"):
        p.plan(basin.lat0_rad + 1e-6, s_lon, g_lat, g_lon)
    c_lat, c_lon, _, _ = _start_goal(basin, fs=(0.5, 0.5))
    with pytest.raises(RouteNotFoundError, match="no route found .* 1000 m"):
        TerrainInformationPlanner(basin, PlannerConfig(max_featureless_m=1000.0)).plan(
            s_lat, s_lon, c_lat, c_lon
        )


_RAMP_LAT0, _RAMP_LON0, _RAMP_STEP_M = math.radians(36.0), math.radians(-84.0), 100.0
_RAMP_DLAT = _RAMP_STEP_M / 6.371e6
_RAMP_DLON = _RAMP_DLAT / math.cos(_RAMP_LAT0)


def _ramp_dem(gradient: float, void_column: int | None = None):
    """201 x 201 posts 100 m apart rising `gradient` m per m eastwards (and a 5 m ripple, slope < 0.02);
    optionally one column of posts void."""
    from trn_env.terrain.dem import Dem
    n_m = np.arange(201)[:, None] * _RAMP_STEP_M
    e_m = np.arange(201)[None, :] * _RAMP_STEP_M
    h = 300.0 + gradient * e_m + 5.0 * np.sin(2 * np.pi * n_m / 2000.0) * np.cos(2 * np.pi * e_m / 1500.0)
    if void_column is not None:
        h[:, void_column] = np.nan
    return Dem(h, _RAMP_LAT0, _RAMP_LON0, _RAMP_DLAT, _RAMP_DLON, "ramp")


def _ramp_post(i: int, j: int) -> tuple[float, float]:
    return _RAMP_LAT0 + i * _RAMP_DLAT, _RAMP_LON0 + j * _RAMP_DLON


def test_straight_line_limits_name_the_constraint_the_line_breaks(basin):
    """On a ramp the climb limit (5 m/s at 85 m/s: 0.0588) is broken climbing a 0.07 slope, not a 0.05 one,
    nor descending or across it; a line over voids breaks the map's; a line across the basin breaks a
    featureless bound shorter than the basin."""
    for gradient, climbing in ((0.05, []), (0.07, ["climb"])):
        dem = _ramp_dem(gradient)
        p = TerrainInformationPlanner(dem, PlannerConfig())
        assert p.config.climb_gradient == pytest.approx(5.0 / 85.0)
        at = _ramp_post
        assert p.straight_line_limits(*at(100, 30), *at(100, 170)) == climbing        # eastwards: up
        assert p.straight_line_limits(*at(100, 170), *at(100, 30)) == []              # westwards: down
        assert p.straight_line_limits(*at(30, 100), *at(170, 100)) == []              # along the contours
        no_limit = TerrainInformationPlanner(dem, PlannerConfig(climb_rate_mps=None))
        assert no_limit.straight_line_limits(*at(100, 30), *at(100, 170)) == []
    void = TerrainInformationPlanner(_ramp_dem(0.05, void_column=100), PlannerConfig(climb_rate_mps=None))
    assert void.straight_line_limits(*_ramp_post(100, 170), *_ramp_post(100, 30)) == ["map"]
    assert void.straight_line_limits(*_ramp_post(30, 60), *_ramp_post(170, 60)) == []
    s_lat, s_lon, g_lat, g_lon = _start_goal(basin)
    bounded = TerrainInformationPlanner(basin, PlannerConfig(max_featureless_m=2000.0, climb_rate_mps=None))
    assert bounded.straight_line_limits(s_lat, s_lon, g_lat, g_lon) == ["featureless"]
    assert TerrainInformationPlanner(basin, PlannerConfig(climb_rate_mps=None)).straight_line_limits(
        s_lat, s_lon, g_lat, g_lon) == []
    for bad in (math.nan, math.inf, "36.7"):
        with pytest.raises(ValueError, match="goal must be finite latitude/longitude"):
            bounded.straight_line_limits(s_lat, s_lon, bad, g_lon)


def test_leg_lengths_match_the_ecef_chord_and_collinear_steps_add_up():
    """The planner's leg length against the straight chord between the two ends' ECEF positions (an
    independent computation; the chord is shorter than the arc by L^3 / 24 R^2, 1e-6 relative at 30 km):
    within 2e-6 in every direction and either way; and a leg split into the equal latitude/longitude steps of
    a grid path adds up to the whole within dlat^2 / 24, the bound string pulling allows for (the
    small-offset form taken at the leg's start made a 30 km north-east leg 6e-4 too long, a south-west one
    6e-4 too short)."""
    from trn_env.terrain.geodesy import lla_to_ecef, ned_offset_to_latlon

    from trn_env.guidance.planner import _leg_ne_m

    lat0, lon0 = math.radians(36.5), math.radians(-84.3)
    for dist_m in (1_000.0, 10_000.0, 30_000.0):
        for bearing_deg in range(0, 360, 45):
            b = math.radians(bearing_deg)
            lat1, lon1 = ned_offset_to_latlon(lat0, lon0, 0.0, dist_m * math.cos(b), dist_m * math.sin(b))
            chord = math.dist(lla_to_ecef(lat0, lon0, 0.0), lla_to_ecef(lat1, lon1, 0.0))
            there = math.hypot(*_leg_ne_m(lat0, lon0, lat1, lon1))
            back = math.hypot(*_leg_ne_m(lat1, lon1, lat0, lon0))
            assert there == pytest.approx(chord, rel=2e-6) and back == pytest.approx(chord, rel=2e-6)
            f = np.linspace(0.0, 1.0, 61)
            la, lo = lat0 + f * (lat1 - lat0), lon0 + f * (lon1 - lon0)
            steps = sum(math.hypot(*_leg_ne_m(la[k], lo[k], la[k + 1], lo[k + 1])) for k in range(60))
            assert abs(there - steps) <= there * ((lat1 - lat0) ** 2 / 24 + 1e-12)


def test_a_straight_route_is_one_leg():
    """Without the climb limit the straight line over the real DEM (no map voids, no featureless terrain) is
    the best route: string pulling leaves its two ends only, at weight 0 and at the default weight."""
    dem = terrain.load("jacksboro")
    s_lat, s_lon, g_lat, g_lon = (math.radians(v) for v in (36.49, -84.37, 36.66, -84.18))
    for weight in (0.0, 3.0):
        p = TerrainInformationPlanner(dem, PlannerConfig(weight=weight, climb_rate_mps=None))
        assert p.straight_line_limits(s_lat, s_lon, g_lat, g_lon) == []
        route = p.plan(s_lat, s_lon, g_lat, g_lon)
        assert np.allclose(route.waypoints_deg, [(36.49, -84.37, 600.0), (36.66, -84.18, 600.0)], rtol=0,
                           atol=1e-12)
        assert route.length_m == pytest.approx(route.straight_length_m, rel=1e-12)


def test_route_plot_contour_interval_is_round_and_gives_5_to_12_contours():
    from trn_env.guidance.planner import _contour_step_m

    for relief in (3.0, 14.0, 60.0, 95.0, 840.0, 2_500.0, 7_000.0):
        step = _contour_step_m(relief)
        mantissa = step / 10.0 ** math.floor(math.log10(step) + 1e-12)
        assert round(mantissa, 9) in (1.0, 2.0, 5.0) and 4.8 <= relief / step <= 12.0, (relief, step)


def test_cli_plan_writes_route_and_plot_or_exits_2(tmp_path, capsys):
    from trn_env.cli import main

    out = tmp_path / "route.toml"
    assert (
        main(["plan", "basin_route", "--goal", "36.716", "-84.1325", "--weight", "1", "--out", str(out)]) == 0
    )
    route = tomllib.loads(out.read_text())["route"]
    assert len(route["waypoints"]) >= 3 and (tmp_path / "route.png").stat().st_size > 10_000
    why = capsys.readouterr().out.strip().splitlines()[-1]       # why the route is longer than the line
    assert why.startswith("why +") and "the straight line crosses" in why and "expected error" in why
    # over the Jacksboro DEM neither route crosses featureless terrain: the straight line climbs faster than
    # the limit, which the reason names; without the limit the route is the straight line, one leg
    assert main(["plan", "default", "--goal", "36.66", "-84.18", "--out", str(tmp_path / "j.toml")]) == 0
    why = capsys.readouterr().out.strip().splitlines()[-1]
    assert why.startswith("why +") and "not featureless terrain" in why and "faster than the aircraft" in why
    assert "gradient of 0.059" in why and "--no-climb-limit" in why
    j2 = tmp_path / "j2.toml"
    assert main(["plan", "default", "--goal", "36.66", "-84.18", "--no-climb-limit", "--out", str(j2)]) == 0
    assert capsys.readouterr().out.strip().splitlines()[-1].startswith("why: the straight line is already")
    assert len(tomllib.loads(j2.read_text())["route"]["waypoints"]) == 2
    # each file's second line is the command that plans it again, every option spelled out
    for written, again in ((out, tmp_path / "again.toml"), (j2, tmp_path / "again2.toml")):
        command = written.read_text().splitlines()[1].removeprefix("# ")
        assert command.startswith("trn-env plan ") and "--agl" in command and "--cell" in command
        assert main([*shlex.split(command)[1:], "--out", str(again)]) == 0
        capsys.readouterr()
        assert tomllib.loads(again.read_text()) == tomllib.loads(written.read_text())
    assert "--no-climb-limit" in j2.read_text().splitlines()[1]
    bad = tmp_path / "bad.toml"
    afile = tmp_path / "a.txt"
    afile.write_text("a file")
    goal = ["--goal", "36.716", "-84.1325"]
    for args, msg in (
        (["--goal", "37.9", "-84.13"], "off the map"),
        ([*goal, "--weight", "-2"], "--weight"),
        ([*goal, "--cell", "0"], "--cell must be a finite number > 0"),
        (["--goal", "36.64", "-84.1325", "--max-featureless", "500"], "no route found"),
        ([*goal, "--plot", str(tmp_path)], f"--plot {tmp_path}: is a folder"),
        ([*goal, "--plot", str(tmp_path / "p.txt")], "give a file name ending in one of"),
        ([*goal, "--plot", str(afile / "p.png")], "is not a directory"),
        ([*goal, "--plot", str(bad)], "give a file name ending in one of"),
    ):
        assert main(["plan", "basin_route", *args, "--out", str(bad)]) == 2
        assert msg in capsys.readouterr().err
        assert not bad.exists() and not bad.with_suffix(".png").exists()
    # the route file is one the scenario accepts: a height above the ceiling is refused before writing,
    # once per kind of problem however many waypoints share it (the file used to be written)
    assert main(["plan", "default", "--goal", "36.66", "-84.18", "--agl", "9000", "--out", str(bad)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("error: the planned route is not one scenario 'default' can fly")
    assert len(err) == 2
    assert err[1].startswith("  - route.waypoints[0].h_agl_m: ") and "service ceiling" in err[1]
    assert "--agl" in err[1] and "the same at 27 more waypoint(s)" in err[1]
    assert not bad.exists() and not bad.with_suffix(".png").exists()
    # a featureless bound above any route's stretch plans the unbounded route (it overflowed, or sized the
    # search by the bound: 1e8 m was a MemoryError)
    for bound in ("1e8", "1e308"):
        unbounded = tmp_path / f"b{bound}.toml"
        assert main(["plan", "basin_route", *goal, "--weight", "1", "--max-featureless", bound,
                     "--out", str(unbounded)]) == 0
        assert tomllib.loads(unbounded.read_text())["route"] == tomllib.loads(out.read_text())["route"]
    capsys.readouterr()
    png = tmp_path / "r.png"
    assert main(["plan", "basin_route", *goal, "--out", str(png)]) == 2
    assert "the plot's default name" in capsys.readouterr().err and not png.exists()
    for target, msg in ((tmp_path, "is a folder; give a file name"),
                        (afile / "r.toml", "is not a directory")):
        assert main(["plan", "basin_route", *goal, "--out", str(target)]) == 2
        assert f"--out {target}: " in (err := capsys.readouterr().err) and msg in err
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []
