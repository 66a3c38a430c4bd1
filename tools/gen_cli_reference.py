"""Write docs/cli.md, the command-line reference, from the Typer app itself.

    .venv/bin/python tools/gen_cli_reference.py          # rewrite docs/cli.md
    .venv/bin/python tools/gen_cli_reference.py --check  # exit 1 when docs/cli.md is stale

Every built-in command, its help text, usage, arguments and options (type, default, environment
variable) come from the same objects `zooctl CMD --help` prints, so the page cannot drift from
the CLI: tests/test_cli_reference.py fails until this is rerun. Plugin commands are left out
(they exist only where the plugin is installed). The environment variables are described in
`ENVIRONMENT` below; the test also fails when zooctl reads a ``ZOOCTL_*`` variable not listed.
"""

from __future__ import annotations

import argparse
import inspect
import sys
from pathlib import Path

import click

REPO = Path(__file__).resolve().parents[1]
OUTPUT = REPO / "docs" / "cli.md"

# name -> (who reads it, what it does). zooctl's own first, then the first-party plugins'.
ENVIRONMENT: dict[str, tuple[str, str]] = {
    "ZOOCTL_STORE": ("zooctl", "The data root, as `--store` (which wins)."),
    "ZOOCTL_LOCK_TIMEOUT": (
        "zooctl",
        "Seconds a writer waits for the store lock (default 120), as `--wait`.",
    ),
    "ZOOCTL_DEBUG": ("zooctl", "`1`: print the traceback behind an error line (and USD's own warnings)."),
    "ZOOCTL_SLOW_EXIT": ("zooctl", "`1`: tear the interpreter down at exit the usual way (slower)."),
    "ZOOCTL_LOAD_PLUGINS": (
        "zooctl",
        "Comma-separated entry-point or distribution names: only these third-party plugins load.",
    ),
    "ZOOCTL_VIEWS": (
        "zooctl",
        "`0`: `bank add` / `bank seed` do not render retrieval views by default (`--views` still does).",
    ),
    "ZOOCTL_EMBEDDERS": (
        "zooctl",
        "Comma-separated embedders whose views `bank add` stores and `bank search` uses "
        "(default effnet and silhouette).",
    ),
    "ZOOCTL_PROCNET_WEIGHTS": (
        "zooctl",
        "Weights of the `procnet` embedder (default `STORE/models/procnet.npz`, written by `embed train`).",
    ),
    "ZOOCTL_ANIMALNET_WEIGHTS": (
        "zooctl",
        "Weights of the `animalnet` segmenter (default `STORE/models/animalnet.npz`, written by `segment train`).",
    ),
    "ZOOCTL_TORCH_THREADS": ("zooctl", "Threads of the embedders' CPU inference (default: torch's)."),
    "ZOOCTL_RENDER_KERNELS": (
        "zooctl",
        "`0`: the renderers skip their compiled C++ kernels and use the PyTorch path (same results, slower).",
    ),
    "ZOOCTL_ASSIMP": (
        "zooctl",
        "The `assimp` executable for FBX/DAE/BVH import (default: `assimp` on PATH).",
    ),
    "ZOOCTL_MAX_FILE_MB": ("zooctl", "Largest input file read whole, in MB (default 512)."),
    "ZOOCTL_MAX_JSON_MB": (
        "zooctl",
        "Largest JSON text read (an index, a card, a config), in MB (default 64).",
    ),
    "ZOOCTL_MAX_ARRAY_MB": (
        "zooctl",
        "Largest arrays one read of a stored HDF5 file may allocate, in MB (default 1024).",
    ),
    "ZOOCTL_RAY_OBJECT_STORE_MB": (
        "zooctl-ray",
        "Object store of a Ray started for a batch, in MB (default 300).",
    ),
    "ZOOCTL_CLIP_WEIGHTS": ("zooctl-clip", "A local CLIP `.pt`/`.pth` file for the `clip` embedder."),
    "ZOOCTL_CLIP_ACT": (
        "zooctl-clip",
        "The activation the CLIP weights were trained with (default `quick_gelu`).",
    ),
    "ZOOCTL_VIEWER_CACHE": (
        "zooctl-viewer",
        "Where `zooctl view --bank` caches turntables and GLBs per asset (default `$XDG_CACHE_HOME/zooctl/viewer`).",
    ),
    "ZOOCTL_CHROMIUM": (
        "zooctl-viewer",
        "The Chromium executable the viewer's browser tests and benchmark drive (default `chromium` on PATH).",
    ),
    "TORCH_EXTENSIONS_DIR": (
        "zooctl",
        "Where the compiled renderer kernels are cached (`$TORCH_EXTENSIONS_DIR/zooctl`; "
        "default the user cache dir, `~/.cache/zooctl/kernels`).",
    ),
    "CXX": (
        "zooctl",
        "The C++ compiler for the renderer kernels (default `g++`, `c++` or `clang++` on PATH).",
    ),
}


def _root_command() -> click.Command:
    import typer

    from zooctl.cli.main import _register_groups, app

    _register_groups()  # the built-in groups only: no plugin is loaded here
    root = typer.main.get_command(app)
    # ... though a test that ran the CLI in this process may have added a plugin's command to `app`
    builtin = {g.name for g in app.registered_groups} | {
        c.name or c.callback.__name__
        for c in app.registered_commands
        if c.callback is not None and c.callback.__module__.startswith("zooctl.")
    }
    if isinstance(root, click.Group):
        for name in [n for n in root.commands if n not in builtin]:
            root.commands.pop(name)
    return root


