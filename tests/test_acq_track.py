"""The acquisition-and-tracking TRN (seed 001): kernels against numpy twins, acquisition within one bin,
tracking of ramps, recovery from a speed step in about one transect, integrity, bad settings and samples.

Data: noise-free kinematic frames over the bundled Jacksboro DEM (tests/acq_track_helpers.py), so the
truth is exact and independent of the navigator."""

from __future__ import annotations

import math

import numpy as np
import pytest
from acq_track_helpers import (
    H_MSL,
    LAT0,
    LON0,
    fly,
    frames_for,
    horizontal_error_m,
    initial_estimate,
    radii_m,
    trajectory,
)
from trn_env.navigators import registry
from trn_env.navigators.acquisition_tracking import (
    AcqTrackConfig,
    AcqTrackNavigator,
    acquisition,
    correlation,
    loop_kernel,
    tracking,
)
from trn_env.navigators.acquisition_tracking.integrity import OutputAverage, terrain_snr_db
from trn_env.navigators.acquisition_tracking.profile import plumb_height_m
from trn_env.navigators.protocol import EXTRA_INNOVATION, EXTRA_MEASUREMENT_TIME, EXTRA_NIS

from trn_env import terrain


@pytest.fixture(scope="module")
def dem():
    return terrain.load("jacksboro")


def _profile(dem, lat_s, lon_s, n, speed, track, dt=1.0):
    """Noise-free measured heights of a constant-speed, constant-track transect (the DEM at the truth)."""
    r_n, r_e = radii_m(lat_s)
    dts = np.full(n, dt)
    dts[0] = 0.0
    la, lo = correlation.replica_positions_reference(
        lat_s, lon_s, dts, np.zeros(n), np.zeros(n), speed, track, r_n, r_e
    )
    return np.asarray(dem.height(la, lo), float), dts, r_n, r_e


# ------------------------------------------------------------------------------------------ kernels


def test_kernels_match_numpy_twins(dem):
    rng = np.random.default_rng(3)
    n = 25
    d, dts, r_n, r_e = _profile(dem, LAT0, LON0, n, 80.0, math.radians(30.0))
    m_v = 2.0 * rng.standard_normal(n)
    m_psi = 0.05 * rng.standard_normal(n)
    dla, dlo = np.empty(n), np.empty(n)
    correlation.replica_offsets(dts, m_v, m_psi, 78.0, 0.4, r_n, r_e, dla, dlo)
    la, lo = correlation.replica_positions_reference(LAT0, LON0, dts, m_v, m_psi, 78.0, 0.4, r_n, r_e)
    np.testing.assert_allclose(LAT0 + dla, la, rtol=0, atol=1e-12)
    np.testing.assert_allclose(LON0 + dlo, lo, rtol=0, atol=1e-12)
    valid = rng.random(n) > 0.2
    h = d + 5.0 * rng.standard_normal(n) + 12.0
    h[3] = np.nan  # off the map
    for cost in ("mad", "pearson"):
        for rb in (True, False):
            got = correlation.profile_cost(d, valid, h, correlation.COSTS[cost], rb, 5)
            assert got == pytest.approx(
                correlation.profile_cost_reference(d, valid, h, cost, rb, 5), abs=1e-10
            )
    # a plain MAD by hand
    ok = valid & np.isfinite(h)
    assert correlation.profile_cost(d, valid, h, 0, False, 1) == pytest.approx(np.mean(np.abs(d[ok] - h[ok])))
    assert correlation.profile_cost(d, valid, h, 0, False, 99) == np.inf


