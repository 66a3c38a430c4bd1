"""The fit configuration's schema and its run-time checks come from one declaration per field."""

from __future__ import annotations

import copy
import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import pytest
from jsonschema import Draft202012Validator

from zooctl.errors import UsageError
from zooctl.fit.config import PRESET_NAMES, PRESETS, FitConfig, preset

REPO = Path(__file__).resolve().parents[1]
SCHEMA = json.loads((REPO / "schemas" / "fit_config.schema.json").read_text())


def test_the_schema_file_is_written_from_the_fields():
    r = subprocess.run(
        [sys.executable, "tools/gen_fit_config_schema.py", "--check"],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert tuple(PRESETS) == PRESET_NAMES


def test_every_preset_is_valid_by_the_schema():
    for name in PRESETS:
        Draft202012Validator(SCHEMA).validate(preset(name).to_dict())


BAD = [-1, 0, 0.5, 2, 1e9, -1e9, float("nan"), True, "x", "", None, [], [1.0], ["a"], {}]


def _leaves(obj, path=()):
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if dataclasses.is_dataclass(v):
            yield from _leaves(v, (*path, f.name))
        else:
            yield (*path, f.name)


def _set(d, path, value):
    for k in path[:-1]:
        d = d[k]
    d[path[-1]] = value


@pytest.mark.parametrize("path", list(_leaves(FitConfig())), ids=lambda p: ".".join(p))
def test_the_run_time_checks_agree_with_the_schema(path):
    """Every field, every kind of bad value: `FitConfig.validate` refuses exactly what the schema
    refuses (components named in the registry and the preset's name are checked by hand too)."""
    base = preset("fast").to_dict()
    validator = Draft202012Validator(SCHEMA)
    for value in BAD:
        doc = copy.deepcopy(base)
        _set(doc, path, value)
        schema_ok = not any(validator.iter_errors(json.loads(json.dumps(doc, allow_nan=True))))
        if value != value:  # NaN: JSON has none, a config from Python may
            schema_ok = False
        try:
            cfg = preset("fast")
            obj = cfg
            for k in path[:-1]:
                obj = getattr(obj, k)
            setattr(obj, path[-1], value)
            cfg.validate()
            checks_ok = True
        except UsageError:
            checks_ok = False
        if path[-1] in ("renderer", "articulation") and isinstance(value, str) and value:
            assert not checks_ok  # no such component: the registry says so, not the schema
            continue
        assert checks_ok == schema_ok, (path, value, schema_ok, checks_ok)


def test_a_bad_value_is_one_line_naming_the_field_and_what_it_means():
    cfg = preset("fast")
    cfg.camera.search_size = 4
    with pytest.raises(UsageError, match=r"camera.search_size 4 must be >= 8") as err:
        cfg.validate()
    assert "image size" in err.value.hint
