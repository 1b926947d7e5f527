"""The fast tier's batch TERCOM fix covariance (trn_env.env.fast.fix_noise, a numba kernel) against the full
navigator's (navigators.tercom.fix_noise.lad_fix_covariance, numpy) on the same batches.

Two independent implementations of one model: a smooth synthetic map (sums of sinusoids, 30 m posts) and a
real one (the basin scenario's map), batches of 40 samples at 1 Hz along straight and curved INS tracks
(the fast tier's profile), measured heights = the map at the true positions + white noise, residuals
mean-removed or median-centred, with and without the unresolved-terrain term. The kernel is given the
reference's metres per radian at the batch's mean latitude; the reference converts each sample's slope at
that sample's own latitude (terrain.Dem.gradient), which moves the east slope by tan(lat) x the batch's
latitude span (~5e-4 over 4 km at 36 deg). So the two must agree within RTOL = 2e-3 relative per element
of the 2 x 2 covariance (scaled by its largest diagonal) over every batch (measured: 3e-4 to 6e-4).
A flat map gives no information in both.
"""

import math

import numpy as np
import pytest
from synthetic_terrain import wave_map
from trn_env.navigators.tercom.fix_noise import lad_fix_covariance as full_cov
from trn_env.terrain.dem import Dem
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

from trn_env.env.fast.fix_noise import NO_INFORMATION_VAR_M2
from trn_env.env.fast.fix_noise import lad_fix_covariance as fast_cov

M = 40
RTOL = 2e-3


def _map(flat: bool = False) -> Dem:
    return wave_map(7, flat)


def _batches(dem: Dem, n_batches: int, seed: int):
    """(lat_ins, lon_ins, h_meas, dn_fix, de_fix) per batch: 1 Hz samples at 80-120 m/s, straight or turning,
    INS offset by a random shift, the fix's correction near minus that shift."""
    rng = np.random.default_rng(seed)
    lat_a, lat_b = dem.lat0_rad, dem.lat0_rad + (dem.n_lat - 1) * dem.dlat_rad
    lon_a, lon_b = dem.lon0_rad, dem.lon0_rad + (dem.n_lon - 1) * dem.dlon_rad
    out = []
    for _ in range(n_batches):
        lat_c = 0.5 * (lat_a + lat_b)
        r_n = meridian_radius_m(lat_c)
        r_e = prime_vertical_radius_m(lat_c) * math.cos(lat_c)
        span_n, span_e = (lat_b - lat_a) * r_n, (lon_b - lon_a) * r_e
        n0, e0 = rng.uniform(0.3, 0.7) * span_n, rng.uniform(0.3, 0.7) * span_e
        psi = rng.uniform(0, 2 * math.pi) + np.cumsum(np.full(M, rng.choice([0.0, 0.03])))
        v = rng.uniform(80.0, 120.0)
        n_true = n0 + np.cumsum(v * np.cos(psi))
        e_true = e0 + np.cumsum(v * np.sin(psi))
        shift = rng.normal(0.0, 40.0, 2)
        noise_m = rng.uniform(1.0, 20.0)
        h = dem.height(lat_a + n_true / r_n, lon_a + e_true / r_e) + rng.normal(0.0, noise_m, M)
        lat_ins = lat_a + (n_true + shift[0]) / r_n
        lon_ins = lon_a + (e_true + shift[1]) / r_e
        fix = -shift + rng.normal(0.0, 5.0, 2)
        out.append((lat_ins, lon_ins, h, float(fix[0]), float(fix[1])))
    return out


def _fast(dem, lat, lon, h, dn, de, cell_m, remove_bias, sigma_t):
    lat_c = float(np.mean(lat))
    m_per_rad = (meridian_radius_m(lat_c), prime_vertical_radius_m(lat_c) * math.cos(lat_c))
    work = np.zeros((3, len(lat) + 2))
    c_nn, c_ne, c_ee = fast_cov((h, lat, lon), len(lat), dem.record(), dn, de, m_per_rad, cell_m,
                                remove_bias, sigma_t, work)
    return np.array([[c_nn, c_ne], [c_ne, c_ee]])


def _agree(dem, batches, remove_bias, sigma_t):
    worst = 0.0
    for lat, lon, h, dn, de in batches:
        zeros = np.zeros(len(lat))
        want = full_cov(dem, lat, lon, h, zeros, zeros, dn, de, 5.0, remove_bias, sigma_t)
        got = _fast(dem, lat, lon, h, dn, de, 5.0, remove_bias, sigma_t)
        assert want[0, 0] < NO_INFORMATION_VAR_M2          # an informative batch: the test resolves the model
        worst = max(worst, float(np.max(np.abs(got - want)) / max(want[0, 0], want[1, 1])))
    return worst


@pytest.mark.parametrize("remove_bias", [True, False])
@pytest.mark.parametrize("sigma_t", [0.0, 4.0])
def test_kernel_matches_full_navigator_on_a_synthetic_map(remove_bias, sigma_t):
    dem = _map()
    worst = _agree(dem, _batches(dem, 30, 3), remove_bias, sigma_t)
    print(f"\nworst relative difference {worst:.2e} over 30 batches")
    assert worst < RTOL


def test_kernel_matches_full_navigator_on_the_basin_map():
    from trn_env.navigators.measurements.ira_map_noise import interpolation_sigma_m

    from trn_env.scenario import build as components
    from trn_env.scenario.loading import load_scenario
    from trn_env.sim.closed_loop import spawn_rngs

    sc = load_scenario("basin_route")
    _, dem = components.build_terrain(sc, sc.extras, spawn_rngs(sc.seed)["map"])
    worst = _agree(dem, _batches(dem, 30, 5), True, interpolation_sigma_m(dem))
    print(f"\nbasin map: worst relative difference {worst:.2e} over 30 batches")
    assert worst < RTOL


def test_flat_map_gives_no_information_in_both():
    flat = _map(flat=True)
    lat, lon, h, dn, de = _batches(flat, 1, 1)[0]
    zeros = np.zeros(M)
    full = full_cov(flat, lat, lon, h * 0 + 401.0, zeros, zeros, dn, de, 5.0, True)
    fast = _fast(flat, lat, lon, h * 0 + 401.0, dn, de, 5.0, True, 0.0)
    assert np.all(np.diag(full) >= NO_INFORMATION_VAR_M2)
    assert np.all(np.diag(fast) >= NO_INFORMATION_VAR_M2)
