"""The navigator's map: a DEM derived from the world DEM through an error model.

`MapErrorModel` fields (all optional, SI):
    bias_m                 constant vertical offset
    tilt_n, tilt_e         vertical ramp, metres per metre of north / east displacement from the grid centre
    random_sigma_m         spatially correlated random vertical error, standard deviation
    correlation_length_m   its correlation length L (m): finite, > 0 and, where the error is drawn, no
                           longer than the map is across
    correlation_function   "gaussian": covariance sigma^2 exp(-d^2 / (2 L^2)) (smooth error), or
                           "exponential": sigma^2 exp(-d / L) (first-order Gauss-Markov along any line: the
                           model fitted to DEM error correlograms); `correlation(d_m, L, function)`
    shift_n_m, shift_e_m   horizontal shift: a feature at true position p appears at p + shift in the map
    spacing_arcsec         coarser post spacing (area-averaged like a real DEM product); None keeps the grid

Accuracy classes (`ACCURACY_CLASSES`) turn published 90 % figures into a random model: CE90 (circular
horizontal error) -> per-axis sigma_h = CE90 / 2.1460; LE90 (linear vertical error) -> sigma_v = LE90 /
1.6449 (Gaussian). A realisation draws the shift from N(0, sigma_h^2) per axis and splits the vertical
variance between a bias (fraction `bias_fraction` of the variance, drawn once) and correlated random error.
The split is a modelling assumption, not from the sources. Each class carries its default correlation
(`AccuracyClass.correlation_length_m`, exponential) with its source in `correlation_source`: the one
published measurement used is Ehlschlaeger & Shortridge (1996, "Modeling elevation uncertainty in
geographical analyses", Proc. Spatial Data Handling; NCGIA): the error of a USGS 1-degree (3 arcsec) DEM
against 7.5-minute DEMs stayed correlated to 3,210 m, an exponential correlogram's practical range (3 L),
so L = 1,070 m for the 3 arcsec products (SRTM, CartoDEM, ASTER, DTED-1); DTED-0 and DTED-2 scale it by their
post spacing (an assumption). The DEM integrity monitor reads the same model
(navigators.integrity.dem_monitor, `correlation_length_m`), so its test keeps its false-alarm rate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import geodesy, kernels
from .dem import Dem, read_only_heights

CORRELATION_FUNCTIONS = ("gaussian", "exponential")
CE90_PER_SIGMA = 2.1460  # circular normal: P(r < 2.146 sigma) = 0.90
LE90_PER_SIGMA = 1.6449  # normal: P(|z| < 1.6449 sigma) = 0.90


def check_correlation_length(value, name: str = "correlation_length_m", allow_zero: bool = False) -> float:
    """float(value) if it is a finite length > 0 m (>= 0 with allow_zero: 0 = uncorrelated), else ValueError
    naming the setting."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: must be a finite length in m, got {value!r}") from None
    if isinstance(value, bool) or not np.isfinite(v) or v < 0.0 or (v == 0.0 and not allow_zero):
        raise ValueError(f"{name}: must be a finite length {'>=' if allow_zero else '>'} 0 m, got {value!r}")
    return v


def correlation(d_m, correlation_length_m: float, function: str = "exponential"):
    """Correlation of the random map error at horizontal distance d_m (m): exp(-d / L) ("exponential") or
    exp(-d^2 / (2 L^2)) ("gaussian"); L = 0 means uncorrelated (1 at d = 0, else 0)."""
    d = np.abs(np.asarray(d_m, float))
    if correlation_length_m == 0.0:
        return (d == 0.0).astype(float)
    if function == "exponential":
        return np.exp(-d / correlation_length_m)
    if function == "gaussian":
        return np.exp(-0.5 * (d / correlation_length_m) ** 2)
    raise ValueError(f"correlation_function: must be one of {CORRELATION_FUNCTIONS}, got {function!r}")


