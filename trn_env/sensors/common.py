"""Shared machinery of the sensor models: the configs' base, absolute-time sampling, error recursions.

Sampling rule: a sensor at `rate_hz` owns the time grid k / rate_hz (k integer). Truth step i is a sample
when its grid index floor(t_i * rate_hz) differs from the previous step's, i.e. the first truth step at or
after each grid instant is sampled. When the rate divides the truth rate this is exactly the steps whose
t_s lies on the grid. The previous step's index is carried between chunks, so where the chunk boundaries
fall never changes which steps are sampled.

Random numbers: each sensor call draws exactly one standard-normal block of shape (n_samples, m) from its
Generator (plus one fixed-size block when its state is created), so sampling a flight chunk by chunk gives
bit-for-bit the same output as sampling it in one call.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, ClassVar, NamedTuple

import numpy as np
from numba import njit

from trn_env.navigators.core.settings import Settings, SettingsError
from trn_env.terrain.geodesy import C_en, ecef_to_lla, lla_to_ecef

_GRID_EPS = 1e-6   # tolerance, in grid periods, for "on the grid" (t_s is a float multiple of the step)


def initial_grid_index(t0_s: float, rate_hz: float) -> int:
    """Grid index 'before' the first step so that a first step lying on the grid is sampled."""
    return int(math.ceil(t0_s * rate_hz - _GRID_EPS)) - 1


def no_sample_due(t_s: np.ndarray, rate_hz: float, last_k: int | None) -> bool:
    """True when a sensor at `rate_hz` with carried grid index `last_k` samples no step of t_s (its last
    step's grid index is not past last_k; t_s increases), so sample_steps would return no indices and
    carry last_k unchanged. Same floating-point expression as _grid_indices."""
    n = t_s.shape[0]
    return last_k is not None and (n == 0 or math.floor(float(t_s[n - 1]) * rate_hz + _GRID_EPS) <= last_k)


def due_samples(truth, config, rng: np.random.Generator, state, state_cls):
    """The start of a sampling call of a sensor whose errors need no update between samples: (state,
    indices of the chunk's sampled truth steps, grid index to carry). The state is state_cls.initial(config,
    rng) on the first call (its draws come first); indices None when no sample is due (state unchanged)."""
    if state is None:
        state = state_cls.initial(config, rng)
    elif no_sample_due(truth.t_s, config.rate_hz, state.last_k):
        return state, None, state.last_k
    idx, last_k = sample_steps(truth.t_s, config.rate_hz, state.last_k)
    return state, idx, last_k


def trusted_frame(cls, **values):
    """A frame dataclass (navigators.frames) built from arrays the sensor model made consistent itself,
    without its per-construction length check (the hot path constructs several frames per tick)."""
    frame = object.__new__(cls)
    frame.__dict__.update(values)
    return frame


# zero-length arrays shared by the frames of sensors with no sample due in a chunk (nothing to write)
EMPTY_F = np.zeros(0)
EMPTY_B = np.zeros(0, dtype=bool)
EMPTY_F3 = np.zeros((0, 3))


def sample_steps(t_s: np.ndarray, rate_hz: float, last_k: int | None) -> tuple[np.ndarray, int | None]:
    """Indices of the truth steps sampled by a sensor at `rate_hz` and the grid index to carry forward.

    Raises ValueError if the sensor's grid is finer than the truth steps (rate above the truth rate).
    """
    if t_s.shape[0] == 0:
        return np.zeros(0, dtype=np.int64), last_k
    first = last_k is None
    if first:
        last_k = initial_grid_index(float(t_s[0]), rate_hz)
    idx, k, max_jump = _grid_indices(t_s, float(rate_hz), int(last_k), first)
    if max_jump > 1:
        dt = float(t_s[1] - t_s[0]) if t_s.shape[0] > 1 else float("nan")
        raise ValueError(f"rate_hz = {rate_hz} exceeds the truth step rate (step {dt} s): a sensor samples "
                         "truth steps, so its rate must not exceed the flight core's")
    return idx, int(k)


@njit(cache=True)
def _grid_indices(t_s, rate_hz, last_k, first):
    n = t_s.shape[0]
    out = np.empty(n, dtype=np.int64)
    m = 0
    prev = last_k
    max_jump = 0
    for i in range(n):
        k = np.int64(np.floor(t_s[i] * rate_hz + _GRID_EPS))
        if k > prev:
            out[m] = i
            m += 1
            if not (first and i == 0) and k - prev > max_jump:
                max_jump = k - prev
        prev = k
    return out[:m], prev, max_jump


def gm_coefficients(sigma, tau_s, dt_s: float):
    """phi and drive of a stationary discrete Gauss-Markov process with std sigma and correlation time tau
    (x_k = phi x_{k-1} + drive w_k); scalars or arrays."""
    phi = np.exp(-dt_s / np.asarray(tau_s, float))
    return phi, np.asarray(sigma, float) * np.sqrt(1.0 - phi * phi)


def antenna_positions(lat_rad: np.ndarray, lon_rad: np.ndarray, h_m: np.ndarray, C_bn: np.ndarray,
                      lever_arm_b_m: tuple[float, float, float]):
    """Geodetic position of a point at body-FRD offset `lever_arm_b_m` from the truth position."""
    arm = np.asarray(lever_arm_b_m, float)
    if not np.any(arm):
        return lat_rad, lon_rad, h_m
    d_ned = C_bn @ arm
    return ned_displace(lat_rad, lon_rad, h_m, d_ned)


def ned_displace(lat_rad, lon_rad, h_m, d_ned_m):
    """Exact (through ECEF) geodetic position of (lat, lon, h) displaced by d_ned_m (n, 3) metres."""
    lat = np.atleast_1d(np.asarray(lat_rad, float))
    lon = np.atleast_1d(np.asarray(lon_rad, float))
    h = np.atleast_1d(np.asarray(h_m, float))
    d = np.atleast_2d(np.asarray(d_ned_m, float))
    return _ned_displace(lat, lon, h, d)


@njit(cache=True)
def _ned_displace(lat, lon, h, d):
    n = lat.shape[0]
    out_lat, out_lon, out_h = np.empty(n), np.empty(n), np.empty(n)
    for i in range(n):
        x, y, z = lla_to_ecef(lat[i], lon[i], h[i])
        c = C_en(lat[i], lon[i])
        dx = c[0, 0] * d[i, 0] + c[0, 1] * d[i, 1] + c[0, 2] * d[i, 2]
        dy = c[1, 0] * d[i, 0] + c[1, 1] * d[i, 1] + c[1, 2] * d[i, 2]
        dz = c[2, 0] * d[i, 0] + c[2, 1] * d[i, 1] + c[2, 2] * d[i, 2]
        out_lat[i], out_lon[i], out_h[i] = ecef_to_lla(x + dx, y + dy, z + dz)
    return out_lat, out_lon, out_h


@njit(cache=True)
def ned_vectors_kernel(lat0, lon0, h0, lat1, lon1, h1):
    """Exact NED vectors (n, 3), resolved at points 0, from geodetic points 0 to points 1 (through ECEF);
    all inputs (n,) float arrays (rad, rad, m)."""
    n = lat0.shape[0]
    out = np.empty((n, 3))
    for i in range(n):
        x0, y0, z0 = lla_to_ecef(lat0[i], lon0[i], h0[i])
        x1, y1, z1 = lla_to_ecef(lat1[i], lon1[i], h1[i])
        c = C_en(lat0[i], lon0[i])
        dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
        for j in range(3):
            out[i, j] = c[0, j] * dx + c[1, j] * dy + c[2, j] * dz
    return out


@dataclass(frozen=True)
class MappingConfig(Settings):
    """Base of the sensor configs (navigators.core.settings fields): `from_mapping` builds one from a
    scenario table, where the key `noise_free = true` starts from the class's `noise_free()` configuration
    and the other keys override it. Unknown keys and bad values raise one SettingsError (a ValueError) naming
    every field."""

    @classmethod
    def from_mapping(cls, mapping: dict | None = None, base=None):
        mapping = dict(mapping or {})
        noise_free = mapping.pop("noise_free", False)
        if not isinstance(noise_free, bool):
            raise SettingsError([("noise_free", f"must be true or false, got {noise_free!r}")])
        if noise_free:
            base = cls.noise_free()
        return super().from_mapping(mapping, base)

    ERROR_FIELDS: ClassVar[tuple[str, ...]] = ()   # each sensor's error settings, zero in noise_free()

    @classmethod
    def noise_free(cls, **overrides: Any):
        """The configuration without errors: the defaults with every ERROR_FIELDS setting 0, then
        `overrides`."""
        if not cls.ERROR_FIELDS:
            raise NotImplementedError(f"{cls.__name__} declares no ERROR_FIELDS")
        return replace(cls(**{name: 0.0 for name in cls.ERROR_FIELDS}), **overrides)


class TimeGridState(NamedTuple):
    """State of a sensor whose errors are white (no memory): only the index of its last sample on the
    absolute time grid, so chunked sampling continues the grid."""

    last_k: int | None

    @classmethod
    def initial(cls, config, rng) -> TimeGridState:
        return cls(None)
