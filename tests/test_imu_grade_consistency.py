"""Every navigator takes its INS error model from the IMU's specification (navigators.core.imu_spec), says in
Health where its covariance is known not to describe its error, and is consistent on the tactical grade.

The statistical check (slow): one recorded JSBSim flight of the whole default route (DURATION_S is longer
than the route: the flight ends with it at 473 s, its two turns included; GNSS denied from t = 0), RUNS
seeds (SEED0...) each with its own sensor noise, IMU biases, initial error and world detail
(scripts/grade_consistency.py), every navigator built as a scenario builds it (the acq_track as in its
regression scenario, with the INS as its aiding). Per navigator, over the epochs after 15 s: the horizontal
NEES (2 dof) averaged over all epochs of all runs lies inside the
two-sided 99 % chi-square bounds of the decorrelated sample count, chi2.ppf([0.005, 0.995], 2 n) / n
computed here, n the runs times the epochs left when thinned to every k-th (k the lag where the NEES
autocorrelation falls below 0.1: scripts/filter_statistics.pooled_nees_figures; the all-epoch mean averages
the k thinned means, so its spread is at most theirs: scripts/grade_consistency.py), about 1 % false alarms
per navigator; and at least 90 % of all epochs have NEES <= 9 (the 3-sigma ellipse). A navigator whose
covariance the whole-route grid measured conservative on this grade
(navigators.core.measured_consistency.MEASURED, where Health says so; docs/validation/navigators.md) is held
to the upper bound only: it must still bound its error (the rbpf since its regularised resampling). The
pmf passes it by a small margin on these seeds (ANEES 2.59 against the upper bound 2.62, 96 % inside 3
sigma), and so does the ins_tercom with its defaults (2.645 against 2.66, 96 % inside; inside over seeds
1000-1023 and over the 32 pooled); the rbpf with room (1.03 over 56 decorrelated samples, 100 % inside 3
sigma); all measured with scripts/grade_consistency.py on the same seeds (docs/validation/navigators.md).
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from trn_env.navigators.core.imu_spec import (
    VERTICAL_OFFSET_MEMORY_S,
    ImuSpec,
    equivalent_ramp_walk_density,
    equivalent_walk_density,
    gm_drive,
    vertical_offset_walk_density,
)
from trn_env.navigators.core.measured_consistency import (
    CONSERVATIVE,
    MEASURED,
    OVERCONFIDENT,
    VALIDATION_PAGE,
    grade_warning,
    measured_direction,
)
from trn_env.navigators.integrity.consistency_check import ConsistencyCheck
from trn_env.navigators.protocol import Health

from trn_env.scenario.build import build_navigator, imu_spec
from trn_env.scenario.loading import load_scenario
from trn_env.scenario.sections import from_dict

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))

RUNS = 8
SEED0 = 2000
DURATION_S = 600.0
NAVIGATORS = ["ins", "ins_tercom", "pmf", "pf", "rbpf", "acq_track"]
# not in the check: a navigator measured overconfident on the tactical grade over the whole route (Health
# warns; the fast tests check it): none since the rbpf's regularised resampling
# (docs/validation/navigators.md)
NOT_CHECKED: dict[str, str] = {}


def test_imu_spec_from_the_scenario_grade():
    nav, tac = imu_spec({"grade": "navigation"}), imu_spec({"grade": "tactical"})
    g = 9.80665
    assert nav.accel_bias_sigma_mps2 == pytest.approx(50e-6 * g)
    # tactical: 1 mg turn-on, 0.1 mg instability, 0.5 mrad misalignment (trn_env.sensors.imu)
    assert tac.accel_bias_sigma_mps2 == pytest.approx(math.hypot(1e-3 * g, 1e-4 * g))
    assert tac.body_accel_sigma_mps2 == pytest.approx(math.sqrt((1e-3 * g) ** 2 + (1e-4 * g) ** 2
                                                                + (0.5e-3 * g) ** 2))
    assert imu_spec(None) is None and imu_spec({"grade": "no such grade"}) is None
    assert gm_drive(2.0, 100.0, 1.0) == pytest.approx(2.0 * math.sqrt(1.0 - math.exp(-0.02)))
    # a constant rate r over T and the walk q = r^2 T have the same variance at T
    assert equivalent_walk_density(3.0, 50.0) ** 2 * 50.0 == pytest.approx((3.0 * 50.0) ** 2)
    # a ramp 3 t moves the state by 1.5 t^2: the walk matches its variance at T
    assert equivalent_ramp_walk_density(3.0, 50.0) ** 2 * 50.0 == pytest.approx((1.5 * 50.0**2) ** 2)
    with pytest.raises(ValueError, match="gyro_bias_tau_s"):
        ImuSpec(gyro_bias_tau_s=0.0)
    with pytest.raises(ValueError, match="accel_bias_mps2"):
        ImuSpec(accel_bias_mps2=math.nan)


def _sections(name: str, grade: str):
    """The default scenario's typed sections with the grade's IMU and navigator `name` (acq_track with the INS
    as its aiding; the sensors are not checked against the navigator: only its construction is tested)."""
    d = load_scenario("default", navigator="ins_tercom").to_dict()
    settings = {"aiding_source": "ins"} if name == "acq_track" else {}
    return from_dict({**d, "sensors": {**d["sensors"], "imu": {"grade": grade}},
                      "navigator": {"name": name, "settings": settings}})


def test_baro_loop_height_rate_against_the_loop_integrated():
    """The baro loop's transient rate (ImuSpec.baro_loop_height_rate_sigma_mps) against the third-order
    vertical channel integrated step by step (gains 3 / tau, 3 / tau^2, 1 / tau^3, as
    navigators.inertial.strapdown): height error e_h' = e_v - k1 e_h, e_v' = a - k2 e_h - e_b,
    e_b' = k3 e_h, for a step a of vertical specific-force error."""
    spec = imu_spec({"grade": "tactical"})
    a, tau, dt = spec.vertical_accel_sigma_mps2, 30.0, 0.001
    k1, k2, k3 = 3.0 / tau, 3.0 / tau**2, 1.0 / tau**3
    e_h = e_v = e_b = 0.0
    rates, heights = [], []
    for _ in range(int(300.0 / dt)):
        de_h = e_v - k1 * e_h
        e_v += (a - k2 * e_h - e_b) * dt
        e_b += k3 * e_h * dt
        e_h += de_h * dt
        rates.append(de_h)
        heights.append(e_h)
    assert max(rates) == pytest.approx(spec.baro_loop_height_rate_sigma_mps(tau), rel=2e-3)
    assert max(heights) == pytest.approx(2.0 * a * tau**2 * math.exp(-2.0), rel=2e-3)   # at t = 2 tau
    # tactical: 1 mg bias + 0.1 mg instability + 300 ppm x g -> 0.071 m/s; the vertical-offset walk over 20 s
    assert vertical_offset_walk_density(spec, tau) == pytest.approx(
        spec.baro_loop_height_rate_sigma_mps(tau) * math.sqrt(VERTICAL_OFFSET_MEMORY_S))


