"""A synthetic DEM for the TERCOM fix-covariance tests: a sum of plane waves over a square grid."""

from __future__ import annotations

import math

import numpy as np
from trn_env.terrain.dem import Dem
from trn_env.terrain.geodesy import meridian_radius_m, prime_vertical_radius_m

LAT0, LON0 = math.radians(36.4), math.radians(-84.4)
POST_M = 30.0
N_POSTS = 240


def wave_map(seed: int, flat: bool = False) -> Dem:
    """N_POSTS x N_POSTS posts of POST_M m from (LAT0, LON0): 400 m plus 12 plane waves of 300-2,000 m
    wavelength and 10-25 m amplitude drawn from `seed` (flat: 400 m everywhere)."""
    r_n = meridian_radius_m(LAT0)
    r_e = prime_vertical_radius_m(LAT0) * math.cos(LAT0)
    y, x = np.meshgrid(np.arange(N_POSTS) * POST_M, np.arange(N_POSTS) * POST_M, indexing="ij")
    rng = np.random.default_rng(seed)
    h = np.full(y.shape, 400.0)
    if not flat:
        for _ in range(12):
            k = rng.uniform(2 * math.pi / 2000.0, 2 * math.pi / 300.0)
            a = rng.uniform(0.0, 2 * math.pi)
            phase = rng.uniform(0.0, 2 * math.pi)
            h += rng.uniform(10.0, 25.0) * np.sin(k * (math.cos(a) * x + math.sin(a) * y) + phase)
    return Dem(h, LAT0, LON0, POST_M / r_n, POST_M / r_e, "synthetic")


def jacksboro_with_a_void(path, lat_deg: float, lon_deg: float, half_posts: int = 5):
    """The bundled DEM with a (2 half_posts + 1)^2-post void centred on a place, saved as our NPZ at `path`
    (a map or world DEM file for a scenario); returns the path."""
    from trn_env.terrain.loaders import save_npz

    from trn_env import terrain
    dem = terrain.load("jacksboro")
    h = np.array(dem.heights_m, dtype=float)
    r = int(round((math.radians(lat_deg) - dem.lat0_rad) / dem.dlat_rad))
    c = int(round((math.radians(lon_deg) - dem.lon0_rad) / dem.dlon_rad))
    h[r - half_posts:r + half_posts + 1, c - half_posts:c + half_posts + 1] = np.nan
    save_npz(Dem(h, dem.lat0_rad, dem.lon0_rad, dem.dlat_rad, dem.dlon_rad, "jacksboro with a void"), path)
    return path
