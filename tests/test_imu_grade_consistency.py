"""Every navigator takes its INS error model from the IMU's specification (navigators.core.imu_spec) and is
consistent on the tactical grade.

The statistical check (slow): one recorded JSBSim flight of the default route (120 s, GNSS denied from
t = 0), RUNS seeds each with its own sensor noise, IMU biases, initial error and world detail
(scripts/grade_consistency.py), every navigator built as a scenario builds it. The runs are independent, so
the mean of each run's time-averaged horizontal NEES after 15 s (2 dof) must not be significantly above 2
(overconfidence, the failure the IMU-specification model removes): the lower end of its one-sided 99 % t
interval (RUNS - 1 degrees of freedom; about 4 % false alarms for the four navigators together) must not
exceed 2; and at least 90 % of all epochs must have NEES <= 9 (the 3-sigma ellipse). The particle filters'
per-run NEES is heavy-tailed and the EKF's TERCOM fix noise deliberately pessimistic, so the two-sided
thinned chi-square check needs more runs than a test affords: it is measured over 20 seeds in
docs/validation/navigators.md (with the PMF 5 % above its upper bound there). Without the
IMU-specification error model ins_tercom, pmf and pf were at ANEES 13-20 with 34-57 % of epochs inside
(3 seeds x 150 s).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from trn_env.navigators.core.imu_spec import ImuSpec, equivalent_walk_density, gm_drive

from trn_env.scenario.build import build_navigator, imu_spec
from trn_env.scenario.loading import load_scenario

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))

RUNS = 8
DURATION_S = 120.0


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
    with pytest.raises(ValueError, match="gyro_bias_tau_s"):
        ImuSpec(gyro_bias_tau_s=0.0)
    with pytest.raises(ValueError, match="accel_bias_mps2"):
        ImuSpec(accel_bias_mps2=math.nan)


@pytest.mark.parametrize("name", ["ins_tercom", "pmf", "pf"])
def test_build_navigator_applies_the_grade(name):
    """The tactical grade raises the navigator's error model above the navigation grade's; a navigation-grade
    scenario keeps the tuned figures (they are floors)."""
    sc = load_scenario("default", navigator=name)
    import dataclasses

    from trn_env import terrain
    from trn_env.scenario.sections import SensorsSection
    dem = terrain.load("jacksboro")
    navs = {}
    for grade in ("navigation", "tactical"):
        tables = {**sc.sensors.tables.to_dict(), "imu": {"grade": grade}}
        sensors = SensorsSection.from_mapping(tables, "sensors", [])
        dd = dataclasses.replace(sc.sections, sensors=sensors)
        navs[grade] = build_navigator(dd, dem, np.random.default_rng(0))
    n, t = navs["navigation"], navs["tactical"]
    if name == "ins_tercom":
        assert n.sig_ba == pytest.approx(50e-6 * 9.80665) and t.sig_ba > 20 * n.sig_ba
        assert t.sig_bg > 100 * n.sig_bg and t._q_tilt > 100 * n._q_tilt
        assert t._turn_tilt2 > 0.0 and n._turn_tilt2 == 0.0
    elif name == "pmf":
        assert t.accel_bias_sigma > 20 * n.accel_bias_sigma
        assert t._imu_noise[0] > 100 * n._imu_noise[0] and t._imu_noise[3] > 0.0 == n._imu_noise[3]
    else:
        assert t.s_vel > 2 * n.s_vel and t.s_psi > n.s_psi


@pytest.mark.slow
def test_tactical_grade_consistency():
    import filter_statistics as fs
    import grade_consistency as gc
    flight = fs.record_flight(duration_s=DURATION_S)
    names = ["ins", "ins_tercom", "pmf", "pf"]
    runs = {n: [] for n in names}
    for s in range(RUNS):
        for n, run in gc.run_seed(flight[0], names, "tactical", 2000 + s, flight).items():
            runs[n].append(run)
    from scipy import stats

    problems = []
    for n in names:
        f = gc.figures(runs[n], 15.0)
        nees, _ = gc.run_nees(runs[n], 15.0)
        means = nees.mean(axis=1)
        lo = means.mean() - stats.t.ppf(0.99, RUNS - 1) * means.std(ddof=1) / math.sqrt(RUNS)
        if not (lo <= 2.0 and f["inside_3sigma"] >= 0.9):
            problems.append(f"{n}: runs' mean NEES {means.mean():.2f}, one-sided 99 % lower end {lo:.2f} "
                            f"(thinned ANEES {f['anees']:.2f}, bounds {f['bounds_95']}), "
                            f"{100 * f['inside_3sigma']:.0f} % inside 3 sigma")
    assert not problems, problems
