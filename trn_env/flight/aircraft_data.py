"""Where the JSBSim aircraft data lives, and a bare FGFDMExec loaded with it.

The data is installed as the package `trn_env.aircraft` (mapped from the repository's top-level
aircraft/ folder), so it is found from any working directory; a source checkout falls back to the
repository folder.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from functools import lru_cache
from pathlib import Path

import jsbsim

KG_PER_LB = 0.45359237
_KG_PER_UNIT = {"LBS": KG_PER_LB, "KG": 1.0}   # the mass units JSBSim accepts for a tank's capacity


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
    # JSBSim's debug level is one static of its base class: zero before the constructor, whose start-up
    # banner would otherwise go to the C-level stdout of whoever builds a flight (scripts, notebooks)
    jsbsim.FGJSBBase().debug_lvl = 0
    fdm = jsbsim.FGFDMExec(str(root), None)
    fdm.set_debug_level(0)
    fdm.set_aircraft_path(str(root))
    fdm.set_engine_path(str(root / aircraft / "Engines"))
    fdm.set_systems_path(str(root / aircraft / "Systems"))
    # before the model: each FCS component (the autopilot's rate limits, PIDs, filters) takes its step from
    # the executive when it is built and keeps it, so a step set only afterwards would leave them running at
    # JSBSim's default 1/120 s (at 0.02 s the 1.5 m/s^2 vertical-speed rate limit became 0.625)
    fdm.set_dt(dt_s)
    if not fdm.load_model(aircraft):
        raise RuntimeError(f"JSBSim could not load aircraft {aircraft!r} from {root / aircraft}")
    fdm.set_dt(dt_s)
    return fdm


@lru_cache(maxsize=8)
def _fuel_tanks_kg(aircraft: str) -> tuple[tuple[int, float], ...]:
    known = available_aircraft()
    if aircraft not in known:
        raise ValueError(f"unknown aircraft {aircraft!r}; available: {', '.join(known) or 'none'}")
    root = ET.parse(aircraft_root() / aircraft / f"{aircraft}.xml").getroot()
    out = []
    for index, tank in enumerate(root.iter("tank")):   # JSBSim numbers every tank, fuel or oxidizer
        if tank.get("type", "").upper() != "FUEL":
            continue
        cap = tank.find("capacity")
        if cap is None or cap.text is None:
            out.append((index, 0.0))   # JSBSim's default: a tank with no capacity holds nothing
            continue
        unit = cap.get("unit", "LBS").upper()
        if unit not in _KG_PER_UNIT:
            raise ValueError(f"{aircraft}.xml: tank capacity unit {unit!r} (expected LBS or KG)")
        out.append((index, float(cap.text) * _KG_PER_UNIT[unit]))
    return tuple(out)


def fuel_tanks_kg(aircraft: str = "kingair") -> dict[int, float]:
    """{JSBSim tank index: capacity (kg)} of every FUEL tank of `aircraft`, read from its XML file
    (`<propulsion><tank type="FUEL"><capacity unit=...>`, JSBSim's default unit LBS). ValueError for an
    unknown aircraft or a capacity unit JSBSim does not take."""
    return dict(_fuel_tanks_kg(aircraft))
