"""Navigator registry: `create(name, **settings)` and `available()`.

"ins"          strapdown INS + barometer, no terrain aiding (navigators.filters.InsTrnNavigator)
"ins_tercom"   INS + batch TERCOM (IRA by default, aiding="radar_altimeter" for eq 1) + 13-state EKF;
               needs dem= (terrain.Dem or a name/path for terrain.load); formula="proposed" | ...

Monitors run beside a navigator on the same frames and its estimate (`create_monitor(name, **settings)`,
`available_monitors()`): "dem_integrity" is the terrain-database integrity monitor of seed 003
(navigators.integrity.dem_monitor; needs dem=, the navigator's map).

Every navigator validates its settings in its constructor and raises `ValueError` naming the setting.
A navigator that draws random numbers (particle filters) is registered with `takes_rng=True` and gets the
scenario's `navigator` random stream as `rng=` (a `numpy.random.Generator`), so one scenario seed fixes its
run bit for bit; `create(..., rng=None)` leaves it to the navigator's own documented default.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from navigators.filters.ins_trn_ekf import InsTrnNavigator

# name -> (factory, takes_rng)
_FACTORIES: dict[str, tuple[Callable[..., object], bool]] = {
    "ins": (lambda **kw: InsTrnNavigator(aiding=None, **kw), False),
    "ins_tercom": (lambda **kw: InsTrnNavigator(**{"aiding": "ira", **kw}), False),
}


def available() -> list[str]:
    """Names accepted by create()."""
    return sorted(_FACTORIES)


def create(name: str, rng: np.random.Generator | None = None, **settings):
    """A new navigator by name with its settings (keyword arguments of its class); `rng` reaches only the
    navigators registered with takes_rng=True."""
    if name not in _FACTORIES:
        raise ValueError(f"unknown navigator {name!r}; available: {available()}")
    factory, takes_rng = _FACTORIES[name]
    if takes_rng:
        settings["rng"] = rng
    try:
        return factory(**settings)
    except TypeError as exc:
        import re
        m = re.search(r"unexpected keyword argument '(\w+)'", str(exc))
        if m:
            raise ValueError(f"navigator {name!r}: bad settings: unknown setting '{m.group(1)}'") from exc
        raise ValueError(f"navigator {name!r}: bad settings {sorted(settings)}: {exc}") from exc


def register(name: str, factory: Callable[..., object], takes_rng: bool = False) -> None:
    """Add a navigator factory (a class or a callable taking the settings as keyword arguments)."""
    _FACTORIES[name] = (factory, takes_rng)


# ------------------------------------------------------------------------------------------ monitors

def _dem_integrity(**kw):
    from navigators.integrity.dem_monitor import DemIntegrityMonitor
    return DemIntegrityMonitor(**kw)


_MONITORS: dict[str, Callable[..., object]] = {"dem_integrity": _dem_integrity}


def available_monitors() -> list[str]:
    """Names accepted by create_monitor()."""
    return sorted(_MONITORS)


def create_monitor(name: str, **settings):
    """A new monitor by name (it runs beside a navigator: `monitor.update(frames, estimate)`)."""
    if name not in _MONITORS:
        raise ValueError(f"unknown monitor {name!r}; available: {available_monitors()}")
    try:
        return _MONITORS[name](**settings)
    except TypeError as exc:
        raise ValueError(f"monitor {name!r}: bad settings {sorted(settings)}: {exc}") from exc


def register_monitor(name: str, factory: Callable[..., object]) -> None:
    """Add a monitor factory (keyword settings; `dem=` is the navigator's map)."""
    _MONITORS[name] = factory
