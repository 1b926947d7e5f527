"""The parts of the RBPF, each against an independent computation:

- the time update's fast path for the constant bias states (unit rows of the transition) against eqs 5-8
  and 13-15 written out in numpy;
- the GNSS position update of the cloud (square-root update) against a Kalman filter on the cloud's
  moments, with the receiver-drift floor;
- the map noise model: the coarse map's interpolation sigma from its spectrum against the height error
  measured between the 3" map and a 30 m refinement of it, and the calibrated range and look-angle
  variances (map_noise_calibration, on other refinements) against their errors measured between the two
  maps at random states;
- on a 3" map against the 30 m world, GNSS then denied, the RBPF's horizontal NEES lies inside the
  two-sided 95 % chi-square bounds computed here, as with map = world.
"""

import math

import numpy as np
import pytest
from scipy.stats import chi2
from trn_env.navigators.filters import _rbpf_kernels as kern
from trn_env.navigators.filters.rbpf import RaoBlackwellizedPF
from trn_env.navigators.measurements import ira_seed002 as ira_model
from trn_env.terrain.geodesy import euler_to_C_bn

from trn_env import terrain


@pytest.fixture(scope="module")
def dem():
    return terrain.load("jacksboro")


def _reference_time_update(xn, xl, P, Phi, qn, ql, w):
    """Seed 002 eqs 5-8, 13-15 in numpy, one particle at a time."""
    A, B = Phi[:3, :3], Phi[:3, 3:]
    Cm, D = Phi[3:, :3], Phi[3:, 3:]
    out = []
    for k in range(xn.shape[0]):
        N = B @ P[k] @ B.T + np.diag(qn)                                   # eq 13
        mean = A @ xn[k] + B @ xl[k]
        x_new = mean + np.linalg.cholesky(N) @ w[k]                       # eq 5
        L = D @ P[k] @ B.T @ np.linalg.inv(N)                             # eq 14
        z = x_new - A @ xn[k]                                             # eq 15
        xl_new = Cm @ xn[k] + D @ xl[k] + L @ (z - B @ xl[k])             # eq 6
        P_new = D @ P[k] @ D.T + np.diag(ql) - L @ N @ L.T                # eq 7
        out.append((x_new, xl_new, P_new))
    return out


def test_time_update_with_constant_biases_matches_eqs_5_to_15():
    """A transition whose bias rows are unit rows (eq 18: the biases are constant) takes the kernel's fast
    path; it must equal the equations written out."""
    rng = np.random.default_rng(4)
    Phi = np.eye(15) + 0.05 * rng.standard_normal((15, 15))
    Phi[9:] = np.eye(15)[9:]                                              # accelerometer and gyro biases
    n = 5
    xn = rng.standard_normal((n, 3))
    xl = rng.standard_normal((n, 12))
    G = rng.standard_normal((n, 12, 12))
    P = np.einsum("kij,klj->kil", G, G) + np.eye(12)
    qn, ql = rng.uniform(0.2, 1.0, 3), rng.uniform(0.01, 0.1, 12)
    w = rng.standard_normal((n, 3))
    ref = _reference_time_update(xn, xl, P, Phi, qn, ql, w)
    bad = kern.time_update(xn, xl, P, Phi, qn, ql, w)
    assert bad == 0
    for k, (x_new, xl_new, P_new) in enumerate(ref):
        assert np.allclose(xn[k], x_new, atol=1e-10)
        assert np.allclose(xl[k], xl_new, atol=1e-10)
        assert np.allclose(P[k], P_new, atol=1e-9)


