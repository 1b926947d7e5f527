"""acq_track: MSD (eq 3.4), the loop kernel, ELS bias mitigation (eq 3.7), the bounded serial search.

Every check is against an independent computation: numpy brute force (replica positions from the numpy
twin, terrain.kernels.bilinear_batch, the cost written out in the test), an analytic V, the thesis' formula
or discriminator (3.5) written out, or the exhaustive search kernel. Data: noise-free profiles over the
bundled Jacksboro DEM."""

from __future__ import annotations

import math

import numpy as np
import pytest
from acq_track_helpers import (
    H_MSL,
    LAT0,
    LON0,
    fly,
    horizontal_error_m,
    initial_estimate,
    radii_m,
    trajectory,
)
from trn_env.navigators.acquisition_tracking import AcqTrackNavigator, acquisition, correlation, loop_kernel
from trn_env.navigators.acquisition_tracking.footprint import FootprintMaps
from trn_env.terrain.kernels import bilinear_batch

from trn_env import terrain

SPEED_SET = np.array([2.4, 1.92, 1.44, 0.96, 0.48])  # the thesis' radar-run 1st-stage set, widest first


@pytest.fixture(scope="module")
def dem():
    return terrain.load("jacksboro")


def _bf_heights(grid, lat_s, lon_s, dts, speed, track, r_n, r_e):
    """Map heights of a constant speed/track replica: numpy positions + the batch bilinear kernel."""
    n = dts.size
    la, lo = correlation.replica_positions_reference(
        lat_s, lon_s, dts, np.zeros(n), np.zeros(n), speed, track, r_n, r_e
    )
    h = np.empty(n)
    bilinear_batch(*grid, la, lo, h)
    return h


def _bf_scf(grid, d, lat_s, lon_s, dts, speeds, track, r_n, r_e, kind="mad"):
    """Brute-force speed correlation function (mean-removed MAD or MSD written out here)."""
    out = np.empty(speeds.size)
    for k, v in enumerate(speeds):
        r = d - _bf_heights(grid, lat_s, lon_s, dts, v, track, r_n, r_e)
        r = r - r.mean()
        out[k] = np.mean(np.abs(r)) if kind == "mad" else np.mean(r * r)
    return out


def _transect(n=25):
    dts = np.full(n, 1.0)
    dts[0] = 0.0
    return dts, np.zeros(n)


# ------------------------------------------------------------------------------------------------ MSD


