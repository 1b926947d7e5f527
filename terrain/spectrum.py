"""Radially averaged power spectral density of a DEM and power-law fits (used by refine and tests).

Convention: for heights z on an (ny, nx) grid of spacing (dy, dx) metres, the one-sided-in-nothing 2-D
periodogram is P(f) = |FFT(w z)|^2 dx dy / (nx ny mean(w^2)) in m^2 / (cycle/m)^2 with a Hann window w
after removing the best-fit plane; then sum(P) / (nx dx ny dy) ~ variance. A field synthesised with
Fourier amplitudes sqrt(P(f) / (dx dy)) times the FFT of unit white noise has this periodogram.
"""

from __future__ import annotations

import numpy as np


def detrend_plane(z: np.ndarray) -> np.ndarray:
    """z minus its least-squares plane."""
    ny, nx = z.shape
    yy, xx = np.mgrid[0:ny, 0:nx]
    a = np.column_stack([np.ones(z.size), xx.ravel(), yy.ravel()])
    coef, *_ = np.linalg.lstsq(a, z.ravel(), rcond=None)
    return z - (a @ coef).reshape(z.shape)


def radial_psd(z: np.ndarray, dy_m: float, dx_m: float, n_bins: int = 40):
    """(f_cycles_per_m, psd) radially averaged over log-spaced bins, from f = 1/(n d) to the Nyquist of the
    finer axis. Voids (NaN) are not allowed here: fill them first."""
    if not np.isfinite(z).all():
        raise ValueError("radial_psd: heights contain NaN voids; fill them first")
    ny, nx = z.shape
    w = np.outer(np.hanning(ny), np.hanning(nx))
    zz = detrend_plane(np.asarray(z, dtype=np.float64)) * w
    p = np.abs(np.fft.fft2(zz)) ** 2 * dx_m * dy_m / (nx * ny * np.mean(w * w))
    fy = np.fft.fftfreq(ny, d=dy_m)
    fx = np.fft.fftfreq(nx, d=dx_m)
    f = np.hypot(fy[:, None], fx[None, :])
    f_lo = 1.0 / min(ny * dy_m, nx * dx_m)
    f_hi = 0.5 / max(dx_m, dy_m)
    edges = np.geomspace(f_lo, f_hi, n_bins + 1)
    idx = np.digitize(f.ravel(), edges) - 1
    ok = (idx >= 0) & (idx < n_bins)
    sums = np.bincount(idx[ok], weights=p.ravel()[ok], minlength=n_bins)
    counts = np.bincount(idx[ok], minlength=n_bins)
    centres = np.sqrt(edges[:-1] * edges[1:])
    keep = counts > 0
    return centres[keep], sums[keep] / counts[keep]


def fit_power_law(f: np.ndarray, psd: np.ndarray, f_min: float, f_max: float):
    """Least-squares fit log P = log C - beta log f over f_min <= f <= f_max; returns (C, beta)."""
    sel = (f >= f_min) & (f <= f_max) & (psd > 0)
    if sel.sum() < 3:
        raise ValueError(f"fit_power_law: fewer than 3 PSD bins in [{f_min}, {f_max}] cycles/m")
    slope, intercept = np.polyfit(np.log(f[sel]), np.log(psd[sel]), 1)
    return float(np.exp(intercept)), float(-slope)
