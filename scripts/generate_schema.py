"""Write the scenario schema's generated sections (sensors.*, monitors.*, navigator.settings per built-in
navigator) into trn_env/scenario/schema.json, from the components' Settings classes.

    python scripts/generate_schema.py          # rewrite the file
    python scripts/generate_schema.py --check  # exit 1 if the file is out of date

The loader puts the same sections in at load time (trn_env.scenario.schema_sections), so validation never
depends on this file being current; the file is for editors and the docs, and tests/test_settings.py
checks it is up to date.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from trn_env.scenario.schema_sections import with_generated_sections

SCHEMA = Path(__file__).resolve().parents[1] / "trn_env" / "scenario" / "schema.json"


def generated_text(path: Path = SCHEMA) -> str:
    return json.dumps(with_generated_sections(json.loads(path.read_text(encoding="utf-8"))), indent=2) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if the file is out of date")
    args = ap.parse_args(argv)
    text = generated_text()
    if args.check:
        current = SCHEMA.read_text(encoding="utf-8")
        print("up to date" if current == text else f"{SCHEMA} is out of date: run {__file__}")
        return 0 if current == text else 1
    SCHEMA.write_text(text, encoding="utf-8")
    print(f"wrote {SCHEMA}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