@pytest.mark.parametrize("name", ["ins_tercom", "pmf", "pf", "rbpf", "acq_track"])
def test_build_navigator_applies_the_grade(name):
    """The tactical grade raises the navigator's error model above the navigation grade's; a navigation-grade
    scenario keeps the tuned figures (they are floors)."""
    from trn_env import terrain
    dem = terrain.load("jacksboro")
    navs = {grade: build_navigator(_sections(name, grade), dem, np.random.default_rng(0))
            for grade in ("navigation", "tactical")}
    n, t = navs["navigation"], navs["tactical"]
    g = 9.80665
    if name == "ins_tercom":
        assert n.sig_ba == pytest.approx(50e-6 * g) and t.sig_ba > 20 * n.sig_ba
        assert t.sig_bg > 100 * n.sig_bg and t._q_tilt > 100 * n._q_tilt
        assert t._turn_tilt2 > 0.0 and n._turn_tilt2 == 0.0
    elif name == "pmf":
        # the baro loop's transient: the vertical specific-force error beta, and the walk as a floor
        assert t.vertical_noise > 1.4 * n.vertical_noise and n.vertical_noise == pytest.approx(0.3, rel=1e-2)
        assert t._beta_sigma == pytest.approx(imu_spec({"grade": "tactical"}).vertical_accel_sigma_mps2)
        assert t._beta_sigma > 10 * n._beta_sigma > 0.0
        assert t.accel_bias_sigma > 20 * n.accel_bias_sigma
        assert t._imu_noise[0] > 100 * n._imu_noise[0] and t._imu_noise[3] > 0.0 == n._imu_noise[3]
    elif name == "pf":
        # default velocity_noise_model "imu_spec": the walk stays the tuned setting, the velocity's noise is
        # the specification's acceleration error (`_velocity_step_var`)
        assert t.s_vel == n.s_vel and t.s_psi > n.s_psi
        # (tests/test_pf_velocity_noise.py checks the model itself); here: the grade reached the filter
        assert n._spec_velocity and t._spec_velocity
        assert t._imu_spec.body_accel_sigma_mps2 > 10 * n._imu_spec.body_accel_sigma_mps2 > 0.0
        assert t._imu_spec.tilt_accel_rate_sigma_mps3 > 10 * n._imu_spec.tilt_accel_rate_sigma_mps3 > 0.0
        assert t.vertical_noise > 1.4 * n.vertical_noise
    elif name == "rbpf":
        # per 1 s TRN epoch: velocity noise = the velocity random walk (tactical 100 ug/sqrt(Hz)), attitude
        # noise = the angle random walk (0.07 deg/sqrt(h)); the navigation grade's 10 ug/sqrt(Hz) stays
        # under the 1e-4 m/s setting
        assert math.sqrt(n.ql_var[0]) == pytest.approx(1e-4)
        assert math.sqrt(t.ql_var[0]) == pytest.approx(100e-6 * g)
        assert math.sqrt(t.ql_var[3]) == pytest.approx(0.07 * math.pi / 180 / 60)
        # x / y accelerometer-bias prior: bias, instability and misalignment x g (1, 0.1 mg, 0.5 mrad)
        assert math.sqrt(t.P0_settings[6, 6]) == pytest.approx(g * math.sqrt(1e-6 + 1e-8 + 0.25e-6))
        assert t._turn_att_var[0] > 0.0 == n._turn_att_var[0]
    else:
        # acq_track with the INS as aiding: the specification's velocity-error growth replaces e_ne's tuned
        # walk from the reset on (ins_error.py; tests/test_acq_track_ins_error.py checks the model); the
        # walk setting stays as given. Tactical: 1.12 mg body-fixed (1, 0.1 mg, 0.5 mrad x g), the tilt ramp
        # g 1.04 deg/h, the velocity random walk 100 ug/sqrt(Hz)
        assert n._imu_spec.grade == "navigation" and t._imu_spec.grade == "tactical"
        assert math.sqrt(n._bias_walk2) == pytest.approx(0.03) == math.sqrt(t._bias_walk2)
        for nav in (n, t):
            nav._start_ins_growth(np.eye(9) * 1e-6, np.array([100.0, 0.0, 0.0]), 0.0)
        assert math.sqrt(t._ins_growth.body2) == pytest.approx(g * math.sqrt(1e-6 + 1e-8 + 0.25e-6))
        ramp = g * math.hypot(1.0, 0.3) * math.pi / 180 / 3600
        assert math.sqrt(t._ins_growth.ramp2) == pytest.approx(ramp)
        assert math.sqrt(t._ins_growth.noise2) == pytest.approx(100e-6 * g)
        assert t._ins_growth.body2 > 100 * n._ins_growth.body2 > 0.0
        assert t.X[2, 2] == n.X[2, 2] == 1e-6   # e_ne's prior: the initial velocity variance


