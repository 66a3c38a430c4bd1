"""Where the store lives: ``--store``, else ``ZOOCTL_STORE``, else ``./store`` in a checkout,
else the user data directory."""

from __future__ import annotations

import os
from pathlib import Path

_chosen: Path | None = None  # the CLI's --store, for this process


def use_store(path: Path | None) -> None:
    """Make `default_store` answer ``path`` (the CLI's ``--store``); None: back to the defaults."""
    global _chosen
    _chosen = None if path is None else Path(path).expanduser()


def _checkout_root() -> Path | None:
    """The zooctl source checkout this package runs from, if it is one (editable install)."""
    here = Path(__file__).resolve().parent.parent
    if (here / "pyproject.toml").is_file() and (here / "store" / "README.md").is_file():
        return here
    return None


def default_store() -> Path:
    if _chosen is not None:
        return _chosen
    env = os.environ.get("ZOOCTL_STORE")
    if env:
        return Path(env).expanduser()
    cwd_store = Path.cwd() / "store"
    if (Path.cwd() / "pyproject.toml").is_file() and (cwd_store / "README.md").is_file():
        return cwd_store
    root = _checkout_root()
    if root is not None:
        return root / "store"
    from platformdirs import user_data_dir

    return Path(user_data_dir("zooctl")) / "store"
