"""Write schemas/fit_config.schema.json from the fit configuration's own field declarations.

    .venv/bin/python tools/gen_fit_config_schema.py          # rewrite the schema
    .venv/bin/python tools/gen_fit_config_schema.py --check  # exit 1 when it is stale

Types, defaults' ranges and descriptions are declared once, on the dataclass fields of
`zooctl.fit.config` (`zooctl.fit.config_spec.spec`); the same rules validate a config at run
time, so the schema cannot drift from the checks (tests/test_fit_config_schema.py).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUTPUT = REPO / "schemas" / "fit_config.schema.json"


def render() -> str:
    from zooctl.fit.config import RENAMED, FitConfig
    from zooctl.fit.config_spec import schema_of

    schema = {
        "$id": "https://zooctl.dev/schemas/fit_config.schema.json",
        "title": "zooctl fit configuration (config.json of a fit; --config files may hold any subset)",
    } | schema_of(FitConfig, RENAMED)
    schema = {"$schema": schema.pop("$schema"), **schema}
    return json.dumps(schema, indent=2) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 when the file is stale")
    args = ap.parse_args()
    text = render()
    if args.check:
        if OUTPUT.read_text() != text:
            print(f"{OUTPUT} is stale: run tools/gen_fit_config_schema.py", file=sys.stderr)
            return 1
        return 0
    OUTPUT.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
