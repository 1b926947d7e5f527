"""The records loop_kernel.track_loops takes instead of loose arguments: the loops' settings (fixed by the
navigator's configuration), one epoch's transect, and the outputs the caller allocates. numba passes them
as tuples; track_loops unpacks them."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np


class LoopSettings(NamedTuple):
    """track_loops' settings, fixed by the navigator's configuration (AcqTrackConfig): the correlation
    (cost, remove_bias, n_min; the interpolation is the map record's), which loops run and in what order,
    the V analysis (n_side points,
    symmetry_max, break_iteration, discriminator, bias mitigation), the correlation functions' reach f_r (m)
    and the sample period (s), and per loop (speed m/s, heading rad, position m) its reach, first-stage
    spacings (widest first) and threshold, second-stage spacing and threshold."""

    cost: int
    remove_bias: bool
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

    @classmethod
    def from_config(cls, cfg, map_resolution_m: float, cost: int, n_min: int, discriminator: int,
                    mitigation: int) -> LoopSettings:
        """The settings of an AcqTrackConfig on a map of map_resolution_m posts: the spacing sets widest
        first, the speed loop's reach (f_r over the transect's duration, at least the widest spacing) and the
        start-point loops' (f_r = scf_offset_cells posts, at least the widest position spacing)."""
        speed_set = np.array(cfg.speed_spacings_mps)
        heading_set = np.radians(np.array(cfg.heading_spacings_deg))
        position_set = np.array(cfg.position_spacings_cells) * map_resolution_m
        f_r = cfg.scf_offset_cells * map_resolution_m
        return cls(
            cost, bool(cfg.remove_bias), n_min, bool(cfg.aiding),
            bool(cfg.position_loops), cfg.loop_order == "speed_first",
            int(cfg.scf_points), float(cfg.symmetry_ratio_max), int(cfg.break_iteration), discriminator,
            mitigation, float(f_r), float(cfg.sample_period_s),
            max(f_r / (cfg.transect_samples * cfg.sample_period_s), float(speed_set.max())),
            np.sort(speed_set)[::-1].copy(), float(cfg.speed_threshold_mps),
            float(cfg.speed_narrow_spacing_mps), float(cfg.speed_narrow_threshold_mps),
            np.sort(heading_set)[::-1].copy(),
            math.radians(cfg.heading_threshold_deg), math.radians(cfg.heading_narrow_spacing_deg),
            math.radians(cfg.heading_narrow_threshold_deg),
            float(max(cfg.scf_offset_cells * map_resolution_m, float(position_set.max()))),
            np.sort(position_set)[::-1].copy(), float(cfg.position_threshold_m),
            float(cfg.position_narrow_spacing_cells * map_resolution_m),
            float(cfg.position_narrow_threshold_m),
        )  # fmt: skip


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
