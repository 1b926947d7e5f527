"""Capture: when a terrain filter can no longer represent the INS error it rides on, and what it publishes.

A terrain filter's belief covers the INS error only as far as two things hold (both from the IMU's
specification, navigators.core.imu_spec.ImuSpec, so a navigation- or tactical-grade IMU never reaches them
within a flight of the default route's length):

1. the small-angle error model: the attitude error the gyros build since the last absolute fix (the
   filter's reset, or a GNSS fix) stays below SMALL_ANGLE_LIMIT_RAD (imu_spec.consistency_warning's
   criterion, here at run time): beyond it the INS attitude and velocity every terrain likelihood is computed
   through (an IRA closest point's geometry, seed 000 eqs 14-36; a TERCOM batch's rigid shift) carry errors
   no filter's linear error model describes, so a terrain match is no longer evidence of where the truth is;
2. the capture range: CAPTURE_SIGMAS times the free INS's horizontal position sigma since that fix stays
   inside what the filter can cover - the point-mass grid's half-span at its largest spacing, the TERCOM
   search window at its widest, a particle cloud's widest recovery re-spread (navigators.core.recovery).
   Beyond it, a filter that lost the truth cannot find it again and its small covariance only states where
   its belief converged, true or not.

The check runs only on an IMU beyond the filter's small-angle model over its memory (`capture_spec`: the
same criterion as Health's small-angle warning, imu_spec.consistency_warning): there it is what keeps the
covariance honest. On a better grade the filter's own error model holds over its memory, and a long
GNSS-denied flight on which its terrain updates keep it on the truth must not be suspended because the free
INS's error since the last GNSS fix has grown (the filters that correct their INS hold an attitude error far
below the free INS's); there the guard is inert (no specification) and only the covariance floor applies.

When both are exceeded (`CaptureGuard.check`) the filter is "beyond capture": it suspends its terrain
updates (latched until the next absolute fix re-anchors it), keeps its belief's mean offset as it stood, lets
the INS run free as the free `ins` does, and publishes as its horizontal covariance its belief's at the
suspension plus the free INS error's growth since the suspension (`published_covariance`): the error then
is the belief's error at the suspension plus the INS error's growth since, e(t) - e(t_s), each source's
term of the closed form below taken as its change over [t_s, t] (a filter that corrects its INS with its
whole error state, the RBPF, restarts the growth at the suspension from its own velocity, tilt and bias
variances: `rebase`). Health says so ("degraded", with the reason as an event).

Between the two limits a filter that computes its terrain samples through the free INS's attitude (the
point-mass and particle filters, which never correct their INS) still updates, but each sample's closest
point (seed 000 eqs 14-36) sits off by about the range times the INS's attitude error, the same for
consecutive samples: a bias its likelihood does not describe. Its published horizontal covariance adds
(range x the free INS's attitude sigma)^2 per axis past the small-angle limit (`geometry_variance_m2`; the
range the last sample's), and so does its covariance at the suspension.

The check trades the filter's accuracy after the suspension (it is then the free INS plus the offset it
held) for a covariance that bounds the error (measured: docs/validation/navigators.md).

The free INS's horizontal error per axis (`free_ins_position_variance_m2`) is the short-term solution of the
INS error equations without Schuler feedback (Titterton & Weston 2004, Strapdown Inertial Navigation
Technology, sec. 12.3.4, eqs 12.20-12.21: dp = dp0 + dv0 t + (da + g dtheta0) t^2 / 2 + g dw t^3 / 6), the
sources independent: the initial position, velocity and tilt variances, the body-fixed horizontal
specific-force error (ImuSpec.body_accel_sigma_mps2), the gyro bias (turn-on and instability, constant over
the flight: ImuSpec.gyro_bias_sigma_rps), the velocity random walk (N_a^2 t^3 / 3) and the angle random
walk's tilt (g^2 N_g^2 t^5 / 20); the tilt likewise (`free_ins_tilt_sigma_rad`). It leaves out the Schuler
loop, which bounds the tilt (the closed forms lie above, by (w_s t)^2 / 20 in the position's sigma and
(w_s t)^2 / 6 in the tilt's: 3 % and 9 % at 600 s), the heading error's
share (it turns only the specific force's horizontal part, the manoeuvres') and the turns' gyro scale factor
and misalignment. The free `ins` navigator's 13-state EKF (navigators.filters.InsTrnNavigator) carries the
same sources with the x / y gyro biases as a tilt walk; tests/test_capture.py holds this against a 15-state
error model (seed 002 eqs 16-22) propagated along a level flight.

`floored_horizontal` is the always-true covariance floor: a published horizontal covariance is symmetric
with eigenvalues at least a floor the filter knows holds (a point-mass grid's cell, uniform, adds d^2 / 12
per axis), so a covariance that is not positive definite is never published.
"""

