"""Navigator registry: `create(name, **settings)` and `available()`.

"ins"          strapdown INS + barometer, no terrain aiding (navigators.ins_trn_ekf.InsTrnNavigator)
"ins_tercom"   INS + batch TERCOM (IRA by default, aiding="radar_altimeter" for eq 1) + 13-state EKF;
               needs dem= (terrain.Dem or a name/path for terrain.load); formula="proposed" | ...
"""

from __future__ import annotations

from collections.abc import Callable

from .ins_trn_ekf import InsTrnNavigator

_FACTORIES: dict[str, Callable[..., object]] = {
    "ins": lambda **kw: InsTrnNavigator(aiding=None, **kw),
    "ins_tercom": lambda **kw: InsTrnNavigator(**{"aiding": "ira", **kw}),
}


def available() -> list[str]:
    """Names accepted by create()."""
    return sorted(_FACTORIES)


def create(name: str, **settings):
    """A new navigator by name with its settings (keyword arguments of its class)."""
    if name not in _FACTORIES:
        raise ValueError(f"unknown navigator {name!r}; available: {available()}")
    try:
        return _FACTORIES[name](**settings)
    except TypeError as exc:
        raise ValueError(f"navigator {name!r}: bad settings {sorted(settings)}: {exc}") from exc


def register(name: str, factory: Callable[..., object]) -> None:
    """Add a navigator factory (later issues' navigators register here)."""
    _FACTORIES[name] = factory