def check_fits(dem: Dem, correlation_length_m: float, name: str = "correlation_length_m") -> None:
    """ValueError naming the setting if the correlation length is longer than the map is across."""
    dn, de = dem.spacing_m
    across = max((dem.heights_m.shape[0] - 1) * dn, (dem.heights_m.shape[1] - 1) * de)
    if correlation_length_m > across:
        raise ValueError(f"{name}: {correlation_length_m:g} m is longer than the map {dem.name!r} is across "
                         f"({across:.0f} m)")


@dataclass(frozen=True)
class MapErrorModel:
    """Deterministic map error parameters (see the module docstring for units and meaning)."""

    bias_m: float = 0.0
    tilt_n: float = 0.0
    tilt_e: float = 0.0
    random_sigma_m: float = 0.0
    correlation_length_m: float = 500.0
    shift_n_m: float = 0.0
    shift_e_m: float = 0.0
    spacing_arcsec: float | None = None
    correlation_function: str = "gaussian"

    def __post_init__(self):
        if not (self.random_sigma_m >= 0.0):
            raise ValueError(f"MapErrorModel.random_sigma_m must be >= 0, got {self.random_sigma_m}")
        check_correlation_length(self.correlation_length_m)
        if self.correlation_function not in CORRELATION_FUNCTIONS:
            raise ValueError(f"correlation_function: must be one of {CORRELATION_FUNCTIONS}, got "
                             f"{self.correlation_function!r}")
        if self.spacing_arcsec is not None and not (self.spacing_arcsec > 0.0):
            raise ValueError(f"MapErrorModel.spacing_arcsec must be > 0, got {self.spacing_arcsec}")


@dataclass(frozen=True)
class AccuracyClass:
    """A DEM product's published accuracy: post spacing (arcsec), CE90 and LE90 (m), and the source."""

    spacing_arcsec: float
    ce90_m: float
    le90_m: float
    source: str
    correlation_length_m: float = 1070.0
    correlation_source: str = ""

    @property
    def sigma_h_m(self) -> float:
        return self.ce90_m / CE90_PER_SIGMA

    @property
    def sigma_v_m(self) -> float:
        return self.le90_m / LE90_PER_SIGMA


_E3 = ("Ehlschlaeger & Shortridge 1996 (NCGIA): USGS 1-degree (3 arcsec) DEM error correlated to 3,210 m = "
       "3 L of an exponential correlogram")

ACCURACY_CLASSES = {
    # seed 003 Table 1 (Digital Elevation Models and their Accuracies): post spacing, CEP and LEP at 90 %
    "srtm": AccuracyClass(3.0, 15.0, 16.0, "seed 003 Table 1: SRTM, 3 arcsec, CE 15 m 90 %, LE 16 m 90 %",
                          1070.0, _E3),
    "cartodem": AccuracyClass(
        3.0, 15.0, 8.0, "seed 003 Table 1: CartoDEM30 (hilly), 3 arcsec, CE 15 m 90 %, LE 8 m 90 %",
        1070.0, _E3,
    ),
    "aster": AccuracyClass(
        3.0,
        17.0,
        17.0,
        "seed 003 Table 1: Aster-USGS, 3 arcsec, CE 17 m 90 %, LE 'TBD' in the table; "
        "LE90 17 m assumed here (of the order of the published ASTER GDEM validation)",
        1070.0,
        _E3,
    ),
    # DTED levels: spacing and absolute accuracies of the DTED specification (MIL-PRF-89020B), not in the
    # seeds; seed 003 reports DTED-1 absolute disparities ~ N(0, 18.9^2) m, consistent with LE90 30 m.
    "dted0": AccuracyClass(
        30.0, 50.0, 30.0, "DTED level 0 (MIL-PRF-89020B): 30 arcsec, CE90 50 m, LE90 30 m", 10700.0,
        "assumption: the 3 arcsec figure (" + _E3 + ") times the post-spacing ratio 10",
    ),
    "dted1": AccuracyClass(
        3.0,
        50.0,
        30.0,
        "DTED level 1 (MIL-PRF-89020B): 3 arcsec, CE90 50 m, LE90 30 m; seed 003: disparity sigma 18.9 m",
        1070.0,
        _E3,
    ),
    "dted2": AccuracyClass(1.0, 23.0, 18.0, "DTED level 2 (MIL-PRF-89020B): 1 arcsec, CE90 23 m, LE90 18 m",
                           357.0, "assumption: the 3 arcsec figure (" + _E3 + ") times the post-spacing "
                           "ratio 1/3"),
}


