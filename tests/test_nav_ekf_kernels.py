"""The numba kernels behind the INS/TRN filter's speed, against the plain computations they replace."""

import numpy as np
import pytest
from trn_env.navigators.core.maps import map_record
from trn_env.navigators.filters import _ekf_kernels as kern
from trn_env.navigators.inertial.strapdown import quat_from_C_bn, quat_to_dcm
from trn_env.navigators.measurements.ira_closest_point import closest_point_ned
from trn_env.navigators.tercom.mad import _block_void_free, mad_surface, mad_surface_reference
from trn_env.terrain.geodesy import (
    OMEGA_EARTH_RPS,
    euler_to_C_bn,
    meridian_radius_m,
    prime_vertical_radius_m,
)

from trn_env import terrain


@pytest.fixture(scope="module")
def dem():
    return terrain.load("jacksboro")


def _batch(dem, rng, m, lat_c, lon_c, spread_m):
    lat = lat_c + rng.uniform(-1, 1, m) * spread_m / 6.37e6
    lon = lon_c + rng.uniform(-1, 1, m) * spread_m / 5.1e6
    hm = rng.uniform(200.0, 900.0, m)
    d_lat = 5.0 / meridian_radius_m(lat_c)
    d_lon = 5.0 / (prime_vertical_radius_m(lat_c) * np.cos(lat_c))
    return lat, lon, hm, d_lat, d_lon


@pytest.mark.parametrize("remove_bias", [False, True])
@pytest.mark.parametrize("where", ["inside", "south_edge", "west_edge", "void"])
def test_mad_surface_is_bit_identical_to_per_lookup_reference(dem, remove_bias, where):
    rng = np.random.default_rng(7)
    heights, lat0, lon0, dlat, dlon = dem.grid
    lat_min, lat_max, lon_min, lon_max = dem.bounds
    mid = (0.5 * (lat_min + lat_max), 0.5 * (lon_min + lon_max))
    if where == "inside":
        args = (mid[0], mid[1], 1500.0)
    elif where == "south_edge":
        args = (lat_min + 60.0 / 6.37e6, mid[1], 30.0)
    elif where == "west_edge":
        args = (mid[0], lon_min + 60.0 / 5.1e6, 30.0)
    else:
        heights = heights.copy()
        i = int(round((mid[0] - lat0) / dlat))
        j = int(round((mid[1] - lon0) / dlon))
        heights[i, j] = np.nan
        args = (lat0 + i * dlat + 150.0 / 6.37e6, lon0 + j * dlon, 30.0)   # 90-210 m north of the void
    lat, lon, hm, d_lat, d_lon = _batch(dem, rng, 40, *args)
    rec = map_record((heights, lat0, lon0, dlat, dlon), False)
    fast = mad_surface(rec, lat, lon, hm, d_lat, d_lon, 12, remove_bias)
    ref = mad_surface_reference(rec, lat, lon, hm, d_lat, d_lon, 12, remove_bias)
    assert np.array_equal(fast, ref)
    if where != "inside":
        assert np.isinf(ref).any() and np.isfinite(ref).any()   # the case really straddles the edge / void


def _takes_void_free_path(heights, lat0, lon0, dlat, dlon, lat, lon, d_lat, d_lon, half):
    return _block_void_free(map_record((heights, lat0, lon0, dlat, dlon), False), lat, lon, half * abs(d_lat),
                            half * abs(d_lon))


def _fast_and_reference(*args):
    return mad_surface(*args), mad_surface_reference(*args)


