"""Refine a DEM to a finer grid with synthetic fractal detail that continues the coarse spectrum.

The "world" the sensors see can be finer than any map: `refine(dem, spacing_m=10)` returns
    bicubic(coarse) + detail,
where `detail` is a seeded Gaussian field whose radially averaged PSD continues the power law
P(f) = C f^-beta fitted to the coarse DEM's PSD (terrain.spectrum) over the band f_nyq/10 .. f_nyq/2, and
covers only the band the coarse grid cannot hold (f > f_nyq of the coarse grid). The part of the detail
that the coarse posts would see is removed (detail minus its bicubic interpolation from the coarse posts),
so the refined DEM equals the coarse DEM at every coarse post.

Memory: one float64 array of the refined grid plus FFT work space (~4 x that); 34 x 32 km at 10 m is
3400 x 3200 posts (87 MB per array). Use `region` to refine a sub-area; `max_posts` guards against typos.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import geodesy, kernels, spectrum
from .dem import Dem


def fit_dem_spectrum(dem: Dem, band=(0.1, 0.5)):
    """(C, beta, f_nyquist) of the coarse DEM's radial PSD power law, fitted over band x Nyquist."""
    dn, de = dem.spacing_m
    z = dem.heights_m
    if not np.isfinite(z).all():
        from .loaders import fill_voids

        z = fill_voids(z, dem.name)
    f, p = spectrum.radial_psd(z, dn, de)
    f_nyq = 0.5 / max(dn, de)
    c, beta = spectrum.fit_power_law(f, p, band[0] * f_nyq, band[1] * f_nyq)
    return c, beta, f_nyq


@dataclass(frozen=True)
class RefinementPlan:
    """The refined grid `refine` would build: its posts (radians) and the coarse region it covers."""

    lat_rad: np.ndarray            # the fine posts' latitudes, south to north
    lon_rad: np.ndarray            # ... and longitudes, west to east
    k_lat: int                     # fine posts per coarse spacing (coarse posts are fine posts)
    k_lon: int
    region: tuple[float, float, float, float]     # lat_min, lat_max, lon_min, lon_max clipped to the DEM

    @property
    def shape(self) -> tuple[int, int]:
        return self.lat_rad.size, self.lon_rad.size


def refinement_plan(dem: Dem, spacing_m: float = 10.0, region=None, max_posts: int = 40_000_000
                    ) -> RefinementPlan:
    """The grid `refine(dem, spacing_m, region=region, max_posts=max_posts)` builds, without building it;
    raises ValueError for the arguments `refine` refuses (a spacing not finer than the DEM's, a region
    outside it, more than max_posts posts)."""
    if not (np.isfinite(spacing_m) and spacing_m > 0):
        raise ValueError(f"refine: spacing_m must be positive, got {spacing_m}")
    dn_c, de_c = dem.spacing_m
    if spacing_m >= min(dn_c, de_c):
        raise ValueError(f"refine: spacing_m={spacing_m} is not finer than the DEM's {min(dn_c, de_c):.1f} m")
    lat_min, lat_max, lon_min, lon_max = dem.bounds if region is None else region
    b = dem.bounds
    lat_min, lat_max = max(lat_min, b[0]), min(lat_max, b[1])
    lon_min, lon_max = max(lon_min, b[2]), min(lon_max, b[3])
    if not (lat_max > lat_min and lon_max > lon_min):
        raise ValueError("refine: region does not overlap the DEM")
    # fine posts: integer subdivisions of the coarse spacing, so that coarse posts are fine posts
    k_lat = int(np.ceil(dn_c / spacing_m))
    k_lon = int(np.ceil(de_c / spacing_m))
    i0 = int(np.floor((lat_min - dem.lat0_rad) / dem.dlat_rad + 1e-9))
    i1 = int(np.ceil((lat_max - dem.lat0_rad) / dem.dlat_rad - 1e-9))
    j0 = int(np.floor((lon_min - dem.lon0_rad) / dem.dlon_rad + 1e-9))
    j1 = int(np.ceil((lon_max - dem.lon0_rad) / dem.dlon_rad - 1e-9))
    n_lat = (i1 - i0) * k_lat + 1
    n_lon = (j1 - j0) * k_lon + 1
    if n_lat * n_lon > max_posts:
        raise ValueError(
            f"refine: {n_lat} x {n_lon} posts exceeds max_posts={max_posts}; pass a smaller region"
        )
    lat0 = dem.lat0_rad + i0 * dem.dlat_rad
    lon0 = dem.lon0_rad + j0 * dem.dlon_rad
    return RefinementPlan(lat0 + np.arange(n_lat) * (dem.dlat_rad / k_lat),
                          lon0 + np.arange(n_lon) * (dem.dlon_rad / k_lon), k_lat, k_lon,
                          (lat_min, lat_max, lon_min, lon_max))


def refine(
    dem: Dem,
    spacing_m: float = 10.0,
    seed: int | np.random.Generator = 0,
    region=None,
    max_posts: int = 40_000_000,
    detail: bool = True,
    name: str | None = None,
) -> Dem:
    """Refined copy of `dem` at about `spacing_m` (north and east), over `region` = (lat_min, lat_max,
    lon_min, lon_max) radians (default: the whole DEM). Seeded; see the module docstring."""
    plan = refinement_plan(dem, spacing_m, region, max_posts)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    lat, lon = plan.lat_rad, plan.lon_rad
    lat0, lon0 = lat[0], lon[0]
    dlat, dlon = dem.dlat_rad / plan.k_lat, dem.dlon_rad / plan.k_lon
    grid = dem.grid
    base = _bicubic_grid(grid, lat, lon)
    heights = base
    if detail:
        c, beta, f_nyq_c = fit_dem_spectrum(dem.subset(*plan.region) if region is not None else dem)
        lat_c = 0.5 * (lat[0] + lat[-1])
        dy = dlat * geodesy.meridian_radius_m(lat_c)
        dx = dlon * geodesy.prime_vertical_radius_m(lat_c) * np.cos(lat_c)
        field = _power_law_band(rng, plan.shape, dy, dx, c, beta, f_nyq_c)
        # remove what the coarse posts see: subtract the bicubic interpolation of the coarse-post samples
        coarse_samples = field[::plan.k_lat, ::plan.k_lon]
        sub = Dem(coarse_samples, lat0, lon0, dem.dlat_rad, dem.dlon_rad, "detail")
        field -= _bicubic_grid(sub.grid, lat, lon)
        heights = base + field
    return Dem(heights, lat0, lon0, dlat, dlon, name or f"{dem.name}@{spacing_m:g}m")


def _bicubic_grid(grid, lat, lon) -> np.ndarray:
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    out = np.empty(la.size)
    kernels.bicubic_batch(*grid, la.ravel(), lo.ravel(), out)
    return out.reshape(la.shape)


def _power_law_band(rng, shape, dy_m, dx_m, c, beta, f_lo):
    """Gaussian field with PSD c f^-beta for f > f_lo (zero below), periodogram convention of spectrum."""
    ny, nx = shape
    fy = np.fft.fftfreq(ny, d=dy_m)
    fx = np.fft.rfftfreq(nx, d=dx_m)
    f = np.hypot(fy[:, None], fx[None, :])
    amp = np.zeros_like(f)
    band = f > f_lo
    amp[band] = np.sqrt(c * f[band] ** (-beta) / (dx_m * dy_m))
    noise = np.fft.rfft2(rng.standard_normal(shape))
    return np.fft.irfft2(noise * amp, s=shape)