def model_for_class(
    name: str,
    seed: int | np.random.Generator = 0,
    bias_fraction: float = 0.5,
    correlation_length_m: float | None = None,
    correlation_function: str = "exponential",
) -> MapErrorModel:
    """A random MapErrorModel realising accuracy class `name` (see ACCURACY_CLASSES and the module doc);
    correlation_length_m None: the class's default (exponential, with its source)."""
    key = name.strip().lower()
    if key not in ACCURACY_CLASSES:
        raise ValueError(f"unknown DEM accuracy class {name!r}; choose from {sorted(ACCURACY_CLASSES)}")
    if not (0.0 <= bias_fraction <= 1.0):
        raise ValueError(f"bias_fraction must be in [0, 1], got {bias_fraction}")
    cls = ACCURACY_CLASSES[key]
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    sigma_b = cls.sigma_v_m * np.sqrt(bias_fraction)
    sigma_r = cls.sigma_v_m * np.sqrt(1.0 - bias_fraction)
    shift = rng.normal(0.0, cls.sigma_h_m, 2)
    return MapErrorModel(
        bias_m=float(rng.normal(0.0, sigma_b)),
        random_sigma_m=float(sigma_r),
        correlation_length_m=(cls.correlation_length_m if correlation_length_m is None
                              else correlation_length_m),
        correlation_function=correlation_function,
        shift_n_m=float(shift[0]),
        shift_e_m=float(shift[1]),
        spacing_arcsec=cls.spacing_arcsec,
    )


def correlated_field(
    shape, dy_m: float, dx_m: float, sigma_m: float, correlation_length_m: float, rng: np.random.Generator,
    function: str = "gaussian",
) -> np.ndarray:
    """Gaussian field with covariance sigma^2 exp(-d^2 / (2 L^2)) ("gaussian": white noise smoothed by a
    Gaussian of standard deviation L / sqrt(2) in the Fourier domain) or sigma^2 exp(-d / L) ("exponential":
    its 2-D spectrum (1 + (2 pi f L)^2)^(-3/2), amplitude gain the square root), scaled to the sample
    standard deviation sigma."""
    ny, nx = shape
    fy = np.fft.fftfreq(ny, d=dy_m)
    fx = np.fft.rfftfreq(nx, d=dx_m)
    f2 = fy[:, None] ** 2 + fx[None, :] ** 2
    if function == "exponential":
        gain = (1.0 + (2.0 * np.pi * correlation_length_m) ** 2 * f2) ** -0.75
    else:
        s = correlation_length_m / np.sqrt(2.0)
        gain = np.exp(-2.0 * np.pi**2 * s**2 * f2)
    field = np.fft.irfft2(np.fft.rfft2(rng.standard_normal(shape)) * gain, s=shape)
    field -= field.mean()
    sd = field.std()
    return field * (sigma_m / sd) if sd > 0 else field


def _coarsen(dem: Dem, spacing_arcsec: float) -> Dem:
    step = np.radians(spacing_arcsec / 3600.0)
    r_i = step / dem.dlat_rad
    r_j = step / dem.dlon_rad
    if r_i <= 1.0 + 1e-9 and r_j <= 1.0 + 1e-9:
        return dem
    size = (max(1, int(round(r_i))), max(1, int(round(r_j))))
    h = dem.heights_m
    from scipy import ndimage  # at first use: importing scipy.ndimage costs about a second
    smooth = ndimage.uniform_filter(np.nan_to_num(h, nan=0.0), size=size, mode="nearest")
    weight = ndimage.uniform_filter(np.isfinite(h).astype(float), size=size, mode="nearest")
    with np.errstate(invalid="ignore", divide="ignore"):
        smooth = np.where(weight > 0.999, smooth / np.maximum(weight, 1e-12), np.nan)
    b = dem.bounds
    n_lat = int(np.floor((b[1] - b[0]) / step + 1e-9)) + 1
    n_lon = int(np.floor((b[3] - b[2]) / step + 1e-9)) + 1
    if n_lat < 2 or n_lon < 2:
        raise ValueError(f"map spacing {spacing_arcsec} arcsec leaves fewer than 2 x 2 posts on {dem.name!r}")
    lat = b[0] + np.arange(n_lat) * step
    lon = b[2] + np.arange(n_lon) * step
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    out = np.empty(la.size)
    kernels.bilinear_batch(
        smooth, dem.lat0_rad, dem.lon0_rad, dem.dlat_rad, dem.dlon_rad, la.ravel(), lo.ravel(), out
    )
    return Dem(out.reshape(la.shape), b[0], b[2], step, step, dem.name)


