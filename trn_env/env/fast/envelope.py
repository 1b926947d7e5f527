"""The King Air's point-mass envelope for the fast tier, measured once from our JSBSim aircraft.

Every figure the fast tier's 3-DOF aircraft (trn_env.env.fast.dynamics) uses to stand in for the JSBSim
King Air with its autopilot (aircraft/kingair, Systems/kingair_autopilot.xml) is in `KINGAIR_ENVELOPE`.
How each was measured (`measure_envelope`, which regenerates them; `python -m trn_env.env.fast.envelope`):
one JSBSim flight at 1,500 m MSL and 85 m/s true airspeed in calm air, autopilot in track hold and altitude
hold at the 25 deg bank limit and 7.5 m/s climb limit (the autopilot's defaults, the ones TerrainNav-v0
flies), sampled every 0.1 s:

- a 90 deg track change: the largest bank (bank_max_rad), the steady turn rate at it
  (turn_rate_max_rps) and the bank's first-order time constant (bank_tau_s: the time to reach 63 % of the
  steady bank);
- a +400 m altitude step: the steady climb rate (climb_rate_max_mps, the median vertical speed while the
  altitude error exceeds 100 m) and then a -400 m step: the steady descent rate (descent_rate_max_mps);
- the true airspeed's trade against the vertical speed (tas_per_vs, m/s of airspeed lost per m/s of
  climb) and its first-order lag (tas_tau_s), measured not in this calm flight but in the full loop as
  the fast tier's reference routes fly it (turbulence, terrain following at the task's settings:
  scripts/fast_tier_speed_trade.py): the least-squares fit of TAS = tas_mps - tas_per_vs x VS lagged by
  tas_tau_s (fit_speed_trade). The autopilot holds the true airspeed by power (ap/speed-mode 1, a PI on
  the throttle), but following the terrain the throttle saturates (idle in the descents), so the aircraft
  speeds up descending and slows climbing; with it, the airspeed's slow wander (tas_wander_mps,
  tas_wander_tau_s, a first-order Gauss-Markov process): the same script takes the full loop's horizontal
  ground speed less that fit, its departure from the mean over the seeds at each second, and its variance
  and integral time scale, and attributes what exceeds the fast tier's gusts (kernel_params.TURBULENCE_*,
  along the track) to the wander (wander_from_spread);
- the autopilot's own laws, read from the XML (not measured): turn-rate command = track error / 5 s
  (track_gain_per_s), vertical-speed command = 0.15 1/s x height error (height_gain_per_s), the
  vertical-speed target's rate limit 1.5 m/s^2 (vs_accel_max_mps2).

The fast tier's true airspeed is tas_mps - tas_per_vs x (its vertical speed lagged by tas_tau_s).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class Envelope:
    """Point-mass envelope (SI units). See the module docstring for how each figure was measured."""

    tas_mps: float
    bank_max_rad: float
    turn_rate_max_rps: float
    bank_tau_s: float
    climb_rate_max_mps: float
    descent_rate_max_mps: float
    track_gain_per_s: float
    height_gain_per_s: float
    vs_accel_max_mps2: float
    tas_per_vs: float
    tas_tau_s: float
    tas_wander_mps: float
    tas_wander_tau_s: float


# Measured with measure_envelope() (JSBSim 1.3 King Air, see the module docstring); the command and the
# output are in docs/validation/fast_tier.md.
KINGAIR_ENVELOPE = Envelope(
    tas_mps=85.0,
    bank_max_rad=0.4577,  # 26.2 deg (the 25 deg limit plus the roll loop's overshoot)
    turn_rate_max_rps=0.05579,  # 3.20 deg/s
    bank_tau_s=1.0,
    climb_rate_max_mps=7.54,
    descent_rate_max_mps=7.46,
    track_gain_per_s=0.2,
    height_gain_per_s=0.15,
    vs_accel_max_mps2=1.5,
    # scripts/fast_tier_speed_trade.py --seeds 4 --routes jacksboro_sw_ne basin_west jacksboro_flat_patch
    tas_per_vs=0.71,
    tas_tau_s=3.0,
    tas_wander_mps=1.48,
    tas_wander_tau_s=40.0,
)


def fit_speed_trade(runs, tas_mps: float, taus_s=None) -> tuple[float, float]:
    """(tas_per_vs, tas_tau_s): the least-squares fit of TAS - tas_mps = -tas_per_vs x VS_lagged over the
    rows of every run (arrays of rows: time s, true airspeed m/s, vertical speed m/s up, evenly spaced),
    VS_lagged the vertical speed through a first-order lag of tas_tau_s (zero at each run's start), the lag
    taken from the grid taus_s (default 0.5 to 12 s in 0.5 s steps)."""
    if taus_s is None:
        taus_s = np.arange(0.5, 12.01, 0.5)
    best = (math.inf, 0.0, 0.0)
    for tau in taus_s:
        num = den = 0.0
        lagged_runs = []
        for x in runs:
            x = np.asarray(x, float)
            dt = float(x[1, 0] - x[0, 0])
            a = 1.0 - math.exp(-dt / tau)
            lagged = np.empty(x.shape[0])
            acc = 0.0
            for k in range(x.shape[0]):
                acc += a * (x[k, 2] - acc)
                lagged[k] = acc
            d_tas = x[:, 1] - tas_mps
            num += float(lagged @ d_tas)
            den += float(lagged @ lagged)
            lagged_runs.append((lagged, d_tas))
        gain = -num / den
        res = sum(float(np.sum((d + gain * g) ** 2)) for g, d in lagged_runs)
        if res < best[0]:
            best = (res, gain, float(tau))
    return best[1], best[2]


def seed_spread(residuals) -> tuple[float, float]:
    """(variance m^2/s^2, integral time scale s) of a speed residual's departure from its mean over the
    seeds at each time: residuals (seeds x times, m/s, 1 Hz, two seeds or more), the variance unbiased over
    the seeds, the time scale 0.5 s + the sum of the autocorrelation up to its first negative lag."""
    m = np.asarray(residuals, float)
    n = m.shape[0]
    dev = (m - m.mean(0)) * math.sqrt(n / (n - 1))
    var = float(np.mean(dev * dev))
    t_int = 0.5
    for k in range(1, m.shape[1] // 2):
        r = float(np.mean(dev[:, :-k] * dev[:, k:])) / var
        if r < 0.0:
            break
        t_int += r
    return var, t_int


def wander_from_spread(var: float, t_int_s: float, gust_sigma_mps: float,
                       gust_tau_s: float) -> tuple[float, float]:
    """(tas_wander_mps, tas_wander_tau_s): the first-order Gauss-Markov speed process that adds to the fast
    tier's along-track gust (std gust_sigma_mps, correlation time gust_tau_s) what the full loop's seed
    spread (var, t_int_s: seed_spread) has beyond it: its variance and its variance x time scale (the
    position spread it makes grows as 2 sigma^2 tau t). (0, 0) when the gust already accounts for it."""
    dv = var - gust_sigma_mps**2
    dvt = var * t_int_s - gust_sigma_mps**2 * gust_tau_s
    if dv <= 0.0 or dvt <= 0.0:
        return 0.0, 0.0
    return math.sqrt(dv), dvt / dv


def measure_envelope(tas_mps: float = 85.0, h_msl_m: float = 1500.0) -> dict:
    """Fly the JSBSim King Air through a 90 deg track change and +-400 m altitude steps (calm air) and return
    the envelope's figures (see the module docstring) as a dict of floats."""
    from trn_env.flight.core import AutopilotTargets, Flight, InitialCondition, LateralMode, VerticalMode

    lat0, lon0 = math.radians(36.5), math.radians(-84.3)
    fl = Flight(InitialCondition(lat0, lon0, h_msl_m, tas_mps, 0.0), dt_s=0.01, constant_fuel=True)

    def fly(targets, seconds):
        fl.set_targets(targets)
        rows = []
        for _ in range(int(round(seconds / 0.1))):
            c = fl.advance(10)
            v = c.v_ned_mps[-1]
            rows.append(
                (c.t_s[-1], c.roll_rad[-1], math.atan2(v[1], v[0]), c.h_msl_m[-1], -v[2], c.tas_mps[-1])
            )
        return np.array(rows)

    def hold(track_rad: float, h_cmd_m: float) -> AutopilotTargets:
        return AutopilotTargets(lateral_mode=LateralMode.TRACK, track_cmd_rad=track_rad,
                                vertical_mode=VerticalMode.ALTITUDE_MSL, altitude_cmd_m=h_cmd_m,
                                tas_cmd_mps=tas_mps)

    fly(hold(0.0, h_msl_m), 20.0)
    turn = fly(hold(math.pi / 2, h_msl_m), 60.0)
    bank = turn[:, 1]
    bank_max = float(np.max(np.abs(bank)))
    track = np.unwrap(turn[:, 2])
    rate = np.gradient(track, turn[:, 0])
    steady = np.abs(bank) > 0.95 * bank_max
    i63 = int(np.argmax(np.abs(bank) >= 0.63 * bank_max))
    climb = fly(hold(math.pi / 2, h_msl_m + 400.0), 120.0)
    up = climb[:, 3] < h_msl_m + 300.0
    descent = fly(hold(math.pi / 2, h_msl_m), 120.0)
    down = descent[:, 3] > h_msl_m + 100.0
    return {
        "tas_mps": float(np.median(turn[:, 5])),
        "bank_max_rad": bank_max,
        "turn_rate_max_rps": float(np.median(np.abs(rate[steady]))),
        "bank_tau_s": float(turn[i63, 0] - turn[0, 0]),
        "climb_rate_max_mps": float(np.median(climb[up, 4][5:])),
        "descent_rate_max_mps": float(-np.median(descent[down, 4][5:])),
        "tas_range_mps": [
            float(np.min(np.r_[turn[:, 5], climb[:, 5], descent[:, 5]])),
            float(np.max(np.r_[turn[:, 5], climb[:, 5], descent[:, 5]])),
        ],
    }


if __name__ == "__main__":  # pragma: no cover - regenerates the figures
    import json

    print(json.dumps({"measured": measure_envelope(), "stated": asdict(KINGAIR_ENVELOPE)}, indent=1))