def _chi2_mean_bounds(n: int, p: float) -> tuple[float, float]:
    """Two-sided probability-p bounds on the mean of n independent chi2(2) samples."""
    from scipy.stats import chi2
    return chi2.ppf((1 - p) / 2, 2 * n) / n, chi2.ppf((1 + p) / 2, 2 * n) / n


def test_no_navigator_left_out_of_the_tactical_check():
    assert not set(NAVIGATORS) & set(NOT_CHECKED)
    assert all(measured_direction(n, "tactical") == OVERCONFIDENT for n in NOT_CHECKED)


@pytest.fixture(scope="module")
def tactical_runs() -> dict:
    """Per navigator, its RUNS runs on the one recorded flight (flown once for all the navigators' tests)."""
    import filter_statistics as fs
    import grade_consistency as gc
    flight = fs.record_flight(duration_s=DURATION_S)
    runs = {n: [] for n in NAVIGATORS}
    for s in range(RUNS):
        for n, run in gc.run_seed(flight[0], NAVIGATORS, "tactical", SEED0 + s, flight).items():
            runs[n].append(run)
    return runs


# Known misses (strict: one that comes back inside is reported), with the measured figures
TACTICAL_KNOWN_MISSES: dict[str, str] = {}


# one test per navigator (its own verdict; the runs are shared); as a file of six slow tests pytest-xdist's
# loadfile scheduling also starts it early, beside the other long file
@pytest.mark.slow
@pytest.mark.parametrize("name", [
    pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=TACTICAL_KNOWN_MISSES[n]))
    if n in TACTICAL_KNOWN_MISSES else n for n in NAVIGATORS])
