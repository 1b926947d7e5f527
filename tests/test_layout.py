"""The package layout: no import runs backwards, and every package folder is listed for the wheel.

Order (DESIGN.md "Layout"): trn_env -> navigators -> terrain; inside trn_env
cli -> bench -> campaign -> env -> logs -> sim -> scenario -> (sensors, guidance) -> (flight, output).
A module may import its own stage or a lower one; siblings on one level (sensors/guidance, flight/output)
do not import each other. Every import is read from the source (ast), lazy ones inside functions included.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parent.parent
TOP = ("trn_env", "navigators", "terrain")
TOP_RANK = {"terrain": 0, "navigators": 1, "trn_env": 2}
STAGE_RANK = {"flight": 0, "output": 0, "sensors": 1, "guidance": 1, "scenario": 2, "sim": 3, "logs": 4,
              "env": 5, "policies": 5, "campaign": 6, "bench": 7, "cli": 8}


def _modules() -> list[Path]:
    return [p for top in TOP for p in sorted((ROOT / top).rglob("*.py"))]


def _module_name(path: Path) -> str:
    """The module's name as the source folders give it (terrain/dem.py -> terrain.dem)."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _installed_name(module: str) -> str:
    """terrain/ and navigators/ install as trn_env.terrain and trn_env.navigators."""
    return f"trn_env.{module}" if module.split(".")[0] in ("terrain", "navigators") else module


def _folder_name(module: str) -> str:
    """The inverse of _installed_name: trn_env.terrain.dem -> terrain.dem (the rank of its source folder)."""
    parts = module.split(".")
    if len(parts) >= 2 and parts[0] == "trn_env" and parts[1] in ("terrain", "navigators"):
        return ".".join(parts[1:])
    return module


