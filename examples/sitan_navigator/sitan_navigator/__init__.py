"""A template trn-env plug-in: the SITAN-style radar-altimeter EKF navigator (`sitan`).

Installed (`pip install ./examples/sitan_navigator`), its entry point in the group `trn_env.navigators`
makes the name `sitan` work wherever trn-env accepts a navigator name; without installing,
`sitan_navigator:SitanNavigator` works as a reference when the package is importable.
"""

from sitan_navigator.navigator import SitanNavigator, SitanSettings

__all__ = ["SitanNavigator", "SitanSettings"]
