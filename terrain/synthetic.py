"""Synthetic terrain by spectral synthesis (seeded), for controlled studies.

The surface is Gaussian with the von Karman (self-affine) power spectrum

    P(k) ~ (1 + (k L)^2)^-(H + 1)        (2-D, k in rad/m)

so it is smooth-random below the correlation length L and fractal (Hurst exponent H, fractal dimension
3 - H, radial PSD slope -2(H + 1) at k >> 1/L) above it; heights are scaled to the requested RMS. White
Gaussian noise from a seeded numpy Generator is shaped in the Fourier domain (the result is periodic over
the grid).

A preset with `basin_radius_fraction > 0` ("basin") has a flat basin: the relief is multiplied by a taper
that is `basin_relief_fraction` inside a disc around the grid's centre (radius = that fraction of the
smaller grid side) and rises to 1 over `basin_edge_fraction` of the side outside it, so a route from the
south edge to the north edge crosses a featureless stretch (a terrain-referenced navigator drifts there)
unless it goes round the basin over rough terrain (the route planner's test terrain).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import geodesy
from .dem import Dem


@dataclass(frozen=True)
class TerrainPreset:
    """Statistics of a synthetic terrain: RMS height (m), correlation length (m), Hurst exponent, mean (m)."""

    rms_height_m: float
    correlation_length_m: float
    hurst: float
    mean_height_m: float
    basin_radius_fraction: float = 0.0
    basin_edge_fraction: float = 0.05
    basin_relief_fraction: float = 0.005


PRESETS = {
    "flat": TerrainPreset(rms_height_m=4.0, correlation_length_m=3000.0, hurst=0.9, mean_height_m=100.0),
    "rolling": TerrainPreset(rms_height_m=40.0, correlation_length_m=1500.0, hurst=0.8, mean_height_m=300.0),
    "mountainous": TerrainPreset(
        rms_height_m=300.0, correlation_length_m=4000.0, hurst=0.7, mean_height_m=1500.0
    ),
    # rolling hills (rms 60 m) with a flat basin of radius 0.2 x 30 km = 6 km in the middle
    # (relief 0.5 %: 0.3 m rms)
    "basin": TerrainPreset(rms_height_m=60.0, correlation_length_m=1500.0, hurst=0.8, mean_height_m=300.0,
                           basin_radius_fraction=0.2),
}


def basin_taper(shape, radius_fraction: float, edge_fraction: float, relief_fraction: float) -> np.ndarray:
    """Relief multiplier (shape) of a flat basin around the grid centre (see the module docstring):
    relief_fraction inside the disc, a raised-cosine rise to 1 over edge_fraction of the smaller side."""
    n_y, n_x = shape
    side = min(n_y, n_x)
    y = np.arange(n_y)[:, None] - 0.5 * (n_y - 1)
    x = np.arange(n_x)[None, :] - 0.5 * (n_x - 1)
    r = np.hypot(y, x) / side
    t = np.clip((r - radius_fraction) / max(edge_fraction, 1e-9), 0.0, 1.0)
    rise = 0.5 - 0.5 * np.cos(np.pi * t)
    return relief_fraction + (1.0 - relief_fraction) * rise


def psd_field(
    shape, spacing_m: float, correlation_length_m: float, hurst: float, rng: np.random.Generator
) -> np.ndarray:
    """Zero-mean, unit-RMS Gaussian field (shape) with the von Karman spectrum of the module docstring."""
    n_y, n_x = shape
    ky = 2.0 * np.pi * np.fft.fftfreq(n_y, d=spacing_m)
    kx = 2.0 * np.pi * np.fft.rfftfreq(n_x, d=spacing_m)
    k2 = ky[:, None] ** 2 + kx[None, :] ** 2
    amp = (1.0 + k2 * correlation_length_m**2) ** (-(hurst + 1.0) / 2.0)
    amp[0, 0] = 0.0
    noise = np.fft.rfft2(rng.standard_normal((n_y, n_x)))
    field = np.fft.irfft2(noise * amp, s=(n_y, n_x))
    field -= field.mean()
    rms = field.std()
    if rms == 0.0:
        return field
    return field / rms


def generate(
    n_lat: int = 256,
    n_lon: int = 256,
    spacing_m: float = 90.0,
    rms_height_m: float = 40.0,
    correlation_length_m: float = 1500.0,
    hurst: float = 0.8,
    mean_height_m: float = 300.0,
    seed: int | np.random.Generator = 0,
    lat0_deg: float = 36.5,
    lon0_deg: float = -84.3,
    name: str = "synthetic",
) -> Dem:
    """A seeded synthetic DEM of n_lat x n_lon posts spaced spacing_m (north and east) from the SW post."""
    if n_lat < 2 or n_lon < 2:
        raise ValueError(f"generate: need at least 2 x 2 posts, got n_lat={n_lat}, n_lon={n_lon}")
    for field_name, value in (("spacing_m", spacing_m), ("correlation_length_m", correlation_length_m)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"generate: {field_name} must be positive, got {value}")
    if not (0.0 < hurst <= 1.0):
        raise ValueError(f"generate: hurst must be in (0, 1], got {hurst}")
    if not (rms_height_m >= 0.0):
        raise ValueError(f"generate: rms_height_m must be >= 0, got {rms_height_m}")
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    field = psd_field((n_lat, n_lon), spacing_m, correlation_length_m, hurst, rng)
    heights = mean_height_m + rms_height_m * field
    lat0 = np.radians(lat0_deg)
    lat_c = lat0 + 0.5 * (n_lat - 1) * spacing_m / geodesy.meridian_radius_m(lat0)
    dlat = spacing_m / geodesy.meridian_radius_m(lat_c)
    dlon = spacing_m / (geodesy.prime_vertical_radius_m(lat_c) * np.cos(lat_c))
    return Dem(heights, lat0, np.radians(lon0_deg), dlat, dlon, name)


def from_preset(
    preset: str,
    seed: int | np.random.Generator = 0,
    n_lat: int = 334,
    n_lon: int = 334,
    spacing_m: float = 90.0,
    **grid,
) -> Dem:
    """Synthetic DEM from a named preset ('flat', 'rolling', 'mountainous', 'basin'); 30 x 30 km at 90 m by
    default."""
    key = preset.strip().lower()
    if key not in PRESETS:
        raise ValueError(f"unknown synthetic terrain preset {preset!r}; choose from {sorted(PRESETS)}")
    p = PRESETS[key]
    dem = generate(
        n_lat,
        n_lon,
        spacing_m,
        p.rms_height_m,
        p.correlation_length_m,
        p.hurst,
        p.mean_height_m,
        seed=seed,
        name=f"synthetic:{key}",
        **grid,
    )
    if p.basin_radius_fraction <= 0.0:
        return dem
    taper = basin_taper(dem.heights_m.shape, p.basin_radius_fraction, p.basin_edge_fraction,
                        p.basin_relief_fraction)
    return dem.with_heights(p.mean_height_m + (dem.heights_m - p.mean_height_m) * taper, name=dem.name)