@pytest.mark.parametrize("remove_bias", [False, True])
@pytest.mark.parametrize(("half", "m"), [(0, 3), (3, 1), (3, 9), (12, 37), (20, 8)])
def test_mad_surface_void_free_path_any_size_matches_reference(dem, remove_bias, half, m):
    # reference-matrix sizes that are and are not whole vectors (2 half + 1 = 1, 7, 25, 41), batch sizes
    # that leave chunk and 4-sample tails (1, 3, 8, 9, 37), on real terrain without voids
    rng = np.random.default_rng(11 + half + m)
    heights, lat0, lon0, dlat, dlon = dem.grid
    lat_min, lat_max, lon_min, lon_max = dem.bounds
    mid = (0.5 * (lat_min + lat_max), 0.5 * (lon_min + lon_max))
    lat, lon, hm, d_lat, d_lon = _batch(dem, rng, m, mid[0], mid[1], 900.0)
    assert _takes_void_free_path(heights, lat0, lon0, dlat, dlon, lat, lon, d_lat, d_lon, half)
    fast, ref = _fast_and_reference(map_record((heights, lat0, lon0, dlat, dlon), False), lat, lon, hm, d_lat,
                                    d_lon, half, remove_bias)
    assert fast.shape == (2 * half + 1, 2 * half + 1)
    assert np.isfinite(ref).all()
    assert np.array_equal(fast, ref)


@pytest.mark.parametrize("threads", [2, 3])
@pytest.mark.parametrize("remove_bias", [False, True])
def test_mad_surface_split_over_threads_is_bit_identical(dem, remove_bias, threads):
    """The rows split into bands computed on threads at once: the same bits as the reference (and the
    banded kernel really runs: 25 rows give 2 or 3 bands)."""
    rng = np.random.default_rng(3)
    heights, lat0, lon0, dlat, dlon = dem.grid
    lat_min, lat_max, lon_min, lon_max = dem.bounds
    mid = (0.5 * (lat_min + lat_max), 0.5 * (lon_min + lon_max))
    lat, lon, hm, d_lat, d_lon = _batch(dem, rng, 29, mid[0] + 2e-4, mid[1] - 3e-4, 1100.0)
    args = (dem.record(), lat, lon, hm, d_lat, d_lon, 12, remove_bias)
    split = mad_surface(*args, threads=threads)
    assert np.isfinite(split).all()
    assert np.array_equal(split, mad_surface_reference(*args))
    assert np.array_equal(split, mad_surface(*args, threads=1))


@pytest.mark.parametrize("remove_bias", [False, True])
@pytest.mark.parametrize(
    "case", ["negative_steps", "one_sample_off_map", "void_away_from_track", "north_edge"]
)
def test_mad_surface_void_free_path_edge_cases_match_reference(dem, remove_bias, case):
    rng = np.random.default_rng(5)
    heights, lat0, lon0, dlat, dlon = dem.grid
    lat_min, lat_max, lon_min, lon_max = dem.bounds
    mid = (0.5 * (lat_min + lat_max), 0.5 * (lon_min + lon_max))
    lat, lon, hm, d_lat, d_lon = _batch(dem, rng, 23, mid[0], mid[1], 1200.0)
    half = 10
    if case == "negative_steps":  # shifts run south / west with the index
        d_lat, d_lon = -d_lat, -d_lon
    elif case == "one_sample_off_map":  # sample 6 is far outside: every cell invalid
        lat = lat.copy()
        lat[6] = lat_max + 0.01
    elif case == "void_away_from_track":  # a void 5 km from the track does not force the general path
        heights = heights.copy()
        i_void = int(round((mid[0] + 5000.0 / 6.37e6 - lat0) / dlat))
        heights[i_void, int(round((mid[1] - lon0) / dlon))] = np.nan
    else:  # north-east corner: rows and columns partly off the map, sample by sample
        ne = (lat_max - 40.0 / 6.37e6, lon_max - 40.0 / 5.1e6)
        lat, lon, hm, d_lat, d_lon = _batch(dem, rng, 23, ne[0], ne[1], 30.0)
    assert _takes_void_free_path(heights, lat0, lon0, dlat, dlon, lat, lon, d_lat, d_lon, half)
    fast, ref = _fast_and_reference(map_record((heights, lat0, lon0, dlat, dlon), False), lat, lon, hm, d_lat,
                                    d_lon, half, remove_bias)
    assert np.array_equal(fast, ref)
    if case == "one_sample_off_map":
        assert np.isinf(ref).all()
    elif case == "north_edge":
        assert np.isinf(ref).any() and np.isfinite(ref).any()
    else:
        assert np.isfinite(ref).all()


