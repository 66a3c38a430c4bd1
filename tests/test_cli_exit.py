"""The console script's exit: fast (no interpreter teardown), yet exit handlers, streams and
threads are honoured as by a normal exit."""

from __future__ import annotations

import subprocess
import sys

from cli_helpers import REPO, zooctl


def _python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)


def test_exit_runs_exit_handlers_flushes_and_keeps_the_code():
    p = _python(
        "import atexit, sys\n"
        "from zooctl.cli.main import _exit\n"
        "atexit.register(lambda: print('handler ran'))\n"
        "sys.stdout.write('buffered, no newline')\n"
        "_exit(3)\n"
    )
    assert p.returncode == 3
    assert "buffered, no newline" in p.stdout and "handler ran" in p.stdout


def test_exit_waits_for_a_running_thread():
    p = _python(
        "import threading, time\n"
        "from zooctl.cli.main import _exit\n"
        "def work():\n"
        "    time.sleep(0.3)\n"
        "    print('thread finished', flush=True)\n"
        "threading.Thread(target=work).start()\n"
        "_exit(0)\n"
    )
    assert p.returncode == 0 and "thread finished" in p.stdout


def test_console_script_exit_codes_and_output():
    ok = zooctl("--help")
    assert ok.code == 0 and "Usage" in ok.out
    bad = zooctl(
        "animate", "no-such-animal", "--sample", "1", env={"ZOOCTL_STORE": str(REPO / "no-such-store")}
    )
    assert bad.code != 0 and "error:" in bad.err and "Traceback" not in bad.err