def test_gnss_position_moves_the_cloud_to_the_kalman_posterior(dem):
    """A 50 m cloud and one GNSS fix: the weighted cloud's mean and covariance equal the Kalman update of
    the cloud's own moments with R = white + drift (computed here); weights are untouched; repeated fixes
    never take the cloud below the receiver's drift."""
    nav = RaoBlackwellizedPF(dem=dem, rng=np.random.default_rng(3), n_particles=2000,
                             terrain_model_sigma_m=0.0)
    nav._init_cloud()
    nav.logw = np.log(np.random.default_rng(5).uniform(0.5, 1.5, nav.n))
    nav.logw -= np.log(np.exp(nav.logw).sum())
    w = nav._weights()
    m = w @ nav.xn
    d = nav.xn - m
    Pc = (d * w[:, None]).T @ d
    R = np.diag(nav.gnss_pos_var + nav.gnss_bias_var)
    y = np.array([30.0, -20.0, 5.0])
    K = Pc @ np.linalg.inv(Pc + R)
    m_kf, P_kf = m + K @ (y - m), (np.eye(3) - K) @ Pc
    logw0 = nav.logw.copy()
    nav._gnss_cloud_update(y)
    m2 = w @ nav.xn
    d2 = nav.xn - m2
    P2 = (d2 * w[:, None]).T @ d2
    assert np.array_equal(nav.logw, logw0)
    assert np.allclose(m2, m_kf, atol=1e-6)
    assert np.allclose(np.diag(P2), np.maximum(np.diag(P_kf), nav.gnss_bias_var), rtol=1e-6)
    for _ in range(30):
        nav._gnss_cloud_update(y)
    d3 = nav.xn - w @ nav.xn
    sd = np.sqrt(np.diag((d3 * w[:, None]).T @ d3))
    assert np.all(sd >= np.sqrt(nav.gnss_bias_var) * (1 - 1e-6)), sd
    assert np.allclose(w @ nav.xn, y, atol=0.5)


@pytest.fixture(scope="module")
def map_and_world(dem):
    from trn_env.terrain.refine import refine

    lat0, lon0 = math.radians(36.50), math.radians(-84.36)
    region = (lat0, lat0 + 0.09 / 57.2958, lon0, lon0 + 0.11 / 57.2958)
    return dem, refine(dem, spacing_m=30.0, seed=0, region=region), region


def test_interpolation_sigma_matches_the_map_against_a_finer_world(map_and_world):
    """The 3" map's unresolved height sigma (from its spectrum) against the RMS of world - map at random
    points of a 30 m refinement (detail down to 30 m; the spectrum's tail beyond adds ~0.7 m in quadrature):
    within 35 %."""
    dem, world, (la0, la1, lo0, lo1) = map_and_world
    sig = ira_model.interpolation_sigma_m(dem)
    rng = np.random.default_rng(0)
    lat = rng.uniform(la0 + 1e-4, la1 - 1e-4, 4000)
    lon = rng.uniform(lo0 + 1e-4, lo1 - 1e-4, 4000)
    diff = world.height(lat, lon) - dem.height(lat, lon)
    measured = float(np.sqrt(np.nanmean(diff ** 2)))
    assert 2.0 < sig < 4.0, sig
    assert abs(sig - measured) < 0.35 * measured, (sig, measured)


def _map_against_world(dem, world, region, n_states: int, seed: int, agl_m: float = 1500.0) -> np.ndarray:
    """At n_states random states agl_m above the region (random heading, small bank): per state with a
    return on both, (theta world - map, R world - map, map's runner-up gap R2 - R, map's R, theta world -
    map's runner-up theta) - eqs 23/26 evaluated on the world and on the map."""
    la0, la1, lo0, lo1 = region
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(n_states):
        lat = rng.uniform(la0 + 0.2 * (la1 - la0), la1 - 0.2 * (la1 - la0))
        lon = rng.uniform(lo0 + 0.2 * (lo1 - lo0), lo1 - 0.2 * (lo1 - lo0))
        h = float(dem.height(lat, lon)) + agl_m
        yaw = rng.uniform(0, 2 * math.pi)
        v = 85.0 * np.array([math.cos(yaw), math.sin(yaw), 0.0])
        C = euler_to_C_bn(rng.normal(0, 0.05), 0.04, yaw)
        a = ira_model.predict_ira(world, [lat], [lon], [h], v, C)[0]
        b = ira_model.predict_ira(dem, [lat], [lon], [h], v, C)[0]
        if a[ira_model.OUT_VALID] and b[ira_model.OUT_VALID]:
            rows.append((a[ira_model.OUT_THETA] - b[ira_model.OUT_THETA],
                         a[ira_model.OUT_R] - b[ira_model.OUT_R],
                         b[ira_model.OUT_R2] - b[ira_model.OUT_R], b[ira_model.OUT_R],
                         a[ira_model.OUT_THETA] - b[ira_model.OUT_THETA2]))
    return np.array(rows)


