"""Run-time covariance-consistency check: a long-window NIS test that withdraws the navigator's health.

The short innovation test (navigators.integrity.innovation_monitor, a window of ~3 updates at a wide band)
catches a navigator that has lost the terrain: NIS values far out of their chi-square band. It does not
catch a navigator whose covariance is consistently a little too small (an unmodelled map or IMU error
that inflates every innovation by a few tens of percent): each update stays in band, the navigator stays
healthy, and its protection level (drawn from the same covariance) is then too tight. Over a long window
that mild excess is visible: for a consistent filter the innovations are white and each NIS is chi-square
with its dof (the NIS consistency test: Bar-Shalom, Li & Kirubarajan 2001, Estimation with Applications
to Tracking and Navigation, sec. 5.4.2, eq. 5.4.2-7/-8: the time average of the NIS against its chi-square
bound), so the sum of the last `window` NIS values is chi-square with the summed dof.

`ConsistencyCheck.add` keeps that sum over the last `window` updates and flags "inconsistent" while a full
window's sum is above its one-sided chi-square quantile at `alpha` (per update: a consistent filter is
flagged with probability alpha at most). Each NIS enters capped at its single-update chi-square quantile
at `cap_alpha` (the heavy-tailed filters take an outlier without harm, one alone must not flag them); the
cap only lowers the sum, so the false-flag probability stays at most alpha.

What the flag does to the navigator's Health (`apply`): ok = False, status = "inconsistent" (unless the
navigator already names a fault: degraded, acquiring, diverged or lost stay) and consistency_warning = the
test's message (after the navigator's static warning, if any), for every estimate published while the
window is over its bound. A static warning alone (navigators.core.measured_consistency: a covariance known
to be conservative, or known not to bound the error on that IMU grade) withdraws nothing here: only the
flag does. A consumer therefore reads the flag as "do not trust the position or its protection level
now"; the protection-level campaign (docs/validation/integrity.md section 6) counts flagged epochs as not
healthy, as certification counts an alerted epoch. The check never changes the estimate itself.
"""

from __future__ import annotations

import math
from collections import deque

CONSISTENCY_WINDOW = 30          # updates in the window (one terrain update per epoch: 30 s at 1 Hz)
CONSISTENCY_ALPHA = 1e-3         # per-update probability that a consistent navigator is flagged (at most)
CONSISTENCY_CAP_ALPHA = 1e-4     # each NIS capped at its single-update chi-square quantile at this
STATUS_INCONSISTENT = "inconsistent"

_QUANTILES: dict[tuple[float, int], float] = {}


def chi2_upper(alpha: float, dof: int) -> float:
    """The chi-square quantile with upper-tail probability alpha for dof degrees of freedom (cached)."""
    key = (float(alpha), int(dof))
    q = _QUANTILES.get(key)
    if q is None:
        from scipy.stats import chi2
        q = _QUANTILES[key] = float(chi2.isf(alpha, dof))
    return q


def _check_probability(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (0.0 < float(value) < 1.0):
        raise ValueError(f"{name}: must be a probability in (0, 1), got {value!r}")
    return float(value)


class ConsistencyCheck:
    """Sum of the last `window` capped NIS values against its chi-square bound (see the module docstring).

    Parameters
    ----------
    window : int
        Updates in the window (>= 2).
    alpha : float
        Per-update false-flag probability of a consistent navigator, in (0, 1).
    cap_alpha : float
        Each NIS is capped at its single-update chi-square quantile at this upper-tail probability.
    """

    def __init__(self, window: int = CONSISTENCY_WINDOW, alpha: float = CONSISTENCY_ALPHA,
                 cap_alpha: float = CONSISTENCY_CAP_ALPHA):
        if isinstance(window, bool) or not isinstance(window, int) or window < 2:
            raise ValueError(f"consistency_window: must be an integer >= 2, got {window!r}")
        self.window = int(window)
        self.alpha = _check_probability(alpha, "consistency_alpha")
        self.cap_alpha = _check_probability(cap_alpha, "consistency_cap_alpha")
        self._items: deque[tuple[float, int]] = deque(maxlen=self.window)
        self.reset()

    def reset(self) -> None:
        """Empty the window and clear the flag."""
        self._items.clear()
        self.inconsistent = False
        self.statistic = math.nan
        self.bound = math.nan
        self.flags = 0            # updates flagged so far
        self.updates = 0          # updates seen so far

    def add(self, nis: float, dof: int) -> bool:
        """Add one update's NIS (dof degrees of freedom; non-finite counts as the cap); True while flagged."""
        dof = int(dof)
        if dof < 1:
            return self.inconsistent
        cap = chi2_upper(self.cap_alpha, dof)
        x = float(nis)
        self._items.append((min(x, cap) if math.isfinite(x) else cap, dof))
        self.updates += 1
        if len(self._items) < self.window:
            self.inconsistent = False
            return False
        self.statistic = sum(v for v, _ in self._items)
        self.bound = chi2_upper(self.alpha, sum(d for _, d in self._items))
        self.inconsistent = self.statistic > self.bound
        self.flags += int(self.inconsistent)
        return self.inconsistent

    @property
    def message(self) -> str:
        """The run-time warning while flagged, else ""."""
        if not self.inconsistent:
            return ""
        return (f"innovations inconsistent with the covariance: NIS sum {self.statistic:.1f} over the last "
                f"{self.window} updates above its chi-square bound {self.bound:.1f} (alpha {self.alpha:g}); "
                "position and protection level not to be trusted")

    def apply(self, ok: bool, status: str, warning: str) -> tuple[bool, str, str]:
        """(ok, status, consistency_warning) of the Health to publish: unchanged unless flagged, else
        (False, status, the message after any static warning), where status is "inconsistent" if the
        navigator's own word was "ok", and its own word (acquiring, degraded, diverged, lost: a fault it
        has already named, and ok already withdrawn) otherwise."""
        if not self.inconsistent:
            return ok, status, warning
        keep = STATUS_INCONSISTENT if status == "ok" else status
        return False, keep, (warning + "; " if warning else "") + self.message


__all__ = ["CONSISTENCY_ALPHA", "CONSISTENCY_CAP_ALPHA", "CONSISTENCY_WINDOW", "STATUS_INCONSISTENT",
           "ConsistencyCheck", "chi2_upper"]
