"""World vs map: synthetic terrain statistics, refinement spectrum continuation, map error models."""

import numpy as np
import pytest
from trn_env.terrain import map_error, refine, spectrum, synthetic

from trn_env import terrain


def test_synthetic_statistics_and_seeding():
    a = synthetic.generate(
        256, 256, 30.0, rms_height_m=50.0, correlation_length_m=600.0, hurst=0.7, mean_height_m=400.0, seed=7
    )
    b = synthetic.generate(
        256, 256, 30.0, rms_height_m=50.0, correlation_length_m=600.0, hurst=0.7, mean_height_m=400.0, seed=7
    )
    c = synthetic.generate(
        256, 256, 30.0, rms_height_m=50.0, correlation_length_m=600.0, hurst=0.7, mean_height_m=400.0, seed=8
    )
    np.testing.assert_array_equal(a.heights_m, b.heights_m)
    assert not np.array_equal(a.heights_m, c.heights_m)
    assert a.heights_m.std() == pytest.approx(50.0, rel=1e-9)
    assert a.heights_m.mean() == pytest.approx(400.0, abs=1e-6)
    assert a.spacing_m[0] == pytest.approx(30.0, rel=1e-3) and a.spacing_m[1] == pytest.approx(30.0, rel=1e-3)
    # above 1/L the spectrum is a power law of slope -2(H + 1) = -3.4
    f, p = spectrum.radial_psd(a.heights_m, 30.0, 30.0)
    _, beta = spectrum.fit_power_law(f, p, 2.0 / 600.0, 0.4 / 30.0)
    assert beta == pytest.approx(3.4, abs=0.2)


def test_synthetic_presets_and_load_dispatch():
    flat = terrain.load("synthetic:flat")
    mountains = synthetic.from_preset("mountainous", seed=1)
    assert flat.heights_m.std() == pytest.approx(synthetic.PRESETS["flat"].rms_height_m, rel=1e-6)
    assert mountains.heights_m.std() > 50 * flat.heights_m.std()
    with pytest.raises(ValueError, match="unknown synthetic terrain preset"):
        terrain.load("synthetic:alps")


def test_refine_continues_the_coarse_spectrum_and_keeps_the_posts():
    coarse = terrain.load("jacksboro")
    lat_c, lon_c = coarse.center_rad
    region = (lat_c - 0.0008, lat_c + 0.0008, lon_c - 0.001, lon_c + 0.001)  # ~10 x 10 km
    fine = refine.refine(coarse, spacing_m=10.0, seed=4, region=region)
    assert fine.spacing_m[0] < 10.0 and fine.spacing_m[1] < 10.0
    c0, beta0, f_nyq = refine.fit_dem_spectrum(coarse.subset(*region))
    f, p = spectrum.radial_psd(fine.heights_m, *fine.spacing_m)
    _, beta_hi = spectrum.fit_power_law(f, p, 1.5 * f_nyq, 0.5 * 0.05)  # the synthesised band
    assert beta_hi == pytest.approx(beta0, abs=0.4)
    # the detail carries power where the coarse grid has none: the PSD at 3 x the coarse Nyquist continues
    # the fitted law within a factor of 2
    k = np.argmin(np.abs(f - 3 * f_nyq))
    assert 0.5 < p[k] / (c0 * f[k] ** -beta0) < 2.0
    # heights at the coarse posts are the coarse heights
    la = coarse.lat_rad[(coarse.lat_rad >= fine.bounds[0]) & (coarse.lat_rad <= fine.bounds[1])]
    lo = coarse.lon_rad[(coarse.lon_rad >= fine.bounds[2]) & (coarse.lon_rad <= fine.bounds[3])]
    LA, LO = np.meshgrid(la, lo, indexing="ij")
    np.testing.assert_allclose(fine.height(LA, LO), coarse.height(LA, LO), atol=1e-6)
    # and between posts it differs (detail was added), with a plausible amplitude
    mid = fine.height(LA[:-1, :-1] + 0.5 * coarse.dlat_rad, LO[:-1, :-1] + 0.5 * coarse.dlon_rad)
    smooth = coarse.height(
        LA[:-1, :-1] + 0.5 * coarse.dlat_rad, LO[:-1, :-1] + 0.5 * coarse.dlon_rad, "bicubic"
    )
    assert 0.05 < np.std(mid - smooth) < 20.0


def test_refine_bad_arguments():
    coarse = terrain.load("jacksboro")
    with pytest.raises(ValueError, match="not finer"):
        refine.refine(coarse, spacing_m=200.0)
    with pytest.raises(ValueError, match="max_posts"):
        refine.refine(coarse, spacing_m=1.0)


_REFINEMENTS = [{"spacing_m": 30.0}, {"spacing_m": 200.0}, {"spacing_m": 1.0}, {"spacing_m": -5.0},
                 {"spacing_m": 30.0, "region_deg": [36.47, 36.56, -84.40, -84.33]},
                 {"spacing_m": 10.0, "region_deg": [36.47, 36.56, -84.40, -84.33], "detail": False},
                 {"spacing_m": 30.0, "region_deg": [10.0, 11.0, 20.0, 21.0]},
                 {"spacing_m": 30.0, "region_deg": [36.56, 36.47, -84.40, -84.33]},
                 {"spacing_m": 30.0, "extent": 3}]


