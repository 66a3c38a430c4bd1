"""Shared CLI helpers: the store from the global option, rich consoles, JSON output."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import typer
from rich.console import Console

console = Console()
err_console = Console(stderr=True)


class State:
    store: Path | None = None


state = State()


def store_root() -> Path:
    from ..paths import default_store

    return state.store if state.store is not None else default_store()


def print_json(obj: Any) -> None:
    sys.stdout.write(json.dumps(obj, indent=2, sort_keys=False, default=_default) + "\n")


def _default(o: Any) -> Any:
    import numpy as np

    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


JsonOpt = typer.Option(False, "--json", help="Print JSON instead of a table (for scripts).")