def test_tactical_grade_consistency(name, tactical_runs):
    import filter_statistics as fs
    import grade_consistency as gc
    nees, _ = gc.run_nees(tactical_runs[name], 15.0)
    k = fs.pooled_nees_figures(nees)["thinning_epochs"]
    n_thin = nees[:, ::k].size
    anees = float(nees.mean())
    lo, hi = _chi2_mean_bounds(n_thin, 0.99)
    inside = float(np.mean(nees <= 9.0))
    conservative = measured_direction(name, "tactical") == CONSERVATIVE
    ok = anees <= hi if conservative else lo <= anees <= hi
    print(f"{name}: ANEES {anees:.3f} against [{lo:.3f}, {hi:.3f}], {100 * inside:.1f} % inside 3 sigma")
    assert ok and inside >= 0.9, (
        f"{name}: ANEES {anees:.2f} over {nees.size} epochs ({n_thin} decorrelated: k {k}) "
        f"against [{lo:.2f}, {hi:.2f}]{' (upper only)' if conservative else ''}, "
        f"{100 * inside:.0f} % of epochs inside 3 sigma")


@pytest.mark.parametrize("name", ["ins", "ins_tercom", "pmf", "pf", "rbpf", "acq_track"])
def test_health_warns_on_the_grades_measured_outside(name):
    """Health.consistency_warning from construction on: on the consumer grade (its 100 deg/h gyro bias builds
    more than 0.57 deg of attitude error over every navigator's memory) the small-angle warning; on the
    navigation and tactical grades the measured direction's statement where the grid found the cell outside
    (navigators.core.measured_consistency.MEASURED), nothing where it found it inside; nothing for a grade
    with overrides (not a measured grade)."""
    from trn_env import terrain
    dem = terrain.load("jacksboro")
    for grade in ("navigation", "tactical", "consumer"):
        nav = build_navigator(_sections(name, grade), dem, np.random.default_rng(0))
        warning = nav._consistency_warning
        direction = measured_direction(name, grade)
        if grade == "consumer":
            assert "not calibrated" in warning and name in warning
            assert f"measured {direction}" in warning if direction else "measured " not in warning
        elif direction:
            assert warning.startswith(f"{name}: covariance known to be {direction} on the {grade} IMU grade")
            assert VALIDATION_PAGE in warning
        else:
            assert warning == "", (grade, warning)
        # the estimate carries it; a conservative (or any static) warning withdraws nothing
        h = nav.health.snapshot(warning, ConsistencyCheck())
        assert h.consistency_warning == warning and h.ok == nav.health.ok
    custom = _sections(name, "tactical")
    custom = from_dict({**custom.to_dict(), "sensors": {**custom.to_dict()["sensors"],
                                                        "imu": {"grade": "tactical", "gyro_bias_rps": 1e-6}}})
    assert imu_spec(custom.sensors.imu).grade == ""
    assert build_navigator(custom, dem, np.random.default_rng(0))._consistency_warning == ""


