"""Batch TERCOM / MAD correlation (seed 000 section 2).

Measured terrain heights along the INS track are compared with the map shifted over a reference matrix
(default 101 x 101 cells of 5 m, seed 000 Table 2):

    MAD_ij = (1/M) sum_k | h_meas,k - h_DB(lat_k + p_k,lat + j dlat, lon_k + p_k,lon + i dlon) |

- plain radar altimeter (eq 1): h_meas,k = h_baro,k - RA range, p_k = 0 (terrain assumed straight below);
- IRA (eq 2): h_meas,k = h_baro,k - |p_k,alt|, (p_k,lat, p_k,lon) = (p_n / R_ns, p_e / R_ew) from the
  closest-point relative position (navigators.measurements.ira_closest_point).

The cell with the smallest MAD is the fix: the INS position plus (j dn, i de) metres is the matched
position. The surface and a quality figure come with each fix. Cells for which any sample falls off the
map (NaN lookups) are invalid (MAD = inf).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...terrain.geodesy import meridian_radius_m, prime_vertical_radius_m
from ..core.maps import map_record
from ._mad_kernels import (  # noqa: F401  (re-exported: tests, bench)
    PARALLEL_MIN_LOOKUPS,
    TERCOM_THREADS,
    _block_void_free,
    _in_bands,
    _mad_rows_finish,
    _mad_rows_pass,
    _mad_surface_separable,
    _shift_offsets,
    mad_surface,
    mad_surface_reference,
)


@dataclass
class TercomFix:
    """One batch fix. Correction (dn_m, de_m): matched position = INS position + correction, i.e. the INS
    position error (INS - true) is estimated as -(dn_m, de_m)."""

    t_s: float
    valid: bool
    reason: str  # "ok" or why the fix is unusable (no_samples, off_map, ...)
    dn_m: float
    de_m: float
    dlat_rad: float
    dlon_rad: float
    mad_min_m: float
    quality: float  # second-best separated local minimum / best (>= 1; larger = more distinct)
    on_edge: bool  # minimum on the border of the reference matrix (true offset may lie outside)
    n_samples: int
    surface_m: np.ndarray  # (2 half + 1, 2 half + 1), rows north shift, columns east shift
    cell_m: float


def _second_minimum(surface: np.ndarray, ia: int, ib: int, exclusion: int) -> float:
    """Smallest local minimum of the surface farther than `exclusion` cells (Chebyshev) from (ia, ib)."""
    s = surface
    n = s.shape[0]
    pad = np.pad(s, 1, constant_values=np.inf)
    core = pad[1:-1, 1:-1]
    is_min = np.isfinite(core)
    for da in (-1, 0, 1):
        for db in (-1, 0, 1):
            if da or db:
                is_min &= core <= pad[1 + da : n + 1 + da, 1 + db : n + 1 + db]
    a, b = np.nonzero(is_min)
    far = np.maximum(np.abs(a - ia), np.abs(b - ib)) > exclusion
    return float(s[a[far], b[far]].min()) if far.any() else np.inf


def correlate(
    grid,
    t_s: float,
    lat_rad,
    lon_rad,
    h_meas_m,
    dn_rel_m=None,
    de_rel_m=None,
    half: int = 50,
    cell_m: float = 5.0,
    exclusion_cells: int = 4,
    remove_bias: bool = False,
    lat_ref_rad: float | None = None,
    accumulator: MadAccumulator | None = None,
) -> TercomFix:
    """Batch MAD fix from M samples (seed 000 eqs 1-2).

    grid: Dem.grid tuple (heights_m, lat0, lon0, dlat, dlon) or an object with `.grid`.
    lat_rad, lon_rad: INS positions (M,); h_meas_m: measured terrain heights (M,) (baro - RA range, or baro -
    |p_alt| for the IRA); dn_rel_m, de_rel_m: horizontal closest-point offsets (M,) for the IRA (None: 0).
    Non-finite samples are dropped. half: reference matrix is (2 half + 1)^2 cells of cell_m metres.
    remove_bias: correlate after removing each cell's mean height difference (insensitive to a baro bias;
    seed 000 uses plain MAD, the default). lat_ref_rad: latitude of the radii that turn metres into
    radians (default: the samples' mean). accumulator: a MadAccumulator fed these same samples (with
    lat_ref_rad = its own): its surface is used instead of computing one here.
    """
    if hasattr(grid, "grid"):
        grid = grid.grid
    rec = map_record(grid, False)       # the map record (bilinear: TERCOM's MAD, seed 000 eq 1/2)
    lat = np.asarray(lat_rad, float)
    lon = np.asarray(lon_rad, float)
    hm = np.asarray(h_meas_m, float)
    dn = np.zeros_like(lat) if dn_rel_m is None else np.asarray(dn_rel_m, float)
    de = np.zeros_like(lat) if de_rel_m is None else np.asarray(de_rel_m, float)
    ok = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(hm) & np.isfinite(dn) & np.isfinite(de)
    n = 2 * half + 1
    empty = np.full((n, n), np.inf)
    if ok.sum() < 2:
        return _unusable_fix(t_s, "no_samples", int(ok.sum()), empty, cell_m)
    lat, lon, hm, dn, de = lat[ok], lon[ok], hm[ok], dn[ok], de[ok]
    lat_c = float(np.mean(lat)) if lat_ref_rad is None else float(lat_ref_rad)
    r_ns = meridian_radius_m(lat_c)
    r_ew = prime_vertical_radius_m(lat_c) * np.cos(lat_c)
    lat_k = lat + dn / r_ns  # seed 000 eq 2: p_lat = p_n / R_ns
    lon_k = lon + de / r_ew  #                p_lon = p_e / R_ew
    d_lat_cell = cell_m / r_ns
    d_lon_cell = cell_m / r_ew
    if accumulator is not None:
        if (accumulator.n_samples != lat.size or accumulator.lat_ref_rad != lat_c or accumulator.half != half
                or accumulator.cell_m != cell_m or accumulator.remove_bias != bool(remove_bias)):
            raise ValueError("correlate: the accumulator was not fed these samples with these settings")
        surf = accumulator.surface()
    else:
        surf = _surface(rec, lat_k, lon_k, hm, d_lat_cell, d_lon_cell, half, remove_bias)
    return _fix_from_surface(t_s, surf, lat.size, half, cell_m, r_ns, r_ew, exclusion_cells)


def _surface(rec, lat_k, lon_k, hm, d_lat_cell, d_lon_cell, half, remove_bias):
    return mad_surface(
        rec,
        np.ascontiguousarray(lat_k),
        np.ascontiguousarray(lon_k),
        np.ascontiguousarray(hm),
        d_lat_cell,
        d_lon_cell,
        half,
        bool(remove_bias),
    )


def _unusable_fix(t_s, reason: str, n_samples: int, surface: np.ndarray, cell_m: float) -> TercomFix:
    """A fix that cannot be used (valid False, NaN correction and quality) for `reason`."""
    nan = np.nan
    return TercomFix(t_s, False, reason, nan, nan, nan, nan, nan, nan, False, n_samples, surface, cell_m)


def _fix_from_surface(t_s, surf, n_samples, half, cell_m, r_ns, r_ew, exclusion_cells) -> TercomFix:
    """The fix of a MAD surface: its smallest cell, the quality and edge tests (correlate's second half)."""
    n = 2 * half + 1
    if not np.isfinite(surf).any():
        return _unusable_fix(t_s, "off_map", int(n_samples), surf, cell_m)
    ia, ib = np.unravel_index(int(np.argmin(surf)), surf.shape)
    best = float(surf[ia, ib])
    second = _second_minimum(surf, ia, ib, exclusion_cells)
    quality = second / max(best, 1e-9) if np.isfinite(second) else np.inf
    on_edge = bool(ia in (0, n - 1) or ib in (0, n - 1))
    partly_off = not np.isfinite(surf).all()
    dn_fix = (ia - half) * cell_m
    de_fix = (ib - half) * cell_m
    near = surf[
        max(ia - exclusion_cells, 0) : ia + exclusion_cells + 1,
        max(ib - exclusion_cells, 0) : ib + exclusion_cells + 1,
    ]
    valid = not on_edge and bool(np.isfinite(near).all())
    if on_edge:
        reason = "edge"
    elif not valid:
        reason = "minimum_next_to_map_edge"
    else:
        reason = "ok_partial_map" if partly_off else "ok"
    return TercomFix(
        t_s,
        valid,
        reason,
        dn_fix,
        de_fix,
        dn_fix / r_ns,
        de_fix / r_ew,
        best,
        quality,
        on_edge,
        int(n_samples),
        surf,
        cell_m,
    )


# samples an accumulator lets wait before adding them to its sums in one kernel call (a navigator update
# brings ~50 at the IRA's 50 Hz; a block of a few hundred costs ~8 % less per sample and one call's overhead)
SUM_BLOCK_SAMPLES = 256


class MadAccumulator:
    """A batch's MAD surface built while its samples come in (seed 000 eqs 1-2), so that little is left for
    the fix: the sum of |d| (plain MAD: nothing is left) or of d (remove_bias: the first of two passes; the
    second needs each cell's mean) is added as the samples arrive, in sample order, in blocks of at least
    SUM_BLOCK_SAMPLES (and the rest at the fix). The surface is
    bit for bit mad_surface's on the same samples with the same radii, which here come from lat_ref_rad (the
    batch's first sample: known at its start) where correlate() by default takes the batch's mean latitude,
    a relative difference of about 1e-6 in the 5 m cells over a 5 km batch. Non-finite samples are dropped as
    correlate() drops them; samples whose shifts could touch a DEM void make it fall back to computing the
    whole surface at the fix."""

    def __init__(self, grid, half: int, cell_m: float, remove_bias: bool, lat_ref_rad: float):
        if hasattr(grid, "grid"):
            grid = grid.grid
        self.grid = tuple(grid)
        self.rec = map_record(self.grid, False)
        self.half, self.cell_m, self.remove_bias = int(half), float(cell_m), bool(remove_bias)
        self.lat_ref_rad = float(lat_ref_rad)
        self.r_ns = meridian_radius_m(self.lat_ref_rad)
        self.r_ew = prime_vertical_radius_m(self.lat_ref_rad) * np.cos(self.lat_ref_rad)
        self.dlat_cell = self.cell_m / self.r_ns
        self.dlon_cell = self.cell_m / self.r_ew
        n = 2 * self.half + 1
        self.lat_off, self.lon_off = _shift_offsets(self.half, self.dlat_cell, self.dlon_cell)
        self._acc = np.zeros(n * self.lon_off.shape[0])
        self._row_ok = np.ones(n, np.bool_)
        self._col_ok = np.ones(n, np.bool_)
        self._parts: list[np.ndarray] = []     # rows lat_k, lon_k, h_meas
        self._summed = 0                       # parts already added to the sums (the rest wait: _flush)
        self._waiting = 0                      # samples in the waiting parts
        self.void_free = True

    @property
    def n_samples(self) -> int:
        return int(sum(p.shape[1] for p in self._parts))

    def add(self, lat_rad, lon_rad, h_meas_m, dn_rel_m, de_rel_m) -> None:
        lat, lon, hm, dn, de = (np.asarray(x, float)
                                for x in (lat_rad, lon_rad, h_meas_m, dn_rel_m, de_rel_m))
        ok = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(hm) & np.isfinite(dn) & np.isfinite(de)
        if not ok.any():
            return
        part = np.stack([lat[ok] + dn[ok] / self.r_ns, lon[ok] + de[ok] / self.r_ew, hm[ok]])  # seed 000 eq 2
        self._parts.append(part)
        self._waiting += part.shape[1]
        if self._waiting >= SUM_BLOCK_SAMPLES:
            self._flush()

    def _flush(self) -> None:
        """Add the waiting parts to the sums as one block (in sample order: the same bits as part by part)."""
        parts = self._parts[self._summed:]
        self._summed = len(self._parts)
        self._waiting = 0
        if not self.void_free or not parts:
            return
        block = parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)
        lat_k, lon_k, h_k = (np.ascontiguousarray(r) for r in block)
        if not _block_void_free(self.rec, lat_k, lon_k, self.half * abs(self.dlat_cell),
                                self.half * abs(self.dlon_cell)):
            self.void_free = False
            return
        _mad_rows_pass(self.rec, lat_k, lon_k, h_k, 0, lat_k.shape[0], self.lat_off, self.lon_off,
                       2 * self.half + 1, 1 if self.remove_bias else 0, self._acc, self._acc, self._row_ok,
                       self._col_ok)

    def surface(self, threads: int | None = None) -> np.ndarray:
        """The MAD surface of every sample added (rows north shifts, columns east shifts), as mad_surface."""
        self._flush()
        n = 2 * self.half + 1
        samples = np.concatenate(self._parts, axis=1) if self._parts else np.zeros((3, 0))
        lat_k, lon_k, h_k = (np.ascontiguousarray(r) for r in samples)
        m = lat_k.shape[0]
        if not self.void_free or m == 0:
            return mad_surface(self.rec, lat_k, lon_k, h_k, self.dlat_cell, self.dlon_cell, self.half,
                               self.remove_bias, threads)
        out = np.empty((n, n))
        if not self.remove_bias:
            _mad_rows_finish(self._acc, m, n, self._row_ok, self._col_ok, out)
            return out
        nb = self.lon_off.shape[0]
        mean = self._acc / m                    # the reference's mean = s / m, per cell
        acc = np.zeros_like(mean)
        if threads is None:
            threads = TERCOM_THREADS if m * n * n > PARALLEL_MIN_LOOKUPS else 1
        row_ok = self._row_ok.copy()
        col_oks = [self._col_ok.copy() for _ in range(max(1, int(threads)))]   # per band: no shared writes
        args = (self.rec, lat_k, lon_k, h_k, 0, m)

        def band(a0: int, a1: int, i: int) -> None:
            _mad_rows_pass(*args, self.lat_off[a0:a1], self.lon_off, n, 2, mean[a0 * nb:a1 * nb],
                           acc[a0 * nb:a1 * nb], row_ok[a0:a1], col_oks[i])

        _in_bands(n, threads, band)
        col_ok = np.logical_and.reduce(col_oks)
        _mad_rows_finish(acc, m, n, row_ok, col_ok, out)
        return out


