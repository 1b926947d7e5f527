"""Sensor aiding and wind (seed 001 ch. 4; spec section 5).

Aided loop: the replica's sample i moves with v_i = m_v[i] + b_v and psi_i = m_psi[i] + b_psi, where m are
the supportive sensors' per-sample values and b the one unknown reference per loop: a constant bias
(sensor bias, the wind's data bias) is absorbed into b, and a ramp in the true speed is followed by m, so
the loop sees only what the sensors get wrong. Unaided, m = 0 and b is the speed / heading itself.

Sources:
- "air_data": true airspeed and compass heading are air-referenced; the ground speed and track differ by
  the wind (the data bias). With wind estimation, the ground vector is predicted as air vector + wind
  estimate W (NED, m/s), so a turn does not turn the wind's bias into a speed/heading ramp; W is updated
  from the wind triangle W = ground - air whenever the ground vector is known (GNSS velocity, or the
  tracked speed and track while in lock) by a first-order low-pass (wind_gain per sample).
- "ins": the strapdown INS's ground velocity (an IRS, as in the thesis' flights): speed and track directly
  (no wind bias); its slow drift is the bias the loops absorb.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


def wrap_rad(a):
    """Angle(s) wrapped to (-pi, pi]."""
    return np.arctan2(np.sin(a), np.cos(a))


def ground_vector(speed_mps: float, track_rad: float) -> np.ndarray:
    """(north, east) velocity of a speed and a track (clockwise from north)."""
    return np.array([speed_mps * math.cos(track_rad), speed_mps * math.sin(track_rad)])


def speed_track(v_ne: np.ndarray) -> tuple[float, float]:
    """(speed, track) of a (north, east) velocity."""
    return float(math.hypot(v_ne[0], v_ne[1])), float(math.atan2(v_ne[1], v_ne[0]))


@njit(cache=True)
def air_vector_sum(air_t, tas, beta, air_ok, hdg_t, hdg, hdg_ok, lo_s, hi_s, max_gap_s):
    """(sum tas cos(h + beta), sum tas sin(h + beta), count) over the valid air-data samples with
    lo_s < t <= hi_s (1e-9 s tolerance) and a finite tas, h the newest valid finite heading at or before
    each sample's time within max_gap_s (sample_at's rule; samples without one are left out). Both time
    arrays increasing. One pass instead of a dozen array operations per transect sample."""
    sn = 0.0
    se = 0.0
    m = 0
    j = -1  # newest heading index with hdg_t <= the air sample's time + 1e-9
    k = -1  # newest valid finite heading index so far
    nh = hdg_t.shape[0]
    for i in range(air_t.shape[0]):
        ta = air_t[i]
        if not (air_ok[i] and ta > lo_s + 1e-9 and ta <= hi_s + 1e-9):
            continue
        while j + 1 < nh and hdg_t[j + 1] <= ta + 1e-9:
            j += 1
            if hdg_ok[j] and np.isfinite(hdg[j]):
                k = j
        if k < 0 or ta - hdg_t[k] > max_gap_s or not np.isfinite(tas[i]):
            continue
        d = hdg[k] + beta[i]
        sn += tas[i] * math.cos(d)
        se += tas[i] * math.sin(d)
        m += 1
    return sn, se, m


@njit(cache=True)
def lsq_rate(t, v, ok, t_s, window_s):
    """Least-squares slope (per s) of v over the valid finite samples with t_s - window_s <= t <= t_s
    (1e-9 s tolerance at t_s); NaN with fewer than 3 of them."""
    m = 0
    tm = 0.0
    vm = 0.0
    for i in range(t.shape[0]):
        if ok[i] and t[i] <= t_s + 1e-9 and t[i] >= t_s - window_s and np.isfinite(v[i]):
            m += 1
            tm += t[i]
            vm += v[i]
    if m < 3:
        return np.nan
    tm /= m
    vm /= m
    num = 0.0
    den = 0.0
    for i in range(t.shape[0]):
        if ok[i] and t[i] <= t_s + 1e-9 and t[i] >= t_s - window_s and np.isfinite(v[i]):
            x = t[i] - tm
            den += x * x
            num += x * (v[i] - vm)
    return num / den if den > 0.0 else np.nan


class WindEstimator:
    """Wind from the wind triangle W = V_ground - V_air (horizontal, NED), low-passed with `gain` per update;
    `predict` turns an air vector into the predicted ground speed and track."""

    def __init__(self, gain: float):
        self.gain = float(gain)
        self.w_ne = np.zeros(2)
        self.n_updates = 0

    def reset(self) -> None:
        self.w_ne[:] = 0.0
        self.n_updates = 0

    def update(
        self, ground_ne: np.ndarray, tas_mps: float, heading_rad: float, gain: float | None = None
    ) -> None:
        if not (np.all(np.isfinite(ground_ne)) and math.isfinite(tas_mps) and math.isfinite(heading_rad)):
            return
        w_meas = np.asarray(ground_ne, float) - ground_vector(tas_mps, heading_rad)
        k = self.gain if gain is None else float(gain)
        if self.n_updates == 0:
            k = 1.0  # the first triangle sets the estimate
        self.w_ne += k * (w_meas - self.w_ne)
        self.n_updates += 1

    def predict(self, tas_mps: float, heading_rad: float) -> tuple[float, float]:
        """(ground speed, track) = air vector + wind estimate (the wind's data bias removed)."""
        return speed_track(ground_vector(tas_mps, heading_rad) + self.w_ne)


def coordinated_turn_roll_rad(tas_mps: float, heading_rate_rps: float, g_mps2: float = 9.80665) -> float:
    """Bank angle of a coordinated turn, roll = atan(V psi_dot / g) (right turn: positive roll)."""
    return float(math.atan2(tas_mps * heading_rate_rps, g_mps2))


def sample_at(
    t_query: np.ndarray, t: np.ndarray, values: np.ndarray, valid: np.ndarray, max_gap_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Values at t_query from the newest valid sample at or before each time (within max_gap_s); (values,
    found mask). t must be increasing."""
    ok = valid & np.isfinite(values)
    tv, vv = t[ok], values[ok]
    out = np.full(t_query.shape, np.nan)
    found = np.zeros(t_query.shape, bool)
    if tv.size == 0:
        return out, found
    k = np.searchsorted(tv, t_query + 1e-9, side="right") - 1
    has = k >= 0
    kk = np.clip(k, 0, tv.size - 1)
    good = has & (t_query - tv[kk] <= max_gap_s)
    out[good] = vv[kk[good]]
    found[good] = True
    return out, found