@pytest.fixture(scope="module")
def map_world_states(map_and_world):
    dem, world, region = map_and_world
    return _map_against_world(dem, world, region, 600, seed=1)


def _jump_probabilities(dem, gaps: np.ndarray) -> np.ndarray:
    """The RBPF's own basin-jump probability for a one-particle cloud with each map gap."""
    nav = RaoBlackwellizedPF(dem=dem, n_particles=2)
    one = np.ones(1, bool)
    return np.array([nav._basin_jump_probability(np.array([g]), one, np.ones(1)) for g in gaps])


def test_basin_jump_probability_is_calibrated(map_and_world, map_world_states):
    """The RBPF's probability that the map's closest point lies in another basin than the world's (from the
    map's runner-up gap and sigma_h, _basin_jump_probability) against what happens: at 600 random states, the
    states whose world look angle lies nearer the map's runner-up than the map's minimum. Their count over
    all states, and over the states the filter treats as safe (p <= 0.05, the default ambiguity_probability)
    and as ambiguous (p > 0.05), each lies within 3 sigma of the sum of the probabilities (a sum of
    independent Bernoullis: variance sum p (1 - p)). The counts: docs/validation/seed002.md (map noise)."""
    dem = map_and_world[0]
    A = map_world_states
    p = _jump_probabilities(dem, A[:, 2])
    jumped = np.isfinite(A[:, 4]) & (np.abs(A[:, 4]) < np.abs(A[:, 0]))
    assert A.shape[0] > 500 and 20 < jumped.sum() < 0.2 * A.shape[0]
    for sel in (np.ones(p.size, bool), p <= 0.05, p > 0.05):
        expected, var = float(p[sel].sum()), float(np.sum(p[sel] * (1 - p[sel])))
        assert abs(int(jumped[sel].sum()) - expected) <= 3.0 * math.sqrt(var) + 1.0, (
            int(jumped[sel].sum()), expected, var)
    # the jumps are what makes the look angle's map error heavy-tailed: they hold most of its > 3 deg errors
    big = np.abs(A[:, 0]) > math.radians(3.0)
    assert big.sum() >= 5 and (big & (p > 0.05)).sum() >= 0.6 * big.sum()
    # the map that is the world has no jumps: sigma_h = 0 gives probability 0
    nav = RaoBlackwellizedPF(dem=dem, n_particles=2, terrain_model_sigma_m=0.0)
    assert nav._basin_jump_probability(np.array([0.1]), np.ones(1, bool), np.ones(1)) == 0.0


