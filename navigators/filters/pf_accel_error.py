"""The particle filter's carried acceleration error (navigators.filters.pf, velocity_noise_model "imu_spec").

A strapdown INS's horizontal velocity error grows from the acceleration errors its IMU makes (Titterton &
Weston 2004, sec. 12.3, the psi-angle error equations): the specific-force error that is constant in the
body frame (the accelerometers' bias and instability, and their misalignment's share of gravity) turned
into the navigation frame by the heading, and g times the tilt, which the horizontal gyros build - their
bias at a constant body-frame rate, and in a turn their misalignment to the z axis times the angle turned.
These errors are bias-like: a particle that carries them as states moves its velocity offset by its own
acceleration error at every step, whatever the cloud's spread, so the cloud's velocity spread grows as the
free INS's error while nothing observes it, a sharp fix (GNSS) narrows the acceleration only as far as the
fix's velocity actually observes it, and a velocity the terrain tells apart keeps the acceleration it told
apart with it (the weights and resampling act on the joint state).

Carried per particle (M, N_ACC), ACC_* columns:

- ACC_BODY: the horizontal specific-force error in the body frame (m/s^2), prior `body_accel_sigma_mps2`
  (turn-on bias, instability, misalignment x g); its instability's Gauss-Markov drive enters each step
  without the decay (a random walk of the drive: over a flight of a few bias correlation times it overstates
  the instability's wander, the conservative side);
- ACC_TILT_RATE: g x the horizontal gyro biases (m/s^3, body frame), prior `tilt_accel_rate_sigma_mps3`,
  with the gyro instability's drive likewise;
- ACC_TURN: g x the horizontal gyros' misalignment to the z axis (m/s^2 per rad turned, body frame), prior
  g `gyro_misalignment_rad`;
- ACC_TILT: g x the tilt, in the navigation frame (m/s^2): prior g x the initial tilt, moved over each step
  by the heading's rotation of the body-frame tilt rates: R(psi) (ACC_TILT_RATE dt + ACC_TURN dpsi).

The acceleration error over a step (psi the INS heading at mid-step, R(psi) the body-to-NED rotation of
the horizontal plane) is R(psi) ACC_BODY + ACC_TILT at mid-step. g x tilt is a fixed 90 deg rotation of the
tilt in the horizontal plane, which commutes with R(psi); the priors are isotropic, so the states are the
acceleration errors themselves. Not carried: the Schuler feedback on the tilt (the particles' position
carries it, propagate_particles' g / R term), the accelerometers' scale factor (the horizontal specific
force of a coordinated turn is near zero), the heading error (a particle state of its own).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.imu_spec import G0_MPS2, ImuSpec

N_ACC = 8
ACC_BODY = slice(0, 2)
ACC_TILT_RATE = slice(2, 4)
ACC_TURN = slice(4, 6)
ACC_TILT = slice(6, 8)


def ins_heading_rad(st: np.ndarray) -> float:
    """The INS heading (rad) of a navigators.inertial state row (quaternion [w, x, y, z] at st[6:10])."""
    w, x, y, z = float(st[6]), float(st[7]), float(st[8]), float(st[9])
    return math.atan2(2.0 * (w * z + x * y), w * w + x * x - y * y - z * z)


@dataclass(frozen=True)
class AccelErrorModel:
    """The priors and drives of the carried acceleration error (1 sigma per axis, see the module docstring).

    body_mps2: ACC_BODY's prior; tilt_rate_mps3: ACC_TILT_RATE's; turn_mps2_per_rad: ACC_TURN's;
    tilt0_mps2: ACC_TILT's (g x the initial tilt). body_instability_mps2, body_tau_s,
    tilt_rate_instability_mps3, tilt_rate_tau_s: the Gauss-Markov instabilities whose drives enter per step.
    """

    body_mps2: float
    tilt_rate_mps3: float
    turn_mps2_per_rad: float
    tilt0_mps2: float
    body_instability_mps2: float = 0.0
    body_tau_s: float = 3600.0
    tilt_rate_instability_mps3: float = 0.0
    tilt_rate_tau_s: float = 3600.0

    @classmethod
    def from_spec(cls, spec: ImuSpec, tilt0_rad: float) -> AccelErrorModel:
        """From the IMU's specification and the initial tilt's sigma (rad, per axis)."""
        return cls(body_mps2=spec.body_accel_sigma_mps2, tilt_rate_mps3=spec.tilt_accel_rate_sigma_mps3,
                   turn_mps2_per_rad=G0_MPS2 * spec.gyro_misalignment_rad, tilt0_mps2=G0_MPS2 * tilt0_rad,
                   body_instability_mps2=spec.accel_bias_instability_mps2, body_tau_s=spec.accel_bias_tau_s,
                   tilt_rate_instability_mps3=G0_MPS2 * spec.gyro_bias_instability_rps,
                   tilt_rate_tau_s=spec.gyro_bias_tau_s)

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """(n, N_ACC) states drawn from the priors."""
        sig = np.repeat([self.body_mps2, self.tilt_rate_mps3, self.turn_mps2_per_rad, self.tilt0_mps2], 2)
        return rng.standard_normal((n, N_ACC)) * sig

    def advance(self, acc: np.ndarray, dt_s: float, psi0_rad: float, psi1_rad: float,
                rng: np.random.Generator, out: np.ndarray) -> np.ndarray:
        """Move the states over a step of dt_s in which the INS heading went from psi0 to psi1 (rad), in
        place; writes into out (n, 2) and returns each particle's acceleration error over the step (m/s^2,
        NED): R(psi_mid) ACC_BODY + ACC_TILT at mid-step."""
        turn = math.remainder(psi1_rad - psi0_rad, 2.0 * math.pi)
        psi = psi0_rad + 0.5 * turn
        c, s = math.cos(psi), math.sin(psi)
        rate = acc[:, ACC_TILT_RATE] * dt_s + acc[:, ACC_TURN] * turn       # body-frame tilt step x g
        d_n = c * rate[:, 0] - s * rate[:, 1]
        d_e = s * rate[:, 0] + c * rate[:, 1]
        bb = acc[:, ACC_BODY]
        out[:, 0] = c * bb[:, 0] - s * bb[:, 1] + acc[:, 6] + 0.5 * d_n
        out[:, 1] = s * bb[:, 0] + c * bb[:, 1] + acc[:, 7] + 0.5 * d_e
        acc[:, 6] += d_n
        acc[:, 7] += d_e
        for cols, sigma, tau in ((ACC_BODY, self.body_instability_mps2, self.body_tau_s),
                                 (ACC_TILT_RATE, self.tilt_rate_instability_mps3, self.tilt_rate_tau_s)):
            if sigma > 0.0:
                acc[:, cols] += sigma * math.sqrt(-math.expm1(-2.0 * dt_s / tau)) * rng.standard_normal(
                    (acc.shape[0], 2))
        return out
