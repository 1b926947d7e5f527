"""Scenario stage: scenario files, their validation, and the components built from them.

loading   read a TOML scenario (built-in name or path), validate it (every problem by field path), `Scenario`
build     the flight, sensors, maps, navigator and guidance a scenario describes
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

__all__ = ["Scenario", "ScenarioError", "builtin_names", "list_scenarios", "load_scenario",
           "read_scenario_file", "validate"]
