"""Scenario stage: scenario files, their validation, and the components built from them.

loading   read a TOML scenario (built-in name or path), validate it (every problem by field path), `Scenario`
sections  the validated scenario as typed, frozen sections (`Scenario.route`, `.sensors.imu`, ...), to_dict
build     the flight, sensors, maps, navigator and guidance a scenario's sections describe
schema.json  the scenario JSON schema; builtin/  the built-in scenario files
"""

from trn_env.scenario.loading import (
    Scenario,
    ScenarioError,
    builtin_names,
    list_scenarios,
    load_scenario,
    read_scenario_file,
    validate,
)
from trn_env.scenario.sections import ScenarioSections, SectionsError

__all__ = ["Scenario", "ScenarioError", "ScenarioSections", "SectionsError", "builtin_names",
           "list_scenarios", "load_scenario", "read_scenario_file", "validate"]
