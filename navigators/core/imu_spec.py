"""The IMU's error specification as the navigators see it, and the INS error model it parameterises.

`ImuSpec` is a record of the sensor's error budget (SI, 1 sigma per axis): turn-on biases, bias
instabilities (first-order Gauss-Markov: sigma, correlation time), noise densities (velocity and angle
random walk), scale factors and misalignments. The simulator converts its IMU configuration into one
(trn_env.scenario.build.imu_spec; the navigators never import the sensor models), and every navigator that
declares `uses_imu_spec` turns it into its own error model in `apply_imu_spec(spec)`, whatever its state
size (the EKF's 13 states, the PMF's Gaussian velocity-tilt-bias-heading offset, the PF's particles, the
RBPF's Kalman parts, acq_track's velocity bias with the INS as aiding):

- the states a filter carries get the spec's priors and drives: a bias state's prior is the root sum square
  of the turn-on bias and the instability, its process noise the instability's Gauss-Markov drive
  sigma sqrt(1 - exp(-2 dt / tau)) over a step dt (Titterton & Weston 2004, sec. 12.6; seed 002 eq 22's Q);
  the velocity and attitude get the noise densities (q = N^2 per second);
- an error source a filter does not carry as a state enters as an equivalent random walk of the state it
  drives: a rate error r constant over the filter's memory T moves that state by r t, variance sigma_r^2 t^2,
  which a random walk of density q = sigma_r^2 T matches at t = T (and bounds from above before it); a rate
  that itself grows as a ramp (the acceleration a velocity state gets from the tilt of a constant gyro bias,
  g sigma_bg t) moves the state by sigma t^2 / 2, matched at T by q = sigma^2 T^3 / 4 (a quarter of the
  constant-rate walk of the ramp's value at T: `equivalent_ramp_walk_density`). The
  sources: the horizontal specific-force error that is constant in the body frame (accelerometer bias and
  misalignment times g: `body_accel_sigma_mps2`), the tilt the horizontal gyro biases build (the
  acceleration error's rate g sigma_bg: `tilt_accel_rate_sigma_mps3`), the heading error the z gyro bias
  builds, and in turns the gyro scale factor (heading) and misalignment (tilt) times the angle turned;
- the vertical specific-force error (z bias and scale factor x g) moves a baro-damped INS height by a
  transient of the loop (`baro_loop_height_rate_sigma_mps`), which the terrain filters' vertical offset
  walk takes in root sum square with its tuned value (`vertical_offset_walk_density`).

Beyond SMALL_ANGLE_LIMIT_RAD of attitude error over a filter's memory the small-angle models and the
equivalent walks no longer describe the INS error: `consistency_warning` says so, and the navigator reports
it in Health.consistency_warning (measured: the consumer grade, docs/validation/navigators.md).

A filter's own tuned values stay floors: the spec raises a setting, never lowers it below the value the
filter was tuned with on the navigation grade, so the navigation grade keeps its behaviour.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

G0_MPS2 = 9.80665
# attitude error (rad) the gyro biases may build over a filter's memory before its small-angle error model
# and the equivalent random walks stop describing the INS error (0.57 deg)
SMALL_ANGLE_LIMIT_RAD = 0.01
# memory of a terrain filter's vertical offset: every terrain sample measures it, so its posterior follows the
# last 10-30 s (the lags over which the filters' vertical walk was set: docs/validation/navigators.md)
VERTICAL_OFFSET_MEMORY_S = 20.0


@dataclass(frozen=True)
class ImuSpec:
    """An IMU's error budget (SI, 1 sigma per axis).

    Attributes: accel_bias_mps2 (turn-on bias), accel_bias_instability_mps2 and accel_bias_tau_s
    (Gauss-Markov), accel_noise_density_mps2_rthz (velocity random walk), accel_scale_factor_ppm,
    accel_misalignment_rad; the gyro's likewise in rad/s, rad/s/sqrt(Hz) and rad. grade: the name of the
    simulator's preset this specification is exactly ("navigation", "tactical", "consumer"; "" for any other:
    a preset with overrides), which the measured consistency of each navigator is known for
    (navigators.core.measured_consistency).
    """

    accel_bias_mps2: float = 0.0
    accel_bias_instability_mps2: float = 0.0
    accel_bias_tau_s: float = 3600.0
    accel_noise_density_mps2_rthz: float = 0.0
    accel_scale_factor_ppm: float = 0.0
    accel_misalignment_rad: float = 0.0
    gyro_bias_rps: float = 0.0
    gyro_bias_instability_rps: float = 0.0
    gyro_bias_tau_s: float = 3600.0
    gyro_noise_density_rps_rthz: float = 0.0
    gyro_scale_factor_ppm: float = 0.0
    gyro_misalignment_rad: float = 0.0
    grade: str = ""

    def __post_init__(self):
        if not isinstance(self.grade, str):
            raise ValueError(f"ImuSpec.grade must be a string, got {self.grade!r}")
        for f in fields(self):
            if f.name == "grade":
                continue
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0.0):
                raise ValueError(f"ImuSpec.{f.name} must be a finite number >= 0, got {v!r}")
        for name in ("accel_bias_tau_s", "gyro_bias_tau_s"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"ImuSpec.{name} must be > 0, got {getattr(self, name)!r}")

    @classmethod
    def from_object(cls, obj) -> ImuSpec:
        """From any object (or mapping) with these attribute names (e.g. the simulator's IMU config); `grade`
        is read only from a mapping's string value (the caller names the preset otherwise)."""
        get = obj.get if isinstance(obj, dict) else (lambda k, d: getattr(obj, k, d))
        grade = obj.get("grade", "") if isinstance(obj, dict) else ""
        return cls(**{f.name: float(get(f.name, f.default)) for f in fields(cls) if f.name != "grade"},
                   grade=grade if isinstance(grade, str) else "")

    # ---------------------------------------------------------------- biases carried as states
    @property
    def accel_bias_sigma_mps2(self) -> float:
        """Prior of an accelerometer-bias state: turn-on bias and instability, root sum square."""
        return math.hypot(self.accel_bias_mps2, self.accel_bias_instability_mps2)

    @property
    def gyro_bias_sigma_rps(self) -> float:
        """Prior of a gyro-bias state: turn-on bias and instability, root sum square."""
        return math.hypot(self.gyro_bias_rps, self.gyro_bias_instability_rps)

    def accel_bias_drive(self, dt_s: float) -> float:
        """The accelerometer instability's Gauss-Markov drive over dt_s (1 sigma, m/s^2)."""
        return gm_drive(self.accel_bias_instability_mps2, self.accel_bias_tau_s, dt_s)

    def gyro_bias_drive(self, dt_s: float) -> float:
        """The gyro instability's Gauss-Markov drive over dt_s (1 sigma, rad/s)."""
        return gm_drive(self.gyro_bias_instability_rps, self.gyro_bias_tau_s, dt_s)

    # ---------------------------------------------------------------- error sources as rates
    @property
    def body_accel_sigma_mps2(self) -> float:
        """Horizontal specific-force error constant in the body frame (m/s^2, per axis): the accelerometer
        bias (turn-on and instability) and the misalignment's share of gravity, root sum square."""
        return math.hypot(self.accel_bias_sigma_mps2, G0_MPS2 * self.accel_misalignment_rad)

    @property
    def tilt_accel_rate_sigma_mps3(self) -> float:
        """Rate of the acceleration error the horizontal gyro biases build through the tilt (g sigma_bg)."""
        return G0_MPS2 * self.gyro_bias_sigma_rps

    @property
    def vertical_accel_sigma_mps2(self) -> float:
        """Vertical specific-force error (m/s^2): the z accelerometer's bias (turn-on and instability) and its
        scale factor times gravity, root sum square."""
        return math.hypot(self.accel_bias_sigma_mps2, self.accel_scale_factor_ppm * 1e-6 * G0_MPS2)

    def baro_loop_height_rate_sigma_mps(self, tau_baro_s: float) -> float:
        """Largest rate (m/s) of the height error the vertical specific-force error a drives through a
        baro-damped vertical channel of third order with its triple pole at 1 / tau (gains 3 / tau,
        3 / tau^2, 1 / tau^3; navigators.inertial.strapdown): h(s) / a(s) = s / (s + 1 / tau)^3, so a step a
        gives h(t) = a t^2 exp(-t / tau) / 2, a transient of 0.27 a tau^2 at t = 2 tau that the loop's
        bias integrator then removes; its rate peaks at t = (2 - sqrt 2) tau at 0.2306 a tau."""
        x = 2.0 - math.sqrt(2.0)
        return float(self.vertical_accel_sigma_mps2 * tau_baro_s * x * math.exp(-x) * (1.0 - 0.5 * x))

    def turn_heading_sigma_rad(self, turn_rad: float) -> float:
        """Heading error a turn of turn_rad builds through the gyro scale factor (rad)."""
        return self.gyro_scale_factor_ppm * 1e-6 * abs(turn_rad)

    def turn_tilt_sigma_rad(self, turn_rad: float) -> float:
        """Tilt a turn of turn_rad builds through the gyro misalignment (rad)."""
        return self.gyro_misalignment_rad * abs(turn_rad)


def consistency_warning(spec: ImuSpec, memory_s: float, who: str) -> str:
    """Why `who`'s covariance cannot be trusted on this IMU ("" when nothing is known): the attitude error
    its gyro biases build over the filter's memory beyond SMALL_ANGLE_LIMIT_RAD."""
    att = spec.gyro_bias_sigma_rps * memory_s
    if att <= SMALL_ANGLE_LIMIT_RAD:
        return ""
    bias_deg_h = math.degrees(spec.gyro_bias_sigma_rps) * 3600.0
    return (f"{who}: the IMU's gyro bias ({bias_deg_h:.3g} deg/h) builds {math.degrees(att):.2g} deg of "
            f"attitude error over the filter's {memory_s:g} s memory, beyond its small-angle error model "
            f"({math.degrees(SMALL_ANGLE_LIMIT_RAD):.2g} deg): its covariance is not calibrated for this IMU "
            "(measured: docs/validation/navigators.md)")


def vertical_offset_walk_density(spec: ImuSpec, tau_baro_s: float | None) -> float:
    """Random walk (m/sqrt(s)) of an INS-ridden terrain filter's vertical offset (INS height minus true) that
    the IMU adds to the baro-slaved INS height's own wander: the baro loop's transient at its largest rate
    (ImuSpec.baro_loop_height_rate_sigma_mps) as a constant rate over VERTICAL_OFFSET_MEMORY_S; 0 without
    a baro loop."""
    if tau_baro_s is None:
        return 0.0
    return equivalent_walk_density(spec.baro_loop_height_rate_sigma_mps(tau_baro_s), VERTICAL_OFFSET_MEMORY_S)


def gm_drive(sigma: float, tau_s: float, dt_s: float) -> float:
    """A first-order Gauss-Markov process' drive over dt_s: sigma sqrt(1 - exp(-2 dt / tau))."""
    return float(sigma * math.sqrt(-math.expm1(-2.0 * dt_s / tau_s)))


def equivalent_walk_density(rate_sigma: float, memory_s: float) -> float:
    """Density (per sqrt(s)) of the random walk that matches a constant rate of sigma rate_sigma at
    memory_s: q = sigma^2 T (see the module docstring); returned as sqrt(q)."""
    return float(rate_sigma * math.sqrt(memory_s))


def equivalent_ramp_walk_density(slope_sigma: float, memory_s: float) -> float:
    """Density (per sqrt(s)) of the random walk that matches a ramp - a rate growing as slope_sigma t, e.g.
    the acceleration the tilt of a constant gyro bias builds, g sigma_bg t - at memory_s: the ramp moves the
    state by slope t^2 / 2, variance slope^2 t^4 / 4, which q t matches at t = T for q = slope^2 T^3 / 4;
    returned as sqrt(q) = slope T sqrt(T) / 2 (half the constant-rate walk of the ramp's value at T)."""
    return float(0.5 * slope_sigma * memory_s * math.sqrt(memory_s))



class TurnAngle:
    """The angle a turn term's random walk advances by, from the heading at each epoch: "total", the change
    of heading since the last epoch (the walk then runs in the summed angle turned), or "excursion", the
    growth of the largest net heading change since the anchor (the filter's reset).

    The gyro misalignment m and scale factor s build a tilt m dpsi and a heading error s dpsi from the net
    heading change dpsi since the anchor (turn_tilt_sigma_rad, turn_heading_sigma_rad: a constant error of a
    rate integrated over the angle turned), so a turn undone by the opposite turn, or the back-and-forth of
    the heading on a straight leg, builds no error. A filter not carrying m and s enters them as a random
    walk of density sigma^2 TURN_REFERENCE per rad; in the excursion its variance sigma^2 TURN_REFERENCE
    max|dpsi| bounds sigma^2 dpsi^2 up to |dpsi| = TURN_REFERENCE, as the walk in the summed angle does,
    while the heading's wander about a straight leg (on the default route 2.0 rad of summed 1 s heading
    changes before the first turn, 0.07 rad net) adds only its largest excursion once. `advance(yaw)` takes
    the heading (rad; the net change is unwrapped through +-pi; NaN is skipped) and returns the angle (rad,
    >= 0); `reset()` re-anchors.
    """

    MODES = ("total", "excursion")

    def __init__(self, mode: str = "total") -> None:
        if mode not in self.MODES:
            raise ValueError(f"TurnAngle mode must be one of {list(self.MODES)}, got {mode!r}")
        self.mode = mode
        self.reset()

    def reset(self) -> None:
        self._yaw_prev = math.nan
        self._net_rad = 0.0
        self._max_rad = 0.0

    def advance(self, yaw_rad: float) -> float:
        if not math.isfinite(yaw_rad):
            return 0.0
        step = 0.0
        if math.isfinite(self._yaw_prev):
            step = (yaw_rad - self._yaw_prev + math.pi) % (2.0 * math.pi) - math.pi
        self._yaw_prev = yaw_rad
        if self.mode == "total":
            return abs(step)
        self._net_rad += step
        grow = abs(self._net_rad) - self._max_rad
        if grow <= 0.0:
            return 0.0
        self._max_rad += grow
        return grow


def rss(*values: float) -> float:
    """Root sum square."""
    return float(math.sqrt(sum(v * v for v in values)))


__all__ = ["G0_MPS2", "SMALL_ANGLE_LIMIT_RAD", "VERTICAL_OFFSET_MEMORY_S", "ImuSpec", "TurnAngle",
           "consistency_warning", "equivalent_ramp_walk_density", "equivalent_walk_density", "gm_drive",
           "rss", "vertical_offset_walk_density"]
