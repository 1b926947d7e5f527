"""The resolved scenario as a TOML file: what a run actually flew, so the run replays from its folder alone.

`resolved_toml(scenario)` writes the validated scenario (its typed sections' `to_dict()`: command-line
overrides such as `--seed`, `--navigator`, `--duration` and `--set` applied, every default filled in, DEM
paths made absolute) as a TOML document that `load_scenario` reads back into the same scenario:
`trn-env fly RUN/scenario.toml` flies the same run bit for bit (the seed is in the file).

Tables are written as `[table]` / `[[array.of.tables]]` sections; a list that mixes tables with other values,
and an empty table, are written inline. Floats use `repr`, which round-trips exactly.
"""

from __future__ import annotations

import re
from typing import Any

from trn_env.scenario.overrides import toml_value

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: Any) -> str:
    import json
    k = str(k)
    return k if _BARE_KEY.match(k) else json.dumps(k)


def _is_table_list(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def _emit(table: dict, path: list[str], lines: list[str]) -> None:
    """`key = value` lines of `table`'s plain values, then its sub-tables and arrays of tables."""
    for k, v in table.items():
        if isinstance(v, dict) and v:
            continue
        if _is_table_list(v):
            continue
        lines.append(f"{_key(k)} = {toml_value(v)}")
    for k, v in table.items():
        sub = path + [_key(k)]
        if isinstance(v, dict) and v:
            lines += ["", f"[{'.'.join(sub)}]"]
            _emit(v, sub, lines)
        elif _is_table_list(v):
            for item in v:
                lines += ["", f"[[{'.'.join(sub)}]]"]
                _emit(item, sub, lines)


def dumps(data: dict, header: str = "") -> str:
    """`data` (a parsed scenario) as TOML text; `header` lines become leading comments."""
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    _emit(data, [], lines)
    return "\n".join(lines).lstrip("\n") + "\n"


def resolved_toml(scenario, command_line: str = "") -> str:
    """The validated `scenario` as a replayable TOML file (header: where it came from and how it was run)."""
    from trn_env import __version__
    header = (f"Resolved scenario of one run (trn-env {__version__}): the file as flown, overrides applied "
              f"and defaults filled in.\nSource: {scenario.source}\n"
              + (f"Command: {command_line}\n" if command_line else "")
              + "Replay: trn-env fly scenario.toml --out OTHER_FOLDER")
    return dumps(scenario.to_dict(), header)