def apply(
    dem: Dem, model: MapErrorModel, seed: int | np.random.Generator = 0, name: str | None = None
) -> Dem:
    """The map the navigator carries: `dem` (the world) transformed by `model`. Seeded; order: horizontal
    shift, coarser posts, then vertical bias + tilt + correlated random error."""
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    lat_c, lon_c = dem.center_rad
    r_n = geodesy.meridian_radius_m(lat_c)
    r_e = geodesy.prime_vertical_radius_m(lat_c) * np.cos(lat_c)
    out = dem
    if model.shift_n_m != 0.0 or model.shift_e_m != 0.0:
        la, lo = np.meshgrid(dem.lat_rad, dem.lon_rad, indexing="ij")
        shifted = dem.height(la - model.shift_n_m / r_n, lo - model.shift_e_m / r_e, method="bicubic")
        out = dem.with_heights(shifted) if np.isfinite(shifted).any() else None
        if out is None:
            raise ValueError(
                f"map shift ({model.shift_n_m}, {model.shift_e_m}) m moves everything off {dem.name!r}"
            )
    if model.spacing_arcsec is not None:
        out = _coarsen(out, model.spacing_arcsec)
    h = out.heights_m.copy()
    la = out.lat_rad[:, None]
    lo = out.lon_rad[None, :]
    north = (la - lat_c) * r_n
    east = (lo - lon_c) * r_e
    h += model.bias_m + model.tilt_n * north + model.tilt_e * east
    if model.random_sigma_m > 0.0:
        check_fits(out, model.correlation_length_m)
        dy, dx = out.spacing_m
        h += correlated_field(h.shape, dy, dx, model.random_sigma_m, model.correlation_length_m, rng,
                              model.correlation_function)
    return Dem(h, out.lat0_rad, out.lon0_rad, out.dlat_rad, out.dlon_rad, name or f"{dem.name}[map]")


def make_map(dem: Dem, accuracy: str | MapErrorModel, seed: int | np.random.Generator = 0) -> Dem:
    """Convenience: `apply(dem, model_for_class(accuracy, rng) if a class name else accuracy, rng)`."""
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    model = model_for_class(accuracy, rng) if isinstance(accuracy, str) else accuracy
    return apply(dem, model, rng, name=f"{dem.name}[{accuracy if isinstance(accuracy, str) else 'map'}]")


# ------------------------------------------------------------------------------------------ map faults

FAULT_KINDS = ("bias", "ramp", "spike", "shift", "stale")