def _walk(cmd: click.Command, path: list[str]):
    yield path, cmd
    if isinstance(cmd, click.Group):
        ctx = click.Context(cmd, info_name=path[-1])
        for name in cmd.list_commands(ctx):
            sub = cmd.get_command(ctx, name)
            if sub is not None and not sub.hidden:
                yield from _walk(sub, [*path, name])


def _help_text(cmd: click.Command) -> str:
    text = inspect.cleandoc(cmd.help or "").split("\f")[0]
    lines = [ln for ln in text.splitlines() if ln.strip() != "\b"]
    return "\n".join(lines).strip()


def _short(cmd: click.Command) -> str:
    text = _help_text(cmd)
    return " ".join(text.split("\n\n")[0].split())


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def _type(p: click.Parameter) -> str:
    t = p.type
    if isinstance(p, click.Option) and p.is_flag:
        return ""
    if isinstance(t, click.Choice):
        return " \\| ".join(map(str, t.choices))
    name = {"integer range": "INTEGER", "float range": "FLOAT"}.get(t.name, t.name).upper()
    if isinstance(t, click.types._NumberRangeBase):
        lo = "" if t.min is None else f"{t.min}{'<' if t.min_open else '<='}"
        hi = "" if t.max is None else f"{'<' if t.max_open else '<='}{t.max}"
        name += f" ({lo}x{hi})"
    if p.nargs == -1:
        name += "..."
    return name


def _default(p: click.Parameter) -> str:
    if not isinstance(p, click.Option) or p.show_default is False or p.required:
        return ""
    d = p.default
    if d is None or callable(d) or (isinstance(d, list | tuple) and not d):
        return ""
    if p.is_flag:
        if p.secondary_opts:
            return f"`{p.opts[0] if d else p.secondary_opts[0]}`"
        return ""
    return f"`{d}`"


def _names(p: click.Parameter) -> str:
    if isinstance(p, click.Argument):
        return f"`{p.human_readable_name}`"
    names = " ".join(f"`{o}`" for o in p.opts)
    if p.secondary_opts:
        names += " / " + " ".join(f"`{o}`" for o in p.secondary_opts)
    return names


def _description(p: click.Parameter) -> str:
    parts = [getattr(p, "help", None) or ""]
    if getattr(p, "multiple", False):
        parts.append("Repeatable.")
    if p.required:
        parts.append("Required.")
    env = getattr(p, "envvar", None)
    if env:
        parts.append(
            "Environment: " + ", ".join(f"`{e}`" for e in ([env] if isinstance(env, str) else env)) + "."
        )
    return _cell(" ".join(x for x in parts if x))


def _usage(cmd: click.Command, path: list[str]) -> str:
    ctx = click.Context(cmd, info_name=path[-1])
    return " ".join([*path, *cmd.collect_usage_pieces(ctx)])


def _anchor(path: list[str]) -> str:
    return "-".join(path)


def render() -> str:
    root = _root_command()
    commands = list(_walk(root, ["zooctl"]))
    out = [
        "# Command-line reference",
        "",
        "<!-- Generated by tools/gen_cli_reference.py from the Typer app: do not edit by hand. -->",
        "",
        "Generated from the commands themselves (the same text as `zooctl COMMAND --help`) by",
        "`.venv/bin/python tools/gen_cli_reference.py`; `tests/test_cli_reference.py` fails when it",
        "is out of date. Plugins add commands of their own (`zooctl --help` lists them once",
        "installed, [plugins.md](plugins.md)); they are not listed here. Every `list` and `show`",
        "command takes `--json`; errors are one line and a hint ([troubleshooting.md](troubleshooting.md)).",
        "",
        "## Commands",
        "",
        "| Command | What it does |",
        "| --- | --- |",
    ]
    for path, cmd in commands[1:]:
        out.append(f"| [`{' '.join(path)}`](#{_anchor(path)}) | {_cell(_short(cmd))} |")
    out += ["", f"Environment variables: [below](#environment-variables). {len(ENVIRONMENT)} in all.", ""]
    for path, cmd in commands:
        out += [f"## {' '.join(path)}", ""]
        text = _help_text(cmd)
        if text:
            out += [text, ""]
        out += ["```", _usage(cmd, path), "```", ""]
        params = [p for p in cmd.params if not getattr(p, "hidden", False)]
        if params:
            out += ["| Argument / option | Type | Default | Description |", "| --- | --- | --- | --- |"]
            for p in params:
                out.append(f"| {_names(p)} | {_type(p)} | {_default(p)} | {_description(p)} |")
            out.append("")
        if isinstance(cmd, click.Group):
            ctx = click.Context(cmd, info_name=path[-1])
            subs = [n for n in cmd.list_commands(ctx) if not cmd.get_command(ctx, n).hidden]
            out += ["Commands: " + ", ".join(f"[`{n}`](#{_anchor([*path, n])})" for n in subs) + ".", ""]
    out += [
        "## Environment variables",
        "",
        "| Variable | Read by | What it does |",
        "| --- | --- | --- |",
    ]
    for name, (who, what) in ENVIRONMENT.items():
        out.append(f"| `{name}` | {who} | {_cell(what)} |")
    return "\n".join(out).rstrip() + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if docs/cli.md is not up to date")
    ap.add_argument("-o", "--output", type=Path, default=OUTPUT)
    args = ap.parse_args(argv)
    text = render()
    if args.check:
        current = args.output.read_text() if args.output.exists() else ""
        if current != text:
            print(f"{args.output} is stale: run .venv/bin/python tools/gen_cli_reference.py", file=sys.stderr)
            return 1
        return 0
    args.output.write_text(text)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
