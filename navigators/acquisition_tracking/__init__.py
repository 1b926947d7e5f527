"""The GPS-inspired acquisition-and-tracking TRN of seed 001 (a PhD thesis; condensed in thesis-spec.md).

It does not output position fixes: it acquires, then tracks, the aircraft's ground speed and track by
correlating a measured terrain profile (barometric height - radar-altimeter range) with replica profiles
from the map, and dead-reckons the position from what it tracks. One module per concept:

    settings.py      AcqTrackConfig: every named setting (the choices the thesis leaves open included)
    profile.py       the sliding transect of N samples and the measured terrain height (roll compensated)
    correlation.py   replica positions and heights, MAD / Pearson / MSD costs (numba kernels)
    footprint.py     the map as the pulse altimeter's beam sees it (grey dilation per height band)
    acquisition.py   serial search over start position x speed x heading (numba over the hypothesis grid)
    tracking.py      the two-stage early-late speed, heading and start-point loops (what they are)
    loop_kernel.py   the loops as numba kernels: SCF / HCF, adaptivity, stages, ELS; one call per epoch
    aiding.py        air-data / INS speed and heading aiding increments, wind triangle estimation
    integrity.py     terrain SNR (5 dB), V-shape flag, false lock, output moving average
    navigator.py     AcqTrackNavigator behind navigators.protocol.Navigator (registered as "acq_track")
"""

from .navigator import AcqTrackNavigator
from .settings import AcqTrackConfig

__all__ = ["AcqTrackConfig", "AcqTrackNavigator"]