from __future__ import annotations

import math

import numpy as np

from .imu_spec import G0_MPS2, SMALL_ANGLE_LIMIT_RAD, ImuSpec, consistency_warning

# the capture range holds when the free INS's error stays within it at this many sigmas
CAPTURE_SIGMAS = 3.0


def free_ins_position_variance_m2(spec: ImuSpec, t_s: float, p0_m2: float, v0_m2ps2: float,
                                  tilt0_rad2: float, accel_bias_m2ps4: float | None = None,
                                  gyro_bias_rad2ps2: float | None = None, since_s: float = 0.0) -> float:
    """Variance (m^2, per horizontal axis) of the free INS's position error t_s seconds after an anchor
    where it had position, velocity and tilt variances p0_m2, v0_m2ps2, tilt0_rad2 (see the module
    docstring: Titterton & Weston 2004 eqs 12.20-12.21 without the Schuler loop). accel_bias_m2ps4,
    gyro_bias_rad2ps2: the horizontal specific-force error's and the x / y gyro bias's variances when a filter
    has estimated them (at most the specification's); None: the specification's.

    since_s > 0: the variance of the error's growth from since_s to t_s after the anchor, e(t) - e(s) (what
    a belief that held the error at s lacks at t): each constant source's term c t^k becomes c (t^k - s^k)
    (so the position's prior drops out), the velocity random walk's N_a^2 (s (t - s)^2 + (t - s)^3 / 3)
    and the angle random walk's g^2 N_g^2 ((t - s)^2 ((t + s)^3 - (t - s)^3) / 24 + (t - s)^5 / 20) (the
    increments of N_a int (t - u) dB(u) and g N_g int (t - u)^2 / 2 dB(u))."""
    t = max(float(t_s), 0.0)
    s = min(max(float(since_s), 0.0), t)
    a2_spec, g2_spec = spec.body_accel_sigma_mps2 ** 2, spec.gyro_bias_sigma_rps ** 2
    a2 = (a2_spec if accel_bias_m2ps4 is None else min(accel_bias_m2ps4, a2_spec)) + G0_MPS2 ** 2 * tilt0_rad2
    gw2 = G0_MPS2 ** 2 * (g2_spec if gyro_bias_rad2ps2 is None else min(gyro_bias_rad2ps2, g2_spec))
    d = t - s
    na2 = spec.accel_noise_density_mps2_rthz ** 2
    ng2 = (G0_MPS2 * spec.gyro_noise_density_rps_rthz) ** 2
    return float((p0_m2 if s == 0.0 else 0.0) + v0_m2ps2 * d ** 2 + a2 * (t ** 2 - s ** 2) ** 2 / 4.0
                 + gw2 * (t ** 3 - s ** 3) ** 2 / 36.0 + na2 * (s * d ** 2 + d ** 3 / 3.0)
                 + ng2 * (d ** 2 * ((t + s) ** 3 - d ** 3) / 24.0 + d ** 5 / 20.0))