def test_serial_search_kernel_matches_brute_force(dem):
    n = 15
    d, dts, r_n, r_e = _profile(dem, LAT0, LON0, n, 80.0, math.radians(30.0))
    valid = np.ones(n, bool)
    kw = dict(
        position_half_m=100.0,
        position_bin_m=50.0,
        speed_half_mps=2.0,
        speed_bin_mps=1.0,
        heading_half_rad=math.radians(2.0),
        heading_bin_rad=math.radians(1.0),
        distinct_ratio=0.8,
        exclusion_m=60.0,
    )
    args = (dem.record(), LAT0 + 30.0 / r_n, LON0, dts, np.zeros(n), np.zeros(n), 79.0, math.radians(31.0),
            r_n, r_e, d, valid)
    fast = acquisition.serial_search(*args, cost=0, remove_bias=True, n_min=5, **kw)
    ref = acquisition.serial_search_reference(*args, n_min=5, **kw)
    assert (fast.dn_m, fast.de_m, fast.b_v, fast.b_psi_rad) == pytest.approx(
        (ref.dn_m, ref.de_m, ref.b_v, ref.b_psi_rad)
    )
    assert fast.cost == pytest.approx(ref.cost, abs=1e-9)
    assert fast.n_hypotheses == 5 * 5 * 5 * 5


def test_acquisition_recovers_speed_heading_start_within_one_bin(dem):
    """Noise-free profile; the estimate is off by +7.4 m/s, -6.3 deg, (+320, -410) m inside the default
    uncertainty (+-10 m/s, +-10 deg, +-500 m); truth lies between the grid's cells."""
    cfg = AcqTrackConfig()
    n = cfg.transect_samples
    v_true, psi_true = 81.3, math.radians(33.7)
    d, dts, r_n, r_e = _profile(dem, LAT0, LON0, n, v_true, psi_true)
    lat_c, lon_c = LAT0 + 320.0 / r_n, LON0 - 410.0 / r_e
    res = acquisition.serial_search(
        dem.record(),
        lat_c,
        lon_c,
        dts,
        np.zeros(n),
        np.zeros(n),
        v_true + 7.4,
        psi_true - math.radians(6.3),
        r_n,
        r_e,
        d,
        np.ones(n, bool),
        cost=0,
        remove_bias=True,
        n_min=10,
        **acquisition.search_grid(cfg),
    )
    assert res.distinct
    assert res.n_hypotheses == 21 * 21 * 21 * 21
    tol = 1e-9
    assert abs(res.b_v - v_true) <= cfg.acquisition_speed_bin_mps + tol
    assert abs(math.degrees(res.b_psi_rad - psi_true)) <= cfg.acquisition_heading_bin_deg + tol
    assert abs(res.dn_m - (-320.0)) <= cfg.acquisition_position_bin_m + tol
    assert abs(res.de_m - 410.0) <= cfg.acquisition_position_bin_m + tol


def test_navigator_acquires_then_tracks(dem):
    """Unaided navigator started 500 m / 7 m/s / 6 deg off with a 300 m sigma: it acquires, then tracks."""
    traj = trajectory(dem, LAT0, LON0, H_MSL, lambda t: 81.0, lambda t: math.radians(33.0), 80.0)
    nav = AcqTrackNavigator(dem=dem, aiding=False)
    nav.reset(
        initial_estimate(
            traj, H_MSL, sigma_m=300.0, dn_m=300.0, de_m=-400.0, dv_mps=7.0, dpsi_rad=math.radians(-6.0)
        )
    )
    ests, truth = fly(nav, dem, traj, H_MSL, 60)
    assert nav.acquisitions >= 1
    assert any("acquired" in m for e in ests for _, m in e.health.events)
    last = ests[-1]
    assert last.health.status == "ok" and last.extra["lock_state"] == "tracking"
    assert horizontal_error_m(last, truth[-1, 0], truth[-1, 1]) < 50.0
    assert abs(last.extra["tracked_speed_mps"] - 81.0) < 0.5
    assert abs(last.extra["tracked_track_deg"] - 33.0) < 0.5
    for key in (
        EXTRA_INNOVATION,
        EXTRA_NIS,
        EXTRA_MEASUREMENT_TIME,
        "snr_db",
        "speed_spacing_mps",
        "heading_spacing_deg",
        "lock_state",
        "v_shape",
    ):
        assert key in last.extra


# ------------------------------------------------------------------------------------------ tracking


