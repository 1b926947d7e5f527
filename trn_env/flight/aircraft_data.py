"""Where the JSBSim aircraft data lives, and a bare FGFDMExec loaded with it.

The data is installed as the package `trn_env.aircraft` (mapped from the repository's top-level
aircraft/ folder), so it is found from any working directory; a source checkout falls back to the
repository folder.
"""

from __future__ import annotations

from pathlib import Path

import jsbsim


def aircraft_root() -> Path:
    """Folder holding one sub-folder per aircraft (e.g. kingair/kingair.xml)."""
    here = Path(__file__).resolve().parent.parent   # the trn_env package folder
    for root in (here / "aircraft", here.parent / "aircraft"):   # installed package, then source checkout
        if root.is_dir() and any(root.glob("*/*.xml")):
            return root
    raise FileNotFoundError(f"trn-env aircraft data not found next to {here}: reinstall (pip install .)")


# Published service ceilings (m MSL) of the aircraft the data models: King Air C90-class 30,000 ft (POH).
SERVICE_CEILING_M = {"kingair": 9144.0}


def service_ceiling_m(aircraft: str) -> float | None:
    """The aircraft's service ceiling in m MSL (None when not known)."""
    return SERVICE_CEILING_M.get(aircraft)


def available_aircraft() -> list[str]:
    root = aircraft_root()
    return sorted(p.name for p in root.iterdir() if (p / f"{p.name}.xml").is_file())


def new_fdm(aircraft: str = "kingair", dt_s: float = 0.01) -> jsbsim.FGFDMExec:
    """An FGFDMExec with `aircraft` loaded and its integration step set; no initial condition applied."""
    known = available_aircraft()
    if aircraft not in known:
        raise ValueError(f"unknown aircraft {aircraft!r}; available: {', '.join(known) or 'none'}")
    root = aircraft_root()
    fdm = jsbsim.FGFDMExec(str(root), None)
    fdm.set_debug_level(0)
    fdm.set_aircraft_path(str(root))
    fdm.set_engine_path(str(root / aircraft / "Engines"))
    fdm.set_systems_path(str(root / aircraft / "Systems"))
    if not fdm.load_model(aircraft):
        raise RuntimeError(f"JSBSim could not load aircraft {aircraft!r} from {root / aircraft}")
    fdm.set_dt(dt_s)
    return fdm