def free_ins_tilt_sigma_rad(spec: ImuSpec, t_s: float, tilt0_rad2: float) -> float:
    """Attitude error (1 sigma per axis, rad) of the free INS t_s seconds after an anchor with tilt variance
    tilt0_rad2: the gyro bias's ramp and the angle random walk."""
    t = max(float(t_s), 0.0)
    return float(math.sqrt(tilt0_rad2 + (spec.gyro_bias_sigma_rps * t) ** 2
                           + spec.gyro_noise_density_rps_rthz ** 2 * t))


def capture_spec(spec: ImuSpec, memory_s: float, who: str) -> ImuSpec | None:
    """The specification a navigator's CaptureGuard runs on: `spec` when the IMU is beyond the filter's
    small-angle model over its memory memory_s (imu_spec.consistency_warning non-empty), else None (the guard
    inert; see the module docstring)."""
    return spec if consistency_warning(spec, memory_s, who) else None


def floored_horizontal(cov_m2: np.ndarray, floor_m2: float) -> np.ndarray:
    """The 2 x 2 horizontal covariance as published: returned unchanged (the same object) when its symmetric
    part's smaller eigenvalue is at least floor_m2 (> 0), else symmetrised with its eigenvalues raised to
    floor_m2 (a non-finite matrix: its finite diagonal, at least the floor). Never not positive definite."""
    c = np.asarray(cov_m2, float)
    floor = max(float(floor_m2), 1e-9)
    if not np.all(np.isfinite(c)):
        d = np.nan_to_num(np.diag(c), nan=floor, posinf=floor, neginf=floor)
        return np.diag(np.maximum(d, floor))
    # smaller eigenvalue of the symmetric part [[a, b], [b, d]] in closed form
    a, b, d = float(c[0, 0]), 0.5 * float(c[0, 1] + c[1, 0]), float(c[1, 1])
    if 0.5 * (a + d) - math.sqrt(0.25 * (a - d) ** 2 + b * b) >= floor:
        return c
    s = 0.5 * (c + c.T)
    w, V = np.linalg.eigh(s)
    return (V * np.maximum(w, floor)) @ V.T