def test_early_late_stage_is_the_discriminator_by_hand(dem):
    """The speed loop's first stage (loop_epoch, no bias mitigation) from 81.5 m/s at the spacing its
    adaptivity block chose lands where discriminator (3.5) iterated by hand on a brute-force cost (numpy
    replica positions, the batch bilinear kernel, the mean-removed MAD written out) does, near the truth."""
    n = 25
    d, dts, r_n, r_e = _profile(dem, LAT0, LON0, n, 80.0, math.radians(30.0))
    valid = np.ones(n, bool)
    zeros = np.zeros(n)
    h = np.empty(n)

    def cost(x):
        la, lo = correlation.replica_positions_reference(
            LAT0, LON0, dts, zeros, zeros, x, math.radians(30.0), r_n, r_e
        )
        terrain.kernels.bilinear_batch(*dem.grid, la, lo, h)
        r = d - h
        return float(np.mean(np.abs(r - r.mean())))

    out = loop_kernel.loop_epoch(
        dem.record(), LAT0, LON0, correlation.Motion(dts, zeros, zeros, r_n, r_e), 81.5, math.radians(30.0),
        correlation.Profile(d, valid, 0, True, 5), 0, (3.68, np.array([2.4, 1.92, 1.44, 0.96, 0.48]), 0.005,
        0.24, 0.002), (10, 2.0, 101, tracking.DISC_THESIS, loop_kernel.MITIGATION_NONE), zeros, zeros,
    )  # fmt: skip
    x, it, locked, s = out[0], out[1], out[4], out[11]
    xr, itr, lockr = 81.5, 101, False
    for k in range(1, 101):
        he, hl = cost(xr - s), cost(xr + s)
        eps = s * (he - hl) / (he + hl)
        xr += eps
        if abs(eps) < 0.005:
            itr, lockr = k, True
            break
    assert locked and lockr and abs(it - itr) <= 1
    assert x == pytest.approx(xr, abs=0.01)
    assert abs(x - 80.0) < 0.3


def _run(dem, speed_fn, track_fn, t_end, tas_fn=None, hdg_fn=None, **settings):
    traj = trajectory(dem, LAT0, LON0, H_MSL, speed_fn, track_fn, t_end + 1)
    nav = AcqTrackNavigator(dem=dem, **settings)
    nav.reset(initial_estimate(traj, H_MSL, sigma_m=20.0))
    ests, truth = fly(nav, dem, traj, H_MSL, t_end, tas_fn=tas_fn, hdg_fn=hdg_fn)
    return nav, ests, truth


def test_aided_loops_follow_ramps_with_a_biased_air_data(dem):
    """Speed ramp 0.1 m/s^2 and heading ramp 0.3 deg/s; the air data read 3 m/s slow and the compass 2 deg
    off (a constant bias the one unknown reference absorbs)."""
    v = lambda t: 78.0 + 0.1 * max(0.0, t - 40.0)  # noqa: E731
    p = lambda t: math.radians(20.0 + 0.3 * max(0.0, t - 40.0))  # noqa: E731
    nav, ests, truth = _run(
        dem,
        v,
        p,
        110,
        tas_fn=lambda t: v(t) - 3.0,
        hdg_fn=lambda t: p(t) - math.radians(2.0),
        wind_estimation=False,
        reference_frame="speed_track",  # a constant speed / heading sensor bias: the thesis' reference
    )
    tail = range(45, 110)
    dv = np.array([ests[k].extra["tracked_speed_mps"] - truth[k, 2] for k in tail])
    dp = np.array([ests[k].extra["tracked_track_deg"] - math.degrees(truth[k, 3]) for k in tail])
    err = np.array([horizontal_error_m(ests[k], truth[k, 0], truth[k, 1]) for k in tail])
    locked = np.mean([ests[k].extra["lock_state"] == "tracking" for k in tail])
    assert locked > 0.8
    assert np.sqrt(np.mean(dv**2)) < 0.5 and np.sqrt(np.mean(dp**2)) < 0.5
    assert err.max() < 60.0


