"""Built-in executor: ``local`` (this process, or ``--jobs N`` processes on this machine)."""

from __future__ import annotations

from ..components import ComponentSpec
from ..plugins import hookimpl


def _local(**options):
    from ..executors.local import LocalExecutor

    return LocalExecutor(**options)


@hookimpl
def register_executors(register):
    register(
        ComponentSpec(
            "executor", "local", _local, "tasks one after another, or in --jobs N processes on this machine"
        )
    )