def test_look_angle_map_noise_matches_map_against_world(map_and_world, map_world_states):
    """At the same states, the IRA's look angle on the map minus on the world where the filter takes it
    (basin- jump probability <= 0.05, and inside the filter's 3-sigma gate of the calibrated variance plus
    the sensor's): its RMS lies between 0.6 and 1.25 times the calibrated model's sqrt(f_theta sigma_h /
    3R) (map_noise_calibration over the map's centre, other realisations than this region's world, as the
    filter computes it), and over all of them (no gate) between 0.5 and 0.85 times the flat-ground model's;
    the range's standard deviation between 0.6 and 1.4 times the calibrated sqrt(f_R) sigma_h and between
    0.5 and 0.95 times sigma_h (the closest point is a minimum over the map's errors; the world's is also
    nearer on average, which the vertical state takes). The ratios these bands were set on:
    docs/validation/seed002.md (map noise)."""
    dem = map_and_world[0]
    A = map_world_states
    sig = ira_model.interpolation_sigma_m(dem)
    nav = RaoBlackwellizedPF(dem=dem, n_particles=2)
    p = _jump_probabilities(dem, A[:, 2])
    taken = p <= 0.05
    assert taken.sum() > 300
    s_r = float(np.std(A[:, 1]))
    cases = ((nav.terrain_factors(1500.0), nav.theta_gate_sigmas, 0.6, 1.25, 0.6, 1.4),
             ((1.0, 1.0), 0.0, 0.5, 0.85, 0.5, 0.95))
    for f, gate, lo_th, hi_th, lo_r, hi_r in cases:
        model = np.array([ira_model.map_noise_variances(0.0, sig, r, f) for r in A[:, 3]])
        keep = taken.copy()
        if gate > 0:
            keep &= A[:, 0] ** 2 <= gate ** 2 * (model[:, 1] + nav.r_var[1])
            assert keep.sum() > 0.95 * taken.sum()
        s_th = float(np.sqrt(np.mean(A[keep, 0] ** 2)))
        m_th = math.sqrt(np.mean(model[keep, 1]))
        m_r = math.sqrt(np.mean(model[:, 0]))
        assert lo_th < s_th / m_th < hi_th, (f, math.degrees(s_th), math.degrees(m_th))
        assert lo_r < s_r / m_r < hi_r, (f, s_r, m_r)


def _gated_look_angle_rms(dem, A: np.ndarray, nav, f: tuple[float, float],
                          gate: float) -> tuple[float, float]:
    """(RMS of the map's look-angle error, the model's RMS) over the states the filter takes it at (basin-
    jump probability <= 0.05, inside `gate` sigmas of the model's variance with factors f plus the
    sensor's), rad."""
    sig = ira_model.interpolation_sigma_m(dem)
    model = np.array([ira_model.map_noise_variances(0.0, sig, r, f) for r in A[:, 3]])
    keep = _jump_probabilities(dem, A[:, 2]) <= 0.05
    if gate > 0:
        keep &= A[:, 0] ** 2 <= gate ** 2 * (model[:, 1] + nav.r_var[1])
    return float(np.sqrt(np.mean(A[keep, 0] ** 2))), math.sqrt(np.mean(model[keep, 1]))


def test_look_angle_map_noise_is_calibrated_at_the_flights_height(map_and_world):
    """The look angle's map error depends on the height more than the flat-ground model's 1 / R: at 600
    random states 600 m above the map (the protection-level campaign's flights), with the calibration the
    filter picks for their range (ira_seed002.calibration_height_m: 750 m), the map's look-angle error where
    the filter takes it (basin-jump probability <= 0.05) has an RMS within 0.8-1.1 times the model's inside
    the filter's gate and below 1.15 times it without the gate; with the 1,500 m calibration of seed 002's
    flights it is above 1.2 times the model's without the gate (the variance underrated by 1.4).
    The ratios these bands were set on: docs/validation/integrity.md, section 6.7."""
    dem, world, region = map_and_world
    A = _map_against_world(dem, world, region, 600, seed=2, agl_m=600.0)
    nav = RaoBlackwellizedPF(dem=dem, n_particles=2)
    r_median = float(np.median(A[:, 3]))
    assert ira_model.calibration_height_m(r_median) == 750.0
    own, seed002s = nav.terrain_factors(r_median), nav.terrain_factors(1500.0)
    s_th, m_th = _gated_look_angle_rms(dem, A, nav, own, nav.theta_gate_sigmas)
    assert 0.8 < s_th / m_th < 1.1, (math.degrees(s_th), math.degrees(m_th))
    s_th, m_th = _gated_look_angle_rms(dem, A, nav, own, 0.0)
    assert s_th / m_th < 1.15, (math.degrees(s_th), math.degrees(m_th))
    s_old, m_old = _gated_look_angle_rms(dem, A, nav, seed002s, 0.0)
    assert s_old / m_old > 1.2, (math.degrees(s_old), math.degrees(m_old))