def test_unaided_loop_follows_a_slow_ramp(dem):
    v = lambda t: 80.0 + 0.02 * t  # noqa: E731  (0.5 m/s per 25-sample transect)
    nav, ests, truth = _run(dem, v, lambda t: math.radians(30.0), 90, aiding=False)
    dv = np.array([ests[k].extra["tracked_speed_mps"] - truth[k, 2] for k in range(40, 90)])
    assert np.sqrt(np.mean(dv**2)) < 0.6  # the constant-speed replica lags half a transect's ramp


def test_speed_step_recovers_in_about_one_transect(dem):
    """The air data's bias steps by 3 m/s at 50 s (e.g. a wind shear): the aided loop's reference is back
    within 0.5 m/s after about one transect of N = 25 samples (chapter 4). That is the thesis' loop, all of
    each epoch's correction into the reference (reference_gain = 1); the air-data default 0.1 trades the
    step response for less noise (settings.py)."""
    v = lambda t: 80.0  # noqa: E731
    nav, ests, truth = _run(
        dem,
        v,
        lambda t: math.radians(30.0),
        130,
        tas_fn=lambda t: 80.0 + (3.0 if t >= 50.0 else 0.0),
        wind_estimation=False,
        reference_gain=1.0,
        reference_frame="speed_track",  # the thesis' loop (the "ne" frame is a filter, settings.py)
    )
    dv = np.array([e.extra["tracked_speed_mps"] - 80.0 for e in ests])
    assert abs(dv[48]) < 0.5 and dv[52] > 1.0  # the step reaches the output
    back = next(k for k in range(52, 130) if np.all(np.abs(dv[k : k + 10]) < 0.5))
    n = nav.config.transect_samples
    assert 0.3 * n <= back - 50 <= 2.0 * n


def test_flat_terrain_out_of_lock_not_a_wrong_position(dem):
    """A flat map: SNR < 5 dB, the tracker says it is out of lock (health not ok) instead of a fix: "lost" or
    "degraded" after a lock, or still "acquiring" (the search deferred by the predicted SNR) without one."""
    flat = dem.with_heights(np.full_like(dem.heights_m, 300.0), name="flat")
    traj = trajectory(flat, LAT0, LON0, H_MSL, lambda t: 80.0, lambda t: math.radians(30.0), 70)
    nav = AcqTrackNavigator(dem=flat)
    nav.reset(initial_estimate(traj, H_MSL, sigma_m=20.0))
    ests, truth = fly(
        nav,
        flat,
        traj,
        H_MSL,
        60,
        ra_override=lambda t, r: r + np.random.default_rng(int(t[0])).standard_normal(r.size),
    )
    late = ests[-10:]
    assert all(not e.health.ok and e.health.status in ("lost", "degraded", "acquiring") for e in late)
    assert all(e.extra["snr_db"] < 5.0 for e in late)
    sig = [math.sqrt(e.covariance[0, 0] + e.covariance[1, 1]) for e in ests[30:]]
    assert sig[-1] > sig[0]  # the covariance grows with what the loops cannot see


# ------------------------------------------------------------------------------------------ integrity


def test_snr_moving_average_and_roll_compensation():
    h = np.array([0.0, 10.0, 20.0, 10.0, 0.0])
    d = h + 3.0  # a bias only: mean-removed residual 0, a-priori sigma rules
    snr, res = terrain_snr_db(h, d, np.ones(5, bool), 2.0)
    assert res == pytest.approx(0.0) and snr == pytest.approx(10 * math.log10(np.var(h) / 4.0))
    avg = OutputAverage(3, 0.5, math.radians(0.5))
    for x in (80.0, 80.2, 80.4, 80.6):
        out = avg.push(x, 0.0)
    assert out[0] == pytest.approx(80.4) and len(avg) == 3
    assert avg.push(83.0, 0.0)[0] == pytest.approx(83.0)  # disagreement restarts it
    # level ground, 20 deg roll in a 17 deg beam: the shortest range is along the cone edge at 11.5 deg
    r = 1000.0 / math.cos(math.radians(20.0 - 8.5))
    assert float(plumb_height_m(r, math.radians(20.0), 0.0, 17.0)) == pytest.approx(1000.0)
    assert float(plumb_height_m(1000.0, math.radians(5.0), 0.0, 17.0)) == pytest.approx(1000.0)


