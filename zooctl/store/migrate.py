"""Upgrading stored files to the current layout with the named migrations of `asset_h5`."""

from __future__ import annotations

import shutil
from typing import Any

from ..errors import StoreError
from .asset_h5 import SCHEMA_VERSION, Migration, migrate_file
from .bank import Bank
from .fs import publish, store_lock, temp_path, writing
from .h5 import open_h5


def migrate_bank(bank: Bank, migrations: list[Migration] | None = None) -> dict[str, Any]:
    """Migrate every asset file older than `SCHEMA_VERSION`; each one is copied, upgraded and
    published atomically, so an interrupted migration leaves every asset readable. Unreadable
    files are reported in ``skipped`` and left as they are."""
    migrated, current, applied, skipped = 0, 0, {}, {}
    with store_lock(bank.root), writing("migrating the bank"):
        for name in bank.names():
            path = bank.asset_path(name)
            try:
                with open_h5(path, "asset file", "re-add the asset with --replace") as f:
                    v = int(f.attrs.get("schema_version", 0))
            except StoreError as exc:
                skipped[name] = exc.message
                continue
            except (OSError, ValueError, TypeError) as exc:
                skipped[name] = f"unreadable: {exc}"
                continue
            if v >= SCHEMA_VERSION:
                current += 1
                continue
            tmp = temp_path(path)
            try:
                shutil.copyfile(path, tmp)
                applied[name] = migrate_file(tmp, migrations)
                publish(tmp, path)
            finally:
                tmp.unlink(missing_ok=True)
            migrated += 1
    return {"migrated": migrated, "current": current, "applied": applied, "skipped": skipped}