def test_calibration_height_is_the_nearest_octave_of_1500_m():
    """One calibration per octave of range, centred on 1,500 m: the band edges at 1,500 * 2^(k +- 1/2)."""
    h = ira_model.calibration_height_m
    assert h(1500.0) == h(1061.0) == h(2121.0) == 1500.0
    assert h(1060.0) == h(600.0) == h(531.0) == 750.0 and h(530.0) == 375.0
    assert h(2122.0) == 3000.0 and h(1e6) == 6000.0 and h(1.0) == 93.75
    assert h(math.nan) == h(-5.0) == h(0.0) == h(math.inf) == 1500.0


def test_map_noise_calibration(dem):
    """map_noise_calibration on the 3" map (24 m detail, three realisations): the flat-ground model is an
    upper bound (factors below 1; their values: docs/validation/seed002.md), the result depends on the map's
    content, not the object (a reloaded map hits the cache), and the variances combine as stated: with no
    terrain part the map's own sigma takes the flat-ground values, with factors (1, 1) the flat-ground model
    of the RSS."""
    f_r, f_th = ira_model.map_noise_calibration(dem, 30.0)
    assert 0.4 < f_r < 0.95 and 0.4 < f_th < 0.95, (f_r, f_th)
    assert ira_model.map_noise_calibration(terrain.load("jacksboro"), 30.0) == (f_r, f_th)
    # the look angle's heavy tail: gated at 3 sigma (as the filter's theta_gate_sigmas) the rest's variance
    # is smaller, the range's unchanged
    sens = math.radians(0.1) ** 2
    f_r_g, f_th_g = ira_model.map_noise_calibration(dem, 30.0, gate_sigmas=3.0, theta_sensor_var=sens)
    assert f_r_g == f_r and 0.5 * f_th < f_th_g < 0.95 * f_th, (f_th, f_th_g)
    r = 1500.0
    assert ira_model.map_noise_variances(2.0, 0.0, r, (f_r, f_th)) == pytest.approx([4.0, 2.0 / (3 * r)])
    assert ira_model.map_noise_variances(3.0, 4.0, r) == pytest.approx([25.0, 5.0 / (3 * r)])
    assert ira_model.map_noise_variances(0.0, 4.0, r, (f_r, f_th)) == pytest.approx(
        [16.0 * f_r, 4.0 * f_th / (3 * r)])
    assert np.all(ira_model.map_noise_variances(0.0, 0.0, r, (f_r, f_th)) == 0.0)
    # the filter: calibrated by default, flat ground on request, nothing to calibrate on a map = world
    assert RaoBlackwellizedPF(dem=dem, n_particles=2).terrain_factors(r) == (f_r_g, f_th_g)
    assert RaoBlackwellizedPF(dem=dem, n_particles=2, theta_gate_sigmas=0.0).terrain_factors(r) == (f_r, f_th)
    assert RaoBlackwellizedPF(dem=dem, n_particles=2, map_noise_model="flat_ground").terrain_factors(r) == (
        1.0, 1.0)
    nav = RaoBlackwellizedPF(dem=dem, n_particles=2, terrain_model_sigma_m=0.0)
    assert nav.terrain_factors(r) == (1.0, 1.0)
    # another octave of range, another calibration: at that height
    assert RaoBlackwellizedPF(dem=dem, n_particles=2).terrain_factors(700.0) == (
        ira_model.map_noise_calibration(dem, 30.0, agl_m=750.0, gate_sigmas=3.0, theta_sensor_var=sens))


def _horizontal_nees(res, after_s: float, every: int) -> list[float]:
    a = res.arrays
    e, cov, t = a["err_ned_m"], a["est_cov"], a["t_s"]
    return [float(e[k, :2] @ np.linalg.solve(cov[k, :2, :2], e[k, :2]))
            for k in np.flatnonzero(t >= after_s)[::every]]


def _chi2_mean_bounds(n: int, dof: int, p: float) -> tuple[float, float]:
    """Two-sided probability-p bounds on the mean of n independent chi2(dof) samples."""
    return chi2.ppf((1 - p) / 2, dof * n) / n, chi2.ppf((1 + p) / 2, dof * n) / n


