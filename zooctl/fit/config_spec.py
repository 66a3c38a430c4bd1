"""One source for the fit configuration's fields: type, default, range and description.

Each field of the config dataclasses (`zooctl.fit.config`) is declared with `spec`, which keeps
its rules (JSON Schema keywords: ``minimum``, ``exclusiveMaximum``, ``enum``, ``minItems``,
``pattern``...) and description in the field's metadata. From them `schema_of` writes the JSON
Schema (``schemas/fit_config.schema.json``: `tools/gen_fit_config_schema.py` writes it, a test
checks it is current) and `check_fields` validates a config with one clear error per bad value.
Only what a schema cannot say (a plugin's renderer exists, the presets' names) is checked by hand.
"""

from __future__ import annotations

import dataclasses
import math
import re
import types
import typing
from typing import Any

from ..errors import UsageError

_KEYWORDS = {
    "minimum",
    "maximum",
    "exclusiveMinimum",
    "exclusiveMaximum",
    "enum",
    "const",
    "minItems",
    "minLength",
    "pattern",
}


def spec(
    default: Any = dataclasses.MISSING,
    *,
    factory: Any = dataclasses.MISSING,
    help: str = "",
    required: bool = True,
    only: dict[str, dict[str, Any]] | None = None,
    **rules: Any,
) -> Any:
    """A dataclass field with its rules and description (module docstring). ``required``: listed
    as required in the schema (fields added later are not, so configs of earlier fits stay valid);
    ``only``: extra rules for fields of a nested config in this place (stage 2's ``iters``)."""
    unknown = set(rules) - _KEYWORDS
    if unknown:
        raise TypeError(f"unknown rule(s) {sorted(unknown)}")
    meta = {"help": help, "rules": rules, "required": required, "only": only or {}}
    if factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


# -- types -------------------------------------------------------------------------------------


def _json_type(tp: Any) -> tuple[dict[str, Any], bool]:
    """(schema of ``tp``, nullable)."""
    args = typing.get_args(tp)
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        inner = [a for a in args if a is not type(None)]
        schema, _ = _json_type(inner[0])
        return schema, len(inner) < len(args)
    if typing.get_origin(tp) is list:
        return {"type": "array", "items": _json_type(args[0])[0]}, False
    names = {bool: "boolean", int: "integer", float: "number", str: "string"}
    if tp in names:
        return {"type": names[tp]}, False
    raise TypeError(f"no JSON type for {tp!r}")


def _hints(cls: type) -> dict[str, Any]:
    import sys

    return typing.get_type_hints(cls, vars(sys.modules[cls.__module__]))


# -- the schema -------------------------------------------------------------------------------


def schema_of(cls: type, renamed: dict[type, dict[str, str]] | None = None) -> dict[str, Any]:
    """The JSON Schema of config dataclass ``cls`` (nested configs inline, ``$defs`` for one used
    twice); ``renamed``: per class, old key -> new key, listed as deprecated aliases."""
    renamed = renamed or {}
    counts: dict[type, int] = {}

    def count(c: type) -> None:
        for f in dataclasses.fields(c):
            t = _hints(c)[f.name]
            if dataclasses.is_dataclass(t):
                counts[t] = counts.get(t, 0) + 1
                count(t)

    count(cls)
    defs = {t.__name__: _object(t, renamed, counts) for t, n in counts.items() if n > 1}
    out = {"$schema": "https://json-schema.org/draft/2020-12/schema"} | _object(cls, renamed, counts)
    if defs:
        out["$defs"] = defs
    return out


