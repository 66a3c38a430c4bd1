"""`zooctl plugins`: what is installed and what each plugin registers."""

from __future__ import annotations

from ._common import JsonOpt, console, print_json


def plugins(json_out: bool = JsonOpt) -> None:
    """List every plugin with its distribution, version and what it registers."""
    from ..plugins import get_plugin_manager

    pm = get_plugin_manager()
    registry = pm.registry
    infos = sorted(pm.infos.values(), key=lambda i: (not i.builtin, i.name))
    if json_out:
        print_json({"plugins": [i.to_json() for i in infos], "problems": registry.problems})
        return
    from rich.markup import escape
    from rich.table import Table

    table = Table(title=f"{len(infos)} plugins", title_justify="left")
    for col in ("name", "distribution", "version", "status", "registers"):
        table.add_column(col)
    for i in infos:
        regs = "; ".join(f"{k.replace('_', ' ')}: {', '.join(v)}" for k, v in sorted(i.registers.items()))
        if "register_commands" in i.hooks:
            regs = (regs + "; " if regs else "") + "commands"
        status = {"loaded": "[green]loaded[/]", "failed": "[red]failed[/]", "skipped": "[dim]skipped[/]"}[
            i.status
        ]
        if i.error:
            status += f"\n[dim]{escape(i.error)}[/]"
        table.add_row(i.name, i.distribution, i.version, status, escape(regs))
    console.print(table, soft_wrap=False)
    for p in registry.problems:
        console.print(f"[yellow]warning:[/] {escape(p)}")
