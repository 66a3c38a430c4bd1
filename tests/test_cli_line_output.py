"""Off a terminal (a log of a batch run, a pipe) each of the CLI's messages stays one line: a path or
a one-line error broken at rich's 80 columns cannot be copied back into a shell."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

from cli_helpers import REPO


def test_a_long_path_is_printed_whole_into_a_log(tmp_path: Path) -> None:
    store = tmp_path / ("d" * 120) / "store"
    env = {k: v for k, v in os.environ.items() if k != "COLUMNS"}
    env.update({"PYTHONPATH": str(REPO), "NO_COLOR": "1"})
    p = subprocess.run(
        [sys.executable, "-m", "zooctl", "--store", str(store), "bank", "list"],
        capture_output=True,
        text=True,
        env=env,
        cwd=REPO,
        timeout=120,
    )
    assert p.returncode == 0, p.stderr
    lines = [ln for ln in p.stdout.splitlines() if "the bank is empty" in ln]
    assert len(lines) == 1 and str(store) in lines[0], p.stdout


def test_a_table_keeps_its_columns_off_a_terminal() -> None:
    from rich.table import Table

    from zooctl.cli._common import LineConsole

    con = LineConsole(width=40, record=True, file=io.StringIO())
    table = Table("name", "registers")
    table.add_row("embed", "embedder: effnet, silhouette, procnet, and a longer list")
    con.print(table, soft_wrap=False)
    text = con.export_text()
    assert max(len(ln) for ln in text.splitlines()) <= 40
    assert "procnet" in text and "…" not in text
