"""The INS aiding's north/east velocity error growth from the IMU's specification (acq_track, seed 001).

With the strapdown INS as the aiding (aiding_source "ins", reference_frame "ne"), the north/east velocity
bias e_ne the centroid filter estimates is the free INS's velocity error (seed 001 ch. 4: the aided loop's
reference absorbs the supportive sensor's bias; spec section 5). Its growth over the flight follows from the
specification (Titterton & Weston 2004, sec. 12.3, the short-term error propagation of a strapdown INS), per
north / east axis, t counted from the INS's start (the navigator's reset):

    Var e(t) = Var e(0) + N^2 t + (g sigma_tilt)^2 t^2 + sigma_b^2 |int_0^t u(psi) dt'|^2
               + (g sigma_bg)^2 t^4 / 4 + sigma_psi^2 |v(t) - v(0)|^2 / 2

- N: the accelerometers' white noise (velocity random walk);
- g sigma_tilt: an acceleration error constant in the north/east frame, gravity through the initial tilt
  (the initial estimate's roll / pitch sigma) and the tilt a 90 deg turn builds through the gyro
  misalignment (ImuSpec.turn_tilt_sigma_rad);
- sigma_b: the body-fixed horizontal specific-force error (ImuSpec.body_accel_sigma_mps2: accelerometer bias
  and instability, misalignment x g). It turns with the aircraft: its north/east velocity error is
  M b with M = int R(psi) dt, whose covariance sigma_b^2 M M^T = sigma_b^2 |int u(psi) dt|^2 I, u the unit
  vector along the heading (the ground track here; the crab angle is a few degrees). On a straight leg
  this is sigma_b^2 t^2; a turn back cancels part of it;
- g sigma_bg: the ramp of the acceleration the horizontal gyro biases' tilt builds (Schuler's feedback left
  out: within 2 % over 500 s);
- sigma_psi: the initial heading error, which turns the velocity change since the start by sigma_psi
  (a rotation error of the integrated acceleration), half on each axis.

The filter's random walk takes each sample the growth of this variance (never negative: its largest value so
far, as a walk cannot shrink), so without fixes e_ne's variance follows Var e(t) from the prior Var e(0),
the initial estimate's velocity covariance. A GNSS fix resets the INS's velocity (intake.py): the growth
restarts there (`restart`), the gyro biases' tilt ramp on its clock from the start.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.imu_spec import G0_MPS2, ImuSpec, rss


class InsVelocityErrorGrowth:
    """Per-axis variance (m^2/s^2) of a free INS's north/east velocity error grown from its start (module
    docstring), and each sample's increment for the centroid filter's velocity-bias walk.

    Parameters
    ----------
    spec : ImuSpec
        The IMU's specification.
    tilt0_rad : float
        Initial tilt error sigma (rad, per axis: the initial estimate's roll / pitch).
    heading0_rad : float
        Initial heading error sigma (rad).
    v0_ne_mps : array_like
        Velocity (north, east m/s) at the INS's start.
    t0_s : float
        Time of the INS's start (s).
    """

    def __init__(self, spec: ImuSpec, tilt0_rad: float, heading0_rad: float, v0_ne_mps, t0_s: float):
        self.noise2 = spec.accel_noise_density_mps2_rthz ** 2
        self.earth2 = rss(G0_MPS2 * spec.turn_tilt_sigma_rad(0.5 * math.pi), G0_MPS2 * tilt0_rad) ** 2
        self.body2 = spec.body_accel_sigma_mps2 ** 2
        self.ramp2 = spec.tilt_accel_rate_sigma_mps3 ** 2
        self.heading2 = float(heading0_rad) ** 2
        self.t0_s = float(t0_s)
        self.restart(t0_s, v0_ne_mps)

    def restart(self, t_s: float, v_ne_mps) -> None:
        """The INS's velocity reset at t_s to v_ne_mps (north, east m/s; a GNSS fix): its velocity error grows
        anew from there on the same accelerations; the gyro biases' tilt keeps its clock from the start (its
        ramp adds g sigma_bg (t^2 - t_r^2) / 2 after a reset at t_r)."""
        self.t_reset_s = float(t_s)
        self.v0 = np.asarray(v_ne_mps, float)[:2].copy()
        self.c_s = 0.0   # int cos(psi) dt since the reset (s)
        self.s_s = 0.0   # int sin(psi) dt since the reset (s)
        self.grown = 0.0   # the largest growth so far (m^2/s^2)

    def growth(self, t_s: float, v_ne_mps) -> float:
        """Var e(t) - Var e(t_r) (m^2/s^2 per axis) at t_s, t_r the INS's start or last reset, with the
        heading integral so far and the velocity v_ne_mps (north, east m/s)."""
        t = max(t_s - self.t_reset_s, 0.0)
        t1, tr = max(t_s - self.t0_s, 0.0), max(self.t_reset_s - self.t0_s, 0.0)
        dv = np.asarray(v_ne_mps, float)[:2] - self.v0
        return (self.noise2 * t + self.earth2 * t * t + self.body2 * (self.c_s ** 2 + self.s_s ** 2)
                + 0.25 * self.ramp2 * (t1 * t1 - tr * tr) ** 2 + 0.5 * self.heading2 * float(dv @ dv))

    def step(self, t_s: float, dt_s: float, psi_rad: float, v_ne_mps) -> float:
        """Advance by one sample of dt_s s ending at t_s along heading psi_rad at v_ne_mps; returns the
        increment of the variance (m^2/s^2 per axis, >= 0) for the filter's random walk."""
        self.c_s += dt_s * math.cos(psi_rad)
        self.s_s += dt_s * math.sin(psi_rad)
        g = self.growth(t_s, v_ne_mps)
        q = max(g - self.grown, 0.0)
        self.grown = max(self.grown, g)
        return q