def test_msd_matches_brute_force_and_its_minimum_is_the_true_offset(dem):
    rng = np.random.default_rng(11)
    n = 25
    dts, z = _transect(n)
    r_n, r_e = radii_m(LAT0)
    d = _bf_heights(dem.grid, LAT0, LON0, dts, 80.0, math.radians(30.0), r_n, r_e)
    valid = rng.random(n) > 0.2
    h = d + 4.0 * rng.standard_normal(n) + 9.0
    h[5] = np.nan
    ok = valid & np.isfinite(h)
    r = d[ok] - h[ok]
    for rb, want in ((True, np.sum((r - r.mean()) ** 2) / ok.sum()), (False, np.sum(r**2) / ok.sum())):
        assert correlation.profile_cost(d, valid, h, correlation.COST_MSD, rb, 5) == pytest.approx(
            want, rel=1e-12
        )
    assert correlation.profile_cost(d, valid, h, correlation.COST_MSD, True, 99) == np.inf
    # noise-free: the brute-force SCF and HCF of MSD are zero at the truth, positive elsewhere, and the
    # kernel's correlation function agrees with them
    speeds = 80.0 + np.linspace(-3.0, 3.0, 61)
    scf = _bf_scf(dem.grid, d, LAT0, LON0, dts, speeds, math.radians(30.0), r_n, r_e, "msd")
    assert speeds[int(np.argmin(scf))] == pytest.approx(80.0, abs=1e-9) and scf.min() < 1e-12
    assert np.all(np.delete(scf, int(np.argmin(scf))) > 1e-3)
    got = np.empty(speeds.size)
    loop_kernel.correlation_function(
        dem.record(), LAT0, LON0, correlation.Motion(dts, z, z, r_n, r_e), 80.0, math.radians(30.0),
        correlation.Profile(d, np.ones(n, bool), correlation.COST_MSD, True, 5), 0, speeds - 80.0, got,
    )  # fmt: skip
    np.testing.assert_allclose(got**2, scf, rtol=1e-9, atol=1e-9)  # the loops see MSD's square root
    # and the serial search with MSD recovers truth within one bin from +-10 m/s, +-10 deg, +-500 m
    v_true, psi_true = 81.3, math.radians(33.7)
    d2 = _bf_heights(dem.grid, LAT0, LON0, dts, v_true, psi_true, r_n, r_e)
    res = acquisition.serial_search(
        dem.record(), LAT0 + 320.0 / r_n, LON0 - 410.0 / r_e, dts, z, z, v_true + 7.4,
        psi_true - math.radians(6.3), r_n, r_e, d2, np.ones(n, bool), position_half_m=500.0,
        position_bin_m=50.0, speed_half_mps=10.0, speed_bin_mps=1.0, heading_half_rad=math.radians(10.0),
        heading_bin_rad=math.radians(1.0), cost=correlation.COST_MSD, remove_bias=True, n_min=10,
        distinct_ratio=0.9, exclusion_m=200.0,
    )  # fmt: skip
    assert res.distinct
    assert abs(res.b_v - v_true) <= 1.0 and abs(math.degrees(res.b_psi_rad - psi_true)) <= 1.0
    assert abs(res.dn_m + 320.0) <= 50.0 and abs(res.de_m - 410.0) <= 50.0


def test_navigator_tracks_with_msd(dem):
    """correlation = 'msd' through the whole navigator: noise-free constant flight, in lock, within 50 m."""
    traj = trajectory(dem, LAT0, LON0, H_MSL, lambda t: 80.0, lambda t: math.radians(30.0), 61)
    nav = AcqTrackNavigator(dem=dem, correlation="msd")
    nav.reset(initial_estimate(traj, H_MSL, sigma_m=20.0))
    ests, truth = fly(nav, dem, traj, H_MSL, 60)
    last = ests[-1]
    assert last.extra["lock_state"] == "tracking" and last.health.status == "ok"
    assert horizontal_error_m(last, truth[-1, 0], truth[-1, 1]) < 50.0


# ------------------------------------------------------------------------------------- loop kernel


def _early_late_by_hand(cost, x, s, threshold, break_iteration=101):
    """Discriminator (3.5) written out: x += s (H_E - H_L) / (H_E + H_L) until |eps| < threshold, at most
    break_iteration - 1 updates: (x, iterations, locked)."""
    for it in range(1, break_iteration):
        he, hl = cost(x - s), cost(x + s)
        eps = s * (he - hl) / (he + hl)
        x += eps
        if abs(eps) < threshold:
            return x, it, True
    return x, break_iteration, False