# ------------------------------------------------------------------------------------------ bad input


@pytest.mark.parametrize(
    "settings, word",
    [
        ({"transect_samples": 4}, "transect_samples"),
        ({"transect_samples": 25.5}, "transect_samples"),
        ({"speed_spacings_mps": [0.5, -1.0]}, "speed_spacings_mps"),
        ({"heading_spacings_deg": []}, "heading_spacings_deg"),
        ({"speed_threshold_mps": -0.001}, "speed_threshold_mps"),
        ({"heading_narrow_threshold_deg": float("nan")}, "heading_narrow_threshold_deg"),
        ({"speed_narrow_spacing_mps": 0.0}, "speed_narrow_spacing_mps"),
        ({"acquisition_speed_half_mps": 0.0}, "acquisition_speed_half_mps"),
        ({"acquisition_heading_half_deg": 0.2}, "acquisition_heading_half_deg"),
        ({"correlation": "ssd"}, "correlation"),
        ({"aiding_source": "doppler"}, "aiding_source"),
        ({"symmetry_ratio_max": 0.5}, "symmetry_ratio_max"),
        ({"break_iteration": 1}, "break_iteration"),
        ({"bogus": 1}, "bogus"),
    ],
)
def test_bad_settings_are_refused_by_name(dem, settings, word):
    with pytest.raises(ValueError, match=word):
        registry.create("acq_track", dem=dem, **settings)


def test_required_sensors_follow_the_aiding_setting(dem):
    assert {s for s, _ in AcqTrackNavigator(dem=dem).required_sensors()} == {
        "radar_altimeter",
        "baro",
        "air_data",
        "heading",
    }
    assert {s for s, _ in AcqTrackNavigator(dem=dem, aiding=False).required_sensors()} == {
        "radar_altimeter",
        "baro",
    }
    assert "imu" in {s for s, _ in AcqTrackNavigator(dem=dem, aiding_source="ins").required_sensors()}


def test_bad_samples_drop_out_never_crash(dem):
    """No-returns, NaN ranges, a missing baro frame and a flight off the map's edge: health notes, finite
    estimates, no exception."""
    traj = trajectory(dem, LAT0, LON0, H_MSL, lambda t: 80.0, lambda t: math.radians(30.0), 70)
    nav = AcqTrackNavigator(dem=dem)
    nav.reset(initial_estimate(traj, H_MSL, sigma_m=20.0))

    def holes(t, r):
        r = r.copy()
        r[(t > 30) & (t < 36)] = np.nan
        return r

    ests = []
    for k in range(60):
        fr = frames_for(dem, traj, H_MSL, float(k), float(k + 1), ra_override=holes)
        if k in (40, 41):  # (at 40 s the 39.95 s baro sample still serves)
            fr.baro = None
        if k == 45:
            fr.radar_altimeter = None
        ests.append(nav.update(fr))
    sk = ests[-1].health.skipped
    assert sk.get("radar_no_return", 0) >= 5 and sk.get("baro_missing", 0) >= 1
    assert sk.get("no_radar_altimeter", 0) == 1
    assert all(math.isfinite(e.lat_rad) and math.isfinite(e.lon_rad) for e in ests)
    assert ests[-1].health.status in ("ok", "degraded")
    # off the map: start 3 km inside the west edge flying west
    lat_min, lat_max, lon_min, _ = dem.bounds
    lat_e = 0.5 * (lat_min + lat_max)
    lon_e = lon_min + 3000.0 / radii_m(lat_e)[1]
    traj2 = trajectory(dem, lat_e, lon_e, H_MSL, lambda t: 80.0, lambda t: math.radians(270.0), 90)
    nav2 = AcqTrackNavigator(dem=dem)
    nav2.reset(initial_estimate(traj2, H_MSL, sigma_m=20.0))
    ests2, _ = fly(nav2, dem, traj2, H_MSL, 80)
    assert all(math.isfinite(e.lat_rad) for e in ests2)
    assert ests2[-1].health.status in ("lost", "degraded") and not ests2[-1].health.ok


