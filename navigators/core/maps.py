"""The navigator's map: where a navigator or monitor gets its terrain.Dem from its `dem` setting."""

from __future__ import annotations


def load_map(dem, who: str = "the navigator"):
    """The terrain.Dem a `dem` setting names: a Dem as given, a name or path loaded by terrain.load.

    Raises ValueError naming the setting when it is missing, cannot be loaded or is not a map.
    """
    if dem is None:
        raise ValueError(f"dem: the navigator's terrain map is required by {who}")
    if isinstance(dem, str):
        from trn_env import terrain

        try:
            dem = terrain.load(dem)
        except (OSError, ValueError) as exc:
            raise ValueError(f"dem: cannot load the navigator's map {dem!r}: {exc}") from exc
    if not hasattr(dem, "grid"):
        raise ValueError(f"dem must be a terrain.Dem or a map name, got {type(dem).__name__}")
    return dem


__all__ = ["load_map"]
