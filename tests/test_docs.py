"""The documentation: generated references cover every CLI option, scenario field, navigator setting and
output field; the site builds with Sphinx with warnings as errors and its internal links resolve; the
commands it gives (`trn-env ...`, `python scripts/...`, `python -c "..."`) parse and name what exists.
The guide's Python examples run in tests/test_docs_examples.py."""

from __future__ import annotations

import argparse
import copy
import importlib.util
import json
import re
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import pytest
from _child_processes import NEUTRAL_CWD

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


def _doc_pages() -> list[Path]:
    """Every Markdown page of the docs (the build folder aside) and the README."""
    return [p for p in sorted(DOCS.rglob("*.md")) if "_build" not in p.parts] + [ROOT / "README.md"]


def _reference():
    path = DOCS / "_ext" / "trn_reference.py"
    if not path.is_file():
        pytest.skip("docs/ is not in this checkout")
    spec = importlib.util.spec_from_file_location("trn_reference", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_cli_reference_lists_every_subcommand_and_option():
    ref = _reference()
    page = ref.cli_markdown()
    parser = ref.cli_parser()
    subs = ref._subparsers(parser)
    assert len(subs) >= 8
    for name, sub in subs.items():
        assert f"## `trn-env {name}`" in page, name
        for action in sub._actions:
            if action.dest == "help":
                continue
            for opt in action.option_strings or [action.dest]:
                assert f"`{opt}" in page, f"trn-env {name} {opt} missing from the CLI reference"
    assert isinstance(parser, argparse.ArgumentParser)


def test_scenario_reference_lists_every_schema_field_with_a_meaning():
    ref = _reference()
    page = ref.scenario_markdown()
    fields = ref.scenario_fields()
    assert len(fields) > 100
    for row in fields:
        assert f"| `{row['path']}` |" in page, row["path"]
    # an independent walk of the schema file: every property name appears somewhere in the page
    schema = json.loads((ROOT / "trn_env" / "scenario" / "schema.json").read_text())

    def names(node):
        if isinstance(node, dict):
            for k, v in node.get("properties", {}).items():
                yield k
                yield from names(v)
            for v in node.values():
                if isinstance(v, (dict, list)):
                    yield from names(v)
        elif isinstance(node, list):
            for v in node:
                yield from names(v)

    # the sections generated from the components' settings (sensors.*, monitors.*, navigator.settings per
    # navigator) are listed on the settings reference instead
    generated = copy.deepcopy(schema)
    generated_props = generated["properties"]
    tables = (list(generated_props.pop("sensors")["properties"].values())
              + list(generated_props.pop("monitors")["properties"].values())
              + [b["then"]["properties"]["settings"] for b in generated_props["navigator"].pop("allOf", [])])
    # a table's keys besides its component's settings: preset switches and the navigator's runtime map and
    # published-integrity arguments (on the scenario and navigators pages)
    extras = {"grade", "noise_free", "dem", "integrity_risk", "map_horizontal_sigma_m"}
    settings_names = {k for t in tables for k in t["properties"]} - extras
    missing = sorted({n for n in names(generated) if not re.search(rf"[.`]{re.escape(n)}` \|", page)})
    assert missing == [], missing
    settings_page = ref.settings_markdown()
    missing = sorted(n for n in settings_names if f"| `{n}` |" not in settings_page)
    assert missing == [], missing
    undescribed = [row["path"] for row in fields if not row["description"]]
    assert undescribed == [], f"schema fields without a description: {undescribed}"


def test_campaign_reference_lists_every_key_of_both_campaign_files_with_a_meaning():
    """The campaign file's page against an independent walk of both schemas: every key path appears in its
    section, with a description; and the keys the loaders read (the schemas' top-level properties) are
    exactly what they accept."""
    from trn_env.campaign.log_replay import LOG_SCHEMA
    from trn_env.campaign.spec import SCHEMA

    page = _reference().campaign_markdown()
    flights, logs = page.split("## Sensor logs")

    def paths(node, prefix=""):
        node = dict(node)
        for alt in node.get("oneOf", []):
            if "properties" in alt:
                node = alt
        if node.get("type") == "array" and isinstance(node.get("items"), dict):
            yield from paths(node["items"], prefix + "[]")
            return
        for k, v in node.get("properties", {}).items():
            yield f"{prefix}.{k}" if prefix else k, v
            yield from paths(v, f"{prefix}.{k}" if prefix else k)

    for schema, section in ((SCHEMA, flights), (LOG_SCHEMA, logs)):
        found = list(paths(schema))
        assert len(found) >= 20
        for path, node in found:
            row = next((ln for ln in section.splitlines() if ln.startswith(f"| `{path}` |")), None)
            assert row is not None, path
            assert node.get("description") and row.rstrip(" |").endswith(
                node["description"].replace("|", "\\|")[-20:]), path
    assert "`campaigns/<name>-<UTC time>`" in page and "1,000,000 runs" in page


def test_settings_reference_lists_every_navigator_and_monitor_setting():
    from trn_env.navigators import registry

    ref = _reference()
    page = ref.settings_markdown()
    for name in registry.available():
        assert f"## navigator `{name}`" in page, name
    for name in registry.available_monitors():
        assert f"## monitor `{name}`" in page, name
    common = page.split("## every navigator", 1)[1].split("\n## ", 1)[0]    # what create takes for all
    for name in registry.PUBLISHED_INTEGRITY_KEYS:
        assert f"| `{name}` |" in common, name
    # the pmf's code is the independent source: every setting its constructors read (`s.<name>` with
    # s = self.settings, and the names `s.copy_to(self, "a b ...")` copies, in pmf.py and its base
    # terrain_filter.py) must be in the page
    read = set()
    for mod in ("pmf", "terrain_filter"):
        text = (ROOT / "navigators" / "filters" / f"{mod}.py").read_text()
        read |= set(re.findall(r"\bs\.([a-z][a-z0-9_]*)\b", text)) - {"copy_to"}
        for call in re.findall(r"\bs\.copy_to\(self,((?:\s*\"[^\"]*\")+)\)", text):
            read |= set(" ".join(re.findall(r'"([^"]*)"', call)).split())
    assert len(read) > 20, sorted(read)
    for name in sorted(read):
        assert f"| `{name}` |" in page, f"pmf setting {name} missing from the settings reference"


def test_settings_reference_has_every_field_of_every_settings_class():
    import dataclasses

    from trn_env.navigators import registry

    from trn_env.sensors.suite import SENSOR_MODELS

    page = _reference().settings_markdown()
    classes = [(f"navigator `{n}`", registry.settings_class(n)) for n in registry.available()]
    classes += [(f"monitor `{n}`", registry.monitor_settings_class(n)) for n in registry.available_monitors()]
    classes += [(f"sensor `{n}`", m.config_cls) for n, m in SENSOR_MODELS.items()]
    assert len(classes) >= 14
    for title, cls in classes:
        assert f"## {title}" in page, title
        if cls is None or not dataclasses.is_dataclass(cls):
            continue
        section = page.split(f"## {title}", 1)[1].split("\n## ", 1)[0]
        for f in dataclasses.fields(cls):
            if not f.name.startswith("_"):
                assert f"| `{f.name}` |" in section, f"{title}: setting {f.name} missing from the reference"


def test_every_summary_field_of_a_real_flight_is_documented(tmp_path):
    from trn_env import cli
    from trn_env.output.fields import SUMMARY_FIELDS, undocumented

    out = tmp_path / "run"
    assert cli.main(["fly", "--duration", "12", "--no-plots", "--quiet", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert undocumented(summary, SUMMARY_FIELDS) == []
    page = _reference().outputs_markdown()
    for key in summary:
        if key in SUMMARY_FIELDS:
            assert f"| `{key}` |" in page


class _Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.links: list[str] = []

    def handle_starttag(self, tag, attrs):
        for k, v in attrs:
            if (tag, k) in (("a", "href"), ("img", "src")) and v:
                self.links.append(v)


@pytest.mark.slow
def test_docs_build_with_warnings_as_errors_and_internal_links_resolve(tmp_path):
    pytest.importorskip("sphinx")
    out = tmp_path / "html"
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-E", "-W", "--keep-going", "-q", "-b", "html",
                           "-d", str(tmp_path / "doctrees"), str(DOCS), str(out)],
                          capture_output=True, text=True, timeout=1200,
                          cwd=NEUTRAL_CWD)   # the gallery flies, and autodoc reads, the installed trn_env
    assert proc.returncode == 0, proc.stderr[-4000:]
    pages = list(out.rglob("*.html"))
    assert len(pages) > 20
    broken = []
    for page in pages:
        parser = _Links()
        parser.feed(page.read_text(encoding="utf-8"))
        for link in parser.links:
            if re.match(r"^[a-z]+:", link) or link.startswith("#"):
                continue
            target = (page.parent / link.split("#")[0]).resolve()
            if link.split("#")[0] and not target.exists():
                broken.append(f"{page.relative_to(out)} -> {link}")
    assert broken == [], broken[:20]
    for name in ("reference/cli.html", "reference/scenario.html", "reference/settings.html",
                 "reference/outputs.html", "reference/env.html", "gallery/index.html"):
        assert (out / name).is_file(), name


def test_every_documented_command_line_parses():
    """Every `trn-env ...` line in a code block of the docs and the README (synopses with [...] aside) is
    accepted by the CLI's own parser: no documented option is misspelt, renamed or gone. A one-letter
    placeholder value (`--seed S`) stands for a number."""
    from trn_env.cli.parser import _parser

    checked, bad = 0, []
    for where, command, argv in _documented_cli_lines():
        if {"--help", "-h", "--version"} & set(argv):
            continue
        checked += 1
        try:
            _parser().parse_args(argv)
        except SystemExit:
            bad.append(f"{where}: {command}")
    assert checked >= 38 and bad == [], bad


def _documented_cli_lines() -> list[tuple[str, str, list[str]]]:
    """(page:line, command, argv) of every `trn-env ...` line in a code block of the docs and the README
    (synopses with [...] aside; `&&` and `;` split a line; a leading VAR=value is dropped). A one-letter
    placeholder value (`--seed S`) becomes "1"."""
    import shlex

    files = _doc_pages()
    found = []
    for path in files:
        fence = False
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if line.strip().startswith("```"):
                fence = not fence
                continue
            for part in re.split(r"&&|;", line) if fence else ():
                command = re.sub(r"^(?:[A-Z_][A-Z0-9_]*=\S*\s+)+", "", part.strip())   # PYTHONPATH=. trn-env
                if not command.startswith("trn-env ") or "[" in command:
                    continue
                words = shlex.split(command, comments=True)[1:]
                argv = ["1" if re.fullmatch(r"[A-Z]", a) else a for a in words]
                found.append((f"{path.relative_to(ROOT)}:{number}", command, argv))
    return found


_SCRIPT_ARGV_CHECK = r'''
import argparse, io, json, runpy, sys, contextlib

class Parsed(Exception):
    pass

original = argparse.ArgumentParser.parse_args

def parse_then_stop(self, *args, **kwargs):
    original(self, *args, **kwargs)
    raise Parsed

argparse.ArgumentParser.parse_args = parse_then_stop
results = []
for path, argv in json.loads(sys.stdin.read()):
    sys.argv = [path] + argv
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            runpy.run_path(path, run_name="__main__")
        results.append([path, argv, "ran to the end without parsing its arguments"])
    except Parsed:
        results.append([path, argv, None])
    except SystemExit as exc:
        results.append([path, argv, f"exit {exc.code}: {err.getvalue().strip()[-300:]}"])
    except Exception as exc:
        results.append([path, argv, f"{type(exc).__name__}: {exc}"])
print(json.dumps(results))
'''


def _documented_script_commands() -> list[tuple[str, list[str], str]]:
    """(script path, argv, where) of every `python scripts/NAME.py ...` in the docs and the README: fenced
    blocks (backslash continuations joined) and inline code; scripts that parse with argparse only."""
    import shlex

    files = _doc_pages()
    found = []
    for path in files:
        text = path.read_text(encoding="utf-8")
        blocks = re.findall(r"```[^\n]*\n(.*?)```", text, re.S)
        lines = [ln for b in blocks for ln in b.replace("\\\n", " ").splitlines()]
        lines += re.findall(r"`([^`\n]*python scripts/[^`\n]*)`", text)
        for line in lines:
            m = re.search(r"python (scripts/\w+\.py)((?:\s+[^#|;&]*)?)", line)
            if not m:
                continue
            script = ROOT / m.group(1)
            if not script.is_file() or "ArgumentParser" not in script.read_text(encoding="utf-8"):
                continue
            if re.search(r"\$\(|\.\.\.", m.group(2)):     # a shell substitution, an elided synopsis
                continue
            # an optional part [--opt V] as given, a <placeholder> as a word
            argv = shlex.split(re.sub(r"<[^>]*>", "X", m.group(2)).replace("[", " ").replace("]", " "))
            found.append((str(script), argv, f"{path.relative_to(ROOT)}: {line.strip()}"))
    return found


def test_every_documented_script_command_parses():
    """Every `python scripts/X.py ...` the docs give is accepted by that script's own argument parser (run up
    to its parse_args, in one child process): no option is misspelt, renamed or gone. Placeholders (OUT,
    DIR, N) are taken as the strings they are."""
    commands = _documented_script_commands()
    assert len(commands) >= 40
    unique = sorted({(s, tuple(a)): w for s, a, w in commands}.items())
    payload = json.dumps([[s, list(a)] for (s, a), _ in unique])
    child = subprocess.run([sys.executable, "-c", _SCRIPT_ARGV_CHECK], input=payload, capture_output=True,
                           text=True, timeout=600, cwd=NEUTRAL_CWD)
    assert child.returncode == 0, child.stderr[-2000:]
    results = json.loads(child.stdout.strip().splitlines()[-1])
    bad = [f"{where}\n    -> {problem}"
           for ((_, _), where), (_, _, problem) in zip(unique, results, strict=True) if problem is not None]
    assert bad == [], "\n".join(bad)


def _documented_python_c_commands() -> list[tuple[str, str]]:
    """(source, where) of every `python -c "..."` the docs and the README give, inline or in a fenced block
    (backslash continuations and a command broken over lines joined)."""
    files = _doc_pages()
    found = []
    for path in files:
        text = path.read_text(encoding="utf-8").replace("\\\n", " ")
        for m in re.finditer(r'python -c "([^"]*)"', text):
            source = re.sub(r"\s*\n\s*", " ", m.group(1))
            found.append((source, f"{path.relative_to(ROOT)}: python -c \"{source[:80]}...\""))
    return found


def test_every_documented_python_c_command_compiles_and_its_imports_resolve():
    """Every `python -c "..."` the docs give (the validation pages' regeneration commands) is valid Python
    whose imports name modules and attributes that exist now: a renamed function leaves no stale command."""
    import ast
    import importlib

    commands = _documented_python_c_commands()
    assert len(commands) >= 5
    bad = []
    for source, where in commands:
        try:
            tree = ast.parse(source)
        except SyntaxError as exc:
            bad.append(f"{where}\n    -> {exc}")
            continue
        for node in ast.walk(tree):     # (tests/ is on the path here, as the commands that use it put it)
            try:
                if isinstance(node, ast.Import):
                    for alias in node.names:
                        importlib.import_module(alias.name)
                elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                    module = importlib.import_module(node.module)
                    for alias in node.names:
                        if not hasattr(module, alias.name):
                            try:
                                importlib.import_module(f"{node.module}.{alias.name}")
                            except ImportError:
                                raise ImportError(f"{node.module} has no {alias.name}") from None
            except ImportError as exc:
                bad.append(f"{where}\n    -> {type(exc).__name__}: {exc}")
    assert bad == [], "\n".join(bad)


# Paths the docs name that are deliberately not in this tree, with why.
_NOT_IN_THIS_TREE = {
    "navigators/filters/pf_accel_error.py": "a rejected experiment, named on its branch commit",
    "examples/random_agent.py": "the gymnasium-jsbsim package's own example",
}


def test_every_repository_path_the_docs_name_exists():
    """Every `tests/...`, `scripts/...`, `examples/...`, `docs/...` or package path (a file with its
    extension) in the docs and the README names a file of this tree: a file moved or renamed leaves no
    stale reference for a reader to chase."""
    files = _doc_pages()
    pattern = re.compile(r"\b((?:tests|scripts|examples|docs|trn_env|navigators|terrain|aircraft)/"
                         r"[A-Za-z0-9_./-]+\.(?:py|toml|json|md|xml|yml|yaml|png|csv))\b")
    missing = sorted({f"{path.relative_to(ROOT)}: {m}" for path in files
                      for m in pattern.findall(path.read_text(encoding="utf-8"))
                      if not (ROOT / m).exists() and m not in _NOT_IN_THIS_TREE})
    assert len(files) > 20
    assert missing == [], missing
    assert all(not (ROOT / p).exists() for p in _NOT_IN_THIS_TREE)     # the list holds only what is absent


# Dotted names in the docs' code spans that are not Python references, with what they are.
_NOT_PYTHON_NAMES = {"trn_env.monitors": "the entry-point group of monitors"}


def _is_scenario_field(name: str, schema: dict) -> bool:
    node = schema
    for part in name.split("."):
        props = node.get("properties") if isinstance(node, dict) else None
        if not props or part not in props:
            return False
        node = props[part]
    return True


def test_every_python_name_the_docs_give_resolves():
    """Every dotted `trn_env.x.y`, `navigators.x.y` or `terrain.x.y` in a code span of the docs and the
    README (the source tree's `navigators` and `terrain` are installed under trn_env) names a module,
    class, function or constant that exists: a renamed or moved function leaves no stale reference.
    Scenario field paths (`terrain.map.error_model`) are not Python names and are left out."""
    import importlib

    from trn_env.scenario.validation import schema

    scenario = schema()
    files = _doc_pages()
    names: dict[str, str] = {}
    for path in files:
        for span in re.findall(r"`([^`\n]+)`", path.read_text(encoding="utf-8")):
            for name in re.findall(r"(?<![\w./-])((?:trn_env|navigators|terrain)(?:\.[A-Za-z_]\w*)+)", span):
                names.setdefault(name, str(path.relative_to(ROOT)))

    def resolves(name: str) -> bool:
        parts = (name if name.startswith("trn_env.") else f"trn_env.{name}").split(".")
        for i in range(len(parts), 1, -1):
            try:
                obj = importlib.import_module(".".join(parts[:i]))
            except ModuleNotFoundError as exc:
                if exc.name and exc.name.split(".")[0] != "trn_env":
                    return True     # the module exists but needs an extra not installed here (CI has them)
                continue
            except ImportError:
                continue
            try:
                for attr in parts[i:]:
                    obj = getattr(obj, attr)
            except AttributeError:
                return False
            return True
        return False

    assert len(names) > 100
    bad = [f"{where}: {name}" for name, where in sorted(names.items())
           if name not in _NOT_PYTHON_NAMES and not _is_scenario_field(name, scenario) and not resolves(name)]
    assert bad == [], bad


def test_every_documented_flight_command_names_a_valid_scenario(tmp_path, monkeypatch):
    """Every `trn-env fly | record | validate SCENARIO ...` line in the docs and the README, with a built-in
    scenario or a file of this tree, passes `trn-env validate` with the same --seed, --navigator,
    --duration and --set: the command is accepted, not just parsed (a --set path that moved, a navigator
    renamed, a value the schema refuses). Placeholders (`--navigator NAME`, `my_package.nav:...`) are
    left out; a module a page writes out (a ```python block opening with `# NAME.py`) is put on the path."""
    import contextlib
    import io

    from trn_env.cli import main
    from trn_env.cli.parser import _parser
    from trn_env.scenario.loading import builtin_names

    files = _doc_pages()
    for path in files:                   # the modules the pages write out, for `--navigator module:Name`
        for block in re.findall(r"```python\n(.*?)```", path.read_text(encoding="utf-8"), re.S):
            m = re.match(r"# (\w+)\.py\n", block)
            if m:
                (tmp_path / f"{m.group(1)}.py").write_text(block, encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    commands = {command: (where, _parser().parse_args(argv))
                for where, command, argv in _documented_cli_lines()
                if argv and argv[0] in ("fly", "record", "validate") and not {"-h", "--help"} & {*argv}}
    checked, bad = 0, []
    for command, (where, ns) in sorted(commands.items()):
        scenario = ns.scenario
        if scenario not in builtin_names():
            if not (ROOT / scenario).is_file():
                continue                                         # my.toml, a user's file
            scenario = str(ROOT / scenario)
        if ns.navigator and (re.fullmatch(r"[A-Z_]+", ns.navigator) or ns.navigator.startswith("my_")):
            continue                                             # a placeholder
        argv = ["validate", scenario]
        for option in ("seed", "navigator", "duration"):
            if getattr(ns, option, None) is not None:
                argv += [f"--{option}", str(getattr(ns, option))]
        for assignment in getattr(ns, "set", None) or []:
            argv += ["--set", assignment]
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            rc = main(argv)
        checked += 1
        if rc != 0:
            bad.append(f"{where}: {command}\n    -> {err.getvalue().strip()[-400:]}")
    assert checked >= 12 and bad == [], "\n".join(bad)


def test_the_ci_workflow_example_is_sound():
    """examples/ci/trn-env-regression.yml (shown in the CI guide): every `trn-env ...` line of its steps
    parses, and no env value starts with `~` (GitHub does not expand it, numba takes NUMBA_CACHE_DIR
    literally, so the kernels would land in a folder named `~` that the cache step never saves)."""
    import shlex

    yaml = pytest.importorskip("yaml")
    from trn_env.cli.parser import _parser

    path = ROOT / "examples" / "ci" / "trn-env-regression.yml"
    if not path.is_file():
        pytest.skip("examples/ is not in this checkout")
    steps = yaml.safe_load(path.read_text(encoding="utf-8"))["jobs"]["gate"]["steps"]
    envs = [(s.get("name"), k, v) for s in steps for k, v in (s.get("env") or {}).items()]
    assert [e for e in envs if str(e[2]).startswith("~")] == []
    commands = [line.strip() for s in steps for line in str(s.get("run", "")).splitlines()
                if line.strip().startswith("trn-env ")]
    assert len(commands) >= 3
    for command in commands:
        _parser().parse_args(shlex.split(command, comments=True)[1:])
    assert any("NUMBA_CACHE_DIR=$HOME/" in str(s.get("run", "")) and "GITHUB_ENV" in str(s.get("run", ""))
               for s in steps)
