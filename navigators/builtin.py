"""The built-in navigators and monitors as plug-ins: the objects trn-env's own entry points name.

Every built-in is declared in pyproject.toml under the entry-point groups `trn_env.navigators` and
`trn_env.monitors`, exactly as a user's plug-in package declares its own, and loaded by
`navigators.registry` through the same code path (`BUILTIN_NAVIGATORS` / `BUILTIN_MONITORS` hold the same
references, so a source tree whose package metadata is stale or missing still has them; a test checks that
the two agree).

Where an entry point names a class, the class is the factory: `registry.create(name, **settings)` calls
it with the settings as keyword arguments. "ins" and "ins_tercom" are one class (`InsTrnNavigator`) with
different `aiding`, so they are factory functions here; `settings_class` tells `trn-env navigators` whose
settings to list, `fixed_settings` which of them the factory sets itself, and `capabilities` what each
declares (navigators.core.capabilities).
"""

from __future__ import annotations

from .core.settings import SettingsError
from .filters.ins_trn_ekf import InsTrnNavigator
from .filters.ins_trn_settings import (
    INS_CAPABILITIES,
    INS_TERCOM_CAPABILITIES,
    InsTercomSettings,
    InsTrnSettings,
)

# name -> "module:attribute", the same strings as pyproject.toml's [project.entry-points.*] tables
BUILTIN_NAVIGATORS: dict[str, str] = {
    "ins": "trn_env.navigators.builtin:ins",
    "ins_tercom": "trn_env.navigators.builtin:ins_tercom",
    "acq_track": "trn_env.navigators.acquisition_tracking:AcqTrackNavigator",
    "pmf": "trn_env.navigators.filters.pmf:PointMassFilter",
    "pf": "trn_env.navigators.filters.pf:ParticleFilter",
    "rbpf": "trn_env.navigators.filters.rbpf:RaoBlackwellizedPF",
}
BUILTIN_MONITORS: dict[str, str] = {
    "dem_integrity": "trn_env.navigators.integrity.dem_monitor:DemIntegrityMonitor",
}


def ins(**settings) -> InsTrnNavigator:
    """Strapdown INS + barometer (+ GNSS while available), no terrain aiding: InsTrnNavigator(aiding=None)."""
    if "aiding" in settings:
        raise SettingsError([("aiding", "navigator 'ins' has no terrain aiding (use 'ins_tercom' for TERCOM "
                                        "fixes)")])
    return InsTrnNavigator(aiding=None, **settings)


ins.settings_class = InsTrnSettings
ins.fixed_settings = {"aiding": None}
ins.capabilities = INS_CAPABILITIES


def ins_tercom(**settings) -> InsTrnNavigator:
    """INS + batch TERCOM fixes + EKF (seed 000): InsTrnNavigator with aiding="ira" unless the settings say
    aiding="radar_altimeter" (seed 000 eq 1)."""
    dem, name = settings.pop("dem", None), settings.pop("name", None)
    return InsTrnNavigator(dem=dem, settings=InsTercomSettings.from_mapping(settings), name=name)


ins_tercom.settings_class = InsTercomSettings
ins_tercom.capabilities = INS_TERCOM_CAPABILITIES
