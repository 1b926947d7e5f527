"""Terrain samples a filter takes from a frame: the valid altimeter returns (IRA and/or radar altimeter), at
most one per 1/rate_hz seconds, in time order.

The sensors sample faster than a terrain filter updates (seed 002 updates at 1 Hz); taking the next valid
return once each interval keeps the filter's rate fixed whatever the sensors' rates. A sample is valid when
its sensor says so and its range is finite and positive (and, for the IRA, its look angle finite); the
others are counted so the filter can report them.
"""

from __future__ import annotations

import numpy as np

from ..frames import SensorFrames


def terrain_samples(frames: SensorFrames, aiding: str, rate_hz: float,
                    t_next_s: float) -> tuple[list, float, int]:
    """The frame's terrain samples for a filter aided by `aiding` ("ira", "radar_altimeter" or "both").

    Parameters
    ----------
    frames : SensorFrames
        One interval of sensor data.
    aiding : str
        Which altimeters the filter uses.
    rate_hz : float
        Samples taken per second at most.
    t_next_s : float
        Earliest time (s) the next sample may be taken (the previous call's return).

    Returns
    -------
    samples : list of (t_s, kind, (range_m, look_angle_rad))
        In time order; `kind` is "ira" or "radar_altimeter" (whose look angle is 0).
    t_next_s : float
        Earliest time of the sample after these.
    n_invalid : int
        Samples skipped as invalid or without a return.
    """
    sources = []
    if aiding in ("ira", "both") and frames.ira is not None:
        f = frames.ira
        sources.append(("ira", f.t_s, f.valid, f.range_m, f.look_angle_rad))
    if aiding in ("radar_altimeter", "both") and frames.radar_altimeter is not None:
        f = frames.radar_altimeter
        sources.append(("radar_altimeter", f.t_s, f.valid, f.range_m, np.zeros_like(f.range_m)))
    dt_s = 1.0 / rate_hz
    n_bad = 0
    cand = []
    for kind, ts, valid, rng_m, th in sources:
        ok = np.asarray(valid, bool) & np.isfinite(rng_m) & np.isfinite(th) & (rng_m > 0.0)
        n_bad += int((~ok).sum())
        for i in np.nonzero(ok)[0]:
            cand.append((float(ts[i]), kind, (float(rng_m[i]), float(th[i]))))
    cand.sort(key=lambda c: c[0])
    out = []
    for t_s, kind, payload in cand:   # at most one terrain sample per 1/rate_hz
        if t_s >= t_next_s - 1e-9:
            out.append((t_s, kind, payload))
            t_next_s = t_s + dt_s
    return out, t_next_s, n_bad


def ira_epochs(ira, gnss, t_last_s: float, t_next_s: float, period_s: float) -> tuple[list, float, int]:
    """A filter's epochs in one frame at a fixed period, each on the first valid IRA sample at or after its
    due time (seed 002's 1 Hz TRN epochs); without a usable IRA sample in the frame, on the GNSS fixes.

    Parameters
    ----------
    ira : IraFrame or None
        The frame's IRA samples (t_s, range_m, look_angle_rad, valid).
    gnss : navigators.core.ins_gnss.GnssFixes or None
        The frame's usable GNSS fixes; each epoch carries the fix nearest it.
    t_last_s : float
        The frame's last INS time (s): no epoch after it.
    t_next_s : float
        Due time (s) of the next epoch (the previous call's return).
    period_s : float
        Epoch period, s.

    Returns
    -------
    epochs : list of (t_s, (range_m, look_angle_rad) or None, GNSS fix or None)
    t_next_s : float
        Due time of the epoch after these.
    n_invalid : int
        IRA samples invalid or NaN.
    """
    out = []
    n_bad = 0
    if ira is not None and ira.t_s.shape[0]:
        ts = np.asarray(ira.t_s, float)
        good = np.asarray(ira.valid, bool) & np.isfinite(ira.range_m) & np.isfinite(ira.look_angle_rad)
        n_bad = int((~good).sum())
        while True:
            i = int(np.searchsorted(ts, t_next_s - 1e-9, side="left"))
            while i < ts.shape[0] and not good[i]:
                i += 1
            if i >= ts.shape[0] or ts[i] > t_last_s + 1e-9:
                break
            te = float(ts[i])
            g = None if gnss is None else gnss.nearest(te)
            out.append((te, (float(ira.range_m[i]), float(ira.look_angle_rad[i])), g))
            t_next_s = te + period_s
    if not out and gnss is not None and gnss.n:  # no usable IRA sample: GNSS epochs alone
        for te in gnss.t_s:
            te = float(te)
            if te + 1e-9 >= t_next_s and te <= t_last_s + 1e-9:
                out.append((te, None, gnss.nearest(te)))
                t_next_s = te + period_s
    return out, t_next_s, n_bad