def test_mad_surface_void_next_to_track_takes_general_path(dem):
    # the bit-identity test's "void" case must exercise the void-tolerant path, the others the fast one
    heights, lat0, lon0, dlat, dlon = dem.grid
    lat_min, lat_max, lon_min, lon_max = dem.bounds
    mid = (0.5 * (lat_min + lat_max), 0.5 * (lon_min + lon_max))
    heights = heights.copy()
    i = int(round((mid[0] - lat0) / dlat))
    j = int(round((mid[1] - lon0) / dlon))
    heights[i, j] = np.nan
    lat, lon, hm, d_lat, d_lon = _batch(dem, np.random.default_rng(7), 40, lat0 + i * dlat + 150.0 / 6.37e6,
                                        lon0 + j * dlon, 30.0)
    assert not _takes_void_free_path(heights, lat0, lon0, dlat, dlon, lat, lon, d_lat, d_lon, 12)


def _predict_reference(P, Q, t_imu, f_b, hist, accel_bias, t_ekf0, dt, n_steps, tau):
    """The filter's former per-step numpy algebra (F, Phi = I + Fd + Fd^2/2, P = Phi P Phi^T + Q)."""
    def skew(v):
        return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])

    F = np.zeros((13, 13))
    F[0:3, 3:6] = np.eye(3)
    F[2, 2] = -3.0 / tau
    for s in range(1, n_steps + 1):
        k = min(int(np.searchsorted(t_imu, t_ekf0 + dt * s)), t_imu.size - 1)
        st = hist[k]
        lat, h, vn, ve = st[0], st[2], st[3], st[4]
        C = quat_to_dcm(st[6:10])
        f_n = C @ (f_b[k] - accel_bias)
        rn = meridian_radius_m(lat) + h
        re = prime_vertical_radius_m(lat) + h
        w_ie = np.array([OMEGA_EARTH_RPS * np.cos(lat), 0.0, -OMEGA_EARTH_RPS * np.sin(lat)])
        w_en = np.array([ve / re, -vn / rn, -ve * np.tan(lat) / re])
        g_r = 9.80665 / np.sqrt(rn * re)
        F[3, 0] = F[4, 1] = -g_r
        F[5, 2] = 2.0 * g_r - 3.0 / tau**2
        F[3:6, 3:6] = -skew(2.0 * w_ie + w_en)
        F[3:6, 6:9] = skew(f_n)
        F[3:6, 9:12] = C
        F[6:9, 6:9] = -skew(w_ie + w_en)
        F[6:9, 12] = -C[:, 2]
        Fd = F * dt
        Phi = np.eye(13) + Fd + 0.5 * Fd @ Fd
        P = Phi @ P @ Phi.T + Q
    return P


def test_predict_covariance_matches_dense_numpy_algebra():
    rng = np.random.default_rng(3)
    n = 10
    t_imu = 5.0 + 0.01 * np.arange(1, n + 1)
    hist = np.empty((n, 10))
    for k in range(n):
        C = euler_to_C_bn(0.3 * rng.standard_normal(), 0.1 * rng.standard_normal(), rng.uniform(-3, 3))
        hist[k, :6] = (0.63 + 1e-5 * k, -1.47, 1800.0 + k, 80.0, 20.0, -1.0)
        hist[k, 6:] = quat_from_C_bn(np.asarray(C).reshape(3, 3))
    f_b = np.column_stack([rng.normal(0, 1, n), rng.normal(0, 1, n), -9.8 + rng.normal(0, 1, n)])
    A = rng.standard_normal((13, 13))
    P0 = A @ A.T + np.eye(13)
    Q = np.diag(rng.uniform(1e-9, 1e-3, 13))
    bias = np.array([1e-3, -2e-3, 5e-4])
    ref = _predict_reference(P0.copy(), Q, t_imu, f_b, hist, bias, 5.0, 0.02, 5, 30.0)
    P = P0.copy()
    kern.predict_covariance(P, Q, t_imu, f_b, hist, hist[-1].copy(), f_b[-1].copy(), bias, 5.0, 0.02, 5, 30.0)
    assert np.allclose(P, ref, rtol=1e-11, atol=1e-14)
    assert not np.allclose(P, P0)


