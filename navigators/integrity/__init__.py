"""Integrity monitoring beside and inside the navigators.

dem_monitor          `DemIntegrityMonitor`: the terrain-database integrity monitor of seed 003 (eqs 1-5)
innovation_monitor   `InnovationMonitor`: sliding-window normalised innovation statistic for any navigator
"""

from .dem_monitor import DemIntegrityMonitor, DemMonitorConfig, MonitorOutput
from .innovation_monitor import InnovationMonitor

__all__ = ["DemIntegrityMonitor", "DemMonitorConfig", "InnovationMonitor", "MonitorOutput"]
