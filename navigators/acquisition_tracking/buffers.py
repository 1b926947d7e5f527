"""Small helpers of the acquisition-and-tracking navigator (seed 001): the closed-form 2 x 2 (north, east)
covariance algebra, scalar statistics without numpy's Python layers, and the buffers that carry the
sensors' recent samples and the transect's beam offsets across frames."""

from __future__ import annotations

import math

import numpy as np

from .aiding import (
    lsq_rate,
    sample_at,
)

_TAIL_S = 3.0  # seconds of each sensor's samples carried into the next frame (sample look-ups)
_TURN_RATE_WINDOW_S = 3.0  # compass heading rate for the coordinated-turn roll: LSQ slope over 3 s
_MAD_VARIANCE_FACTOR = math.pi / 2.0


# closed forms of the 2 x 2 (north, east) covariance algebra: np.linalg on a 2 x 2 costs more in its Python
# call than the arithmetic (once per epoch per operation, it was a visible part of an epoch)
def _rot_diag(psi: float, a: float, b: float) -> np.ndarray:
    """G diag(a, b) G^T, G the rotation from (along, across) track psi (rad) to (north, east)."""
    c, s = math.cos(psi), math.sin(psi)
    cs = c * s * (a - b)
    return np.array([[c * c * a + s * s * b, cs], [cs, s * s * a + c * c * b]])


def _det2(m: np.ndarray) -> float:
    return float(m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0])


def _inv2(m: np.ndarray) -> np.ndarray:
    det = _det2(m)
    if det == 0.0:  # as np.linalg: singular raises, NaN propagates
        raise np.linalg.LinAlgError("singular 2 x 2 matrix")
    return np.array([[m[1, 1], -m[0, 1]], [-m[1, 0], m[0, 0]]]) / det


def _quad2(x: np.ndarray, m: np.ndarray) -> float:
    """x^T m^-1 x of a 2-vector and a 2 x 2 matrix."""
    a, b, c, d = float(m[0, 0]), float(m[0, 1]), float(m[1, 0]), float(m[1, 1])
    det = a * d - b * c
    if det == 0.0:  # as np.linalg: singular raises, NaN propagates
        raise np.linalg.LinAlgError("singular 2 x 2 matrix")
    x0, x1 = float(x[0]), float(x[1])
    return (x0 * (d * x0 - b * x1) + x1 * (a * x1 - c * x0)) / det


def _median(x: np.ndarray) -> float:
    """np.median of a 1-D array without NaN by a sort (the same value: the middle element, or the mean of the
    two middle ones as (a + b) / 2); np.median's Python layers cost more than the sort of N samples."""
    x = np.sort(x)
    m = x.size // 2
    return float(x[m]) if x.size % 2 else float((x[m - 1] + x[m]) / 2.0)


def _mean(x: np.ndarray) -> float:
    """np.mean of a 1-D array as it computes it (sum / count) without its Python layers."""
    return float(x.sum()) / x.size


def _nanmean(x: np.ndarray) -> float:
    """np.nanmean of a 1-D array (NaN when it has no finite value), without its Python layers when no
    element is NaN (then it is sum / count, as np.nanmean computes it)."""
    nan = np.isnan(x)
    if not nan.any():
        return float(x.sum()) / x.size
    if nan.all():
        return math.nan
    return float(np.where(nan, 0.0, x).sum()) / int(x.size - nan.sum())


class _Offsets:
    """The transect's beam offsets (north, east m) as the rows of a buffer, oldest first, with a bounded
    deque's semantics (when full the oldest drops out); rows() is a view (callers copy what they keep)."""

    def __init__(self, n: int):
        self._rows = np.zeros((n, 2))
        self._n = 0

    def __len__(self) -> int:
        return self._n

    def append(self, offset) -> None:
        if self._n == self._rows.shape[0]:
            self._rows[:-1] = self._rows[1:]
        else:
            self._n += 1
        self._rows[self._n - 1] = offset

    def rows(self) -> np.ndarray:
        return self._rows[: self._n]


class _Tail:
    """A sensor's recent samples (t, columns..., valid), carried across frames: the samples within _TAIL_S
    of the newest, kept in buffers that a frame's samples are written into (t, v, ok are views of them)."""

    def __init__(self, n_cols: int):
        self._t = np.zeros(64)
        self._v = np.zeros((64, n_cols))
        self._ok = np.zeros(64, bool)
        self._lo = self._hi = 0
        self._views()

    def _views(self) -> None:
        lo, hi = self._lo, self._hi
        self.t, self.v, self.ok = self._t[lo:hi], self._v[lo:hi], self._ok[lo:hi]

    def extend(self, t, cols, ok) -> None:
        t = np.asarray(t, float)
        n = t.size
        if n == 0:
            return
        live = self._hi - self._lo
        if self._hi + n > self._t.size:  # move the live samples to the front, growing the buffers if needed
            cap = max(self._t.size, 2 * (live + n))
            bt, bv, bo = np.zeros(cap), np.zeros((cap, self._v.shape[1])), np.zeros(cap, bool)
            bt[:live], bv[:live], bo[:live] = self.t, self.v, self.ok
            self._t, self._v, self._ok = bt, bv, bo
            self._lo, self._hi = 0, live
        hi = self._hi
        self._t[hi : hi + n] = t
        if isinstance(cols, np.ndarray):  # (n_cols, n) at once
            self._v[hi : hi + n] = cols.T
        else:
            for j, c in enumerate(cols):
                self._v[hi : hi + n, j] = c
        self._ok[hi : hi + n] = ok
        self._hi = hi + n
        # sensor times increase: the samples within _TAIL_S of the newest are a suffix
        self._lo += int(self._t[self._lo : self._hi].searchsorted(t[-1] - _TAIL_S, side="left"))
        self._views()

    def rate(self, t_s: float, col: int, window_s: float) -> float:
        """Least-squares slope (per s) of column col over the valid samples in [t_s - window_s, t_s]."""
        return float(lsq_rate(self.t, np.ascontiguousarray(self.v[:, col]), self.ok, t_s, window_s))

    def row(self, t_s: float, max_gap_s: float) -> tuple[np.ndarray | None, bool]:
        """(all columns of the newest valid sample at or before t_s within max_gap_s, found)."""
        if self.t.size == 0:
            return None, False
        k = int(self.t.searchsorted(t_s + 1e-9, side="right")) - 1
        while k >= 0 and not self.ok[k]:
            k -= 1
        if k < 0 or t_s - self.t[k] > max_gap_s:
            return None, False
        return self.v[k], True

    def at(self, t_query, col: int, max_gap_s: float):
        return sample_at(
            np.atleast_1d(np.asarray(t_query, float)), self.t, self.v[:, col], self.ok, max_gap_s
        )