def test_is_positive_definite_agrees_with_numpy_cholesky():
    rng = np.random.default_rng(4)
    for trial in range(40):
        A = rng.standard_normal((13, 13))
        M = A @ A.T + (1e-3 if trial % 2 else -3.0) * np.eye(13)
        try:
            np.linalg.cholesky(0.5 * (M + M.T))
            expect = True
        except np.linalg.LinAlgError:
            expect = False
        assert kern.is_positive_definite(M) == expect
    M = np.eye(13)
    M[3, 4] = np.nan
    assert not kern.is_positive_definite(M)


@pytest.mark.parametrize("formula", ["conventional", "proposed"])
def test_closest_point_kernel_matches_ira_geometry(formula):
    rng = np.random.default_rng(5)
    n = 200
    R = rng.uniform(500, 5000, n)
    theta = rng.uniform(-0.6, 0.6, n)
    C = np.stack([np.asarray(euler_to_C_bn(*e)).reshape(3, 3)
                  for e in zip(rng.uniform(-0.5, 0.5, n), rng.uniform(-0.2, 0.2, n), rng.uniform(-3, 3, n),
                               strict=True)])
    v = np.column_stack([rng.normal(60, 20, n), rng.normal(0, 40, n), rng.normal(0, 3, n)])
    ref = closest_point_ned(R, theta, None, None, None, v, formula=formula, C_bn=C)
    out = np.empty((n, 3))
    p = np.empty(3)
    for i in range(n):
        code = kern.FORMULA_CODES[formula]
        kern.closest_point_one(R[i], theta[i], v[i, 0], v[i, 1], v[i, 2], C[i], code, p)
        out[i] = p
    assert np.array_equal(np.isnan(out), np.isnan(ref))
    ok = np.isfinite(ref[:, 0])
    assert ok.sum() > n // 2
    assert np.allclose(out[ok], ref[ok], rtol=0, atol=1e-6)


def test_baro_prepare_masks_and_converts():
    h = np.array([100.0, np.nan, 5600.0, 300.0])
    valid = np.array([True, True, True, False])
    usable = np.empty(4, bool)
    geo = np.empty(4)
    assert not kern.baro_prepare(valid, h, True, usable, geo)
    assert usable.tolist() == [True, False, True, False]
    r0 = 6356766.0
    assert geo[2] == pytest.approx(r0 * 5600.0 / (r0 - 5600.0)) and geo[2] - 5600.0 > 4.0
    assert kern.baro_prepare(np.ones(2, bool), np.array([1.0, 2.0]), False, usable[:2], geo[:2])
    assert geo[:2].tolist() == [1.0, 2.0]


@pytest.mark.parametrize("v_up_mps", [8.0, -6.0])
def test_the_barometers_lag_is_taken_out_of_the_terrain_heights(v_up_mps):
    """A steady climb (or descent) read by the simulator's lagged barometer (trn_env.sensors.baro, tau 0.2 s,
    no noise or bias): the lag's reading trails the height by tau v once its transient has passed (the
    first-order response to a ramp), so each batch row's height reference (its measured terrain height plus
    the closest point's depth, navigators.measurements.ira_closest_point) is the true geometric height with
    baro_lag_s = tau, and tau v below it with no compensation; to the sensor model's discretisation (its
    step takes the new pressure over the whole step, so it trails by tau - dt / 2: v dt / 2 at most, 8 mm
    at the test's 500 Hz) and a few millimetres."""
    from trn_env.navigators.measurements.baro import geometric_height_m, geopotential_height_m

    from trn_env.sensors.baro import _baro_kernel, isa_pressure_pa

    tau_s, dt_s, n = 0.2, 0.002, 5000
    t = np.arange(n) * dt_s
    h_true = 1500.0 + v_up_mps * t                                  # geometric height (m)
    p_pa = isa_pressure_pa(geopotential_height_m(h_true))
    zeros = np.zeros(n)
    h_baro, valid, _, _ = _baro_kernel(t, p_pa, np.arange(n), zeros, 0.0, 0.0, tau_s, np.nan, np.nan)
    assert valid.all()
    lat, lon = np.radians(36.5), np.radians(-84.3)
    C = np.asarray(euler_to_C_bn(0.05, 0.02, 0.3)).reshape(3, 3)
    v_ned = np.array([80.0, 25.0, -v_up_mps])
    hist = np.empty((n, 10))
    hist[:, 0], hist[:, 1], hist[:, 2] = lat, lon, h_true
    hist[:, 3:6] = v_ned
    hist[:, 6:10] = quat_from_C_bn(C)
    R, theta = np.full(n, 900.0), np.full(n, 0.1)
    depth = abs(closest_point_ned(R[:1], theta[:1], None, None, None, v_ned[None], formula="proposed",
                                  C_bn=C[None])[0, 2])
    settled = t >= 10 * tau_s
    tol_m = abs(v_up_mps) * dt_s / 2 + 0.005
    for lag_s, expect in ((tau_s, 0.0), (0.0, -tau_s * v_up_mps)):
        rows = np.empty((n, 6))
        m, n_bad, n_nan = kern.collect_ira(t[0], t[-1], t, hist, (t, R, theta, np.ones(n, bool)), 1,
                                           (t, h_baro, True, True, lag_s), kern.FORMULA_CODES["proposed"],
                                           rows)
        assert (m, n_bad, n_nan) == (n, 0, 0)
        h_ref = rows[:m, 3] + depth
        err = (h_ref - h_true)[settled]
        assert np.abs(err - expect).max() < tol_m, (lag_s, err.min(), err.max())
    # the reading itself (geometric) trails by tau v: the compensation is not hiding a different error
    trail = (geometric_height_m(h_baro) - h_true)[settled]
    assert np.abs(trail + tau_s * v_up_mps).max() < tol_m