def _imports(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    pkg = _installed_name(_module_name(path)).split(".")
    if path.name != "__init__.py":
        pkg = pkg[:-1]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = ".".join(pkg[:len(pkg) - node.level + 1])
                mod = f"{base}.{node.module}" if node.module else base
            else:
                mod = node.module or ""
            # `from trn_env import sim` imports the stage trn_env.sim
            out += [(node.lineno, f"{mod}.{a.name}") for a in node.names]
    out = [(n, _folder_name(m)) for n, m in out]
    return [(n, m) for n, m in out if m.split(".")[0] in TOP]


def _stage(module: str) -> str | None:
    parts = module.split(".")
    if parts[0] != "trn_env" or len(parts) < 2:
        return None
    if parts[1] == "policies":          # trn_env/policies.py re-exports the env stage's policies
        return "env"
    return parts[1] if parts[1] in STAGE_RANK else None


def backward_imports() -> list[str]:
    problems = []
    for path in _modules():
        me = _module_name(path)
        my_top, my_stage = me.split(".")[0], _stage(me)
        for line, target in _imports(path):
            top = target.split(".")[0]
            where = f"{path.relative_to(ROOT)}:{line} imports {target}"
            if TOP_RANK[top] > TOP_RANK[my_top]:
                problems.append(f"{where} ({my_top} is below {top})")
                continue
            if top != "trn_env" or my_top != "trn_env" or me == "trn_env":
                continue
            stage = _stage(target)
            if my_stage is None or stage is None or stage == my_stage:
                continue
            if STAGE_RANK[stage] >= STAGE_RANK[my_stage]:
                problems.append(f"{where} (stage {my_stage} may not import stage {stage})")
    return problems


def test_no_import_runs_backwards():
    assert backward_imports() == []


def test_the_walker_sees_a_backward_import(tmp_path, monkeypatch):
    """The check itself fails on a lower stage importing a higher one (so the test above can fail)."""
    fake = tmp_path / "trn_env" / "flight"
    fake.mkdir(parents=True)
    (tmp_path / "trn_env" / "__init__.py").write_text("")
    (fake / "__init__.py").write_text("")
    (fake / "bad.py").write_text("def f():\n    from trn_env.sim import run_scenario\n")
    (tmp_path / "navigators").mkdir()
    (tmp_path / "navigators" / "x.py").write_text("import trn_env.flight\n")
    (tmp_path / "terrain").mkdir()
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    found = backward_imports()
    assert any("bad.py:2 imports trn_env.sim" in p for p in found)
    assert any("x.py:1 imports trn_env.flight" in p for p in found)


def test_every_package_folder_is_listed_for_the_wheel():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    listed = set(config["packages"])
    on_disk = {_installed_name(_module_name(p.parent / "__init__.py")) for top in TOP
               for p in (ROOT / top).rglob("*.py") if "__pycache__" not in p.parts}
    missing = sorted(on_disk - listed)
    assert not missing, f"package folders with Python files not in pyproject.toml packages: {missing}"
    for pkg in on_disk:
        folder = _folder_name(pkg).replace(".", "/")
        assert (ROOT / folder / "__init__.py").is_file(), f"{pkg} has no __init__.py"


@pytest.mark.parametrize("name", ["trn_env.sim.run_scenario", "trn_env.sim.ClosedLoop",
                                  "trn_env.flight.Flight", "trn_env.flight.InitialCondition",
                                  "trn_env.sensors.suite.SensorSuite",
                                  "trn_env.guidance.Guidance", "trn_env.scenario.load_scenario",
                                  "trn_env.env.TerrainNavEnv", "trn_env.terrain.load",
                                  "trn_env.navigators.registry.create"])
def test_public_names_keep_working(name):
    import importlib

    module, attr = name.rsplit(".", 1)
    assert callable(getattr(importlib.import_module(module), attr))


def test_nothing_installs_under_a_generic_top_level_name():
    """The wheel installs only the project's namespace at the top level (PyPI has an unrelated `terrain`)."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    tops = {p.split(".")[0] for p in config["packages"]}
    assert tops == {"trn_env"}, tops
    for generic in ("terrain", "navigators"):
        import importlib.util

        spec = importlib.util.find_spec(generic)
        assert spec is None or "trn_env" not in str(spec.origin), f"{generic} still importable from trn-env"


def test_terrain_and_navigators_import_no_trn_env_name():
    """terrain/ and navigators/ reach each other by relative imports only, so neither names the simulator's
    package: they import the same whether installed as trn_env.* or read from the checkout."""
    bad = []
    for top in ("terrain", "navigators"):
        for path in sorted((ROOT / top).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                names = ([node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0
                         else [a.name for a in node.names] if isinstance(node, ast.Import) else [])
                bad += [f"{path.relative_to(ROOT)}:{node.lineno} imports {n}" for n in names
                        if n.split(".")[0] == "trn_env"]
    assert bad == [], bad[:10]


def test_no_code_imports_the_folders_by_their_bare_names():
    """tests/, scripts/, examples/ and trn_env/ import the mapped folders as trn_env.navigators,
    trn_env.terrain and trn_env.aircraft: the bare names only resolve when the checkout's root happens to
    head sys.path (`python -m pytest` from the root), never in an installed package (CI runs `pytest`)."""
    bad = []
    for top in ("tests", "scripts", "examples", "trn_env"):
        for path in sorted((ROOT / top).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                names = ([node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0
                         else [a.name for a in node.names] if isinstance(node, ast.Import) else [])
                bad += [f"{path.relative_to(ROOT)}:{node.lineno} imports {n}" for n in names
                        if n.split(".")[0] in ("navigators", "terrain", "aircraft")]
    assert bad == [], bad[:10]


def test_tomllib_is_imported_with_the_python_3_10_fallback():
    """pyproject.toml admits Python 3.10, whose standard library has no tomllib: every import of it (the
    package, tests, scripts, examples) sits under `if sys.version_info >= (3, 11):` with tomli (declared
    for Python < 3.11) as the else branch."""
    assert 'requires-python = ">=3.10"' in (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    bad = []
    for top in ("tests", "scripts", "examples", *TOP):
        for path in sorted((ROOT / top).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            guarded = set()
            for node in ast.walk(tree):
                if (isinstance(node, ast.If) and "version_info" in ast.unparse(node.test)
                        and any(isinstance(n, ast.Import) and n.names[0].name == "tomli"
                                for n in node.orelse)):
                    guarded |= {id(n) for n in node.body}
            bad += [f"{path.relative_to(ROOT)}:{node.lineno}" for node in ast.walk(tree)
                    if isinstance(node, ast.Import) and any(a.name == "tomllib" for a in node.names)
                    and id(node) not in guarded]
            bad += [f"{path.relative_to(ROOT)}:{node.lineno}" for node in ast.walk(tree)
                    if isinstance(node, ast.ImportFrom) and node.module == "tomllib"]
    assert bad == [], bad