def test_loop_kernel_matches_brute_force_and_the_discriminator_by_hand(dem):
    """loop_epoch (ncs) against independent computations: its SCF/HCF minimum is the brute-force one
    (numpy replica positions, the batch bilinear kernel, the cost written out), its spacing lies within the
    V's bandwidth, and both stages land where discriminator (3.5) by hand on the brute-force cost does."""
    rng = np.random.default_rng(5)
    n = 25
    dts, _ = _transect(n)
    for trial in range(6):
        lat_s, lon_s = LAT0 + 0.0006 * trial, LON0 + 0.0005 * trial  # on the map (3.8 km, 2.5 km apart)
        r_n, r_e = radii_m(lat_s)
        m_v = 80.0 + 0.5 * rng.standard_normal(n)
        m_psi = math.radians(30.0 + 20 * trial) + 0.01 * rng.standard_normal(n)
        la, lo = correlation.replica_positions_reference(lat_s, lon_s, dts, m_v, m_psi, 1.1, 0.02, r_n, r_e)
        d = np.empty(n)
        bilinear_batch(*dem.grid, la, lo, d)
        valid = np.ones(n, bool)
        for which, reach, sset, thr1, s2, thr2 in (
            (0, 7.36 / 2.0, SPEED_SET, 0.005, 0.24, 0.002),
            (1, math.radians(5.0), np.radians([5.0, 4, 3, 2, 1]), math.radians(0.03), math.radians(0.5),
             math.radians(0.003)),
        ):  # fmt: skip
            b_v, b_psi = (1.1 + 0.8, 0.02) if which == 0 else (1.1, 0.02 + math.radians(1.5))

            def cost(x, which=which, b_v=b_v, b_psi=b_psi, tr=(lat_s, lon_s, m_v, m_psi, r_n, r_e, d)):
                la_s, lo_s, mv, mp, rn, re, dd = tr
                bv, bp = (x, b_psi) if which == 0 else (b_v, x)
                la2, lo2 = correlation.replica_positions_reference(la_s, lo_s, dts, mv, mp, bv, bp, rn, re)
                h = np.empty(n)
                bilinear_batch(*dem.grid, la2, lo2, h)
                return correlation.profile_cost_reference(dd, np.ones(n, bool), h, "mad", True, 15)

            out = loop_kernel.loop_epoch(
                dem.record(), lat_s, lon_s, correlation.Motion(dts, m_v, m_psi, r_n, r_e), b_v, b_psi,
                correlation.Profile(d, valid, 0, True, 15), which, (reach, sset, thr1, s2, thr2),
                (10, 2.0, 101, 0, loop_kernel.MITIGATION_NCS), np.zeros(n), np.zeros(n),
            )  # fmt: skip
            x, it1, it2, _, locked, v_shape, bw, m_off, m_cost, _, _, sp, _ = out
            x0 = b_v if which == 0 else b_psi
            offs = np.linspace(-reach, reach, 21)
            bf = np.array([cost(x0 + o) for o in offs])
            assert np.isfinite(bf).all()
            assert m_off == pytest.approx(offs[int(np.argmin(bf))], abs=1e-12)
            assert m_cost == pytest.approx(bf.min(), rel=1e-9)
            assert sp in sset and (sp <= bw + 1e-12 or sp == sset.min())
            x1, ref1, l1 = _early_late_by_hand(cost, x0, sp, thr1)
            x2, ref2, l2 = _early_late_by_hand(cost, x1, s2, thr2)
            assert abs(it1 - ref1) <= 1 and abs(it2 - ref2) <= 1 and locked == (l1 and l2)
            assert x == pytest.approx(x2, abs=5 * thr2)
    # the 101-iteration break: a threshold no step meets stops the stage at break_iteration, out of lock
    out = loop_kernel.loop_epoch(
        dem.record(), lat_s, lon_s, correlation.Motion(dts, m_v, m_psi, r_n, r_e), 1.9, 0.02,
        correlation.Profile(d, valid, 0, True, 15), 0, (3.68, SPEED_SET, 0.0, 0.24, 0.002),
        (10, 2.0, 7, 0, loop_kernel.MITIGATION_NONE), np.zeros(dts.size), np.zeros(dts.size),
    )  # fmt: skip
    assert out[1] == 7 and not out[4]


