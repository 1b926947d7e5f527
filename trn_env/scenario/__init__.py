"""Scenario stage: scenario files, their validation, and the components built from them.

loading     read a TOML scenario (built-in name or path), `Scenario`
validation  check it completely (every problem by field path), the schema with its generated sections
sections    the validated scenario as typed, frozen sections (`Scenario.route`, `.sensors.imu`, ...), to_dict
build       the flight, sensors and guidance a scenario's sections describe, the components' checks
maps        the true terrain and the navigator's map (errors, faults, information map)
navigation  the navigator's and monitors' settings and construction
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