def _object(cls: type, renamed: dict[type, dict[str, str]], counts: dict[type, int]) -> dict[str, Any]:
    hints = _hints(cls)
    props: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        t, meta = hints[f.name], f.metadata
        if dataclasses.is_dataclass(t):
            shared = counts.get(t, 0) > 1
            p = {"$ref": f"#/$defs/{t.__name__}"} if shared else _object(t, renamed, counts)
            if meta.get("only"):
                p = {"allOf": [p, {"properties": meta["only"]}]}
        else:
            p, nullable = _json_type(t)
            if "enum" in meta.get("rules", {}) or "const" in meta.get("rules", {}):
                p = {}
            elif nullable:
                p["type"] = [p["type"], "null"]
            p.update(meta.get("rules", {}))
            if "enum" in p:
                p["enum"] = list(p["enum"])
        if meta.get("help"):
            p["description"] = meta["help"]
        props[f.name] = p
    for old, new in renamed.get(cls, {}).items():
        props[old] = {
            **{k: v for k, v in props[new].items() if k != "description"},
            "deprecated": True,
            "description": f"old name of {new} (configs of earlier fits); read as {new}",
        }
    required = [f.name for f in dataclasses.fields(cls) if f.metadata.get("required", True)]
    return {"type": "object", "additionalProperties": False, "required": required, "properties": props}


# -- validation -------------------------------------------------------------------------------


def check_fields(obj: Any, where: str = "", only: dict[str, dict[str, Any]] | None = None) -> None:
    """Check every field of config dataclass ``obj`` (nested ones too) against its type and rules;
    the first bad value is a `UsageError` naming it (``where``: its place, e.g. ``stage2``)."""
    hints = _hints(type(obj))
    for f in dataclasses.fields(obj):
        name = f"{where}.{f.name}" if where else f.name
        value, t = getattr(obj, f.name), hints[f.name]
        if dataclasses.is_dataclass(t):
            check_fields(value, name, f.metadata.get("only"))
            continue
        rules = dict(f.metadata.get("rules", {})) | (only or {}).get(f.name, {})
        if isinstance(value, float) and value.is_integer() and _json_type(t)[0]["type"] == "integer":
            value = int(value)  # JSON's 1e3 is an integer (as for the schema): stored as one
            setattr(obj, f.name, value)
        problem = _problem(value, t, rules)
        if problem:
            help = f.metadata.get("help", "")
            if problem.startswith("must match") and help:  # a pattern says less than its description
                problem = f"must be {help}"
            raise UsageError(f"{name} {value!r} {problem}", hint=f"{f.name}: {help}" if help else None)


def _problem(value: Any, tp: Any, rules: dict[str, Any]) -> str | None:
    schema, nullable = _json_type(tp)
    if value is None:
        return None if nullable else "must be given (null is not allowed)"
    kind = schema["type"]
    if "enum" in rules:
        ok = _is(value, kind) and value in rules["enum"]
        return None if ok else f"must be one of {', '.join(map(str, rules['enum']))}"
    if "const" in rules:
        return None if _is(value, kind) and value == rules["const"] else f"must be {rules['const']!r}"
    if kind == "array":
        if not isinstance(value, list) or not all(_is(v, schema["items"]["type"]) for v in value):
            return f"must be a list of {schema['items']['type']}s"
        if len(value) < rules.get("minItems", 0):
            return f"must hold at least {rules['minItems']} value(s)"
        return None
    if not _is(value, kind):
        return f"must be {'an' if kind[0] in 'aeiou' else 'a'} {kind}"
    if kind == "string":
        if len(value) < rules.get("minLength", 0):
            return "must not be empty"
        if "pattern" in rules and not re.search(rules["pattern"], value):
            return f"must match {rules['pattern']}"
        return None
    bounds = (
        ("minimum", lambda a, b: a >= b, ">="),
        ("exclusiveMinimum", lambda a, b: a > b, ">"),
        ("maximum", lambda a, b: a <= b, "<="),
        ("exclusiveMaximum", lambda a, b: a < b, "<"),
    )
    for key, ok, sign in bounds:
        if key in rules and not ok(value, rules[key]):
            return f"must be {sign} {rules[key]:g}"
    return None


def _is(value: Any, kind: str) -> bool:
    if kind == "boolean":
        return isinstance(value, bool)
    if isinstance(value, bool):
        return False
    if kind == "integer":
        return isinstance(value, int)
    if kind == "number":
        return isinstance(value, (int, float)) and math.isfinite(value)
    return isinstance(value, str)