def test_v_analysis_and_spacing_choice_on_an_analytic_v():
    """A V with slopes -2 and +4 and its minimum at 0.6, sampled at 21 points over +-3: the analysis finds
    the minimum, the slopes and the bandwidth (the narrower side: 12 points of 0.3 on the right less...)
    by hand; the symmetry ratio over +-0.9 is 4 / 2; a monotone function has no V."""
    offs = np.linspace(-3, 3, 21)
    vals = 1.0 + np.where(offs < 0.6, 2.0 * (0.6 - offs), 4.0 * (offs - 0.6))
    v_shape, bw, m_off, m_cost, sl, sr = loop_kernel.analyse_v_kernel(offs, vals, 2, 0.05)
    assert v_shape and m_off == pytest.approx(0.6) and m_cost == pytest.approx(1.0)
    assert sl == pytest.approx(-2.0) and sr == pytest.approx(4.0)
    assert bw == pytest.approx(2.4)  # 8 points of 0.3 to the right edge, 12 to the left: the narrower
    assert loop_kernel.symmetry_ratio_kernel(offs, vals, 0.6, 0.9) == pytest.approx(2.0)
    # the widest spacing within the bandwidth whose ratio passes: every ratio here is 2, so with a limit of
    # 2 the widest within 2.4 (2.0) is chosen, with a limit of 1.5 none passes and the narrowest inside
    spacings = np.array([3.0, 2.0, 1.0, 0.5])
    assert loop_kernel.choose_spacing_kernel(offs, vals, bw, m_off, spacings, 2.0)[0] == 2.0
    assert loop_kernel.choose_spacing_kernel(offs, vals, bw, m_off, spacings, 1.5)[0] == 0.5
    assert loop_kernel.choose_spacing_kernel(offs, vals, 0.1, m_off, spacings, 2.0)[0] == 0.5
    assert not loop_kernel.analyse_v_kernel(offs, offs.copy(), 2, 0.05)[0]  # monotone: no V


# ---------------------------------------------------------------------------------------------- ELS


def test_els_intersection_is_the_thesis_formula_and_exact_on_an_asymmetric_v():
    # eq (3.7) written out for x1 = -s/2, x4 = +s/2 around the prompt (T = prompt - intersection)
    rng = np.random.default_rng(2)
    for _ in range(20):
        s = rng.uniform(0.5, 3.0)
        x2, x3 = -s / 2 + rng.uniform(0.05, s / 2 - 0.01), rng.uniform(0.01, s / 2 - 0.05)
        x1, x4 = -s / 2, s / 2
        y1, y2, y3, y4 = rng.uniform(1, 5, 4)
        a1, a2 = (y2 - y1) / (x2 - x1), (y4 - y3) / (x4 - x3)
        t_thesis = ((y1 - y4) + s * (a1 + a2) / 2) / (a1 - a2)
        xs, _, _ = loop_kernel.els_intersection(x1, y1, x2, y2, x3, y3, x4, y4)
        assert -xs == pytest.approx(t_thesis, rel=1e-9, abs=1e-12)
    # a V with slopes -1 and +3 over a floor, minimum at 0.37 (a skewed, multipath-like triangle): the plain
    # discriminator (3.5) settles where C(x - s) = C(x + s), i.e. s (a_L - a_R) / (a_L + a_R) = -s / 2 off;
    # ELS lands on the apex
    apex, s = 0.37, 1.0

    def cost(x):
        return 2.0 + (1.0 * (apex - x) if x < apex else 3.0 * (x - apex))

    x_el, _, lock = _early_late_by_hand(cost, 1.2, s, 1e-7)
    assert lock and x_el - apex == pytest.approx(-s / 2, abs=1e-5)
    # ELS's four correlators, two on each side of the minimum: the lines through each pair meet at the apex,
    # so its tracking error T = prompt - apex removes the early-late bias in one step
    x1, x2, x3, x4 = x_el - 1.0, x_el + 0.24, x_el + 0.72, x_el + 1.2
    assert x2 < apex < x3
    xs, a1, a2 = loop_kernel.els_intersection(x1, cost(x1), x2, cost(x2), x3, cost(x3), x4, cost(x4))
    assert a1 == pytest.approx(-1.0) and a2 == pytest.approx(3.0) and abs(xs - apex) < 1e-12