@pytest.mark.slow
def test_rbpf_consistent_on_the_coarse_map():
    """The default route as built in (the 3" map against the 30 m world, GNSS for 10 s then denied), 8 seeds
    x 240 s: the horizontal NEES at every 45th epoch after 15 s (the runs' NEES autocorrelation falls below
    0.1 at 43-58 s on this map, scripts/rbpf_consistency.py) lies inside the two-sided 95 % chi-square
    bounds for that many 2-dof samples (issue 17's criterion); the figures: docs/validation/navigators.md
    (RBPF)."""
    _assert_default_route_consistent(map_is_world=False, every=45, max_rms_m=12.0)


def _assert_default_route_consistent(map_is_world: bool, every: int, max_rms_m: float) -> None:
    """8 seeds x 240 s of the default route (2 processes): the horizontal NEES at every `every`-th epoch
    after 15 s inside the two-sided 95 % chi-square bounds for that many 2-dof samples, every run's RMS
    below max_rms_m."""
    from concurrent.futures import ProcessPoolExecutor
    from functools import partial

    with ProcessPoolExecutor(2) as pool:
        runs = list(pool.map(partial(_default_route_run, map_is_world=map_is_world, every=every), range(8)))
    nees = [x for r in runs for x in r[0]]
    lo, hi = _chi2_mean_bounds(len(nees), 2, 0.95)
    where = "map = world" if map_is_world else "coarse map"
    print(f"rbpf, {where}: ANEES {np.mean(nees):.2f} over {len(nees)} epochs against [{lo:.2f}, {hi:.2f}], "
          f"RMS per run {[round(r[1], 1) for r in runs]}")
    assert lo <= np.mean(nees) <= hi, (np.mean(nees), lo, hi, len(nees), [np.mean(r[0]) for r in runs])
    assert max(r[1] for r in runs) < max_rms_m, [r[1] for r in runs]


def _default_route_run(seed: int, map_is_world: bool, every: int) -> tuple[list[float], float]:
    from trn_env.scenario.loading import load_scenario, validate
    from trn_env.sim.closed_loop import ClosedLoop

    sc = load_scenario("default", duration_s=240.0, seed=seed, navigator="rbpf")
    data = sc.to_dict()
    if map_is_world:
        data["terrain"]["map"] = {"dem": "world"}
    res = ClosedLoop(validate(data, source="default"), pipeline=False).run()
    return _horizontal_nees(res, 15.0, every), res.summary["horizontal_error_rms_m"]


@pytest.mark.slow
def test_rbpf_consistent_when_the_map_is_the_world():
    """Where the filter's measurement model is the truth's (map = the ~24 m world, no map error to model):
    the default route in JSBSim, GNSS for 10 s then denied, 8 seeds x 240 s, bias priors from the scenario's
    navigation-grade IMU. The horizontal NEES at every 15th epoch after 15 s (the runs' NEES autocorrelation
    falls below 0.1 at ~15 s here, scripts/rbpf_consistency.py --map-is-world) lies inside the two-sided 95 %
    chi-square bounds for that many 2-dof samples (issue 17's criterion); the figures:
    docs/validation/navigators.md (RBPF)."""
    _assert_default_route_consistent(map_is_world=True, every=15, max_rms_m=10.0)


@pytest.mark.parametrize("setting,value", [
    ("terrain_model_sigma_m", "coarse"), ("terrain_model_sigma_m", -1.0), ("map_bias_sigma_m", float("nan")),
    ("gnss_pos_bias_sigma_m", (1.0, -1.0)), ("gnss_pos_bias_sigma_m", (1.0,)),
    ("acquisition_particles", 10), ("acquisition_particles", 2.5), ("acquisition_particles", 10**7),
    ("window_edge_margin_deg", 50.0), ("window_edge_margin_deg", float("nan")),
    ("ambiguity_gap_m", -1.0), ("ambiguity_weight", 1.5), ("ambiguity_probability", 1.5),
    ("ambiguity_probability", float("nan")), ("search_step_m", "fine"), ("search_step_m", 0.0),
    ("map_noise_model", "exact"), ("map_noise_model", None), ("terrain_detail_spacing_m", "fine"),
    ("terrain_detail_spacing_m", -30.0), ("terrain_detail_spacing_m", float("inf")),
    ("terrain_detail_spacing_m", 80.0), ("terrain_detail_spacing_m", 1.0), ("theta_gate_sigmas", -1.0),
    ("theta_gate_sigmas", float("nan")),
])
def test_new_bad_settings_raise_naming_the_setting(dem, setting, value):
    with pytest.raises(ValueError, match=setting):
        RaoBlackwellizedPF(dem=dem, **{setting: value})


