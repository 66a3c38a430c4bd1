"""Errors the library raises. The CLI turns each into one line plus a hint.

`ZooctlError` subclasses carry an exit code (2: the user's input or usage is wrong, 1: we failed)
and an optional hint that says what to do about it.
"""

from __future__ import annotations


class ZooctlError(Exception):
    """Base class of every error zooctl reports to a user."""

    exit_code = 1
    default_hint: str | None = None

    def __init__(self, message: str, hint: str | None = None):
        super().__init__(message)
        self.message = message
        self.hint = hint if hint is not None else self.default_hint

    def __str__(self) -> str:  # pragma: no cover - trivial
        return self.message

    def __reduce__(self):
        # Pickled whole, hint included: errors cross processes (`zooctl.io.export_worker`).
        return (type(self), (self.message, self.hint))


class UsageError(ZooctlError):
    """The user asked for something that cannot be done as asked (bad option, bad value)."""

    exit_code = 2


class InputError(UsageError):
    """A file or folder the user gave is unreadable, malformed or not what was expected."""


class NotFoundError(UsageError):
    """A named thing (asset, video, fit, plugin) does not exist in the store."""


class AlreadyExistsError(UsageError):
    """A name is already taken; `--replace` or another `--name` is the way out."""


class StoreError(ZooctlError):
    """The store on disk is unreadable, locked for too long, or of an unknown version."""


class PluginError(ZooctlError):
    """A plugin failed to load or misbehaved."""


class MissingDependencyError(UsageError):
    """An optional external tool or package needed for this request is not installed."""


class ReadOnlyStoreError(StoreError):
    """A write to the store was refused by the system (read-only folder or filesystem)."""


class NoSpaceError(StoreError):
    """A store write ran out of room (disk full, quota, or a file-size limit)."""


class Terminated(KeyboardInterrupt):
    """SIGTERM (a scheduler's cancel, `kill`), raised where the process is by the CLI's handler,
    so that what Ctrl-C saves is saved: a fit's state and its record marked ``interrupted``, a
    batch's report."""