def test_els_reduces_the_early_late_bias_on_a_skewed_terrain_correlation(dem):
    """The thesis' situation (3.5.2.2): a correlation function made asymmetric by a distortion of the
    measured signal - here the pulse altimeter's shortest return in its 17 deg beam at 600 m above ground
    (the TRN cousin of multipath), correlated against the plain map. Over fixed-seed transects whose
    brute-force SCF is asymmetric (slope ratio > 1.5) with an interior minimum, the speed loop's lock point
    is compared with that brute-force minimum: plain early-late (bias_mitigation 'none') against ELS."""
    heights, lat0, lon0, dlat, dlon = dem.grid
    fp = FootprintMaps(dem, 17.0).grid(600.0)[0]
    n = 25
    dts, z = _transect(n)
    rng = np.random.default_rng(7)
    errs = {m: [] for m in ("none", "ncs", "els")}
    n_cases = 0
    for _ in range(60):
        lat_s = lat0 + dlat * heights.shape[0] * rng.uniform(0.2, 0.8)
        lon_s = lon0 + dlon * heights.shape[1] * rng.uniform(0.2, 0.8)
        r_n, r_e = radii_m(lat_s)
        track = rng.uniform(0.0, 2.0 * math.pi)
        start = rng.choice([-1.5, -0.5, 0.5, 1.5])
        la, lo = correlation.replica_positions_reference(lat_s, lon_s, dts, z, z, 80.0, track, r_n, r_e)
        d = np.empty(n)
        bilinear_batch(fp, lat0, lon0, dlat, dlon, la, lo, d)  # what the pulse altimeter measures
        speeds = 80.0 + np.arange(-3.0, 3.0 + 1e-9, 0.005)
        scf = _bf_scf(dem.grid, d, lat_s, lon_s, dts, speeds, track, r_n, r_e)
        k = int(np.argmin(scf))
        x_bf = speeds[k]
        if not 0.4 * speeds.size < k < 0.6 * speeds.size + 1 or abs(x_bf - 80.0) > 1.5:
            continue  # no interior minimum near the truth (the distortion hid it)
        left, right = (speeds >= x_bf - 1.0) & (speeds <= x_bf), (speeds >= x_bf) & (speeds <= x_bf + 1.0)
        sl = abs(np.polyfit(speeds[left], scf[left], 1)[0])
        sr = abs(np.polyfit(speeds[right], scf[right], 1)[0])
        if max(sl, sr) < 1.5 * min(sl, sr):
            continue
        n_cases += 1
        for name in errs:
            out = loop_kernel.loop_epoch(
                dem.record(), lat_s, lon_s, correlation.Motion(dts, z, z, r_n, r_e), 80.0 + start, track,
                correlation.Profile(d, np.ones(n, bool), 0, True, 15), 0, (7.36 / 2.0, SPEED_SET, 0.005, 0.24,
                0.002), (10, 2.0, 101, 0, loop_kernel.MITIGATIONS[name]), z, z,
            )  # fmt: skip
            errs[name].append(abs(out[0] - x_bf))
    assert n_cases >= 12
    mean = {k: float(np.mean(v)) for k, v in errs.items()}
    med = {k: float(np.median(v)) for k, v in errs.items()}
    # the figures behind this margin: docs/validation/seed001.md (regression tests' bounds)
    print(f"\n{n_cases} cases; mean |error| (m/s) {mean}; median {med}")
    assert mean["els"] < 0.75 * mean["none"] and med["els"] < 0.75 * med["none"]


def test_navigator_tracks_with_els(dem):
    traj = trajectory(dem, LAT0, LON0, H_MSL, lambda t: 80.0, lambda t: math.radians(30.0), 61)
    nav = AcqTrackNavigator(dem=dem, bias_mitigation="els")
    nav.reset(initial_estimate(traj, H_MSL, sigma_m=20.0))
    ests, truth = fly(nav, dem, traj, H_MSL, 60)
    last = ests[-1]
    assert last.extra["lock_state"] == "tracking" and last.health.status == "ok"
    assert horizontal_error_m(last, truth[-1, 0], truth[-1, 1]) < 50.0


