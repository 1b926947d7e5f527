"""Comparing two closed-loop runs (sim.closed_loop.RunResult) bit for bit, wall-clock figures aside."""

from __future__ import annotations

import numpy as np

WALL_CLOCK_KEYS = ("wall_time_s", "realtime_factor", "closed_loop_steps_per_s", "wall_time_by_stage_s",
                   "pipelined")


def assert_same_run(a, b, ignore: tuple[str, ...] = ()) -> None:
    """Same termination, JSBSim steps, events, every logged array (NaN equal to NaN) and every summary
    figure except the wall-clock ones and `ignore`."""
    assert a.termination == b.termination
    assert a.jsbsim_steps == b.jsbsim_steps
    assert a.events == b.events
    assert a.arrays.keys() == b.arrays.keys()
    for k in a.arrays:
        assert np.array_equal(a.arrays[k], b.arrays[k], equal_nan=True), k
    for k, v in a.summary.items():
        if k not in WALL_CLOCK_KEYS + tuple(ignore):
            assert v == b.summary[k] or (v != v and b.summary[k] != b.summary[k]), k
