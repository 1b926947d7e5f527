"""The RBPF (navigators.filters.rbpf, seed 002): its Kalman part is exact on a linear-Gaussian problem,
bad settings raise naming the setting, one navigator stream fixes a run bit for bit, bad data never
crashes it."""

import math

import numpy as np
import pytest
from trn_env.navigators import registry
from trn_env.navigators.filters import _rbpf_kernels as kern
from trn_env.navigators.filters.rbpf import RaoBlackwellizedPF, table1_covariance
from trn_env.navigators.frames import ImuFrame, IraFrame, SensorFrames
from trn_env.navigators.protocol import (
    EXTRA_ESS,
    EXTRA_INNOVATION,
    EXTRA_LOG_LIKELIHOOD,
    EXTRA_NIS,
    EXTRA_NIS_DOF,
    Estimate,
)

from trn_env import terrain


def test_linear_part_is_the_exact_conditional_kalman_filter():
    """Linear-Gaussian model: x_{k+1} = Phi x_k + w (x = [x^n (3), x^l (12)]),
    y_k = c + Hn x^n_k + Hl x^l_k + e
    (a planar terrain: the range is linear in position). Given one particle's trajectory x^n_{0:T} and
    y_{1:T}, its (x^l, P) from the kernels must equal p(x^l_T | x^n_{0:T}, y_{1:T}) computed by conditioning
    the joint Gaussian of all noises directly (no Kalman recursion)."""
    rng = np.random.default_rng(11)
    n_steps, m = 6, 2
    Phi = np.eye(15) + 0.05 * rng.standard_normal((15, 15))
    qn = rng.uniform(0.5, 2.0, 3)
    ql = rng.uniform(0.01, 0.1, 12)
    P0 = np.diag(rng.uniform(0.5, 1.5, 12))
    Hn = rng.standard_normal((n_steps, m, 3))
    Hl = rng.standard_normal((n_steps, m, 12))
    r = np.array([0.3, 0.2])
    c = rng.standard_normal((n_steps, m))
    xn0 = rng.standard_normal(3)
    # simulate the truth
    x = np.r_[xn0, rng.standard_normal(12) @ np.sqrt(P0)]
    y = np.empty((n_steps, m))
    # the particle filter's draws (eq 5): one particle, noises w
    w = rng.standard_normal((n_steps, 3))
    xn = xn0[None].copy()
    xl = np.zeros((1, 12))
    P = P0[None].copy()
    traj = [xn0.copy()]
    logw = np.zeros(1)
    ll = np.zeros(1)
    for k in range(n_steps):
        kern.time_update(xn, xl, P, Phi, qn, ql, w[k:k + 1])
        traj.append(xn[0].copy())
        x = Phi @ x + np.r_[rng.standard_normal(3) * np.sqrt(qn), rng.standard_normal(12) * np.sqrt(ql)]
        y[k] = c[k] + Hn[k] @ x[:3] + Hl[k] @ x[3:] + rng.standard_normal(m) * np.sqrt(r)
        e = (y[k] - c[k] - Hn[k] @ xn[0])[None]
        kern.linear_update(xl, P, Hl[k][None], e, r, logw, np.ones(1, bool), ll)
    # joint Gaussian: Z = [xl0 (12), w_0..w_{T-1} (15 each), e_1..e_T (m each)], zero mean, independent
    nz = 12 + 15 * n_steps + m * n_steps
    cov_z = np.diag(np.r_[np.diag(P0), np.tile(np.r_[qn, ql], n_steps), np.tile(r, n_steps)])
    a = np.r_[xn0, np.zeros(12)]           # x_k = a_k + M_k Z
    M = np.zeros((15, nz))
    M[3:, :12] = np.eye(12)
    obs_rows, obs_vals = [], []
    for k in range(n_steps):
        a = Phi @ a
        M = Phi @ M
        M[:, 12 + 15 * k:12 + 15 * (k + 1)] += np.eye(15)
        for i in range(3):                       # observed x^n_{k+1}
            obs_rows.append((a[i], M[i]))
            obs_vals.append(traj[k + 1][i])
        Hk = np.hstack([Hn[k], Hl[k]])
        ey = np.zeros((m, nz))
        ey[:, 12 + 15 * n_steps + m * k:12 + 15 * n_steps + m * (k + 1)] = np.eye(m)
        for i in range(m):                       # observed y_{k+1}
            obs_rows.append((c[k][i] + Hk[i] @ a, Hk[i] @ M + ey[i]))
            obs_vals.append(y[k, i])
    oa = np.array([r_[0] for r_ in obs_rows])
    OM = np.array([r_[1] for r_ in obs_rows])
    ov = np.array(obs_vals)
    tgt_a, TM = a[3:], M[3:]
    S = OM @ cov_z @ OM.T
    G = TM @ cov_z @ OM.T @ np.linalg.inv(S)
    mean = tgt_a + G @ (ov - oa)
    cov = TM @ cov_z @ TM.T - G @ OM @ cov_z @ TM.T
    tol = 1e-9 * max(1.0, np.abs(mean).max())
    assert np.allclose(xl[0], mean, rtol=0, atol=tol), np.abs(xl[0] - mean).max()
    assert np.allclose(P[0], cov, rtol=0, atol=1e-9), np.abs(P[0] - cov).max()


