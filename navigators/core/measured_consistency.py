"""What is known of each built-in navigator's covariance on each named IMU grade, for Health.

A navigator's horizontal covariance is consistent when its normalised estimation error squared (NEES,
e' P^-1 e, 2 dof) averages 2 within the chi-square bounds of the decorrelated sample count and at least
90 % of the epochs lie inside the 3-sigma ellipse (Bar-Shalom, Li & Kirubarajan 2001, Estimation with
Applications to Tracking and Navigation, sec. 5.4.2). Where it is known not to be, on a named grade, the
navigator says so in `Health.consistency_warning` from its construction on (navigators.protocol), in one of
two directions:

- OVERCONFIDENT: the covariance is smaller than the error; it does not bound it (nor does a protection
  level drawn from it). This includes the grades beyond a filter's small-angle error model
  (imu_spec.consistency_warning), whatever was measured.
- CONSERVATIVE: the covariance is larger than the error; it bounds it, so the estimate may be trusted, but
  its NEES is below the bounds and its protection levels are pessimistic. Not a fault: it withdraws
  nothing (Health.ok stays; the run-time check, navigators.integrity.consistency_check, flags only
  innovations too large for the covariance).

`MEASURED` holds the cells found outside on the default route with GNSS denied (scripts/grade_consistency.py;
the grid, its seeds and command: docs/validation/navigators.md "Consistency on every IMU grade"), by the
navigator's registered name and the grade's preset name (ImuSpec.grade: a scenario IMU equal to a preset;
an IMU with overrides is not a measured grade and gets no entry's text). The docs' guide table and this one
are checked against each other (tests/test_imu_grade_consistency.py).
"""

from __future__ import annotations

from .imu_spec import ImuSpec, consistency_warning

CONSERVATIVE = "conservative"
OVERCONFIDENT = "overconfident"
VALIDATION_PAGE = "docs/validation/navigators.md"

# navigator -> {IMU grade: direction} of the cells measured outside their consistency bounds
MEASURED: dict[str, dict[str, str]] = {
    "ins": {},
    "ins_tercom": {"consumer": OVERCONFIDENT},
    "pmf": {"consumer": OVERCONFIDENT},
    "pf": {"consumer": OVERCONFIDENT},
    "rbpf": {"navigation": CONSERVATIVE, "consumer": OVERCONFIDENT},
    "acq_track": {},
}

_MEANING = {
    CONSERVATIVE: "larger than its error: it bounds the error, but its NEES lies below the chi-square bounds "
                  "and its protection levels are pessimistic",
    OVERCONFIDENT: "smaller than its error: it does not bound the error, nor does a protection level drawn "
                   "from it",
}


def measured_direction(who: str, grade: str) -> str:
    """CONSERVATIVE, OVERCONFIDENT or "" (consistent, or not measured) for navigator `who` on `grade`."""
    return MEASURED.get(who, {}).get(grade, "") if grade else ""


def grade_warning(spec: ImuSpec, memory_s: float, who: str) -> str:
    """Health.consistency_warning of navigator `who` on this IMU: the small-angle warning
    (imu_spec.consistency_warning over the filter's memory_s) with the measured direction appended when the
    grade was measured, else the measured direction's statement, else ""."""
    direction = measured_direction(who, spec.grade)
    small_angle = consistency_warning(spec, memory_s, who)
    if small_angle:
        return small_angle + (f"; measured {direction} on this grade" if direction else "")
    if not direction:
        return ""
    return (f"{who}: covariance known to be {direction} on the {spec.grade} IMU grade "
            f"({_MEANING[direction]}; measured: {VALIDATION_PAGE})")


__all__ = ["CONSERVATIVE", "MEASURED", "OVERCONFIDENT", "VALIDATION_PAGE", "grade_warning",
           "measured_direction"]
