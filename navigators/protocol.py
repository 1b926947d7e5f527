"""The one interface every navigator implements, and the estimate it returns::

    nav.reset(initial: Estimate)            # initial state and covariance
    est = nav.update(frames: SensorFrames)  # consume one interval of sensor data, return the estimate at
                                            # frames.t_end_s (or the last sample time)

A navigator may keep any internal state (an INS, a particle cloud, a TERCOM batch). It must never raise
on bad data: a NaN sample, a no-return, a window off the map or a covariance that stops being positive
definite is skipped, counted in `Health`, and reported in `Health.events` for the log.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from ..terrain.geodesy import meridian_radius_m, prime_vertical_radius_m
from .frames import SensorFrames

# Estimate.extra keys that every terrain-aided navigator fills after each terrain measurement update, so the
# integrity monitors and the metrics read them the same way whatever the navigator (absent: no update yet).
EXTRA_INNOVATION = "innovation"            # np.ndarray (m, rad): measurement minus prediction, last update
EXTRA_INNOVATION_COV = "innovation_cov"    # np.ndarray: its covariance S (m x m)
EXTRA_NIS = "nis"                          # float: innovation' S^-1 innovation (chi-square with nis_dof dof)
EXTRA_NIS_DOF = "nis_dof"                  # int: degrees of freedom of nis
EXTRA_LOG_LIKELIHOOD = "log_likelihood"    # float: log p(measurement | past), natural log
EXTRA_ESS = "ess"                          # float: particle filters' effective sample size before resampling
EXTRA_MEASUREMENT_TIME = "measurement_t_s"  # float: time of the update these keys describe
# the navigator self-integrity test (navigators.integrity.InnovationMonitor) after its latest update:
EXTRA_INTEGRITY_STATISTIC = "integrity_statistic"  # float: sum of the window's NIS values
EXTRA_INTEGRITY_DOF = "integrity_dof"              # int: its chi-square degrees of freedom
EXTRA_INTEGRITY_BAND = "integrity_band"            # (lower, upper): its chi-square band at integrity_alpha


def update_extra(innovation, innovation_cov, nis, nis_dof, log_likelihood, t_s) -> dict:
    """The Estimate.extra entries of one terrain measurement update under the EXTRA_* keys above (innovation,
    its covariance S, NIS, its degrees of freedom, log-likelihood, measurement time), as every terrain-aided
    navigator publishes them. The values are stored as given."""
    return {EXTRA_INNOVATION: innovation, EXTRA_INNOVATION_COV: innovation_cov, EXTRA_NIS: nis,
            EXTRA_NIS_DOF: nis_dof, EXTRA_LOG_LIKELIHOOD: log_likelihood, EXTRA_MEASUREMENT_TIME: t_s}


@dataclass
class Health:
    """Navigator health: ok is False when the estimate should not be trusted (diverged, lost lock).

    status words: "ok", "acquiring", "degraded", "diverged", and "lost" (the acquisition-and-tracking
    TRN: out of lock for several epochs in a row, dead-reckoning on its aiding until a new acquisition;
    its state machine is acquiring -> ok <-> degraded -> lost -> acquiring, each transition an event), and
    "inconsistent" (ok False: the long-window innovation test, navigators.integrity.consistency_check, finds
    the innovations persistently larger than the covariance says; consistency_warning holds its message)."""

    ok: bool = True
    status: str = "ok"                                   # short word: ok, acquiring, degraded, diverged, ...
    # reason -> count of measurements skipped so far
    skipped: dict[str, int] = field(default_factory=dict)
    events: list[tuple[float, str]] = field(default_factory=list)  # (t_s, message) since the last update
    # why the navigator's covariance is known not to describe its error in this configuration ("" for none
    # known), in either direction: known not to bound it (overconfident, e.g. an IMU grade beyond its error
    # model's validity, navigators.core.imu_spec; or the run-time consistency check's flag, which also
    # withdraws ok) or known to overstate it (conservative: it bounds the error, ok stays, its protection
    # level is pessimistic); the static warnings are set at construction from the IMU grade and the
    # measured grid (navigators.core.measured_consistency)
    consistency_warning: str = ""

    def skip(self, t_s: float, reason: str, message: str | None = None) -> None:
        self.skipped[reason] = self.skipped.get(reason, 0) + 1
        self.events.append((float(t_s), message or reason))

    def snapshot(self, consistency_warning: str = "", check=None) -> Health:
        """A copy for an Estimate (its own skipped counts and event list), with the navigator's
        consistency warning; `check` (a navigators.integrity.consistency_check.ConsistencyCheck, or None)
        withdraws ok and sets status "inconsistent" with its message while it flags the navigator."""
        ok, status, warning = self.ok, self.status, consistency_warning
        if check is not None:
            ok, status, warning = check.apply(ok, status, warning)
        return Health(ok=ok, status=status, skipped=dict(self.skipped), events=list(self.events),
                      consistency_warning=warning)


@dataclass
class Estimate:
    """A navigation estimate at time t_s.

    covariance is over the error state [north_m, east_m, down_m, v_n, v_e, v_d, roll, pitch, yaw] (9 x 9,
    SI units, radians for attitude); navigators with more states report this 9 x 9 block. Position errors
    are in metres in NED even though the position itself is geodetic.
    """

    t_s: float
    lat_rad: float
    lon_rad: float
    h_m: float
    v_ned_mps: np.ndarray
    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    covariance: np.ndarray
    health: Health = field(default_factory=Health)
    # navigator-specific outputs (e.g. a TERCOM fix and its quality)
    extra: dict = field(default_factory=dict)

    def extrapolated(self, t_s: float) -> Estimate:
        """This estimate dead-reckoned to t_s with its own velocity (position only; attitude, velocity,
        covariance and health are shared, not copied). What a consumer of a navigator's output does between
        updates: the closed loop's guidance flies on it between the navigator's updates. The small offset
        goes through the meridian and prime-vertical radii (seed 000 eq 2)."""
        dt = float(t_s) - self.t_s
        v = self.v_ned_mps
        lat, h = self.lat_rad, self.h_m
        r_n = float(meridian_radius_m(lat)) + h
        r_e = float(prime_vertical_radius_m(lat)) + h
        return Estimate(float(t_s), lat + float(v[0]) * dt / r_n,
                        self.lon_rad + float(v[1]) * dt / (r_e * math.cos(lat)), h - float(v[2]) * dt, v,
                        self.roll_rad, self.pitch_rad, self.yaw_rad, self.covariance, self.health, self.extra)

    @property
    def sigma_ned_m(self) -> np.ndarray:
        """One-sigma position uncertainty north, east, down (m)."""
        return np.sqrt(np.clip(np.diag(self.covariance)[:3], 0.0, None))


class NavigatorContractError(TypeError):
    """A navigator (or monitor) returned what the protocol does not allow: the loop stops on it with this,
    naming the navigator and the update (trn_env.testing.check_navigator finds it before a flight)."""


@runtime_checkable
class Navigator(Protocol):
    """Any estimator that runs on SensorFrames. `update` leaves its frames as given (the same frames may go
    to other navigators, the monitors and the log) and returns a new Estimate whose arrays are its own (the
    loop keeps earlier estimates): trn_env.testing.check_navigator checks both."""

    name: str

    def reset(self, initial: Estimate) -> None: ...

    def update(self, frames: SensorFrames) -> Estimate: ...
