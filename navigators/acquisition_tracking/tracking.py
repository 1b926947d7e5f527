"""Early-late tracking loops (seed 001 ch. 3-4; spec section 4).

Three replicas per loop: prompt at x, early at x - s, late at x + s (s: correlator spacing; x: the speed
reference b_v in m/s or the heading reference b_psi in rad). Discriminator (spec section 4):

    eps = s (H_E - H_L) / (H_E + H_L),    x <- x + eps

(H: the costs, lower is better; early worse than late means the minimum lies toward higher x, so x grows.)
Its gain is a s / (H_min + a s) for a V of slope a over a cost floor H_min (the noise), so over noisy
profiles it creeps and the threshold stops it short of the minimum. The optional "v_fit" discriminator
eps = (s / 2)(H_E - H_L) / (max(H_E, H_L) - H_P) subtracts the floor through the prompt and is exact on a
V within +-s (our addition, setting `discriminator`).
The loop iterates within one epoch; it is in lock when consecutive estimates differ by less than its
threshold (|eps| < threshold, in the loop's own unit - m/s or deg: our reading of the thesis' unitless
thresholds, spec section 8), and it breaks at the 101st iteration (at most 100 discriminator updates) out
of lock.

Adaptivity block (each epoch, first stage only): the SCF/HCF around the prompt -> the V's bandwidth (how far
the function rises monotonically on both sides of its minimum; no rise on a side: no V-shape, out of lock)
-> the widest spacing of the stage's set that is within the bandwidth and whose symmetry ratio (larger over
smaller absolute least-squares slope of the two sides, over +-s around the minimum) is at most
`symmetry_ratio_max` (our choice 2.0, spec section 8).

Start-point (position) loops: our addition (the thesis dead-reckons the transect start; spec section 0), the
GPS receiver's code loop beside its carrier loop: the speed and heading loops stretch and turn the replica
about its start point, so they cannot move it as a whole. Two more early-late loops shift the whole replica
along and across the track (x in metres along the unit vector (u_n, u_e)) with the same discriminator; that
shift is the correlation's position fix (navigator.py fuses it).

The loops run as numba kernels (loop_kernel.py: one call per epoch for all of them); this module holds
their names and the V-shape record.
"""

from __future__ import annotations

from dataclasses import dataclass

DISC_THESIS = 0  # eps = s (H_E - H_L) / (H_E + H_L)   (spec section 4)
DISC_V_FIT = 1  # eps = (s / 2) (H_E - H_L) / (max(H_E, H_L) - H_P)
DISCRIMINATORS = {"thesis": DISC_THESIS, "v_fit": DISC_V_FIT}


@dataclass
class VShape:
    """The correlation function's shape around its minimum (the adaptivity block's analysis).

    v_shape: it rises on both sides of an interior minimum; bandwidth: the narrower side's monotone rise
    (same unit as the offsets); min_offset: where the minimum lies; slopes: least-squares slopes (cost per
    unit) left (negative when V-shaped) and right, over the whole V."""

    v_shape: bool
    bandwidth: float
    min_offset: float
    min_cost: float
    slope_left: float
    slope_right: float