@pytest.fixture(scope="module")
def dem():
    return terrain.load("jacksboro")


@pytest.mark.parametrize("setting,value", [
    ("n_particles", 0), ("n_particles", 10**9), ("n_particles", 2.5), ("ess_threshold", 0.0),
    ("ess_threshold", 1.5), ("range_sigma_m", -1.0), ("look_angle_sigma_deg", float("nan")),
    ("q_pos_m", (0.5, -0.5, 0.5)), ("trn_rate_hz", 0.0), ("half_window_deg", 95.0),
    ("init_pos_sigma_m", (50.0, 50.0)), ("gnss_vel_sigma_mps", float("inf")),
    ("recovery_reset_kalman", "false"),
])
def test_bad_settings_raise_naming_the_setting(dem, setting, value):
    with pytest.raises(ValueError, match=setting):
        RaoBlackwellizedPF(dem=dem, **{setting: value})


def test_no_map_raises():
    with pytest.raises(ValueError, match="dem"):
        registry.create("rbpf")


def _frames(t0, n_s, rng_m=2000.0, theta=0.0, valid=True):
    t = t0 + np.arange(1, int(n_s * 100) + 1) * 0.01
    f = np.tile([0.0, 0.0, -9.79], (t.size, 1))
    imu = ImuFrame(t, f, np.zeros((t.size, 3)), np.ones(t.size, bool))
    ti = t[1::2]
    ira = IraFrame(ti, np.full(ti.size, rng_m), np.full(ti.size, theta), np.full(ti.size, valid))
    return SensorFrames(t0, t[-1], imu=imu, ira=ira)


def _initial(dem):
    from trn_env.navigators.protocol import Estimate

    lat, lon = dem.center_rad
    return Estimate(0.0, lat, lon, 2500.0, np.array([228.0, 75.0, 0.0]), 0.0, 0.0, math.radians(18.1575),
                    table1_covariance())


def test_bad_data_never_crashes(dem):
    nav = registry.create("rbpf", dem=dem, rng=np.random.default_rng(1), n_particles=200)
    nav.reset(_initial(dem))
    est = nav.update(_frames(0.0, 2.0, rng_m=np.nan, valid=True))        # NaN measurements: skipped
    assert est.health.skipped.get("ira_invalid", 0) > 0
    est = nav.update(_frames(2.0, 4.0, rng_m=50000.0))                   # impossible range: weights vanish
    assert est.health.status == "degraded" and "weights_underflow" in est.health.skipped
    assert np.isfinite(est.lat_rad) and np.all(np.isfinite(est.covariance))
    far = _initial(dem)
    far.lat_rad += 0.2                                                    # off the map: no hypothesis
    nav.reset(far)
    est = nav.update(_frames(0.0, 2.0))
    assert "ira_no_hypothesis" in est.health.skipped and est.health.status == "degraded"


