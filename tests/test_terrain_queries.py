"""Terrain queries against independent brute-force dense searches (tests/terrain_bruteforce.py: exact ECEF,
dense sampling) on a rough synthetic terrain and on the real jacksboro DEM."""

import numpy as np
import pytest
import terrain_bruteforce as bf

import terrain
from terrain import geodesy, queries, synthetic

HALF_BEAM = np.radians(15.0)
HALF_WINDOW = np.radians(40.0)


@pytest.fixture(scope="module")
def dems():
    rough = synthetic.generate(200, 200, 90.0, rms_height_m=150.0, correlation_length_m=800.0, hurst=0.6,
                               mean_height_m=600.0, seed=3, name="rough")
    return {"rough": rough, "jacksboro": terrain.load("jacksboro")}


# (north offset from centre m, east offset m, height above the highest post m, roll, pitch, yaw deg)
CASES = [
    (1200.0, -800.0, 600.0, 0.0, 0.0, 35.0),
    (-2500.0, 1500.0, 1500.0, 30.0, 10.0, 200.0),
    (900.0, 2500.0, 4600.0, -30.0, -5.0, 110.0),
]


def _state(dem, case):
    dn, de, dh, roll, pitch, yaw = case
    lat_c, lon_c = dem.center_rad
    lat, lon = dem.offset_to_latlon(lat_c, lon_c, dn, de)
    h = float(np.nanmax(dem.heights_m)) + dh
    C = geodesy.euler_to_C_bn(*np.radians([roll, pitch, yaw]))
    psi = np.radians(yaw)
    # 110 m/s along the heading, 20 m/s crosswind component, 3 m/s climb: velocity != body x axis
    v = np.array([110 * np.cos(psi) - 20 * np.sin(psi), 110 * np.sin(psi) + 20 * np.cos(psi), -3.0])
    return float(lat), float(lon), h, C, v


def _horizontal_m(lat1, lon1, lat2, lon2):
    return np.hypot((lat1 - lat2) * 6.3567e6, (lon1 - lon2) * 6.3567e6 * np.cos(lat1))


@pytest.mark.parametrize("case", range(len(CASES)))
@pytest.mark.parametrize("name", ["rough", "jacksboro"])
def test_radar_altimeter_matches_brute_force(dems, name, case):
    dem = dems[name]
    lat, lon, h, C, _ = _state(dem, CASES[case])
    got = queries.radar_altimeter_return(dem, lat, lon, h, C, HALF_BEAM, 8000.0)
    assert got.valid[0]
    agl = h - float(np.nanmin(dem.heights_m))
    inner = bf.radar_altimeter(dem, lat, lon, h, C, HALF_BEAM, 8000.0, search_half_m=min(6000.0, 1.3 * agl),
                               coarse_m=8.0)
    edge = bf.radar_altimeter_boundary(dem, lat, lon, h, C, HALF_BEAM, 8000.0)
    ref = edge if edge[0] < inner[0] else inner
    assert got.range_m[0] == pytest.approx(ref[0], abs=0.5)
    assert _horizontal_m(got.lat_rad[0], got.lon_rad[0], ref[1], ref[2]) < 0.5
    assert got.h_m[0] == pytest.approx(ref[3], abs=0.5)


@pytest.mark.parametrize("case", range(len(CASES)))
@pytest.mark.parametrize("name", ["rough", "jacksboro"])
def test_ira_matches_brute_force(dems, name, case):
    dem = dems[name]
    lat, lon, h, C, v = _state(dem, CASES[case])
    got = queries.ira_return(dem, lat, lon, h, v, C, HALF_WINDOW, 12000.0)
    assert got.valid[0]
    ref = bf.ira(dem, lat, lon, h, v, C, HALF_WINDOW, 12000.0, s_half_m=5000.0)
    assert got.range_m[0] == pytest.approx(ref[0], abs=0.5)
    assert _horizontal_m(got.lat_rad[0], got.lon_rad[0], ref[1], ref[2]) < 0.5
    assert got.h_m[0] == pytest.approx(ref[3], abs=0.5)
    # the returned point lies on the zero-Doppler plane and inside the look-angle window
    ned = queries.ned_of_points(lat, lon, h, got.lat_rad, got.lon_rad, got.h_m)[0]
    assert abs(ned @ v / np.linalg.norm(v)) < 0.05
    theta = queries.look_angle_rad(C, lat, lon, h, got)[0]
    assert abs(theta) <= HALF_WINDOW + 1e-9
    assert theta == pytest.approx(ref[4], abs=1e-3)