@pytest.fixture(scope="module")
def sim_frames():
    """45 s of the default scenario's sensor frames (one TERCOM fix), with some IRA no-returns and a NaN
    baro sample injected, and the sim's initial estimate."""
    from trn_env.scenario.loading import load_scenario
    from trn_env.sim.closed_loop import ClosedLoop
    from trn_env.sim.nav_stage import gate_gnss as _gate_gnss

    loop = ClosedLoop(load_scenario("default", duration_s=60.0), log_sensors=False)
    rng = np.random.default_rng(11)
    frames = []
    for _ in range(450):
        chunk = loop.flight.advance(loop.steps_per_tick)
        fr = _gate_gnss(loop.sensors.sample(chunk, loop.world_dem), loop.outages)
        bad = rng.random(fr.ira.valid.size) < 0.15
        fr.ira.valid[bad] = False
        fr.ira.range_m[bad] = np.nan
        if len(frames) == 200:
            fr.baro.h_baro_m[0] = np.nan
        frames.append(fr)
    e0 = loop.estimate
    return loop.map_dem, e0, frames


@pytest.mark.parametrize("decimation, baro_lag_s", [(1, 0.0), (3, 0.0), (1, 0.2)])
def test_fused_and_fast_paths_match_general_path(sim_frames, decimation, baro_lag_s):
    """Fused one-call frames, the step-by-step kernels and the numpy IRA collection give the same run."""
    from trn_env.navigators import registry

    dem, e0, frames = sim_frames
    navs = [registry.create("ins_tercom", dem=dem, ira_decimation=decimation, baro_lag_s=baro_lag_s)
            for _ in range(3)]
    navs[1].fused = False                                 # step by step, kernel IRA collection
    navs[2].fused = False
    navs[2]._collect = navs[2]._collect_general          # the numpy path the kernel replaced
    ests = [[], [], []]
    for nav, out in zip(navs, ests, strict=True):
        nav.reset(e0)
        for fr in frames:
            out.append(nav.update(fr))
    assert len(navs[0].fixes) >= 1
    for other in (1, 2):
        assert [(f.valid, f.dn_m, f.de_m, f.n_samples) for f in navs[0].fixes] == \
            [(f.valid, f.dn_m, f.de_m, f.n_samples) for f in navs[other].fixes]
        for a, b in zip(ests[0], ests[other], strict=True):
            assert abs(a.lat_rad - b.lat_rad) < 1e-12 and abs(a.lon_rad - b.lon_rad) < 1e-12
            assert abs(a.h_m - b.h_m) < 1e-6 and abs(a.yaw_rad - b.yaw_rad) < 1e-12
            assert np.allclose(a.covariance, b.covariance, rtol=1e-9, atol=1e-12)
        assert navs[0].health.skipped == navs[other].health.skipped
    assert navs[0].health.skipped.get("altimeter_no_return", 0) > 0
    assert navs[0].health.skipped.get("baro_invalid", 0) == 1


