"""Integrity of the tracker (seed 001 ch. 4; spec section 5): terrain SNR, V-shape, false lock, output filter.

- Terrain SNR = var(terrain heights of the prompt profile) / sigma_noise^2, in dB; about 5 dB is the
  thesis' critical minimum. sigma_noise^2 (our choice, spec section 8) is the larger of the a-priori
  noise (radar altimeter const + fraction * range, and the map error) and the residual variance of
  measured minus replica heights at the prompt, so a footprint or map error the model does not know about
  still lowers the SNR.
- V-shape flag: the SCF or HCF has no V around its minimum (tracking.analyse_v) - out of lock.
- False lock (our test; the thesis names it without a formula): the prompt's residual sigma exceeds
  false_lock_sigma_factor x the a-priori sigma (the loop sits on a side peak that does not fit), or an
  aided reference drifted beyond the plausible bias (max_speed_bias_mps / max_heading_bias_deg).
- Output filter: a moving average of length >= N/2 over the tracked speed and track, applied only while
  consecutive estimates agree within the tolerances; a disagreement restarts it.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
from numba import njit


def a_priori_sigma_m(range_m: float, ra_const_m: float, ra_fraction: float, map_sigma_m: float) -> float:
    """1-sigma measured-minus-map height noise (m) from the radar-altimeter and map error models."""
    r = range_m if math.isfinite(range_m) else 0.0
    return math.sqrt((ra_const_m + ra_fraction * r) ** 2 + map_sigma_m**2)


def terrain_snr_db(
    h_prompt: np.ndarray, d: np.ndarray, valid: np.ndarray, sigma_prior_m: float, remove_bias: bool = True
) -> tuple[float, float]:
    """(terrain SNR in dB, residual sigma in m) of the prompt replica heights h_prompt against the measured
    heights d (valid samples with a finite map height; SNR -inf without two of them)."""
    snr, res_sigma = _snr_kernel(
        np.ascontiguousarray(h_prompt, dtype=np.float64), np.ascontiguousarray(d, dtype=np.float64),
        np.ascontiguousarray(valid, dtype=np.bool_), float(sigma_prior_m), bool(remove_bias),
    )  # fmt: skip
    return float(snr), float(res_sigma)


@njit(cache=True)
def _snr_kernel(h, d, valid, sigma_prior_m, remove_bias):
    """terrain_snr_db's arithmetic in one pass set (it runs once per epoch on N samples)."""
    m = 0
    hm = 0.0
    rm = 0.0
    for i in range(h.shape[0]):
        if valid[i] and np.isfinite(h[i]) and np.isfinite(d[i]):
            m += 1
            hm += h[i]
            rm += d[i] - h[i]
    if m < 2:
        return -np.inf, np.nan
    hm /= m
    rm = rm / m if remove_bias else 0.0
    var_h = 0.0
    res_var = 0.0
    for i in range(h.shape[0]):
        if valid[i] and np.isfinite(h[i]) and np.isfinite(d[i]):
            dh = h[i] - hm
            var_h += dh * dh
            r = d[i] - h[i] - rm
            res_var += r * r
    var_h /= m
    res_var /= m
    noise_var = max(res_var, sigma_prior_m * sigma_prior_m, 1e-12)
    snr = 10.0 * math.log10(var_h / noise_var) if var_h > 0.0 else -np.inf
    return snr, math.sqrt(res_var)


def false_lock(
    residual_sigma_m: float,
    sigma_prior_m: float,
    factor: float,
    b_v: float,
    b_psi_rad: float,
    aided: bool,
    max_speed_bias_mps: float,
    max_heading_bias_rad: float,
) -> str:
    """'' when the lock is plausible, else the reason it is a false lock."""
    if math.isfinite(residual_sigma_m) and residual_sigma_m > factor * max(sigma_prior_m, 1e-9):
        return f"residual {residual_sigma_m:.1f} m > {factor:g} x a-priori {sigma_prior_m:.1f} m"
    if aided and abs(b_v) > max_speed_bias_mps:
        return f"speed reference {b_v:+.1f} m/s beyond +-{max_speed_bias_mps:g}"
    if aided and abs(b_psi_rad) > max_heading_bias_rad:
        lim = math.degrees(max_heading_bias_rad)
        return f"heading reference {math.degrees(b_psi_rad):+.1f} deg beyond +-{lim:g}"
    return ""


class OutputAverage:
    """Moving average of (speed, track) over up to `length` epochs, run only while consecutive estimates
    agree within (speed_tol_mps, heading_tol_rad); a disagreement or reset restarts it."""

    def __init__(self, length: int, speed_tol_mps: float, heading_tol_rad: float):
        self.length = int(length)
        self.speed_tol = float(speed_tol_mps)
        self.heading_tol = float(heading_tol_rad)
        self._buf: deque[tuple[float, float]] = deque(maxlen=self.length)

    def reset(self) -> None:
        self._buf.clear()

    def __len__(self) -> int:
        return len(self._buf)

    def push(self, speed_mps: float, track_rad: float) -> tuple[float, float]:
        """Add one estimate; returns the averaged (speed, track)."""
        if self._buf:
            v0, p0 = self._buf[-1]
            dp = abs(math.atan2(math.sin(track_rad - p0), math.cos(track_rad - p0)))
            if abs(speed_mps - v0) > self.speed_tol or dp > self.heading_tol:
                self._buf.clear()
        self._buf.append((float(speed_mps), float(track_rad)))
        n = len(self._buf)
        v = sum(b[0] for b in self._buf) / n
        s = sum(math.sin(b[1]) for b in self._buf) / n
        c = sum(math.cos(b[1]) for b in self._buf) / n
        return v, math.atan2(s, c)
