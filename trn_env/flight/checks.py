"""The one check every flight input passes: a finite number, refused with its field's name otherwise."""

from __future__ import annotations

import math
from typing import Any


def finite(field: str, value: Any) -> float:
    """value as a float; ValueError naming `field` (its full path, e.g. "wind.layers[0].speed_mps") when
    it is not a number or not finite (NaN and infinity mean nothing in a flight's inputs)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{field} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{field} must be finite, got {value!r}")
    return v
