"""The live view's HTTP server: stdlib, read-only, on its own threads.

GET ``/`` (the page, shipped in the package), ``/frame.jpg`` (the annotated newest frame),
``/state.json`` (parts, PLC, health). Anything else is 404, any other method 405: the page
shows, it never controls. It binds 127.0.0.1 unless given another address.
"""

from __future__ import annotations

import logging
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources

from tracker.errors import BadInput
from tracker.web.view import LiveView

log = logging.getLogger(__name__)


class WebServer:
    def __init__(self, view: LiveView, host: str = "127.0.0.1", port: int = 8080) -> None:
        page = resources.files("tracker.web").joinpath("static/index.html").read_bytes()
        handler = type("Handler", (_Handler,), {"view": view, "page": page})
        try:
            self._httpd = ThreadingHTTPServer((host, port), handler)
        except OSError as exc:
            raise BadInput(f"--web {host}:{port}: cannot listen there: {exc.strerror}") from None
        self._httpd.daemon_threads = True  # a vanished browser never holds the exit
        self.host, self.port = host, self._httpd.server_address[1]
        self._thread = threading.Thread(target=self._httpd.serve_forever, name="web", daemon=True)

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    def start(self) -> WebServer:
        self._thread.start()
        log.info("live view on %s", self.url)
        return self

    def close(self) -> None:
        self._httpd.shutdown()
        self._httpd.server_close()


class _Handler(BaseHTTPRequestHandler):
    view: LiveView
    page: bytes
    # A client that stops reading must not hold a server thread for ever.
    timeout = 5.0

    def do_GET(self) -> None:  # noqa: N802 - the stdlib's name
        path = self.path.split("?", 1)[0]
        if path in ("/", "/index.html"):
            self._send(200, "text/html; charset=utf-8", self.page)
        elif path == "/frame.jpg":
            data = self.view.jpeg()
            if data is None:
                self._send(503, "text/plain", b"no frame yet")
            else:
                self._send(200, "image/jpeg", data)
        elif path == "/state.json":
            self._send(200, "application/json", self.view.state_json())
        else:
            self._send(404, "text/plain", b"not found")

    def _refuse(self) -> None:
        self._send(405, "text/plain", b"the live view is read-only")

    do_POST = do_PUT = do_DELETE = do_PATCH = _refuse  # noqa: N815

    def _send(self, code: int, kind: str, body: bytes) -> None:
        try:
            self.send_response(code)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)
        except OSError:
            pass  # the browser went away: nothing to do

    def log_message(self, format: str, *args) -> None:  # noqa: A002 - the stdlib's signature
        pass  # one line per request would drown the status line
