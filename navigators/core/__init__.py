"""Parts the navigators compose instead of rewriting: named error-state indexes, the IMU specification
record and its INS error model, the map record the terrain kernels take, the resampler, the
integrity-recovery policy and the INS + GNSS block; the settings field helper (settings.py), what a
component declares about itself (capabilities.py) and the on-disk cache of costly computed results
(disk_cache.py)."""
