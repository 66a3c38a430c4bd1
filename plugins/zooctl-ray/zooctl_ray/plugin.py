"""Registers the ``ray`` executor. Ray itself is imported only when a batch uses it."""

from __future__ import annotations

from zooctl.components import ComponentSpec
from zooctl.plugins import hookimpl


def _ray(**options):
    from .executor import RayExecutor

    return RayExecutor(**options)


@hookimpl
def register_executors(register):
    register(
        ComponentSpec(
            "executor", "ray", _ray, "tasks on a Ray cluster (--address), or a Ray instance started here"
        )
    )