class CaptureGuard:
    """The capture check of one terrain filter (see the module docstring).

    Parameters
    ----------
    capture_range_m : float
        How far (m) the filter can cover: its grid's half-span, TERCOM search window or widest re-spread.
    who : str
        The navigator's name, for the reason it gives.
    spec : ImuSpec or None
        The IMU's specification; None (no specification) never suspends.
    rebase : bool
        The filter corrects its INS with its full error state (the RBPF feeds its velocity, attitude and
        bias estimates back): at the suspension the free INS's growth restarts from the filter's own
        velocity, tilt and bias variances (its 15 x 15 covariance: NED position, velocity, attitude,
        accelerometer and gyro biases), not from the anchor. False (the point-mass and particle filters ride
        on an INS they never correct; the EKF's 13 states do not carry the x / y gyro biases that drive the
        drift): the growth since the anchor.
    geometry : bool
        The filter computes its terrain samples' geometry through the free INS's attitude (the point-mass
        and particle filters): past the small-angle limit its published horizontal covariance adds
        `geometry_variance_m2` (see the module docstring).
    """

    def __init__(self, capture_range_m: float, who: str, spec: ImuSpec | None = None, rebase: bool = False,
                 geometry: bool = False):
        self.capture_range_m = float(capture_range_m)
        self.who = str(who)
        self.spec = spec
        self.rebase = bool(rebase)
        self.geometry = bool(geometry)
        self.range_m = 0.0      # the last terrain sample's range (the filter sets it)
        self.anchor(0.0, 0.0, 0.0, 0.0)

    def anchor(self, t_s: float, p0_m2: float, v0_m2ps2: float, tilt0_rad2: float) -> None:
        """An absolute fix (the reset, a GNSS fix) at t_s with the INS error's variances then (per
        horizontal axis: position m^2, velocity m^2/s^2, tilt rad^2): the free INS's growth restarts there
        and a suspension ends."""
        self.t_anchor_s = float(t_s)
        self._p0 = max(float(p0_m2), 0.0)
        self._v0 = max(float(v0_m2ps2), 0.0)
        self._tilt0 = max(float(tilt0_rad2), 0.0)
        self.suspended = False
        self._ba2 = self._bg2 = None
        self.t_suspended_s = math.nan
        self._cov_at_suspension = np.zeros((2, 2))
        self.reason = ""

    def free_variance_m2(self, t_s: float) -> float:
        """The free INS's horizontal position variance per axis (m^2) at t_s since the anchor."""
        if self.spec is None:
            return self._p0
        return free_ins_position_variance_m2(self.spec, t_s - self.t_anchor_s, self._p0, self._v0,
                                             self._tilt0, self._ba2, self._bg2)

    def geometry_variance_m2(self, t_s: float) -> float:
        """Variance (m^2 per horizontal axis) of the terrain samples' closest points that the free INS's
        attitude error moves: (range_m sigma_att)^2, sigma_att the free INS's attitude sigma since the
        anchor, once past SMALL_ANGLE_LIMIT_RAD (0 before it, or without `geometry` or a specification)."""
        if not (self.geometry and self.spec is not None):
            return 0.0
        att = free_ins_tilt_sigma_rad(self.spec, t_s - self.t_anchor_s, self._tilt0)
        return (self.range_m * att) ** 2 if att > SMALL_ANGLE_LIMIT_RAD else 0.0

    def beyond(self, t_s: float) -> bool:
        """Whether both limits of the module docstring are exceeded at t_s (no state changed)."""
        if self.spec is None:
            return False
        dt = t_s - self.t_anchor_s
        if free_ins_tilt_sigma_rad(self.spec, dt, self._tilt0) <= SMALL_ANGLE_LIMIT_RAD:
            return False
        return CAPTURE_SIGMAS * math.sqrt(self.free_variance_m2(t_s)) > self.capture_range_m

    def check(self, t_s: float, belief_cov: np.ndarray) -> bool:
        """True when the filter is (now or already) beyond capture; on the first such call it latches the
        suspension, keeping the belief's horizontal covariance now (belief_cov's first 2 x 2 block; with
        `rebase` the 15 x 15 covariance whose velocity, tilt and bias variances restart the growth) and the
        reason."""
        if self.suspended:
            return True
        if not self.beyond(t_s):
            return False
        sig = math.sqrt(self.free_variance_m2(t_s))
        tilt = math.degrees(free_ins_tilt_sigma_rad(self.spec, t_s - self.t_anchor_s, self._tilt0))
        c = np.asarray(belief_cov, float)
        geo = self.geometry_variance_m2(t_s)
        if self.rebase:
            anchor_from_cov9(self, t_s, c)
            self._p0 = 0.0          # the position's part is the belief's, kept below
            self._ba2 = 0.5 * float(c[9, 9] + c[10, 10])
            self._bg2 = 0.5 * float(c[12, 12] + c[13, 13])
        self.suspended = True
        self.t_suspended_s = float(t_s)
        self._cov_at_suspension = floored_horizontal(c[:2, :2], 1e-6) + np.eye(2) * geo
        self.reason = (f"{self.who}: beyond capture - the IMU's free INS error since the last absolute fix "
                       f"({t_s - self.t_anchor_s:.0f} s ago: {sig:.0f} m, {tilt:.2g} deg of attitude) "
                       "exceeds "
                       f"the small-angle model and {self.capture_range_m:.0f} m / {CAPTURE_SIGMAS:g} sigma; "
                       "terrain updates suspended, covariance grows as the free INS's"
                       + (" from here" if self.rebase else ""))
        return True

    def skips(self, t_s: float, belief_cov_m2, health) -> bool:
        """Whether a terrain update at t_s is to be skipped: True while suspended, and on the check that
        latches a suspension (belief_cov_m2: a callable giving the belief's covariance as `check` takes it,
        only called then), when the reason goes to health's events and health turns "degraded" (ok False)."""
        if self.suspended:
            return True
        if not self.beyond(t_s):
            return False
        self.check(t_s, belief_cov_m2())
        health.events.append((float(t_s), self.reason))
        health.ok, health.status = False, "degraded"
        return True

    def publish(self, cov: np.ndarray, t_s: float, floor_m2: float = 0.0) -> np.ndarray:
        """The covariance to publish (n x n, north and east first; a copy): while suspended its horizontal
        block is `published_covariance` and uncorrelated with the rest, else with `geometry_variance_m2`
        added; the horizontal block floored (floored_horizontal) in every case."""
        P = np.array(cov, float)
        if self.suspended:
            P[:2, :] = 0.0
            P[:, :2] = 0.0
            P[:2, :2] = self.published_covariance(t_s)
        else:
            geo = self.geometry_variance_m2(t_s)
            if geo > 0.0:
                P[:2, :2] += np.eye(2) * geo
        P[:2, :2] = floored_horizontal(P[:2, :2], floor_m2)
        return P

    def published_covariance(self, t_s: float) -> np.ndarray:
        """The horizontal covariance (2 x 2, m^2) a suspended filter publishes at t_s: its belief's at the
        suspension plus the free INS's error growth since the suspension on each axis (the belief held the
        error then: free_ins_position_variance_m2 with since_s; with `rebase` the anchor is the
        suspension)."""
        growth = free_ins_position_variance_m2(self.spec, t_s - self.t_anchor_s, 0.0, self._v0, self._tilt0,
                                               self._ba2, self._bg2, self.t_suspended_s - self.t_anchor_s)
        return self._cov_at_suspension + np.eye(2) * growth