class TercomBatch:
    """Accumulates (t, INS lat/lon, measured terrain height, closest-point offsets) between fixes.

    accumulate: None, or (half, cell_m, remove_bias, grid) of the fix to come: a MadAccumulator (radii at
    the batch's first finite sample) is then fed each group of samples as it is added (`accumulator`).
    average: each `average` consecutive samples enter the batch as one, their mean (every column: time,
    position, measured height, offsets); a last, partial group at the fix (`finish`). Along a track sampled
    metres apart on a map of tens of metres the map's bilinear height is linear over a group, so the mean
    sample keeps what the group says about the terrain match with 1/average of the noise variance, and the
    correlation costs 1/average as much. 1: every sample as it comes."""

    def __init__(self, accumulate: tuple | None = None, average: int = 1):
        self.accumulate = accumulate
        if isinstance(average, bool) or int(average) != average or average < 1:
            raise ValueError(f"average must be an integer >= 1, got {average!r}")
        self.average = int(average)
        self.clear()

    def clear(self) -> None:
        self._parts: list[np.ndarray] = []
        self._pending = np.zeros((0, 6))     # (average > 1) samples of the group not yet complete
        self.accumulator: MadAccumulator | None = None

    def _feed(self, rows: np.ndarray) -> None:
        if self.accumulate is None or rows.shape[0] == 0:
            return
        if self.accumulator is None:
            ok = np.isfinite(rows[:, 1:6]).all(axis=1)    # the first sample correlate() keeps
            if not ok.any():
                return
            half, cell_m, remove_bias, grid = self.accumulate
            self.accumulator = MadAccumulator(grid, half, cell_m, remove_bias, float(rows[np.argmax(ok), 1]))
        self.accumulator.add(rows[:, 1], rows[:, 2], rows[:, 3], rows[:, 4], rows[:, 5])

    def _append(self, rows: np.ndarray) -> None:
        if self.average > 1:
            rows = rows[np.isfinite(rows).all(axis=1)]
            if self._pending.shape[0]:
                rows = np.concatenate([self._pending, rows])
            k = self.average
            n = rows.shape[0] // k * k
            self._pending = rows[n:].copy()
            if n == 0:
                return
            rows = rows[:n].reshape(n // k, k, 6).mean(axis=1)
        self._parts.append(rows)
        self._feed(rows)

    def finish(self) -> None:
        """Enter the last, partial group of samples (average > 1) as its mean; call before the fix."""
        if self._pending.shape[0]:
            rows = self._pending.mean(axis=0, keepdims=True)
            self._pending = np.zeros((0, 6))
            self._parts.append(rows)
            self._feed(rows)

    def add(self, t_s, lat_rad, lon_rad, h_meas_m, dn_rel_m=None, de_rel_m=None) -> None:
        t = np.atleast_1d(np.asarray(t_s, float))
        z = np.zeros_like(t)
        cols = [
            t,
            lat_rad,
            lon_rad,
            h_meas_m,
            z if dn_rel_m is None else dn_rel_m,
            z if de_rel_m is None else de_rel_m,
        ]
        self._append(np.stack([np.broadcast_to(np.asarray(c, float), t.shape) for c in cols], 1))

    def add_rows(self, rows: np.ndarray) -> None:
        """Append an (n, 6) float array of rows (t, lat, lon, h_meas, dn_rel, de_rel), taken as is."""
        rows = np.asarray(rows, float)
        if rows.ndim != 2 or rows.shape[1] != 6:
            raise ValueError(f"rows must be an (n, 6) array, got shape {rows.shape}")
        self._append(rows)

    @property
    def samples(self) -> np.ndarray:
        """(M, 6): t, lat, lon, h_meas, dn_rel, de_rel (with average > 1: the groups' means)."""
        return np.concatenate(self._parts) if self._parts else np.zeros((0, 6))

    def __len__(self) -> int:
        return int(sum(p.shape[0] for p in self._parts))

    def shift(self, dlat_rad: float, dlon_rad: float) -> None:
        """Move every stored INS position (after the INS was corrected by a filter update); the accumulated
        surface no longer fits them and is dropped (the fix computes it from the samples)."""
        for p in (*self._parts, self._pending):
            p[:, 1] += dlat_rad
            p[:, 2] += dlon_rad
        self.accumulator = None
        self.accumulate = None