@pytest.mark.parametrize("settings", _REFINEMENTS, ids=lambda s: str(s))
def test_refinement_check_refuses_exactly_what_refining_refuses(settings):
    """The scenario validation's check of [terrain.world.refinement] (without building the grid) raises the
    same error as building it does, for accepted and refused settings alike; refine's plan is the grid it
    builds."""
    from trn_env.scenario.maps import check_refinement, refine_dem
    coarse = terrain.load("jacksboro")

    def outcome(call):
        try:
            return call()
        except (ValueError, TypeError) as exc:
            return type(exc), str(exc)

    built = outcome(lambda: refine_dem(coarse, settings, np.random.default_rng(0)))
    checked = outcome(lambda: check_refinement(coarse, settings))
    if isinstance(built, tuple):
        assert checked[0] is built[0] and checked[1] == built[1]
    else:
        assert checked is None
        kw = {k: v for k, v in settings.items() if k in ("spacing_m",)}
        if "region_deg" in settings:
            kw["region"] = tuple(np.radians(settings["region_deg"]))
        plan = refine.refinement_plan(coarse, **kw)
        np.testing.assert_array_equal(plan.lat_rad, built.lat_rad)
        np.testing.assert_array_equal(plan.lon_rad, built.lon_rad)


def test_a_scenario_validates_its_refinement_without_building_it(monkeypatch):
    """Loading a scenario checks its refinement's settings but builds no refined grid (a tenth of a second
    and more per variant of a campaign); a bad one is still a problem at its field."""
    from trn_env.scenario import ScenarioError, load_scenario
    from trn_env.scenario.loading import read_scenario_file

    def refuse(*a, **k):
        raise AssertionError("the refined grid was built during validation")

    monkeypatch.setattr(refine, "_power_law_band", refuse)
    monkeypatch.setattr(refine, "_bicubic_grid", refuse)
    sc = load_scenario("default", seed=4)
    assert sc.terrain.world.refinement.spacing_m == 30.0
    data, _ = read_scenario_file("default")
    data["terrain"]["world"]["refinement"] = {"spacing_m": 500.0}
    with pytest.raises(ScenarioError, match=r"terrain\.world\.refinement.*not finer than the DEM"):
        load_scenario(data)


def test_map_error_components():
    world = synthetic.generate(
        200, 200, 90.0, rms_height_m=100.0, correlation_length_m=1500.0, hurst=0.8, seed=2
    )
    lat_c, lon_c = world.center_rad
    # bias and tilt: exact
    m = map_error.apply(world, map_error.MapErrorModel(bias_m=12.0, tilt_n=1e-3, tilt_e=-2e-3))
    la, lo = world.offset_to_latlon(lat_c, lon_c, 3000.0, 2000.0)
    assert m.height(la, lo) - world.height(la, lo) == pytest.approx(12.0 + 3.0 - 4.0, abs=0.05)
    # horizontal shift: the map at p + shift equals the world at p
    shifted = map_error.apply(world, map_error.MapErrorModel(shift_n_m=150.0, shift_e_m=-90.0))
    post_lat, post_lon = world.lat_rad[120], world.lon_rad[77]  # a map post
    src_lat, src_lon = world.offset_to_latlon(post_lat, post_lon, -150.0, 90.0)
    assert shifted.height(post_lat, post_lon) == pytest.approx(
        world.height(src_lat, src_lon, "bicubic"), abs=0.05
    )
    assert abs(shifted.height(post_lat, post_lon) - world.height(post_lat, post_lon)) > 1.0
    # correlated random error: requested sigma and correlation length
    noisy = map_error.apply(
        world, map_error.MapErrorModel(random_sigma_m=5.0, correlation_length_m=900.0), seed=3
    )
    err = noisy.heights_m - world.heights_m
    assert err.std() == pytest.approx(5.0, rel=1e-6)
    lag = 10  # posts = 900 m: covariance exp(-d^2 / 2 L^2) = exp(-0.5)
    rho = np.mean(err[:, :-lag] * err[:, lag:]) / err.var()
    assert rho == pytest.approx(np.exp(-0.5), abs=0.15)
    # coarser resolution: DTED-0 posts (30 arcsec)
    coarse = map_error.apply(world, map_error.MapErrorModel(spacing_arcsec=30.0))
    assert np.degrees(coarse.dlat_rad) * 3600 == pytest.approx(30.0)
    assert coarse.n_lat < world.n_lat / 8


def test_accuracy_class_presets_match_table_1():
    srtm = map_error.ACCURACY_CLASSES["srtm"]
    assert (srtm.spacing_arcsec, srtm.ce90_m, srtm.le90_m) == (3.0, 15.0, 16.0)
    carto = map_error.ACCURACY_CLASSES["cartodem"]
    assert (carto.ce90_m, carto.le90_m) == (15.0, 8.0)
    assert map_error.ACCURACY_CLASSES["aster"].ce90_m == 17.0
    # realisations: shifts and vertical errors have the class's 90 % figures
    rng = np.random.default_rng(0)
    models = [map_error.model_for_class("srtm", rng) for _ in range(4000)]
    radial = np.hypot([m.shift_n_m for m in models], [m.shift_e_m for m in models])
    assert np.quantile(radial, 0.9) == pytest.approx(15.0, rel=0.06)
    total_sigma = np.sqrt(np.var([m.bias_m for m in models]) + models[0].random_sigma_m ** 2)
    assert 1.6449 * total_sigma == pytest.approx(16.0, rel=0.06)
    with pytest.raises(ValueError, match="unknown DEM accuracy class"):
        map_error.model_for_class("lidar")
    world = terrain.load("jacksboro")
    m = map_error.make_map(world, "dted1", seed=5)
    assert m.heights_m.shape == world.heights_m.shape and not np.array_equal(m.heights_m, world.heights_m)
