"""Serve a written viewer site over HTTP (the standard library's server), on 127.0.0.1 unless told."""

from __future__ import annotations

import functools
import http.server
import ipaddress
from pathlib import Path

from zooctl.errors import UsageError

DEFAULT_PORT = 8765


class _Quiet(http.server.SimpleHTTPRequestHandler):
    """Serves the site's folder; no line per request on the terminal."""

    def log_message(self, format, *args):  # noqa: A002 (the base class's name)
        pass

    def end_headers(self):
        self.send_header("Cache-Control", "no-store")  # a second `zooctl view` must not show stale data
        super().end_headers()


class _Server(http.server.ThreadingHTTPServer):
    """A browser that closes a connection mid-reply (a reload, a tab closed while frames load, the
    server stopping under a load in flight) is not an error worth a traceback on the user's
    terminal: socket errors pass in silence, anything else is one line."""

    def handle_error(self, request, client_address):
        import sys

        exc = sys.exc_info()[1]
        if isinstance(exc, OSError):  # BrokenPipe, ConnectionReset, a socket closed at shutdown
            return
        print(
            f"viewer: a request from {client_address[0]} failed: {type(exc).__name__}: {exc}", file=sys.stderr
        )


def make_server(site: Path, host: str, port: int) -> http.server.ThreadingHTTPServer:
    """A server of ``site`` bound to ``host:port`` (port 0: a free one). The default port falls back
    to a free one when taken; a port the user named does not."""
    handler = functools.partial(_Quiet, directory=str(site))
    try:
        return _Server((host, port), handler)
    except OSError as exc:
        if port == DEFAULT_PORT:
            return _Server((host, 0), handler)
        raise UsageError(
            f"cannot serve on {host}:{port}: {exc.strerror or exc}",
            hint="choose another --port (0: any free one)",
        ) from None


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def url_of(server: http.server.ThreadingHTTPServer, host: str) -> str:
    port = server.server_address[1]
    shown = "127.0.0.1" if host in ("", "0.0.0.0") else host
    shown = f"[{shown}]" if ":" in shown else shown
    return f"http://{shown}:{port}/"