def test_ira_uses_velocity_not_body_axis(dems):
    """With a 20 m/s crosswind the zero-Doppler plane is not the body y-z plane: the point moves."""
    dem = dems["jacksboro"]
    lat, lon, h, C, v = _state(dem, CASES[1])
    along_body = C[:, 0] * np.linalg.norm(v)
    a = queries.ira_return(dem, lat, lon, h, v, C, HALF_WINDOW)
    b = queries.ira_return(dem, lat, lon, h, along_body, C, HALF_WINDOW)
    assert _horizontal_m(a.lat_rad[0], a.lon_rad[0], b.lat_rad[0], b.lon_rad[0]) > 5.0


def test_ray_cast_matches_dense_march(dems):
    dem = dems["rough"]
    lat, lon, h, C, _ = _state(dem, CASES[1])
    rng = np.random.default_rng(2)
    dirs = np.column_stack([rng.normal(0, 0.4, 6), rng.normal(0, 0.4, 6), np.ones(6)])
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    got = queries.ray_cast(dem, np.full(6, lat), np.full(6, lon), np.full(6, h), dirs, 20000.0)
    cen = bf.ned_to_ecef_matrix(lat, lon)
    t_ref = bf._first_hits(dem, bf.lla_to_ecef(lat, lon, h), dirs @ cen.T, 0.0, 6000.0, 1.0)
    assert got.valid.all()
    np.testing.assert_allclose(got.range_m, t_ref, atol=0.05)
    # the hit is on the surface
    np.testing.assert_allclose(got.h_m, dem.height(got.lat_rad, got.lon_rad), atol=1e-9)


def test_ray_cast_over_flat_ground_includes_earth_curvature():
    """Flat terrain at 0 m: a ray 1 deg below the horizon from 100 m hits where the curved Earth drops."""
    lat0 = np.radians(36.0)
    dem = synthetic.generate(400, 400, 90.0, rms_height_m=0.0, mean_height_m=0.0, seed=1, lat0_deg=36.0)
    lat, lon = dem.center_rad
    dep = np.radians(1.0)
    got = queries.ray_cast(dem, lat, lon, 100.0, np.array([np.cos(dep), 0.0, np.sin(dep)]), 20000.0)
    r_earth = geodesy.meridian_radius_m(lat0)
    # exact circle-line intersection in the meridian plane (sphere of the meridian radius)
    a = 1.0
    b = -2 * (r_earth + 100.0) * np.sin(dep)
    c = (r_earth + 100.0) ** 2 - r_earth ** 2
    t_exact = (-b - np.sqrt(b * b - 4 * a * c)) / (2 * a)
    flat = 100.0 / np.sin(dep)
    assert got.range_m[0] == pytest.approx(t_exact, abs=0.5)
    assert got.range_m[0] - flat > 20.0  # the curvature effect is large and present


def test_outside_grid_and_bad_arguments(dems):
    dem = dems["jacksboro"]
    C = np.eye(3)
    far = queries.radar_altimeter_return(dem, 0.1, 0.1, 1000.0, C, HALF_BEAM)
    assert not far.valid[0] and np.isnan(far.range_m[0])
    far = queries.ira_return(dem, 0.1, 0.1, 1000.0, np.array([100.0, 0, 0]), C, HALF_WINDOW)
    assert not far.valid[0] and np.isnan(far.lat_rad[0])
    with pytest.raises(ValueError, match="half_beamwidth_rad"):
        queries.radar_altimeter_return(dem, 0.6, -1.47, 1000.0, C, 2.0)
    with pytest.raises(ValueError, match="C_bn"):
        queries.radar_altimeter_return(dem, np.zeros(3), np.zeros(3), np.zeros(3), np.eye(2), HALF_BEAM)
    with pytest.raises(ValueError, match="v_ned"):
        queries.ira_return(dem, 0.6, -1.47, 1000.0, np.zeros(2), C, HALF_WINDOW)


def test_batch_equals_single_queries(dems):
    dem = dems["jacksboro"]
    states = [_state(dem, c) for c in CASES]
    lat = np.array([s[0] for s in states])
    lon = np.array([s[1] for s in states])
    h = np.array([s[2] for s in states])
    C = np.stack([s[3] for s in states])
    v = np.stack([s[4] for s in states])
    batch = queries.ira_return(dem, lat, lon, h, v, C, HALF_WINDOW)
    for k in range(3):
        one = queries.ira_return(dem, lat[k], lon[k], h[k], v[k], C[k], HALF_WINDOW)
        assert one.range_m[0] == batch.range_m[k]