def test_bad_mitigation_and_cost_are_refused_by_name(dem):
    with pytest.raises(ValueError, match="bias_mitigation"):
        AcqTrackNavigator(dem=dem, bias_mitigation="double_delta")
    with pytest.raises(ValueError, match="correlation"):
        AcqTrackNavigator(dem=dem, correlation="ssd")


# ------------------------------------------------------------------------------ bounded serial search


@pytest.mark.parametrize("cost", ["mad", "msd", "pearson"])
def test_bounded_search_decides_as_the_exhaustive_one(dem, cost):
    """The early-abandoning search gives the exhaustive kernel's best cell, cost and distinct verdict, with a
    noisy profile (3 m) and a noise-free one, inside the default uncertainty."""
    rng = np.random.default_rng(4)
    heights, lat0, lon0, dlat, dlon = dem.grid
    n = 25
    dts, z = _transect(n)
    code = correlation.COSTS[cost]
    verdicts = []
    for trial in range(3):  # noise-free, 3 m noise, a profile of pure noise (no terrain in it)
        lat_s = lat0 + dlat * heights.shape[0] * (0.35 + 0.15 * trial)
        lon_s = lon0 + dlon * heights.shape[1] * (0.6 - 0.1 * trial)
        r_n, r_e = radii_m(lat_s)
        track = math.radians(33.7 + 40.0 * trial)
        d = _bf_heights(dem.grid, lat_s, lon_s, dts, 81.3, track, r_n, r_e)
        if trial == 1:
            d = d + 3.0 * rng.standard_normal(n)
        elif trial == 2:
            d = 400.0 + 20.0 * rng.standard_normal(n)
        valid = np.ones(n, bool)
        valid[3] = False
        kw = dict(
            position_half_m=300.0, position_bin_m=50.0, speed_half_mps=6.0, speed_bin_mps=1.0,
            heading_half_rad=math.radians(6.0), heading_bin_rad=math.radians(1.0), cost=code,
            remove_bias=True, n_min=10, distinct_ratio=0.9, exclusion_m=200.0,
        )  # fmt: skip
        lat_c, lon_c, bv0, bp0 = lat_s + 120.0 / r_n, lon_s - 180.0 / r_e, 84.0, track - math.radians(4.0)
        res = acquisition.serial_search(dem.record(), lat_c, lon_c, dts, z, z, bv0, bp0, r_n, r_e, d, valid,
                                        **kw)
        dn = acquisition.hypothesis_grid(300.0, 50.0)
        bv = bv0 + acquisition.hypothesis_grid(6.0, 1.0)
        bp = bp0 + acquisition.hypothesis_grid(math.radians(6.0), math.radians(1.0))
        out = np.empty((dn.size, dn.size, bv.size, bp.size))
        acquisition.search_kernel(
            dem.record(), lat_c, lon_c, (dn, dn.copy(), bv, bp), correlation.Motion(dts, z, z, r_n, r_e),
            correlation.Profile(d, valid, code, True, 10), out,
        )  # fmt: skip
        ref = acquisition._decide(out, dn, dn.copy(), bv, bp, 0.9, 200.0)
        assert (res.distinct, res.dn_m, res.de_m, res.b_v, res.b_psi_rad) == (
            ref.distinct, ref.dn_m, ref.de_m, ref.b_v, ref.b_psi_rad,
        )  # fmt: skip
        verdicts.append(ref.distinct)
        assert np.isfinite(ref.cost)
        assert res.cost == ref.cost
        assert res.second_cost <= ref.second_cost + 1e-12
        if not ref.distinct:
            assert res.second_cost == ref.second_cost
    assert verdicts[0] and verdicts[1]
    if cost == "mad":  # the no-distinct-minimum verdict is exercised too
        assert not verdicts[2]
