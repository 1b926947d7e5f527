"""The map's height errors as IRA measurement noise (seed 002's eqs 23 and 26 evaluated on the map instead
of the world), and the coarse scan step a map needs.

`map_noise_variances` gives the range and look-angle variances a map's error class and the terrain it cannot
hold between its posts add to a sample (a flat-ground model, calibrated per map by `map_noise_calibration`
on refinements of the map's own spectrum); `interpolation_sigma_m` is that unresolved terrain's height
sigma; `search_step_for` the zero-Doppler scan step for the map's posts. Re-exported by
navigators.measurements.ira_seed002, whose search (`predict_ira`) the calibration runs.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np

from ... import terrain as _terrain_package
from ..core.disk_cache import cached_floats

_INTERP_CACHE: dict = {}
# the code a calibration depends on (its search, the map's refinement and reading): its disk cache's key
_CODE_DIRS = (str(Path(__file__).resolve().parents[1]), str(Path(_terrain_package.__file__).resolve().parent))


def interpolation_sigma_m(dem) -> float:
    """Height sigma (m) of the terrain a map cannot hold between its posts: the map's radial PSD power law
    P(f) = C f^-beta (terrain.refine.fit_dem_spectrum, fitted over Nyquist/10 .. Nyquist/2) continued above
    its Nyquist frequency f_n: sigma^2 = int_{f_n}^inf P(f) 2 pi f df = 2 pi C f_n^(2 - beta) / (beta - 2)
    (real terrain keeps its fractal spectrum below the posts; the map's bilinear surface misses it). 0 for a
    spectrum too flat to integrate (beta <= 2) or a map too small to fit. Cached per map content."""
    key = _map_key(dem)
    hit = _INTERP_CACHE.get(key)
    if hit is not None:
        return hit
    from ...terrain.refine import fit_dem_spectrum

    try:
        c, beta, f_n = fit_dem_spectrum(dem)
    except (ValueError, np.linalg.LinAlgError):
        c, beta, f_n = 0.0, 0.0, 1.0
    sig = 0.0
    if beta > 2.0 and c > 0:
        sig = float(np.sqrt(2.0 * np.pi * c * f_n ** (2.0 - beta) / (beta - 2.0)))
    if not np.isfinite(sig):
        sig = 0.0
    _INTERP_CACHE[key] = sig
    return sig


_CALIBRATION_CACHE: dict = {}

CALIBRATION_HEIGHT_M = 1500.0  # map_noise_calibration's height above the map by default (seed 002's flights)
_CALIBRATION_OCTAVES = (-4, 2)  # calibration_height_m's range of k: 94 m to 6 km


def calibration_height_m(range_m: float) -> float:
    """The height above the map (m) at which a filter calibrates the map noise for a slant range range_m
    (m): the nearest in ratio of CALIBRATION_HEIGHT_M * 2^k (k integer, 94 m to 6 km), so one calibration
    serves every range within a factor sqrt(2) of its height (1,061-2,121 m for 1,500 m) and a flight
    needs a new one only when its range leaves that band (each 1-6 s the first time, longer higher up; then
    cached in the process and on disk). The look angle's factor varies with height (map_noise_calibration);
    a non-finite or non-positive range gets the default."""
    if not (math.isfinite(range_m) and range_m > 0.0):
        return CALIBRATION_HEIGHT_M
    k = math.floor(math.log2(range_m / CALIBRATION_HEIGHT_M) + 0.5)
    return CALIBRATION_HEIGHT_M * 2.0 ** min(max(k, _CALIBRATION_OCTAVES[0]), _CALIBRATION_OCTAVES[1])


def _map_key(dem) -> tuple:
    """A content key for a map (a scenario loads a new Dem object per run)."""
    heights, lat0, lon0, dlat, dlon = dem.grid
    digest = hashlib.blake2b(np.ascontiguousarray(heights).view(np.uint8), digest_size=16).hexdigest()
    return digest, heights.shape, float(lat0), float(lon0), float(dlat), float(dlon)


def map_noise_calibration(dem, detail_spacing_m: float, agl_m: float = CALIBRATION_HEIGHT_M,
                          n_states: int = 1000, realisations: int = 3, ambiguity_probability: float = 0.05,
                          gate_sigmas: float = 0.0, theta_sensor_var: float = 0.0) -> tuple[float, float]:
    """(range factor, look-angle factor) calibrating map_noise_variances' flat-ground model for the terrain
    a map cannot hold between its posts (interpolation_sigma_m): each the simulated variance over the model's.
    The map's error class is simulated, not the world: terrain.refine continues the map's own spectrum below
    its posts down to detail_spacing_m (realisations seeds 0, 1, ..., over the map's central <= 16 km
    square), and eqs 23/26 are evaluated on the refinement (its own search step) and on the map (the
    filter's, search_step_for) at n_states random states per realisation, agl_m above the map (random
    heading, 85 m/s, small bank), inside the square's inner 60 %. The look angle's leaves out the states
    whose basin-jump probability (as the RBPF's _basin_jump_probability) exceeds ambiguity_probability:
    the filter uses the range alone there, and, with gate_sigmas > 0, those beyond that many sigmas of the
    calibrated look-angle variance plus theta_sensor_var (rad^2), iterated to a fixed point (the RBPF's
    theta_gate_sigmas: the heavy tail goes to the range alone there too). Range: var(R_refined - R_map) /
    sigma_h^2 (a constant offset is the vertical state's); look angle: mean((theta_refined - theta_map)^2 3 R)
    / sigma_h. The flat-ground band is an upper bound: the closest point is the minimum of a rough R(s),
    nearer the band's middle. The factors of the default map: docs/validation/seed002.md (map noise). (1, 1)
    when the map is too smooth (sigma_h 0) or too small to refine. 1-2.5 s for the default map: cached per
    map content in the process and on disk between processes (navigators.core.disk_cache, keyed by the code
    that computes it)."""
    key = (_map_key(dem), float(detail_spacing_m), float(agl_m), int(n_states), int(realisations),
           float(ambiguity_probability), float(gate_sigmas), float(theta_sensor_var))
    hit = _CALIBRATION_CACHE.get(key)
    if hit is None:
        hit = _CALIBRATION_CACHE[key] = cached_floats(
            "map_noise_calibration", key, 2, lambda: _calibrate(dem, *key[1:]), _CODE_DIRS)
    return hit


def _calibrate(dem, detail_spacing_m: float, agl_m: float, n_states: int, realisations: int,
               ambiguity_probability: float, gate_sigmas: float,
               theta_sensor_var: float) -> tuple[float, float]:
    """map_noise_calibration's computation (uncached)."""
    from ...terrain.geodesy import euler_to_C_bn
    from ...terrain.refine import refine
    from .ira_seed002 import OUT_R, OUT_R2, OUT_THETA, OUT_VALID, predict_ira  # (which imports this module)

    sigma_h = interpolation_sigma_m(dem)
    la0, la1, lo0, lo1 = dem.bounds
    lat_c, lon_c = 0.5 * (la0 + la1), 0.5 * (lo0 + lo1)
    half_lat = min(0.5 * (la1 - la0), 8000.0 / 6.371e6)
    half_lon = min(0.5 * (lo1 - lo0), 8000.0 / (6.371e6 * np.cos(lat_c)))
    region = (lat_c - half_lat, lat_c + half_lat, lon_c - half_lon, lon_c + half_lon)
    step_map = search_step_for(dem)
    var_r, th2, rng_th = [], [], []
    for seed in range(int(realisations)) if sigma_h > 0.0 else ():
        try:
            detail = refine(dem, spacing_m=float(detail_spacing_m), seed=seed, region=region)
        except ValueError:
            break
        step_detail = search_step_for(detail)
        rng = np.random.default_rng(seed)
        d_r = []
        for _ in range(int(n_states)):
            lat = lat_c + half_lat * rng.uniform(-0.6, 0.6)
            lon = lon_c + half_lon * rng.uniform(-0.6, 0.6)
            h = float(dem.height(lat, lon)) + float(agl_m)
            yaw = rng.uniform(0.0, 2.0 * np.pi)
            v = 85.0 * np.array([np.cos(yaw), np.sin(yaw), 0.0])
            C = euler_to_C_bn(rng.normal(0.0, 0.05), 0.04, yaw)
            a = predict_ira(detail, [lat], [lon], [h], v, C, ds_m=step_detail)[0]
            b = predict_ira(dem, [lat], [lon], [h], v, C, ds_m=step_map)[0]
            if not (a[OUT_VALID] and b[OUT_VALID]):
                continue
            d_r.append(a[OUT_R] - b[OUT_R])
            gap = b[OUT_R2] - b[OUT_R]
            p_jump = 0.5 * math.erfc(max(gap, 0.0) / (2.0 * sigma_h)) if np.isfinite(gap) else 0.0
            if p_jump <= ambiguity_probability:
                th2.append((a[OUT_THETA] - b[OUT_THETA]) ** 2)
                rng_th.append(b[OUT_R])
        if len(d_r) >= 50:
            var_r.append(float(np.var(d_r)))
    out = (1.0, 1.0)
    if var_r and len(th2) >= 50:
        th2, rng_th = np.asarray(th2), np.asarray(rng_th)
        z2 = th2 * 3.0 * rng_th / sigma_h          # each sample's f_theta
        f_th = float(np.mean(z2))
        for _ in range(20 if gate_sigmas > 0.0 else 0):
            keep = th2 <= gate_sigmas ** 2 * (f_th * sigma_h / (3.0 * rng_th) + float(theta_sensor_var))
            f_new = float(np.mean(z2[keep]))
            if f_new == f_th:
                break
            f_th = f_new
        f_r = float(np.mean(var_r)) / sigma_h ** 2
        if np.isfinite(f_r) and np.isfinite(f_th) and f_r > 0.0 and f_th > 0.0:
            out = (f_r, f_th)
    return out


def search_step_for(dem) -> float:
    """The coarse scan's step along the zero-Doppler line (m) for a map: 45 m, or its smaller post spacing
    / 1.6 where that is less (45 m for the 3" map, with its 75 m posts). The scan must see every basin of
    R(s) before the golden-section refinement, which assumes one minimum within a step; a fixed 45 m step
    misses the minimum on a finer map (the figures: docs/validation/seed002.md, the search step;
    tests/test_rbpf_models.py checks it)."""
    s_n, s_e = dem.spacing_m
    return float(min(45.0, min(s_n, s_e) / 1.6))


def map_noise_variances(map_sigma_m: float, terrain_model_sigma_m: float, range_m: float,
                        terrain_factors: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """Variances (range m^2, look angle rad^2) that a map's height errors add to an IRA sample at slant
    range range_m (eqs 23, 26 evaluated on the map instead of the world): the map's own error class
    (map_sigma_m) and the terrain it cannot hold between its posts (terrain_model_sigma_m), the latter's
    flat-ground variances scaled by terrain_factors (map_noise_calibration; (1, 1): the flat-ground model).
    Flat-ground model of a height error sigma_h: range sigma_h^2 (the closest point's height, seen along a
    line of sight near the vertical); look angle: the closest point is the minimum of R(s) along the
    zero-Doppler line; a height error sigma_h makes every point whose map range lies within about sigma_h / 2
    of the minimum a candidate, on flat ground R(s) = sqrt(s^2 + R^2) the band |s| < sqrt(sigma_h R). Taking
    the map's closest point as uniform over that band, its across-track offset has variance sigma_h R / 3,
    and the look angle's error variance is sigma_h / (3 R) (rad^2). The two parts combine as independent
    height errors: range map_sigma^2 + f_R terrain_sigma^2, look angle sqrt(map_sigma^2 + (f_theta
    terrain_sigma)^2) / (3 R) (each part's flat-ground value where the other is 0). The model's figures on
    the default route against the map-minus-world errors: docs/validation/seed002.md (map noise)."""
    f_r, f_th = terrain_factors
    var_r = float(map_sigma_m) ** 2 + f_r * float(terrain_model_sigma_m) ** 2
    sig_th = math.hypot(float(map_sigma_m), f_th * float(terrain_model_sigma_m))
    if var_r <= 0.0 or not (range_m > 0.0):
        return np.zeros(2)
    return np.array([var_r, sig_th / (3.0 * range_m)])
