"""Sensor frames (navigators.frames): every array field has t_s's rows, and the navigators get C-contiguous,
writable arrays whatever the frame was cut from (numba compiles a kernel again for strided or read-only
arrays: a user's columns of a table, a read-only buffer)."""

from __future__ import annotations

import numpy as np
import pytest
from trn_env.navigators.frames import BaroFrame, ImuFrame, IraFrame


def test_strided_and_read_only_fields_become_contiguous_writable_copies():
    table = np.arange(60.0).reshape(10, 6)        # a user's log table: its columns are strided views
    read_only = np.linspace(0.0, 1.0, 10)
    read_only.flags.writeable = False
    valid = np.ones(20, np.bool_)[::2]            # strided booleans
    baro = BaroFrame(read_only, table[:, 1], valid)
    imu = ImuFrame(table[:, 0], table[:, 1:4], table[:, 3:6], np.ones(10, np.bool_))
    for frame, given in ((baro, (read_only, table[:, 1], valid)),
                         (imu, (table[:, 0], table[:, 1:4], table[:, 3:6]))):
        for name, source in zip(("t_s", "h_baro_m", "valid") if frame is baro else
                                ("t_s", "f_b_mps2", "omega_ib_b_rps"), given, strict=True):
            v = getattr(frame, name)
            assert v.flags.c_contiguous and v.flags.writeable, name
            assert v.dtype == source.dtype and np.array_equal(v, source), name
            assert not np.shares_memory(v, source), name


def test_contiguous_writable_fields_are_kept_as_given():
    t = np.arange(5.0)
    rng = np.full(5, 800.0)
    theta = np.zeros(5)
    ok = np.ones(5, np.bool_)
    frame = IraFrame(t, rng, theta, ok)
    assert frame.t_s is t and frame.range_m is rng and frame.look_angle_rad is theta and frame.valid is ok


def test_a_field_with_other_rows_than_t_s_is_refused_by_name():
    with pytest.raises(ValueError, match=r"BaroFrame\.h_baro_m has 4 rows, t_s has 5"):
        BaroFrame(np.arange(5.0), np.zeros(4), np.ones(5, np.bool_))
