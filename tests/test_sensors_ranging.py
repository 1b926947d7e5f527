"""Radar altimeter and IRA against analytic flat-terrain answers and independent brute-force searches."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize_scalar
from test_sensors_common import chunks_of, straight_truth
from trn_env.terrain.dem import Dem

from trn_env.sensors.ira import IraConfig, look_angle_from_ranges, sample_ira
from trn_env.sensors.radar_altimeter import RadarAltimeterConfig, sample_radar_altimeter

A, E2 = 6378137.0, 6.69437999014e-3
LAT0, LON0 = np.deg2rad(33.0), np.deg2rad(-98.5)
POST_DEG = 1.0 / 3600.0                  # 1" posts (~31 m x 26 m)


# ------------------------------------------------------------------ independent geodesy (numpy, exact)
def lla_to_ecef(lat, lon, h):
    n = A / np.sqrt(1 - E2 * np.sin(lat) ** 2)
    return np.stack([(n + h) * np.cos(lat) * np.cos(lon), (n + h) * np.cos(lat) * np.sin(lon),
                     (n * (1 - E2) + h) * np.sin(lat)], axis=-1)


def ecef_to_lla(x):
    lon = np.arctan2(x[..., 1], x[..., 0])
    p = np.hypot(x[..., 0], x[..., 1])
    lat = np.arctan2(x[..., 2], p * (1 - E2))
    for _ in range(6):
        n = A / np.sqrt(1 - E2 * np.sin(lat) ** 2)
        h = p / np.cos(lat) - n
        lat = np.arctan2(x[..., 2], p * (1 - E2 * n / (n + h)))
    n = A / np.sqrt(1 - E2 * np.sin(lat) ** 2)
    return lat, lon, p / np.cos(lat) - n


def C_ne(lat, lon):
    """NED -> ECEF rotation (columns N, E, D)."""
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    return np.array([[-sl * co, -so, -cl * co], [-sl * so, co, -cl * so], [cl, 0.0, -sl]])


def ned_of(lat_a, lon_a, h_a, lat, lon, h):
    return (lla_to_ecef(lat, lon, h) - lla_to_ecef(lat_a, lon_a, h_a)) @ C_ne(lat_a, lon_a)


def geo_of_ned(lat_a, lon_a, h_a, x_ned):
    return ecef_to_lla(lla_to_ecef(lat_a, lon_a, h_a) + x_ned @ C_ne(lat_a, lon_a).T)


# ------------------------------------------------------------------ terrains
def rough_dem(seed=0, n=500):
    rng = np.random.default_rng(seed)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    hills = 300 + 120 * np.sin(i / 37.0) * np.cos(j / 23.0) + 60 * np.sin((i + 2 * j) / 11.0)
    heights = hills + rng.normal(0.0, 15.0, (n, n))            # rough: 15 m post-to-post noise
    d = np.deg2rad(POST_DEG)
    return Dem(heights, LAT0 - 0.5 * n * d, LON0 - 0.5 * n * d, d, d, name="rough")


def flat_dem(h_m=200.0, n=400):
    d = np.deg2rad(POST_DEG)
    return Dem(np.full((n, n), h_m), LAT0 - 0.5 * n * d, LON0 - 0.5 * n * d, d, d, name="flat")


def truth_at(n, h_m, **kw):
    return straight_truth(n, lat0_deg=np.rad2deg(LAT0), lon0_deg=np.rad2deg(LON0), h_m=h_m, **kw)


# ------------------------------------------------------------------ radar altimeter
@pytest.mark.parametrize("beam_deg, roll_deg, pitch_deg", [
    (17.0, 0.0, 0.0), (17.0, 5.0, 3.0), (17.0, 20.0, 0.0), (35.0, 25.0, -4.0), (35.0, 10.0, 10.0)])
def test_radar_altimeter_flat_terrain_analytic(beam_deg, roll_deg, pitch_deg):
    truth = truth_at(50, 1200.0, roll_deg=roll_deg, pitch_deg=pitch_deg)
    cfg = RadarAltimeterConfig.noise_free(beamwidth_deg=beam_deg)
    frame, _ = sample_radar_altimeter(truth, flat_dem(), np.random.default_rng(0), cfg)
    assert frame.valid.all() and frame.t_s.shape[0] == 10
    # angle between the body down axis and the local vertical
    tilt = np.arccos(np.cos(np.deg2rad(roll_deg)) * np.cos(np.deg2rad(pitch_deg)))
    expected = 1000.0 / np.cos(max(0.0, tilt - np.deg2rad(beam_deg / 2)))
    np.testing.assert_allclose(frame.range_m, expected, atol=0.05)


def test_radar_altimeter_brute_force_rough_terrain():
    dem = rough_dem(1)
    truth = truth_at(100, 1300.0, roll_deg=12.0, pitch_deg=4.0, yaw_deg=70.0, track_deg=60.0,
                     wind_ned_mps=(0.0, -20.0, 0.0))
    cfg = RadarAltimeterConfig.noise_free(beamwidth_deg=17.0, rate_hz=10.0)
    frame, _ = sample_radar_altimeter(truth, dem, np.random.default_rng(0), cfg)
    half = np.deg2rad(8.5)
    for k in range(0, frame.t_s.shape[0], 3):
        j = int(round(frame.t_s[k] / 0.01))
        la, lo, ha = truth.lat_rad[j], truth.lon_rad[j], truth.h_msl_m[j]
        axis = truth.C_bn[j][:, 2]

        def ranges(lat, lon, la=la, lo=lo, ha=ha, axis=axis):
            x = ned_of(la, lo, ha, lat, lon, dem.height(lat, lon))
            r = np.linalg.norm(x, axis=-1)
            inside = x @ axis >= r * np.cos(half)
            return np.where(inside, r, np.inf)

        step = np.deg2rad(1.0 / 3600 / 30)          # ~1 m
        span = 400 * step
        g = np.arange(-span, span, step)
        lat, lon = np.meshgrid(la + g, lo + g, indexing="ij")
        r = ranges(lat, lon)
        best = np.argsort(r, axis=None)[:20]
        fine = []
        for b in best:                              # refine every near-best cell at ~0.1 m
            f = np.arange(-2.5, 2.5, 0.1) * step
            la2, lo2 = np.meshgrid(lat.flat[b] + f, lon.flat[b] + f, indexing="ij")
            fine.append(ranges(la2, lo2).min())
        brute = min(fine)
        assert frame.valid[k]
        assert frame.range_m[k] <= brute + 0.02
        assert frame.range_m[k] >= brute - 0.5
        # on rough terrain the first return is shorter than the plumb-bob height above the nadir point
        assert frame.range_m[k] < ha - dem.height(la, lo) + 1e-6


def test_radar_altimeter_noise_max_range_lever_arm():
    dem = flat_dem(200.0)
    truth = truth_at(20000, 1200.0, pitch_deg=0.0, speed_mps=20.0)
    frame, _ = sample_radar_altimeter(truth, dem, np.random.default_rng(1), RadarAltimeterConfig())
    assert frame.t_s.shape[0] == 4000
    assert abs(frame.range_m.std() / (0.6 + 0.02 * 1000.0) - 1) < 0.05
    assert abs(frame.range_m.mean() - 1000.0) < 1.5
    high = truth_at(10, 6000.0)
    f2, _ = sample_radar_altimeter(high, dem, np.random.default_rng(1),
                                   RadarAltimeterConfig(max_range_m=5000.0))
    assert not f2.valid.any() and np.isnan(f2.range_m).all()
    f3, _ = sample_radar_altimeter(truth.slice(0, 10), dem, np.random.default_rng(1),
                                   RadarAltimeterConfig.noise_free(lever_arm_b_m=(3.0, 1.0, 2.0)))
    np.testing.assert_allclose(f3.range_m, 998.0, atol=0.02)


@pytest.mark.parametrize("field, value", [
    ("beamwidth_deg", 0.0), ("beamwidth_deg", 90.0), ("beamwidth_deg", -5.0), ("rate_hz", -1.0),
    ("noise_fraction", -0.1), ("max_range_m", 0.0), ("lever_arm_b_m", (1.0, 2.0))])
def test_radar_altimeter_bad_config(field, value):
    with pytest.raises(ValueError, match=field):
        RadarAltimeterConfig(**{field: value})


# ------------------------------------------------------------------ IRA
def reconstruct_point(r, theta, v_ned, C_bn):
    """Closest point (NED from the antenna) from R and theta by the exact geometry, solved independently:
    unit u with u . v = 0 (zero-Doppler plane), u . y_b = sin(theta) (interferometric look angle: the range
    difference of antennas on the body lateral axis), |u| = 1, pointing downward."""
    v = v_ned / np.linalg.norm(v_ned)
    y = C_bn[:, 1]
    y_perp = y - (y @ v) * v
    e1 = y_perp / np.linalg.norm(y_perp)
    e2 = np.cross(v, e1)
    c1 = np.sin(theta) / np.linalg.norm(y_perp)
    c2 = np.sqrt(1 - c1 * c1)
    u = c1 * e1 + c2 * e2
    if u[2] < 0:
        u = c1 * e1 - c2 * e2
    return r * u


def brute_force_zero_doppler(dem, la, lo, ha, v_ned, C_bn, half_window):
    """Closest terrain point on the zero-Doppler curve by a dense 1-D search along it (independent)."""
    v = v_ned / np.linalg.norm(v_ned)
    down = np.array([0.0, 0.0, 1.0])
    e1 = down - (down @ v) * v
    e1 /= np.linalg.norm(e1)                  # in-plane, most downward
    e2 = np.cross(v, e1)                      # in-plane, horizontal

    def point(a):
        a = np.atleast_1d(a)
        b = np.full(a.shape, ha - 300.0)
        for _ in range(10):                   # slide along e1 until the point lies on the terrain
            x = a[:, None] * e2 + b[:, None] * e1
            lat, lon, h = geo_of_ned(la, lo, ha, x)
            b = b + (h - dem.height(lat, lon)) / e1[2]
        x = a[:, None] * e2 + b[:, None] * e1
        xb = x @ C_bn
        ok = np.abs(np.arctan2(xb[:, 1], xb[:, 2])) <= half_window
        return x, np.where(ok, np.linalg.norm(x, axis=1), np.inf)

    a = np.arange(-1500.0, 1500.0, 0.5)
    _, r = point(a)
    minima = []
    local = np.flatnonzero((r[1:-1] <= r[:-2]) & (r[1:-1] <= r[2:])) + 1     # local minima of the scan
    for i in local[np.argsort(r[local])[:6]]:
        res = minimize_scalar(lambda s: point(s)[1][0], bounds=(a[i] - 0.5, a[i] + 0.5), method="bounded",
                              options={"xatol": 1e-6})
        minima.append((float(res.fun), point(res.x)[0][0]))
    return sorted(minima, key=lambda m: m[0])


def _crosswind_truth():
    # 20 m/s crosswind from the left: the aircraft crabs 11 deg, velocity is not along body x
    truth = truth_at(200, 1400.0, speed_mps=100.0, track_deg=20.0, yaw_deg=31.5, roll_deg=10.0,
                     pitch_deg=5.0, wind_ned_mps=(0.0, 20.0 * np.cos(np.deg2rad(20.0)), 0.0))
    truth.v_ned_mps[:, 2] = -3.0              # climbing: the zero-Doppler plane is not vertical
    return truth


def test_ira_r_theta_reconstruct_the_returned_closest_point():
    # the sensor's (R, theta) fed back through the exact geometry land on the terrain query's closest point
    from trn_env.terrain import queries

    dem, truth = rough_dem(2), _crosswind_truth()
    frame, _ = sample_ira(truth, dem, np.random.default_rng(0), IraConfig.noise_free(half_window_deg=50.0))
    assert frame.t_s.shape[0] == 100 and frame.valid.all()
    j = np.round(frame.t_s / 0.01).astype(int)
    ret = queries.ira_return(dem, truth.lat_rad[j], truth.lon_rad[j], truth.h_msl_m[j], truth.v_ned_mps[j],
                             truth.C_bn[j], np.deg2rad(50.0), 10000.0)
    for k in range(100):
        jk = j[k]
        p = reconstruct_point(frame.range_m[k], frame.look_angle_rad[k], truth.v_ned_mps[jk], truth.C_bn[jk])
        q = ned_of(truth.lat_rad[jk], truth.lon_rad[jk], truth.h_msl_m[jk], ret.lat_rad[k], ret.lon_rad[k],
                   ret.h_m[k])
        assert np.linalg.norm(p - q) < 0.05
    assert np.ptp(frame.look_angle_rad) > np.deg2rad(2.0)   # the closest point wanders across track


def test_ira_closest_point_matches_brute_force_rough_terrain():
    dem, truth = rough_dem(2), _crosswind_truth()
    frame, _ = sample_ira(truth, dem, np.random.default_rng(0), IraConfig.noise_free(half_window_deg=50.0))
    for k in range(0, 100, 3):
        j = int(round(frame.t_s[k] / 0.01))
        la, lo, ha = truth.lat_rad[j], truth.lon_rad[j], truth.h_msl_m[j]
        v, C = truth.v_ned_mps[j], truth.C_bn[j]
        p = reconstruct_point(frame.range_m[k], frame.look_angle_rad[k], v, C)
        minima = brute_force_zero_doppler(dem, la, lo, ha, v, C, np.deg2rad(50.0))
        r_bf = minima[0][0]
        assert abs(frame.range_m[k] - r_bf) < 0.1, (k, frame.range_m[k], r_bf)
        # the point must be the closest one; where two points tie within 10 cm of range, either will do
        ties = [x for r, x in minima if r < r_bf + 0.1]
        assert min(np.linalg.norm(p - x) for x in ties) < 0.5, (k, p, ties)


@pytest.mark.parametrize("roll_deg, pitch_deg, yaw_offset_deg", [(0.0, 0.0, 0.0), (15.0, 4.0, 0.0),
                                                                  (-20.0, 2.0, 11.0)])
def test_ira_flat_terrain_analytic(roll_deg, pitch_deg, yaw_offset_deg):
    # over flat terrain in level flight the closest zero-Doppler point is the nadir: R = height and
    # sin(theta) = nadir's body-y component = sin(roll) cos(pitch), whatever the crab angle
    truth = truth_at(20, 1200.0, roll_deg=roll_deg, pitch_deg=pitch_deg, yaw_deg=30.0 + yaw_offset_deg)
    for method in ("range_difference", "exact"):
        frame, _ = sample_ira(truth, flat_dem(), np.random.default_rng(0),
                              IraConfig.noise_free(look_angle_method=method))
        np.testing.assert_allclose(frame.range_m, 1000.0, atol=0.05)
        expected = np.arcsin(np.sin(np.deg2rad(roll_deg)) * np.cos(np.deg2rad(pitch_deg)))
        np.testing.assert_allclose(frame.look_angle_rad, expected, atol=2e-5)


def test_ira_sign_right_antenna_closer_gives_positive_theta():
    # terrain rising to the east under a north-bound aircraft: the closest point lies toward the right wing
    n = 400
    d = np.deg2rad(POST_DEG)
    east = np.arange(n) * 26.0
    dem = Dem(np.tile(200.0 + 0.3 * east, (n, 1)), LAT0 - 0.5 * n * d, LON0 - 0.5 * n * d, d, d)
    truth = truth_at(10, 2000.0, track_deg=0.0, roll_deg=0.0, pitch_deg=0.0)
    frame, _ = sample_ira(truth, dem, np.random.default_rng(0), IraConfig.noise_free())
    assert np.all(frame.look_angle_rad > np.deg2rad(10.0))
    # against a plane sloping up at angle s, the foot of the perpendicular is at theta = s
    np.testing.assert_allclose(frame.look_angle_rad, np.arctan(0.3), atol=2e-3)


def test_look_angle_methods_agree_with_geometry():
    rng = np.random.default_rng(4)
    for _ in range(50):
        r = rng.uniform(300, 8000)
        th = rng.uniform(-0.8, 0.8)
        l1, l2 = rng.uniform(0.1, 0.5, 2)
        p = r * np.array([0.0, np.sin(th), np.cos(th)])        # body frame, point in the y-z plane
        r_l = np.linalg.norm(p - [0.0, -l1, 0.0])
        r_r = np.linalg.norm(p - [0.0, l2, 0.0])
        exact = look_angle_from_ranges(r, r_l, r_r, l1, l2, "exact")[0]
        approx = look_angle_from_ranges(r, r_l, r_r, l1, l2, "range_difference")[0]
        assert abs(exact - th) < 1e-9
        # eqs 18 + 19: residual (L1 - L2) cos^2(theta) / (2 R) in sin(theta)
        assert abs(approx - th) < abs(l1 - l2) / (2 * r) / np.cos(th) + 1e-9


def test_ira_noise_rate_chunking():
    dem = flat_dem()
    truth = truth_at(20000, 1200.0, roll_deg=5.0, speed_mps=20.0)
    cfg = IraConfig()
    one, _ = sample_ira(truth, dem, np.random.default_rng(9), cfg)
    assert one.t_s.shape[0] == 10000 and np.allclose(np.diff(one.t_s), 0.02)
    assert abs(one.range_m.std() / 3.5 - 1) < 0.05
    theta_true = np.arcsin(np.sin(np.deg2rad(5.0)) * np.cos(np.deg2rad(2.0)))
    theta_err_deg = np.rad2deg(one.look_angle_rad - theta_true)
    assert abs(theta_err_deg.std() / 0.1 - 1) < 0.05 and abs(theta_err_deg.mean()) < 0.005
    rng, state, parts = np.random.default_rng(9), None, []
    for c in chunks_of(truth.slice(0, 1000), [3, 1, 250, 101]):
        f, state = sample_ira(c, dem, rng, cfg, state)
        parts.append(f.range_m)
    np.testing.assert_array_equal(np.concatenate(parts), one.range_m[:500])


def test_ira_chunks_on_rough_terrain_search_as_one_call():
    # each search starts from the previous return (IraState carries it across chunks): chunked sampling
    # gives the one-call bits, and the carried point is the last return
    dem, truth = rough_dem(2), _crosswind_truth()
    cfg = IraConfig()
    one, end = sample_ira(truth, dem, np.random.default_rng(3), cfg)
    rng, state, parts = np.random.default_rng(3), None, []
    for c in chunks_of(truth, [3, 1, 60, 1, 77]):
        f, state = sample_ira(c, dem, rng, cfg, state)
        parts.append(f)
    for name in ("t_s", "range_m", "look_angle_rad", "valid"):
        np.testing.assert_array_equal(np.concatenate([getattr(f, name) for f in parts]), getattr(one, name))
    assert state == end and np.isfinite(end.last_return_rad).all()


@pytest.mark.parametrize("field, value", [("baseline_left_m", 0.0), ("baseline_right_m", -0.2),
                                          ("half_window_deg", 0.0), ("half_window_deg", 90.0),
                                          ("range_noise_m", -1.0), ("look_angle_noise_deg", -0.1),
                                          ("rate_hz", 0.0), ("look_angle_method", "phase")])
def test_ira_bad_config(field, value):
    with pytest.raises(ValueError, match=field):
        IraConfig(**{field: value})


def test_ira_lever_arm_moves_the_centre_antenna():
    truth = truth_at(10, 1200.0, roll_deg=0.0, pitch_deg=0.0)
    frame, _ = sample_ira(truth, flat_dem(), np.random.default_rng(0),
                          IraConfig.noise_free(lever_arm_b_m=(2.0, 1.5, 3.0)))
    np.testing.assert_allclose(frame.range_m, 997.0, atol=0.02)
    np.testing.assert_allclose(frame.look_angle_rad, 0.0, atol=1e-6)
