"""Navigator self-integrity: a sliding-window normalised innovation squared (NIS) test.

A consistent filter's NIS values are chi-square with nis_dof degrees of freedom each; the sum of the last
`window` of them is chi-square with the summed dof. When the sum leaves its two-sided chi-square band
(probability `alpha` outside it) the navigator's innovations no longer agree with its own covariance: it is
lost (too large, the usual case after a bad map match or a map fault) or too pessimistic (too small). The
monitor says so; the navigator reports Health.status = "degraded" and, where it can, recovers.

How a navigator plugs in (the EKF of navigators/filters/ins_trn_ekf.py does this; pmf/pf/rbpf/acq_track do
the same with their own update's values):

    self.integrity = InnovationMonitor(window=3, alpha=0.01)          # in the constructor (validated)
    ...
    # after each terrain measurement update (accepted or rejected by a gate), with the values it puts under
    # navigators.protocol.EXTRA_NIS / EXTRA_NIS_DOF:
    verdict = self.integrity.add(t_s, nis, nis_dof)
    if verdict.changed:                                               # log the transition
        self.health.events.append((t_s, verdict.message))
    if verdict.degraded:
        self.health.status = "degraded"      # + the navigator's own recovery: widen the search, inflate
                                             #   the covariance, re-spread the cloud, re-acquire
    elif verdict.changed:
        self.health.status = "ok"            # (or its tracking state)

Only the upper side flags "degraded" by default (`two_sided=False`): an over-large covariance is safe,
and the EKF's TERCOM fix noise is deliberately pessimistic. `two_sided=True` flags both sides.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from ..protocol import EXTRA_INTEGRITY_BAND, EXTRA_INTEGRITY_DOF, EXTRA_INTEGRITY_STATISTIC

_BANDS: dict[tuple[float, int], tuple[float, float]] = {}   # (alpha, dof) -> band, shared


@dataclass(frozen=True)
class Verdict:
    """The test after one added NIS: the window's statistic and band, and whether it flags the navigator."""

    t_s: float
    statistic: float
    dof: int
    lower: float
    upper: float
    degraded: bool
    changed: bool
    message: str

    def extra(self) -> dict:
        """The windowed statistic and its band under the navigators.protocol EXTRA_INTEGRITY_* keys."""
        return {EXTRA_INTEGRITY_STATISTIC: self.statistic, EXTRA_INTEGRITY_DOF: self.dof,
                EXTRA_INTEGRITY_BAND: (self.lower, self.upper)}


class InnovationMonitor:
    """Sliding window of the last `window` (NIS, dof) pairs; chi-square band at probability alpha."""

    def __init__(self, window: int = 3, alpha: float = 0.01, two_sided: bool = False):
        if isinstance(window, bool) or not isinstance(window, int) or window < 1:
            raise ValueError(f"integrity_window: must be an integer >= 1, got {window!r}")
        if not (isinstance(alpha, (int, float)) and math.isfinite(alpha) and 0.0 < alpha < 1.0):
            raise ValueError(f"integrity_alpha: must lie in (0, 1), got {alpha!r}")
        self.window = int(window)
        self.alpha = float(alpha)
        self.two_sided = bool(two_sided)
        self._items: deque[tuple[float, int]] = deque(maxlen=self.window)
        self.degraded = False

    def reset(self) -> None:
        self._items.clear()
        self.degraded = False

    def band(self, dof: int) -> tuple[float, float]:
        """(lower, upper) chi-square quantiles at alpha/2 and 1 - alpha/2 for `dof` degrees of freedom."""
        key = (self.alpha, dof)
        if key not in _BANDS:
            from scipy.stats import chi2
            a = 0.5 * self.alpha
            _BANDS[key] = (float(chi2.ppf(a, dof)), float(chi2.isf(a, dof)))
        return _BANDS[key]

    def add(self, t_s: float, nis: float, dof: int) -> Verdict:
        """Add one update's NIS (a non-finite NIS counts as infinitely large: the update failed)."""
        nis = float(nis) if math.isfinite(float(nis)) else math.inf
        self._items.append((nis, int(dof)))
        stat = sum(x for x, _ in self._items)
        d = sum(k for _, k in self._items)
        lo, hi = self.band(d)
        full = len(self._items) == self.window
        high = stat > hi
        low = self.two_sided and full and stat < lo
        degraded = bool(high or low)
        changed = degraded != self.degraded
        self.degraded = degraded
        if degraded:
            side = "above" if high else "below"
            msg = (f"innovation test: NIS sum {stat:.1f} over {len(self._items)} updates ({d} dof) {side} "
                   f"its band [{lo:.1f}, {hi:.1f}]")
        else:
            msg = f"innovation test back in band: NIS sum {stat:.1f} ({d} dof, band [{lo:.1f}, {hi:.1f}])"
        return Verdict(float(t_s), stat, d, lo, hi, degraded, changed, msg)
