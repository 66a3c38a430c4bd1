"""Names of stored things (assets, videos, fits, priors). Light: no numpy, for fast CLI paths."""

from __future__ import annotations

import re

from .errors import InputError

NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]{0,127}$")


def check_name(name: str, what: str = "name") -> str:
    """Names of assets, videos, fits and priors: letters, digits, `_ . -`, at most 128 characters."""
    if not isinstance(name, str) or not NAME_RE.match(name):
        raise InputError(
            f"invalid {what} {name!r}",
            hint="use letters, digits, '_', '.', '-' (starting with a letter or digit, at most 128)",
        )
    return name


def sanitize_name(text: str) -> str:
    """Turn a file stem into a valid asset name."""
    s = re.sub(r"[^A-Za-z0-9_.\-]+", "_", text).strip("._-")
    return (s or "asset")[:128]