def test_scenario_gives_the_map_error_and_map_is_world():
    """build_navigator: the 3" map gets the interpolation sigma from its spectrum (auto) and the world's
    refinement spacing as the calibration's detail (auto without one), map = world gets none, and an
    accuracy class's error reaches map_sigma_m / map_bias_sigma_m."""
    from trn_env.scenario.build import build_navigator
    from trn_env.scenario.loading import load_scenario
    from trn_env.scenario.sections import from_dict

    d = load_scenario("default", navigator="rbpf").to_dict()
    nav = build_navigator(from_dict(d), terrain.load("jacksboro"))
    assert 2.0 < nav.terrain_model_sigma_m < 4.0 and nav.map_sigma_m == 0.0
    assert nav.terrain_detail_spacing_m == 30.0          # the world's refinement
    del d["terrain"]["world"]["refinement"]
    nav = build_navigator(from_dict(d), terrain.load("jacksboro"))
    assert nav.terrain_detail_spacing_m == pytest.approx(min(nav.dem.spacing_m) / 3.0)
    d["terrain"]["map"] = {"dem": "world", "error_model": {"preset": "srtm"}}
    nav = build_navigator(from_dict(d), terrain.load("jacksboro"))
    sig_v = 16.0 / 1.6449
    assert nav.terrain_model_sigma_m == 0.0
    assert nav.map_sigma_m == pytest.approx(sig_v * math.sqrt(0.5))
    assert nav.map_bias_sigma_m == pytest.approx(sig_v * math.sqrt(0.5))


def test_scenario_gives_the_imu_bias_model():
    """build_navigator (imu_bias_settings capability): the priors are the RSS of the IMU's turn-on bias and
    instability, and the biases' process noise per epoch is the instability's first-order Gauss-Markov drive
    over the filter's epoch, sigma sqrt(1 - exp(-2 T / tau)): zero for the navigation grade (constant
    biases; Table 1's 1e-7 random walk made the gyro bias's sigma 70x the IMU's in 300 s), and for the
    tactical grade (0.1 mg / 0.3 deg/h, tau 300 s) at 1 Hz and at 0.5 Hz."""
    from trn_env.scenario.build import build_navigator
    from trn_env.scenario.loading import load_scenario
    from trn_env.scenario.sections import from_dict

    dem = terrain.load("jacksboro")
    d = load_scenario("default", navigator="rbpf").to_dict()
    nav = build_navigator(from_dict(d), dem)
    ug, deg_h = 9.80665e-6, math.radians(1.0) / 3600.0
    assert nav.ql_var[6:12] == pytest.approx(np.zeros(6), abs=0.0)
    assert np.sqrt(nav.P0[6, 6]) == pytest.approx(50.0 * ug) and np.sqrt(nav.P0[9, 9]) == pytest.approx(
        0.005 * deg_h)
    for rate_hz in (1.0, 0.5):
        d["sensors"]["imu"] = {"grade": "tactical"}
        d["navigator"]["settings"] = {"trn_rate_hz": rate_hz}
        nav = build_navigator(from_dict(d), dem)
        T = 1.0 / rate_hz
        q_a = 100.0 * ug * math.sqrt(1.0 - math.exp(-2.0 * T / 300.0))
        q_g = 0.3 * deg_h * math.sqrt(1.0 - math.exp(-2.0 * T / 300.0))
        assert np.sqrt(nav.ql_var[6:9]) == pytest.approx([q_a] * 3, rel=1e-9)
        assert np.sqrt(nav.ql_var[9:12]) == pytest.approx([q_g] * 3, rel=1e-9)
        assert np.sqrt(nav.P0[9, 9]) == pytest.approx(math.hypot(1.0, 0.3) * deg_h)