@dataclass(frozen=True)
class MapFault:
    """A regional fault of the navigator's map (the world stays true), in a rectangle of size_n_m x size_e_m
    centred on (center_lat_deg, center_lon_deg), present from start_s (None: from the start).

    kind "bias":  heights + bias_m inside the region (seed 003's vertical bias error);
    kind "ramp":  heights + bias_m * u, u rising from 0 to 1 across the region along direction_deg
                  (clockwise from north);
    kind "spike": a tower/spike: heights + bias_m at the centre falling linearly to 0 at radius
                  min(size) / 2;
    kind "shift": the region's heights taken from shift_n_m, shift_e_m away (a feature at p appears at
                  p + shift inside the region);
    kind "stale": the region taken from different terrain: from `source_dem` (a terrain.Dem at the same
                  coordinates) or, without one, from the same map source_offset_n_m, source_offset_e_m away.
    """

    kind: str
    center_lat_deg: float
    center_lon_deg: float
    size_n_m: float
    size_e_m: float
    start_s: float | None = None
    bias_m: float = 0.0
    direction_deg: float = 0.0
    shift_n_m: float = 0.0
    shift_e_m: float = 0.0
    source_offset_n_m: float = 5000.0
    source_offset_e_m: float = 0.0
    source_dem: object = None

    def __post_init__(self):
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"kind: must be one of {FAULT_KINDS}, got {self.kind!r}")
        for name in ("center_lat_deg", "center_lon_deg", "size_n_m", "size_e_m", "bias_m", "direction_deg",
                     "shift_n_m", "shift_e_m", "source_offset_n_m", "source_offset_e_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float, np.floating, np.integer)) and np.isfinite(v)):
                raise ValueError(f"{name}: must be a finite number, got {v!r}")
        for name in ("size_n_m", "size_e_m"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name}: the fault region's size must be > 0 m, got {getattr(self, name)}")
        if self.start_s is not None and not (np.isfinite(self.start_s) and self.start_s >= 0.0):
            raise ValueError(f"start_s: must be a finite time >= 0 s, got {self.start_s!r}")

    def describe(self) -> dict:
        """The fault as plain data (for summary.json)."""
        keys = ("kind", "center_lat_deg", "center_lon_deg", "size_n_m", "size_e_m", "start_s")
        out = {k: getattr(self, k) for k in keys}
        if self.kind in ("bias", "ramp", "spike"):
            out["bias_m"] = self.bias_m
        if self.kind == "ramp":
            out["direction_deg"] = self.direction_deg
        if self.kind == "shift":
            out.update(shift_n_m=self.shift_n_m, shift_e_m=self.shift_e_m)
        if self.kind == "stale":
            if self.source_dem is not None:
                out["source_dem"] = getattr(self.source_dem, "name", "dem")
            else:
                out.update(source_offset_n_m=self.source_offset_n_m, source_offset_e_m=self.source_offset_e_m)
        return out


def _region_index(dem: Dem, fault: MapFault):
    """(rows slice, cols slice, north offsets (n_i, 1), east offsets (1, n_j)) of the posts in the fault's
    region; ValueError naming the field when the region is not inside the map."""
    lat_c, lon_c = np.radians(fault.center_lat_deg), np.radians(fault.center_lon_deg)
    r_n = geodesy.meridian_radius_m(lat_c)
    r_e = geodesy.prime_vertical_radius_m(lat_c) * np.cos(lat_c)
    half_lat = 0.5 * fault.size_n_m / r_n
    half_lon = 0.5 * fault.size_e_m / r_e
    b = dem.bounds
    if not (b[0] <= lat_c - half_lat and lat_c + half_lat <= b[1] and b[2] <= lon_c - half_lon
            and lon_c + half_lon <= b[3]):
        raise ValueError(
            f"center_lat_deg, center_lon_deg: the fault region ({fault.center_lat_deg:.5f}, "
            f"{fault.center_lon_deg:.5f}) deg, {fault.size_n_m:.0f} x {fault.size_e_m:.0f} m, is not inside "
            f"the map {dem.name!r} (lat {np.degrees(b[0]):.4f}..{np.degrees(b[1]):.4f}, lon "
            f"{np.degrees(b[2]):.4f}..{np.degrees(b[3]):.4f} deg)")
    i0 = int(np.ceil((lat_c - half_lat - dem.lat0_rad) / dem.dlat_rad - 1e-9))
    i1 = int(np.floor((lat_c + half_lat - dem.lat0_rad) / dem.dlat_rad + 1e-9))
    j0 = int(np.ceil((lon_c - half_lon - dem.lon0_rad) / dem.dlon_rad - 1e-9))
    j1 = int(np.floor((lon_c + half_lon - dem.lon0_rad) / dem.dlon_rad + 1e-9))
    if i1 < i0 or j1 < j0:
        dn, de = dem.spacing_m
        raise ValueError(f"size_n_m, size_e_m: the fault region {fault.size_n_m} x {fault.size_e_m} m holds "
                         f"no post of the map (post spacing {dn:.0f} x {de:.0f} m)")
    rows, cols = slice(i0, i1 + 1), slice(j0, j1 + 1)
    north = ((dem.lat0_rad + np.arange(i0, i1 + 1) * dem.dlat_rad) - lat_c)[:, None] * r_n
    east = ((dem.lon0_rad + np.arange(j0, j1 + 1) * dem.dlon_rad) - lon_c)[None, :] * r_e
    return rows, cols, north, east, r_n, r_e


def check_fault(dem: Dem, fault: MapFault) -> None:
    """Raise ValueError (naming the field) if `fault` cannot be applied to `dem`."""
    _region_index(dem, fault)


def apply_fault(heights_m: np.ndarray, dem: Dem, fault: MapFault) -> None:
    """Apply `fault` in place to heights_m (an array on dem's grid)."""
    rows, cols, north, east, r_n, r_e = _region_index(dem, fault)
    h = heights_m[rows, cols]
    if fault.kind == "bias":
        h += fault.bias_m
    elif fault.kind == "ramp":
        d = np.radians(fault.direction_deg)
        along = north * np.cos(d) + east * np.sin(d)
        half = 0.5 * (abs(fault.size_n_m * np.cos(d)) + abs(fault.size_e_m * np.sin(d)))
        h += fault.bias_m * np.clip((along + half) / (2.0 * half), 0.0, 1.0)
    elif fault.kind == "spike":
        radius = 0.5 * min(fault.size_n_m, fault.size_e_m)
        h += fault.bias_m * np.clip(1.0 - np.hypot(north, east) / radius, 0.0, None)
    else:
        la = (dem.lat0_rad + np.arange(rows.start, rows.stop) * dem.dlat_rad)[:, None] + 0.0 * east
        lo = (dem.lon0_rad + np.arange(cols.start, cols.stop) * dem.dlon_rad)[None, :] + 0.0 * north
        if fault.kind == "shift":
            src, dn, de = dem, -fault.shift_n_m, -fault.shift_e_m
        elif fault.source_dem is not None:
            src, dn, de = fault.source_dem, 0.0, 0.0
        else:
            src, dn, de = dem, fault.source_offset_n_m, fault.source_offset_e_m
        new = src.height(la + dn / r_n, lo + de / r_e, method="bilinear")
        if not np.isfinite(new).all():
            field = "shift_n_m, shift_e_m" if fault.kind == "shift" else (
                "source_dem" if fault.source_dem is not None else "source_offset_n_m, source_offset_e_m")
            raise ValueError(f"{field}: the {fault.kind} fault's source terrain is off the map (or void) for "
                             f"part of the region")
        h[...] = new
    heights_m[rows, cols] = h


def fault_schedule(dem: Dem, faults: list[MapFault]) -> list[tuple[float, np.ndarray]]:
    """[(t_from_s, heights)]: the map's heights from each time on, in time order; the first entry (t = -inf)
    holds the faults present from the start (or dem's own heights). Faults at the same time apply in list
    order; a stale/shift fault reads the map as it was before the faults."""
    times = sorted({-np.inf if f.start_s is None else float(f.start_s) for f in faults} | {-np.inf})
    out = []
    for t in times:
        h = dem.heights_m.copy()
        for f in faults:
            if (-np.inf if f.start_s is None else f.start_s) <= t:
                apply_fault(h, dem, f)
        out.append((t, h))
    return out


def set_heights(dem: Dem, heights_m: np.ndarray) -> None:
    """Swap a Dem's heights for another array of the same shape (a time-dependent map's change at its fault
    time). Every holder of the Dem sees the new heights; the query tables cached on it are keyed by the
    array and so rebuilt, the block bounds are dropped. Kernels keep reading `dem.grid` as before."""
    h = np.ascontiguousarray(heights_m, dtype=np.float64)
    if h.shape != dem.heights_m.shape:
        raise ValueError(f"set_heights: shape {h.shape} differs from the Dem's {dem.heights_m.shape}")
    dem.heights_m = read_only_heights(h)     # as a Dem's own: one array type for the kernels (terrain/dem.py)
    dem._pyramid = None
