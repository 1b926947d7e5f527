"""Navigator registry: `create(name, **settings)` and `available()`.

"ins"          strapdown INS + barometer, no terrain aiding (navigators.filters.InsTrnNavigator)
"acq_track"    the GPS-inspired acquisition-and-tracking TRN of seed 001
               (navigators.acquisition_tracking.AcqTrackNavigator; settings: AcqTrackConfig's fields)
"ins_tercom"   INS + batch TERCOM (IRA by default, aiding="radar_altimeter" for eq 1) + 13-state EKF;
               needs dem= (terrain.Dem or a name/path for terrain.load); formula="proposed" | ...
"rbpf"         seed 002's IRA-aided Rao-Blackwellized particle filter (navigators.filters.rbpf); needs dem=,
               takes rng=
"pmf"          point-mass filter over the INS horizontal position error (navigators.filters.pmf); dem=
"pf"           SIR particle filter over the INS error state (navigators.filters.pf); dem=, rng=

Monitors run beside a navigator on the same frames and its estimate (`create_monitor(name, **settings)`,
`available_monitors()`): "dem_integrity" is the terrain-database integrity monitor of seed 003
(navigators.integrity.dem_monitor; needs dem=, the navigator's map).

Every navigator validates its settings in its constructor and raises `ValueError` naming the setting.
`integrity_risk` (per epoch, in (0, 1), default 1e-3) and `map_horizontal_sigma_m` (the map's horizontal
error per axis, m, default 0) are taken here for every navigator: the risk its published horizontal
protection level is computed for and the map error it covers (navigators.integrity.protection_level).
A navigator that draws random numbers (particle filters) is registered with `takes_rng=True` and gets the
scenario's `navigator` random stream as `rng=` (a `numpy.random.Generator`), so one scenario seed fixes its
run bit for bit; `create(..., rng=None)` leaves it to the navigator's own documented default.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from trn_env.navigators.acquisition_tracking import AcqTrackNavigator
from trn_env.navigators.filters.ins_trn_ekf import InsTrnNavigator
from trn_env.navigators.filters.pf import ParticleFilter
from trn_env.navigators.filters.pmf import PointMassFilter
from trn_env.navigators.integrity.protection_level import configure

# name -> (factory, takes_rng)
_FACTORIES: dict[str, tuple[Callable[..., object], bool]] = {
    "ins": (lambda **kw: InsTrnNavigator(aiding=None, **kw), False),
    "ins_tercom": (lambda **kw: InsTrnNavigator(**{"aiding": "ira", **kw}), False),
    "acq_track": (AcqTrackNavigator, False),
    "pmf": (PointMassFilter, False),
    "pf": (ParticleFilter, True),
}

# navigators that take the map's error as measurement noise: trn_env's build_navigator fills their
# map_sigma_m / map_bias_sigma_m from the scenario's map error model when the settings do not give them
MAP_NOISE_AWARE: set[str] = {"pmf", "pf", "rbpf"}
# navigators that model the interpolation error of a coarse map (terrain_model_sigma_m, default "auto": from
# the map's spectrum): build_navigator gives them 0 when the scenario's map is the world itself, else
# terrain_detail_spacing_m (the calibration's finest terrain) from the world's refinement spacing
MAP_IS_WORLD_AWARE: set[str] = {"rbpf"}
# navigators whose bias priors (accel_bias_sigma_mps2, gyro_bias_sigma_rps) and bias process noise
# (q_accel_bias_mps2, q_gyro_bias_rps per epoch) build_navigator fills from the scenario's IMU error model
# (its turn-on bias and bias instability, trn_env.scenario.build.imu_bias_settings) when the settings do not
# give them
IMU_AWARE: set[str] = {"rbpf"}


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
    # every navigator's published protection level is for this per-epoch risk (protection_level)
    pl_settings = {k: settings.pop(k) for k in ("integrity_risk", "map_horizontal_sigma_m") if k in settings}
    probe = type("_Probe", (), {})()
    configure(probe, **pl_settings)            # bad values fail before the navigator is built
    try:
        nav = factory(**settings)
        if hasattr(nav, "integrity_risk"):
            configure(nav, **pl_settings)
        return nav
    except TypeError as exc:
        import re
        m = re.search(r"unexpected keyword argument '(\w+)'", str(exc))
        if m:
            raise ValueError(f"navigator {name!r}: bad settings: unknown setting '{m.group(1)}'") from exc
        raise ValueError(f"navigator {name!r}: bad settings {sorted(settings)}: {exc}") from exc


def register(name: str, factory: Callable[..., object], takes_rng: bool = False) -> None:
    """Add a navigator factory (a class or a callable taking the settings as keyword arguments)."""
    _FACTORIES[name] = (factory, takes_rng)


def _rbpf(**settings):
    from trn_env.navigators.filters.rbpf import RaoBlackwellizedPF

    return RaoBlackwellizedPF(**settings)


register("rbpf", _rbpf, takes_rng=True)


# ------------------------------------------------------------------------------------------ monitors

def _dem_integrity(**kw):
    from trn_env.navigators.integrity.dem_monitor import DemIntegrityMonitor
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
