"""The records loop_kernel.track_loops takes instead of loose arguments: the loops' settings (fixed by the
navigator's configuration), one epoch's transect, and the outputs the caller allocates. numba passes them
as tuples; track_loops unpacks them."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class LoopSettings(NamedTuple):
    """track_loops' settings, fixed by the navigator's configuration (AcqTrackConfig): the correlation
    (cost, remove_bias, interp, n_min), which loops run and in what order, the V analysis (n_side points,
    symmetry_max, break_iteration, discriminator, bias mitigation), the correlation functions' reach f_r (m)
    and the sample period (s), and per loop (speed m/s, heading rad, position m) its reach, first-stage
    spacings (widest first) and threshold, second-stage spacing and threshold."""

    cost: int
    remove_bias: bool
    interp: int
    n_min: int
    aided: bool
    position_loops: bool
    speed_first: bool
    n_side: int
    symmetry_max: float
    break_iteration: int
    discriminator: int
    mitigation: int
    f_r: float
    sample_period_s: float
    speed_reach: float
    speed_desc: np.ndarray
    speed_threshold_1: float
    speed_spacing_2: float
    speed_threshold_2: float
    heading_desc: np.ndarray
    heading_threshold_1: float
    heading_spacing_2: float
    heading_threshold_2: float
    position_reach: float
    position_desc: np.ndarray
    position_threshold_1: float
    position_spacing_2: float
    position_threshold_2: float


class TransectRecord(NamedTuple):
    """One epoch's transect for track_loops: its start (lat_s, lon_s rad), sample times from the start dt (s),
    aiding speed m_v (m/s) and track m_psi (rad), references b_v, b_psi, radii r_n, r_e_cos (m), measured
    terrain heights d (m) and their validity, the aiding's mean speed and track, beam offsets o_n, o_e (m)."""

    lat_s: float
    lon_s: float
    dt: np.ndarray
    m_v: np.ndarray
    m_psi: np.ndarray
    b_v: float
    b_psi: float
    r_n: float
    r_e_cos: float
    d: np.ndarray
    valid: np.ndarray
    mean_m_v: float
    mean_m_psi: float
    o_n: np.ndarray
    o_e: np.ndarray


class LoopOutputs(NamedTuple):
    """track_loops' outputs, allocated by the caller: iterations (4,), locked (4,), ran (4,), V shapes (4, 6),
    the prompt replica's map heights (n,)."""

    its: np.ndarray
    locked: np.ndarray
    ran: np.ndarray
    shapes: np.ndarray
    h_prompt: np.ndarray