def test_extra_keys_and_one_stream_fixes_the_run(dem):
    from trn_env.navigators.measurements.ira_seed002 import predict_ira
    from trn_env.terrain.geodesy import euler_to_C_bn

    e0 = _initial(dem)
    r0 = predict_ira(dem, [e0.lat_rad], [e0.lon_rad], [e0.h_m], e0.v_ned_mps,
                     euler_to_C_bn(0.0, 0.0, e0.yaw_rad))[0, 0]

    def run(seed):
        nav = registry.create("rbpf", dem=dem, rng=np.random.default_rng(seed), n_particles=300)
        nav.reset(_initial(dem))
        ests = [nav.update(_frames(float(k), 1.0, rng_m=r0 + 3.0 * k, theta=0.001)) for k in range(4)]
        return nav, ests

    nav_a, a = run(7)
    _, b = run(7)
    _, c = run(8)
    for ea, eb in zip(a, b, strict=True):
        assert ea.lat_rad == eb.lat_rad and np.array_equal(ea.covariance, eb.covariance)
    assert a[-1].lat_rad != c[-1].lat_rad
    ex = a[-1].extra
    # 2 dof, or range only (1) when the closest point is about to jump basins (rbpf: ambiguity_gap_m)
    assert ex[EXTRA_NIS_DOF] in (1, 2) and ex[EXTRA_INNOVATION].shape == (ex[EXTRA_NIS_DOF],)
    assert np.isfinite(ex[EXTRA_NIS]) and np.isfinite(ex[EXTRA_LOG_LIKELIHOOD])
    assert 1.0 <= ex[EXTRA_ESS] <= nav_a.n_acquisition      # 5,000 while acquiring, then 300
    assert nav_a.epochs == 4


def test_gnss_fusion_pulls_the_estimate_and_trn_carries_on_without_it(dem):
    """GNSS fixes 60 m north of the INS start: the estimate moves to them within a few fixes (weights on
    the position; the velocity goes to the Kalman parts); with the fixes gone it keeps running."""
    from trn_env.navigators.frames import GnssFrame
    from trn_env.terrain.geodesy import meridian_radius_m

    nav = registry.create("rbpf", dem=dem, rng=np.random.default_rng(2), n_particles=500)
    e0 = _initial(dem)
    nav.reset(e0)
    r = meridian_radius_m(e0.lat_rad) + e0.h_m
    for k in range(6):
        fr = _frames(float(k), 1.0)
        fr.ira = None
        t = np.array([k + 1.0])
        lat_true = e0.lat_rad + 60.0 / r + 228.0 * (k + 1.0) / r
        lon_true = e0.lon_rad + 75.0 * (k + 1.0) / (r * math.cos(e0.lat_rad))
        fr.gnss = GnssFrame(t, np.array([lat_true]), np.array([lon_true]), np.array([2500.0]),
                            np.array([[228.0, 75.0, 0.0]]), np.array([True]))
        est = nav.update(fr)
    dn = (est.lat_rad - lat_true) * r
    assert abs(dn) < 10.0, dn                   # from 60 m off to within GNSS noise
    assert est.sigma_ned_m[0] < 10.0
    fr = _frames(6.0, 2.0)
    fr.ira = None
    est2 = nav.update(fr)                       # denied: no crash, INS carries on
    assert np.isfinite(est2.lat_rad) and est2.t_s > est.t_s


def test_prior_comes_from_the_initial_covariance(dem):
    """prior_from_initial (default): the cloud's position spread and the Kalman parts' velocity-attitude
    block are initial.covariance's (the cloud's sample sigmas within 5 % over 5,000 particles: 1 % standard
    error), the bias priors the settings'; prior_from_initial=False: Table 1's (the init_* settings)."""
    lat, lon = dem.center_rad
    cov = np.diag([30.0**2, 20.0**2, 15.0**2, 0.1**2, 0.2**2, 0.3**2, 5e-5**2, 6e-5**2, 1e-3**2])
    cov[3, 4] = cov[4, 3] = 0.5 * 0.1 * 0.2
    init = Estimate(0.0, lat, lon, 2500.0, np.array([228.0, 75.0, 0.0]), 0.0, 0.0, 0.3, cov)
    nav = RaoBlackwellizedPF(dem=dem, rng=np.random.default_rng(2), gyro_bias_sigma_rps=2.4e-8)
    nav.reset(init)
    assert nav.n == 5000
    assert np.allclose(nav.xn.std(axis=0), [30.0, 20.0, 15.0], rtol=0.05)
    assert np.array_equal(nav.P[0, :6, :6], cov[3:9, 3:9])
    assert np.allclose(np.diag(nav.P[0])[6:], [1e-4**2] * 3 + [2.4e-8**2] * 3)
    # a start known exactly (zero sigmas) stays defined: floors of 0.1 m and 1e-12
    nav.reset(Estimate(0.0, lat, lon, 2500.0, np.array([228.0, 75.0, 0.0]), 0.0, 0.0, 0.3, np.zeros((9, 9))))
    assert np.allclose(nav.xn.std(axis=0), 0.1, rtol=0.05) and np.all(np.diag(nav.P[0]) > 0)
    table1 = RaoBlackwellizedPF(dem=dem, rng=np.random.default_rng(2), prior_from_initial=False)
    table1.reset(init)
    assert np.allclose(table1.xn.std(axis=0), [50.0, 50.0, 20.0], rtol=0.05)
    assert np.allclose(np.diag(table1.P[0])[:6], np.diag(table1_covariance())[3:9])


