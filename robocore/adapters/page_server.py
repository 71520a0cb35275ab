"""A read-only HTTP server of one page and the part of it that changes (``fleet page --serve``).

The standard library's threading HTTP server: ``GET /`` answers the whole page, ``GET /fleet`` the changing part
with an ``ETag`` (a ``304`` when the browser has it already, so the page's poll costs a few bytes while nothing
changes); every other path is a 404 and every other method a 405: nothing is ever written through it. Each answer
carries a Content-Security-Policy that allows the page's inline CSS and script and requests to its own origin
only.
"""

from __future__ import annotations

import errno
import hashlib
import http.server
import socket
import threading
from collections.abc import Callable
from dataclasses import dataclass

from robocore.errors import UsageError

#: Headers of every answer: no caching by a proxy, no sniffing, nothing loaded from elsewhere.
HEADERS = {
    "Cache-Control": "no-store",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Content-Security-Policy": "default-src 'none'; style-src 'unsafe-inline'; script-src 'unsafe-inline'; "
                               "connect-src 'self'; frame-ancestors 'none'",
}


@dataclass(frozen=True)
class Pages:
    """What the server answers, each call a fresh look: the whole page and its changing part."""

    page: Callable[[], str]
    part: Callable[[], str]


def etag(body: bytes) -> str:
    """The entity tag of ``body`` (a digest of it: the same look gives the same tag)."""
    return '"' + hashlib.sha256(body).hexdigest()[:32] + '"'


def _handler(pages: Pages) -> type[http.server.BaseHTTPRequestHandler]:
    class Handler(http.server.BaseHTTPRequestHandler):
        server_version = "robocore-fleet-page"
        sys_version = ""

        def do_GET(self) -> None:
            path = self.path.split("?", 1)[0]
            if path in ("/", "/index.html"):
                self._send(200, pages.page().encode())
            elif path == "/fleet":
                body = pages.part().encode()
                tag = etag(body)
                if self.headers.get("If-None-Match") == tag:
                    self._send(304, b"", tag)
                else:
                    self._send(200, body, tag)
            else:
                self._send(404, b"not found\n", kind="text/plain")

        def do_HEAD(self) -> None:
            self._send(405, b"", kind="text/plain")

        do_POST = do_PUT = do_DELETE = do_PATCH = do_OPTIONS = do_HEAD

        def _send(self, code: int, body: bytes, tag: str = "", kind: str = "text/html") -> None:
            self.send_response(code)
            for key, value in HEADERS.items():
                self.send_header(key, value)
            if code == 405:
                self.send_header("Allow", "GET")
            if tag:
                self.send_header("ETag", tag)
            if code != 304:
                self.send_header("Content-Type", f"{kind}; charset=utf-8")
                self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            if body and self.command != "HEAD":
                self.wfile.write(body)

        def log_message(self, format: str, *args: object) -> None:
            """Quiet: a poll every two seconds is no news."""

    return Handler


class PageServer(http.server.ThreadingHTTPServer):
    """The server of :class:`Pages` (its threads are daemons: Ctrl-C ends it at once)."""

    daemon_threads = True

    @property
    def url(self) -> str:
        """``http://HOST:PORT/`` where it listens (the port chosen when 0 was asked)."""
        host, port = self.server_address[:2]
        name = host.decode() if isinstance(host, bytes) else str(host)
        shown = f"[{name}]" if ":" in name else name
        return f"http://{shown}:{port}/"


class PageServer6(PageServer):
    """:class:`PageServer` on an IPv6 address."""

    address_family = socket.AF_INET6


def start(pages: Pages, bind: str, port: int) -> PageServer:
    """A server of ``pages`` listening on ``bind``:``port`` (0: a free port), not serving yet (call
    ``serve_forever``); a UsageError in one line when the address cannot be had (a port in use, an address this
    machine does not have)."""
    kind = PageServer6 if ":" in bind else PageServer
    try:
        return kind((bind, port), _handler(pages))
    except OSError as exc:
        if exc.errno == errno.EADDRINUSE:
            raise UsageError(f"--port {port}: the port is in use on {bind}",
                             hint="name another with --port N (0 picks a free one)") from None
        raise UsageError(f"--bind {bind} --port {port}: cannot listen there ({exc.strerror or exc})",
                         hint="--bind 127.0.0.1 (the default) serves this machine only") from None


def serve_in_thread(server: PageServer) -> threading.Thread:
    """Serve ``server`` in a daemon thread (tests, and the bench); ``server.shutdown()`` ends it."""
    thread = threading.Thread(target=server.serve_forever, name="fleet-page", daemon=True)
    thread.start()
    return thread