def _exact_look_angle(dem, lat, lon, h, v, C) -> float:
    """theta of the exact closest-point search (terrain.queries.ira_return, what the IRA sensor measures):
    asin(y_b . p / R), p the antenna-to-point vector in NED through ECEF."""
    from trn_env.terrain import queries
    from trn_env.terrain.geodesy import C_en, lla_to_ecef

    ret = queries.ira_return(dem, [lat], [lon], [h], v[None, :], C[None], math.radians(45.0), 10000.0)
    if not ret.valid[0]:
        return math.nan
    a = np.array(lla_to_ecef(lat, lon, h))
    q = np.array(lla_to_ecef(ret.lat_rad[0], ret.lon_rad[0], ret.h_m[0]))
    p = C_en(lat, lon).T @ (q - a)
    return math.asin(float(C[:, 1] @ p) / float(np.linalg.norm(p)))


def test_search_step_finds_the_sensors_closest_point_on_a_fine_map():
    """On the default scenario's world (the 3" DEM refined with fractal detail to ~24 m posts) as the map,
    eq 23's coarse scan at the step search_step_for gives (0.6 of the smaller post spacing) puts the look
    angle within a small part of the sensor's 0.1 deg noise of the exact search's (terrain.queries.ira_return,
    what the IRA measures) at 80 random states 1,500 m above the terrain: RMS below 0.02 deg. The old fixed
    45 m step misses the minimum on such a map, which the filter took for 0.1-deg data (the figures before
    and after: docs/validation/seed002.md, the search step)."""
    from trn_env.scenario.loading import load_scenario, validate
    from trn_env.sim.closed_loop import ClosedLoop

    sc = load_scenario("default", duration_s=60.0, seed=7, navigator="rbpf")
    world = ClosedLoop(validate(sc.to_dict(), source="default"), pipeline=False).world_dem
    step = ira_model.search_step_for(world)
    assert 10.0 < step < 20.0
    heights, lat0, lon0, dlat, dlon = world.grid
    la0, la1 = lat0 + 0.3 * heights.shape[0] * dlat, lat0 + 0.7 * heights.shape[0] * dlat
    lo0, lo1 = lon0 + 0.3 * heights.shape[1] * dlon, lon0 + 0.7 * heights.shape[1] * dlon
    rng = np.random.default_rng(7)
    d_auto, d_45 = [], []
    for _ in range(80):
        lat, lon = rng.uniform(la0, la1), rng.uniform(lo0, lo1)
        h = float(world.height(lat, lon)) + 1500.0
        yaw = rng.uniform(0, 2 * math.pi)
        v = 85.0 * np.array([math.cos(yaw), math.sin(yaw), 0.0])
        C = euler_to_C_bn(rng.normal(0, 0.05), 0.04, yaw)
        ref = _exact_look_angle(world, lat, lon, h, v, C)
        a = ira_model.predict_ira(world, [lat], [lon], [h], v, C, ds_m=step)[0]
        b = ira_model.predict_ira(world, [lat], [lon], [h], v, C, ds_m=45.0)[0]
        if math.isfinite(ref) and a[ira_model.OUT_VALID] and b[ira_model.OUT_VALID]:
            d_auto.append(a[ira_model.OUT_THETA] - ref)
            d_45.append(b[ira_model.OUT_THETA] - ref)
    d_auto, d_45 = np.degrees(d_auto), np.degrees(d_45)
    assert d_auto.size > 60
    rms_auto, rms_45 = float(np.sqrt(np.mean(d_auto ** 2))), float(np.sqrt(np.mean(d_45 ** 2)))
    assert rms_auto < 0.02 and rms_45 > 0.05, (rms_auto, rms_45)
    # the filter takes the step from its map
    assert RaoBlackwellizedPF(dem=world, n_particles=2).search_step_m == step
