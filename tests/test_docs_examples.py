"""The Python examples of the user guide and the README run as written.

Each page's ```python blocks run in order in one namespace (a page's later block may use an earlier one's
names), parsed and run by Sybil, in a fresh working folder. A block that cannot run as written (a sketch
that needs your data or a Ray cluster) is marked in the page with `<!-- skip: next "why" -->`, an HTML
comment that neither GitHub nor the docs site shows; it still has to compile. The campaign files the guide
shows (```toml blocks with a `name` and `scenarios` or `logs`) are loaded and validated as written.
"""

from __future__ import annotations

import re
import sys
import unittest
from pathlib import Path

import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

sybil = pytest.importorskip("sybil")
from sybil.parsers.myst import PythonCodeBlockParser, SkipParser  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
GUIDE = ROOT / "docs" / "guide"
PAGES = sorted(GUIDE.glob("*.md")) + [ROOT / "README.md"]
_SKIP = re.compile(r"<!-- skip: next (?P<reason>.*?) -->|^%\s*skip:", re.M)


def _pages_with_python() -> list[Path]:
    return [p for p in PAGES if p.is_file() and "```python" in p.read_text(encoding="utf-8")]


def _recorded(name: str):
    """The log a page reads, recorded as the page's own command does (shorter)."""
    def record(folder: Path) -> None:
        from trn_env.cli import main

        assert main(["record", "default", "--out", str(folder / name), "--duration", "20"]) == 0
    return record


# What a page's examples assume already exists in the working folder, made as the page says to make it.
_PREPARE = {"logs.md": _recorded("flight.trnlog"), "README.md": _recorded("flight.log")}


def _close_envs(namespace: dict) -> None:
    import gymnasium

    for value in list(namespace.values()):
        if isinstance(value, (gymnasium.Env, gymnasium.vector.VectorEnv)):
            value.close()


def test_every_page_with_python_examples_is_checked():
    """The guide has Python examples and each skip names its reason (a quoted string) in an HTML comment,
    the form GitHub's README view hides too."""
    pages = _pages_with_python()
    if not pages:
        pytest.skip("docs/ is not in this checkout")
    assert {p.name for p in pages} >= {"README.md", "first_flight.md", "fast_tier.md", "own_navigator.md"}
    for page in pages:
        for m in _SKIP.finditer(page.read_text(encoding="utf-8")):
            reason = m.group("reason")
            assert reason is not None and re.fullmatch(r'"[^"]{10,}"', reason), (page.name, m.group(0))


@pytest.mark.parametrize("page", _pages_with_python(), ids=lambda p: p.name)
def test_python_examples_run_as_written(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    if page.name in _PREPARE:
        _PREPARE[page.name](tmp_path)
    document = sybil.Sybil(parsers=[PythonCodeBlockParser(), SkipParser()]).parse(page)
    examples = list(document)
    python_blocks = [e for e in examples if isinstance(e.parsed, str)]
    assert python_blocks, page.name
    for example in python_blocks:          # skipped or not, every block is valid Python
        compile(example.parsed, f"{page.name}:{example.line}", "exec")
    ran = skipped = 0
    try:
        for example in examples:
            try:
                example.evaluate()
            except unittest.SkipTest:
                skipped += 1
                continue
            ran += isinstance(example.parsed, str)
    finally:
        _close_envs(document.namespace)
    assert ran + skipped == len(python_blocks), (page.name, ran, skipped)


def _toml_blocks(page: Path) -> list[str]:
    import textwrap
    text = page.read_text(encoding="utf-8")
    fences = re.finditer(r"^[ \t]*```toml\n(.*?)^[ \t]*```", text, re.M | re.S)    # (ci.md's are indented)
    return [textwrap.dedent(m.group(1)) for m in fences]


def _campaign_blocks() -> list[tuple[str, str]]:
    """(page, TOML text) of every campaign file the guide shows (a `name` and `scenarios` or `logs`)."""
    found = []
    for page in PAGES:
        if not page.is_file():
            continue
        for block in _toml_blocks(page):
            try:
                data = tomllib.loads(block)
            except tomllib.TOMLDecodeError:
                continue                     # a fragment with `...` or two files in one block
            if "name" in data and ("scenarios" in data or "logs" in data):
                found.append((page.name, block))
    return found


def test_the_guides_campaign_files_validate(tmp_path, monkeypatch):
    """Every campaign file the guide shows is accepted as written (every variant validated, nothing flown):
    scenario files it names are the tests' own, logs are recorded first as the logs guide does."""
    import shutil

    from trn_env.campaign.spec import load_campaign
    from trn_env.scenario.loading import builtin_names

    blocks = _campaign_blocks()
    if not blocks:
        pytest.skip("docs/ is not in this checkout")
    assert {p for p, _ in blocks} >= {"campaigns.md", "logs.md", "ci.md"}
    monkeypatch.chdir(tmp_path)
    for i, (page, block) in enumerate(blocks):
        folder = tmp_path / f"{i}"
        folder.mkdir()
        path = folder / "campaign.toml"
        path.write_text(block, encoding="utf-8")
        data = tomllib.loads(block)
        for ref in data.get("scenarios", []):
            if ref not in builtin_names():
                shutil.copy(ROOT / "tests" / "campaigns" / ref, folder / ref)
        for ref in data.get("logs", []):
            _recorded(str(Path(ref)))(folder)
        campaign = load_campaign(path)
        assert campaign.name == data["name"], page