def anchor_from_cov9(guard: CaptureGuard, t_s: float, cov9: np.ndarray) -> None:
    """Anchor `guard` at t_s with the horizontal position, velocity and tilt variances (per axis, the mean
    of north and east / roll and pitch) of a 9 x 9 navigation covariance (NED position, velocity,
    attitude)."""
    d = np.nan_to_num(np.diag(np.asarray(cov9, float)), nan=0.0)
    guard.anchor(t_s, 0.5 * (d[0] + d[1]), 0.5 * (d[3] + d[4]), 0.5 * (d[6] + d[7]))


# ---------------------------------------------------------------------------------- the RBPF's hooks
def rbpf_capture_guard(nav, initial) -> CaptureGuard:
    """The RBPF's guard (navigators.filters.rbpf: `nav` after its reset): its capture range CAPTURE_SIGMAS
    times the widest re-spread of its recovery policy, anchored at the initial estimate."""
    recovery = nav._recovery
    g = CaptureGuard(CAPTURE_SIGMAS * recovery.recovery_sigma_m * 2.0 ** (recovery.max_doublings - 1),
                     nav.name, getattr(nav, "_capture_spec", None), rebase=True)
    anchor_from_cov9(g, float(initial.t_s), np.asarray(initial.covariance, float))
    return g


def rbpf_capture_skips(nav, t_s: float, gnss, covariance15) -> bool:
    """Whether the RBPF skips its epoch at t_s (beyond capture: no time update, terrain update or feedback;
    its INS runs free and its error-model transition restarts; covariance15: a callable giving the cloud's
    15 x 15 mixture covariance, for the suspension's rebase). A GNSS fix (`gnss` not None) ends a
    suspension: the guard re-anchors at the cloud's covariance and the epoch runs."""
    g = nav._capture
    if gnss is not None:
        if g.suspended:
            nav.health.events.append((float(t_s), f"{nav.name}: capture: a GNSS fix ends the suspension"))
        anchor_from_cov9(g, t_s, nav._cov9)
        return False
    if g.skips(t_s, covariance15, nav.health):
        nav._Phi = np.eye(nav._Phi.shape[0])
        return True
    return False


__all__ = ["CAPTURE_SIGMAS", "CaptureGuard", "anchor_from_cov9", "capture_spec", "floored_horizontal",
           "free_ins_position_variance_m2", "free_ins_tilt_sigma_rad", "rbpf_capture_guard",
           "rbpf_capture_skips"]
