"""`trn-env scenarios`, `trn-env navigators` and `trn-env validate`: what there is, and whether a scenario
file is valid."""

from __future__ import annotations

import json
import sys

from trn_env.cli.common import scenario_from_args


def cmd_scenarios() -> int:
    from trn_env.scenario.loading import list_scenarios
    rows = list_scenarios()
    width = max(len(n) for n, _ in rows) if rows else 0
    for name, desc in rows:
        print(f"{name:<{width}}  {desc}")
    return 0


def cmd_navigators(args) -> int:
    """Every navigator and monitor (or the NAMEs given) with its origin and settings; a plug-in that cannot
    be loaded is reported (exit 2) and the others are still listed."""
    from trn_env.navigators import catalogue, registry
    wanted = [(n, None) for n in args.names] or (
        [(n, "navigator") for n in registry.available()]
        + [(n, "monitor") for n in registry.available_monitors()])
    entries, errors = [], []
    for name, kind in wanted:
        plugin, err = None, None
        for k in ([kind] if kind else ["navigator", "monitor"]):
            try:
                plugin = registry.resolve(name, k)
                break
            except registry.PluginError as exc:
                err = str(exc)
                break
            except ValueError as exc:
                err = err or str(exc)
        if plugin is None:
            errors.append(err)
            continue
        origin = {"built-in": "built-in", "registered": "registered in this process",
                  "reference": f"reference {plugin.reference}"}.get(
            plugin.origin, f"plug-in {plugin.distribution or ''} ({plugin.reference})".replace("  ", " "))
        entries.append({"name": name, "kind": plugin.kind, "origin": origin,
                        "summary": catalogue.summary_of(plugin.factory),
                        "settings": [s.as_dict() for s in catalogue.settings_of(plugin.factory)]})
    # the settings registry.create takes for every navigator besides its own (the published protection level)
    common = ([s.as_dict() for s in catalogue.settings_of(registry.PublishedIntegritySettings)]
              if any(e["kind"] == "navigator" for e in entries) else [])
    if args.json:
        print(json.dumps({"plugins": entries, "every_navigator_settings": common, "errors": errors},
                         indent=2))
    else:
        from rich.console import Console
        from rich.table import Table
        console = Console(width=max(Console().width, 140))
        for e in entries:
            table = Table(title=f"{e['kind']} {e['name']}  [{e['origin']}]\n{e['summary']}",
                          title_justify="left")
            for col in ("setting", "type", "unit", "default", "meaning"):
                table.add_column(col, overflow="fold")
            for s in e["settings"]:
                table.add_row(s["name"], s["type"], s["unit"], s["default"], s["meaning"])
            console.print(table)
        if common:
            table = Table(title="every navigator also takes (its published protection level)",
                          title_justify="left")
            for col in ("setting", "type", "unit", "default", "meaning"):
                table.add_column(col, overflow="fold")
            for s in common:
                table.add_row(s["name"], s["type"], s["unit"], s["default"], s["meaning"])
            console.print(table)
    for err in errors:
        print(f"error: {err}", file=sys.stderr)
    return 2 if errors else 0


def cmd_validate(args) -> int:
    sc = scenario_from_args(args)
    if sc is None:
        return 2
    print(f"{sc.source}: ok (scenario {sc.name!r}, navigator {sc.navigator_name}, seed {sc.seed}, "
          f"time limit {sc.duration_s:g} s)")
    return 0