@pytest.mark.parametrize("threads, block", [(1, 1), (2, 1), (1, 8), (2, 256)])
@pytest.mark.parametrize("remove_bias", [False, True])
@pytest.mark.parametrize("where", ["inside", "south_edge", "void"])
def test_accumulated_surface_is_bit_identical_to_the_reference(dem, remove_bias, where, threads, block,
                                                               monkeypatch):
    """The batch's surface summed group by group as samples come (uneven groups, NaN samples dropped, one
    sample off the map's edge or a void near the track; summed at every group, in blocks of >= 8 samples
    with the rest at the fix, or all at the fix: SUM_BLOCK_SAMPLES) equals the per-lookup reference on the
    same samples with the same radii, and correlate() with the accumulator gives the fix correlate()
    computes itself."""
    from trn_env.navigators.tercom import mad
    from trn_env.navigators.tercom.mad import MadAccumulator, correlate

    monkeypatch.setattr(mad, "SUM_BLOCK_SAMPLES", block)

    rng = np.random.default_rng(13)
    heights, lat0, lon0, dlat, dlon = dem.grid
    lat_min, lat_max, lon_min, lon_max = dem.bounds
    mid = (0.5 * (lat_min + lat_max), 0.5 * (lon_min + lon_max))
    grid = dem.grid
    if where == "inside":
        lat, lon, hm, _, _ = _batch(dem, rng, 61, mid[0], mid[1], 1500.0)
    elif where == "south_edge":
        lat, lon, hm, _, _ = _batch(dem, rng, 61, lat_min + 60.0 / 6.37e6, mid[1], 30.0)
    else:
        heights = heights.copy()
        i = int(round((mid[0] - lat0) / dlat))
        j = int(round((mid[1] - lon0) / dlon))
        heights[i, j] = np.nan
        grid = (heights, lat0, lon0, dlat, dlon)
        lat, lon, hm, _, _ = _batch(dem, rng, 61, lat0 + i * dlat + 150.0 / 6.37e6, lon0 + j * dlon, 30.0)
    spread = 300.0 if where == "inside" else 20.0           # closest-point offsets (IRA), m
    dn = rng.uniform(-spread, spread, lat.size)
    de = rng.uniform(-spread, spread, lat.size)
    hm[[4, 30]] = np.nan                                     # dropped, as correlate() drops them
    half = 12
    acc = MadAccumulator(grid, half, 5.0, remove_bias, float(lat[0]))
    for a, b in ((0, 1), (1, 9), (9, 10), (10, 33), (33, 61)):
        acc.add(lat[a:b], lon[a:b], hm[a:b], dn[a:b], de[a:b])
    ok = np.isfinite(hm)
    lat_k = lat[ok] + dn[ok] / acc.r_ns
    lon_k = lon[ok] + de[ok] / acc.r_ew
    ref = mad_surface_reference(map_record(grid, False), lat_k, lon_k, hm[ok], acc.dlat_cell,
                                acc.dlon_cell, half, remove_bias)
    surf = acc.surface(threads=threads)
    assert acc.void_free is (where != "void")                # the void makes it fall back
    assert np.array_equal(surf, ref)
    if where != "inside":
        assert np.isinf(ref).any() and np.isfinite(ref).any()
    own = correlate(grid, 1.0, lat, lon, hm, dn, de, half=half, remove_bias=remove_bias, lat_ref_rad=lat[0])
    given = correlate(grid, 1.0, lat, lon, hm, dn, de, half=half, remove_bias=remove_bias, lat_ref_rad=lat[0],
                      accumulator=acc)
    assert np.array_equal(own.surface_m, given.surface_m) and (own.dn_m, own.de_m) == (given.dn_m, given.de_m)
    with pytest.raises(ValueError, match="accumulator"):
        correlate(grid, 1.0, lat[:-1], lon[:-1], hm[:-1], dn[:-1], de[:-1], half=half,
                  remove_bias=remove_bias, lat_ref_rad=lat[0], accumulator=acc)
