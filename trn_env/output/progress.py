"""The terminal progress bars of `trn-env fly`, `record` and `campaign` (tqdm, on standard error).

tqdm starts a monitor thread with its first bar (it forces a refresh of bars whose `miniters` grew too large).
A campaign's local pool forks its workers, and replaces dead ones, while its bar is open: with that thread
alive every fork is a fork of a multi-threaded process, which Python 3.12 and newer warn about and which
could deadlock a child if the thread held a lock at the time. These bars refresh on time (`mininterval`)
and need no monitor, so theirs is off: the class attribute is set on a subclass, leaving the bars of
the rest of the process as they were.
"""

from __future__ import annotations

from tqdm import tqdm


class _QuietTqdm(tqdm):
    monitor_interval = 0          # no tqdm_monitor thread


def progress_bar(**kwargs) -> tqdm:
    """A tqdm bar (same keyword arguments) that starts no monitor thread."""
    return _QuietTqdm(**kwargs)