def test_same_frames_same_estimates_bit_for_bit(dem):
    """No randomness and no wall time in the output: two navigators on the same frames agree exactly
    (acquisition included)."""
    traj = trajectory(dem, LAT0, LON0, H_MSL, lambda t: 81.0, lambda t: math.radians(33.0), 50.0)
    runs = []
    for _ in range(2):
        nav = AcqTrackNavigator(dem=dem, aiding=False)
        nav.reset(initial_estimate(traj, H_MSL, sigma_m=300.0, dn_m=200.0, dv_mps=3.0))
        ests, _ = fly(nav, dem, traj, H_MSL, 40)
        runs.append(ests)
    assert any("acquired" in m for e in runs[0] for _, m in e.health.events)
    for a, b in zip(*runs, strict=True):
        assert (a.lat_rad, a.lon_rad, a.h_m) == (b.lat_rad, b.lon_rad, b.h_m)
        assert np.array_equal(a.covariance, b.covariance)
        assert a.health.events == b.health.events
        assert a.extra["snr_db"] == b.extra["snr_db"] or (
            math.isnan(a.extra["snr_db"]) and math.isnan(b.extra["snr_db"])
        )


@pytest.mark.parametrize(
    "settings",
    [
        {"loop_order": "heading_first"},
        {"correlation": "pearson"},
        {"interpolation": "bicubic"},
        {"bias_mitigation": "none"},
        {"discriminator": "v_fit"},
        {"transect_samples": 15, "remove_bias": False},
    ],
)
def test_named_choices_all_track(dem, settings):
    """Every choice the thesis leaves open is a working setting: noise-free constant flight, in lock,
    within 50 m at the end. Without the narrow second stage (bias_mitigation "none") the wide, adaptive
    spacing's bias on an asymmetric V is what is left: 50-100 m here (the default ends within 1 m), so that
    case is held to 150 m."""
    nav, ests, truth = _run(dem, lambda t: 80.0, lambda t: math.radians(30.0), 60, **settings)
    last = ests[-1]
    assert last.extra["lock_state"] == "tracking"
    bound = 150.0 if settings.get("bias_mitigation") == "none" else 50.0
    assert horizontal_error_m(last, truth[-1, 0], truth[-1, 1]) < bound


def test_footprint_dilation_by_hand(dem):
    """One 100 m peak on a flat map: the footprint map at a post rho from it holds
    max(flat, peak - rho^2 / (2 a)) inside the beam's radius a tan(8.5 deg), the flat height outside."""
    from trn_env.navigators.acquisition_tracking.footprint import FootprintMaps

    h = np.full_like(dem.heights_m, 200.0)
    i0, j0 = 200, 200
    h[i0, j0] = 300.0
    fm = FootprintMaps(dem.with_heights(h, name="spike"), 17.0)
    a = 1200.0
    heights = fm.grid(a)[0]
    dn, de = (float(x) for x in dem.spacing_m)
    r = a * math.tan(math.radians(8.5))
    for di, dj in ((0, 0), (0, 1), (1, 0), (1, 1), (0, 2), (2, 2)):
        rho = math.hypot(di * dn, dj * de)
        want = max(200.0, 300.0 - rho**2 / (2 * a)) if rho <= r else 200.0
        assert heights[i0 + di, j0 + dj] == pytest.approx(want)
    assert fm.grid(a)[0] is heights  # cached per 50 m band
    assert fm.grid(float("nan"))[0] is fm.dem.heights_m