def test_imu_spec_names_the_preset_it_equals():
    assert [imu_spec({"grade": g}).grade for g in ("navigation", "tactical", "consumer")] == [
        "navigation", "tactical", "consumer"]
    assert imu_spec({"grade": "tactical", "accel_scale_factor_ppm": 100.0}).grade == ""
    assert imu_spec({"grade": "noise_free"}).grade == ""
    with pytest.raises(ValueError, match="ImuSpec.grade"):
        ImuSpec(grade=1.0)


def test_a_static_warning_keeps_ok_and_the_flag_withdraws_it(monkeypatch):
    """Health.snapshot with the run-time check: a conservative warning (ok stays True) until the check flags,
    then ok False with the check's message after the static warning (a conservative cell put in MEASURED
    here: the mechanism, whichever cells are measured so today)."""
    monkeypatch.setitem(MEASURED, "ins_tercom", {**MEASURED["ins_tercom"], "navigation": CONSERVATIVE})
    warning = grade_warning(imu_spec({"grade": "navigation"}), 200.0, "ins_tercom")
    assert measured_direction("ins_tercom", "navigation") == CONSERVATIVE and "conservative" in warning
    check = ConsistencyCheck(window=2)
    h = Health().snapshot(warning, check)
    assert h.ok and h.status == "ok" and h.consistency_warning == warning
    for _ in range(2):
        check.add(1e3, 1)
    h = Health().snapshot(warning, check)
    assert not h.ok and h.status == "inconsistent"
    assert h.consistency_warning.startswith(warning + "; innovations inconsistent")


def _guide_grid() -> dict[str, dict[str, str]]:
    """{navigator: {grade: verdict word}} of docs/guide/navigators.md's consistency table."""
    text = (Path(__file__).resolve().parents[1] / "docs" / "guide" / "navigators.md").read_text()
    table = text.split("<!-- guide-table -->")[1].split("<!-- /guide-table -->")[0]
    rows = [r.strip().strip("|").split("|") for r in table.strip().splitlines()[2:]]
    grades = ("navigation", "tactical", "consumer")
    return {cells[0].strip().strip("`"): {g: cells[i + 1].strip().split()[0] for i, g in enumerate(grades)}
            for cells in rows}


def test_measured_table_matches_the_guide():
    """The cells the guide's grid reports outside (conservative / overconfident) are the ones Health warns
    about, in the same direction, and no other."""
    grid = _guide_grid()
    assert set(grid) == set(MEASURED) == {"ins", "ins_tercom", "pmf", "pf", "rbpf", "acq_track"}
    for name, cells in grid.items():
        for grade, word in cells.items():
            assert word in ("inside", CONSERVATIVE, OVERCONFIDENT), (name, grade, word)
            assert measured_direction(name, grade) == ("" if word == "inside" else word), (name, grade)