@pytest.mark.parametrize("bad,match", [
    (np.full((9, 9), np.nan), "finite"),
    (np.eye(9), "attitude sigma above 0.1 rad"),
    (np.diag([1.0] * 6 + [1e-6] * 3) - 2.0 * np.eye(9)[0:1].T @ np.eye(9)[0:1], "positive semi-definite"),
    (np.eye(6), "9 x 9"),
])
def test_bad_initial_covariance_raises_naming_it(dem, bad, match):
    lat, lon = dem.center_rad
    nav = RaoBlackwellizedPF(dem=dem, rng=np.random.default_rng(2), n_particles=100, acquisition_particles=0)
    with pytest.raises(ValueError, match=match) as exc:
        nav.reset(Estimate(0.0, lat, lon, 2500.0, np.array([228.0, 75.0, 0.0]), 0.0, 0.0, 0.3, bad))
    assert "initial.covariance" in str(exc.value)


def test_cli_refuses_an_attitude_prior_beyond_small_angles(tmp_path, capsys):
    """A scenario whose initial attitude errors the 15-state model cannot take: exit 2, the field named,
    nothing written."""
    from trn_env import cli

    out = tmp_path / "never"
    code = cli.main(["fly", "--navigator", "rbpf", "--duration", "3", "--no-plots", "--quiet",
                     "--out", str(out), "--set", "initial_errors.attitude_mrad=[200, 200, 200]"])
    assert code == 2
    assert "initial_errors.attitude_mrad" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("reset_kalman", [True, False])
def test_recovery_resets_the_kalman_parts_velocity_and_attitude(dem, reset_kalman):
    """A re-spread (the innovation test failed) widens the positions by recovery_sigma_m; with
    recovery_reset_kalman every particle's velocity-attitude covariance becomes the prior's plus the cloud's
    mixture covariance at that moment (computed here with numpy over the resampled cloud), its cross
    terms with the biases zero; without it the Kalman parts are only resampled."""
    lat, lon = dem.center_rad
    cov = np.diag([1.0, 1.0, 1.0, 0.1**2, 0.2**2, 0.3**2, 5e-5**2, 6e-5**2, 1e-3**2])
    init = Estimate(0.0, lat, lon, 2500.0, np.array([228.0, 75.0, 0.0]), 0.0, 0.0, 0.3, cov)
    nav = RaoBlackwellizedPF(dem=dem, rng=np.random.default_rng(4), n_particles=400, acquisition_particles=0,
                             recovery_sigma_m=25.0, recovery_reset_kalman=reset_kalman)
    nav.reset(init)
    rng = np.random.default_rng(9)
    nav.P[:, :12, :12] *= 1e-4                       # an overconfident cloud
    nav.P[:, 0, 9] = nav.P[:, 9, 0] = 1e-12          # a velocity-bias cross term
    nav.xl[:] = rng.standard_normal((nav.n, 12)) * 1e-3
    nav.logw = np.log(rng.uniform(0.5, 1.5, nav.n))
    nav._cov9 = nav._covariance9()
    p_small = nav.P[0, :6, :6].copy()
    nav._streak = 1                                  # the first re-spread of a streak: recovery_sigma_m
    nav._respread(1.0)
    if reset_kalman:
        d = nav.xl[:, :6] - nav.xl[:, :6].mean(axis=0)
        expected = d.T @ d / nav.n + p_small + nav.P0[:6, :6]
        assert np.allclose(nav.P[:, :6, :6], expected, rtol=1e-9, atol=1e-15)
        assert np.all(nav.P[:, :6, 6:] == 0.0) and np.all(nav.P[:, 6:, :6] == 0.0)
        assert np.all(np.linalg.eigvalsh(nav.P[0, :6, :6] - nav.P0[:6, :6]) > -1e-15)
    else:
        assert np.all(nav.P[:, :6, :6] <= 1e-4 * nav.P0[:6, :6].max() + 1e-18)
    # positions (1 m before): resampled, then N(0, 25^2) horizontally (sample sigma of 400: 3.5 % error)
    assert np.all(np.abs(nav.xn[:, :2].std(axis=0) / np.hypot(25.0, 1.0) - 1.0) < 0.12)
    assert nav.xn[:, 2].std() < 1.2
    assert any("re-spread" in m for _, m in nav.health.events)
