"""Batch TERCOM: the MAD correlation surface of seed 000 eqs 1-2.

mad  `TercomBatch`, `TercomFix`, `correlate`, `mad_surface`, `MadAccumulator`, `TERCOM_THREADS`
"""

from .mad import (
    TERCOM_THREADS,
    MadAccumulator,
    TercomBatch,
    TercomFix,
    correlate,
    mad_surface,
)

__all__ = ["TERCOM_THREADS", "MadAccumulator", "TercomBatch", "TercomFix", "correlate", "mad_surface"]
