"""The integrity-recovery policy the filters share: when an innovation test failure asks for a recovery,
and how wide it is.

Each terrain update's NIS enters the navigator's InnovationMonitor (navigators.integrity: the sum over a
sliding window against its chi-square band). `IntegrityRecovery.add` feeds it and decides:

- entering "degraded" asks for a recovery (the filter's own: re-spread its belief, inflate its covariance,
  widen its search);
- with `repeat` (the particle and grid filters), a whole window still out of band after the last recovery
  asks for another, twice as wide each time: sigma = recovery_sigma_m 2^(k - 1) for the k-th recovery in a
  row, k up to `max_doublings` (the belief may have settled where the bad data put it);
- back in band resets the doubling.

With `cap_nis` an update adds at most (just above) its one-update 1 - alpha/2 chi-square quantile
(`capped_nis`): the heavy-tailed likelihoods take one bad sample without harm, so one alone must not flag
the filter; two such in a window do, and so does a run of them (a bias, a shifted map).

Every NIS (uncapped) also enters the long-window covariance-consistency check `consistency`
(navigators.integrity.consistency_check): a navigator whose innovations are mildly but persistently too
large for its covariance is flagged "inconsistent" there; the navigator passes its Health through
`consistency.apply` when it publishes. A new IntegrityRecovery (each navigator reset) starts it empty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..integrity.consistency_check import ConsistencyCheck
from ..integrity.innovation_monitor import InnovationMonitor, Verdict


def capped_nis(monitor: InnovationMonitor, nis: float, dof: int) -> float:
    """The NIS an update adds to the innovation test: at most (just above) its one-update 1 - alpha/2
    chi-square quantile (see the module docstring); an infinite or NaN NIS counts as that cap."""
    hi = monitor.band(dof)[1] * (1.0 + 1e-6)
    return min(float(nis), hi) if math.isfinite(float(nis)) else hi


@dataclass(frozen=True)
class RecoveryDecision:
    """The test's verdict after one update, and whether (and how wide, m) the filter recovers now."""

    verdict: Verdict
    recover: bool
    sigma_m: float


class IntegrityRecovery:
    """The recovery policy around an InnovationMonitor (see the module docstring).

    Parameters
    ----------
    monitor : InnovationMonitor
        The navigator's innovation test.
    recovery_sigma_m : float
        Width (1 sigma, m) of the first recovery in a row.
    repeat : bool
        Recover again, twice as wide, after a whole window still out of band.
    cap_nis : bool
        Feed capped_nis instead of the NIS itself.
    max_doublings : int
        Recoveries in a row that double the width (the k-th is recovery_sigma_m 2^(k - 1)).
    """

    def __init__(self, monitor: InnovationMonitor, recovery_sigma_m: float, repeat: bool = True,
                 cap_nis: bool = True, max_doublings: int = 4):
        self.monitor = monitor
        self.recovery_sigma_m = float(recovery_sigma_m)
        self.repeat = bool(repeat)
        self.cap_nis = bool(cap_nis)
        self.max_doublings = int(max_doublings)
        self.consistency = ConsistencyCheck()
        self.reset()

    def reset(self) -> None:
        """Forget the recoveries in a row (not the monitor's window: the navigator resets that)."""
        self.streak = 0
        self.since_recovery = 0
        self.recoveries = 0

    @property
    def sigma_now_m(self) -> float:
        """recovery_sigma_m, doubled for each recovery in a row that did not bring the test back in band."""
        return self.recovery_sigma_m * 2.0 ** max(self.streak - 1, 0)

    def add(self, t_s: float, nis: float, dof: int) -> RecoveryDecision:
        """Feed one update's NIS (dof degrees of freedom) and decide."""
        value = capped_nis(self.monitor, nis, dof) if self.cap_nis else nis
        self.consistency.add(nis, dof)
        verdict = self.monitor.add(t_s, value, dof)
        recover = False
        if verdict.degraded:
            self.since_recovery += 1
            if verdict.changed or (self.repeat and self.since_recovery >= self.monitor.window):
                self.since_recovery = 0
                self.streak = min(self.streak + 1, self.max_doublings)
                self.recoveries += 1
                recover = True
        elif verdict.changed:
            self.streak = 0
        return RecoveryDecision(verdict, recover, self.sigma_now_m)


__all__ = ["IntegrityRecovery", "RecoveryDecision", "capped_nis"]
