"""The browser view's server: one page, its data as server-sent events, no ROS (standard library only).

Why a page of our own and not a Foxglove bridge: the page needs nothing on
the viewing machine but a browser, also with no network beyond the robot (a
Foxglove viewer is an application to install or a web app served from the
internet), it lays the skin out by the robot description's geometry, which
no generic panel does, and it is tested here in headless Chromium.  The
standard library serves it: a page, a script, JSON and an event stream are
all it takes, so the robot's install gains no web framework.

:class:`Hub` hands every event to every connected page through a queue of
its own, bounded (:data:`CLIENT_QUEUE`): a page that reads slowly (a slow
network, a background tab) loses its oldest frames, counted per client;
one that disconnects is dropped, counted.  Publishing never waits for a
client, so a viewer can never slow the graph.

Routes: ``/`` (the page), ``/view.js``, ``/view.css``, ``/api/config``
(layout and colour scale), ``/api/frame`` (the latest frame), ``/api/stats``
(clients, frames sent and dropped), ``/events`` (``text/event-stream``:
``config`` then ``frame`` events), ``/api/seek?t=SECONDS`` (bags).
"""

from __future__ import annotations

import itertools
import json
import threading
import time
from collections import deque
from collections.abc import Callable
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from typing import Any
from urllib.parse import parse_qs, urlparse

__all__ = ["CLIENT_QUEUE", "Client", "Hub", "ViewServer"]

#: Frames queued for one page before its oldest are dropped (about a second at 10 Hz).
CLIENT_QUEUE = 8
#: Seconds between keep-alive comments on an idle event stream.
KEEPALIVE_S = 10.0

_STATIC = {"/": ("index.html", "text/html; charset=utf-8"), "/index.html": ("index.html", "text/html; charset=utf-8"),
           "/view.js": ("view.js", "text/javascript; charset=utf-8"), "/view.css": ("view.css", "text/css; charset=utf-8")}


class Client:
    """One connected page: its queue of events and its counters."""

    _ids = itertools.count(1)

    def __init__(self, maxlen: int = CLIENT_QUEUE, address: str = "") -> None:
        self.id = next(self._ids)
        self.address = address
        self.queue: deque[bytes] = deque()
        self.maxlen = int(maxlen)
        self.cond = threading.Condition()
        self.sent = 0
        self.dropped = 0
        self.closed = False
        self.connected_at = time.monotonic()

    def offer(self, data: bytes) -> None:
        """Queue ``data``; when the queue is full, drop its oldest frame (counted).  Never blocks on the socket."""
        with self.cond:
            if len(self.queue) >= self.maxlen:
                self.queue.popleft()
                self.dropped += 1
            self.queue.append(data)
            self.cond.notify()

    def take(self, timeout_s: float) -> bytes | None:
        """The next event (None after ``timeout_s`` without one, or once closed)."""
        with self.cond:
            if not self.queue and not self.closed:
                self.cond.wait(timeout_s)
            if self.closed or not self.queue:
                return None
            return self.queue.popleft()

    def close(self) -> None:
        with self.cond:
            self.closed = True
            self.cond.notify_all()

    def stats(self) -> dict[str, Any]:
        return {"id": self.id, "address": self.address, "sent": self.sent, "dropped": self.dropped,
                "queued": len(self.queue), "connected_s": round(time.monotonic() - self.connected_at, 3)}


class Hub:
    """Fan events out to the connected pages (see the module docstring)."""

    def __init__(self, maxlen: int = CLIENT_QUEUE) -> None:
        self.maxlen = maxlen
        self._clients: dict[int, Client] = {}
        self._lock = threading.Lock()
        self.published = 0
        self.disconnects = 0
        self.dropped_by_gone = 0  # frames dropped for pages that have disconnected since
        self.latest: dict[str, bytes] = {}

    @staticmethod
    def event(kind: str, payload: Any) -> bytes:
        """A server-sent event of ``kind`` carrying ``payload`` as JSON (NaN is not JSON: callers send None)."""
        return f"event: {kind}\ndata: {json.dumps(payload, separators=(',', ':'), allow_nan=False)}\n\n".encode()

    def publish(self, kind: str, payload: Any) -> None:
        """Send an event to every page (serialised once); the latest of each kind is kept for new pages."""
        data = self.event(kind, payload)
        with self._lock:
            self.latest[kind] = data
            clients = list(self._clients.values())
            self.published += 1
        for c in clients:
            c.offer(data)

    def connect(self, address: str = "") -> Client:
        """A new page: it gets the latest ``config`` and ``frame`` at once."""
        c = Client(self.maxlen, address)
        with self._lock:
            self._clients[c.id] = c
            for kind in ("config", "frame"):
                if kind in self.latest:
                    c.offer(self.latest[kind])
        return c

    def disconnect(self, client: Client) -> None:
        client.close()
        with self._lock:
            if self._clients.pop(client.id, None) is not None:
                self.disconnects += 1
                self.dropped_by_gone += client.dropped

    def close(self) -> None:
        with self._lock:
            clients = list(self._clients.values())
        for c in clients:
            c.close()

    def stats(self) -> dict[str, Any]:
        with self._lock:
            clients = [c.stats() for c in self._clients.values()]
        return {"published": self.published, "clients": clients, "disconnects": self.disconnects,
                "dropped": sum(c["dropped"] for c in clients) + self.dropped_by_gone}


class ViewServer:
    """Serve the page and its events on ``host:port`` (``port`` 0 picks a free one; :attr:`url` says which).

    Parameters
    ----------
    hub : Hub
    config : callable
        Returns the page's configuration (``/api/config``).
    seek : callable, optional
        ``seek(seconds)`` for ``/api/seek`` (a bag); None answers 404.
    host, port : str, int
    """

    def __init__(self, hub: Hub, config: Callable[[], dict], *, seek: Callable[[float], Any] | None = None,
                 host: str = "127.0.0.1", port: int = 0) -> None:
        self.hub = hub
        self.config = config
        self.seek = seek
        self._stop = threading.Event()
        server = self

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def log_message(self, fmt: str, *args: Any) -> None:  # quiet: the CLI reports what matters
                pass

            def do_GET(self) -> None:  # noqa: N802 - http.server's name
                server._get(self)

        self.httpd = ThreadingHTTPServer((host, int(port)), Handler)
        self.httpd.daemon_threads = True
        self.host, self.port = self.httpd.server_address[:2]
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        host = self.host if ":" not in str(self.host) else f"[{self.host}]"
        return f"http://{host}:{self.port}/"

    def start(self) -> ViewServer:
        """Serve on a daemon thread."""
        self._thread = threading.Thread(target=self.httpd.serve_forever, kwargs={"poll_interval": 0.2},
                                        daemon=True, name="tactile-view-http")
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop serving and close every event stream."""
        self._stop.set()
        self.hub.close()
        self.httpd.shutdown()
        self.httpd.server_close()

    # ------------------------------------------------------------- routes
    def _get(self, h: BaseHTTPRequestHandler) -> None:
        url = urlparse(h.path)
        try:
            if url.path in _STATIC:
                name, ctype = _STATIC[url.path]
                self._send(h, HTTPStatus.OK, ctype, resources.files(__package__).joinpath("static", name).read_bytes())
            elif url.path == "/api/config":
                self._json(h, self.config())
            elif url.path == "/api/frame":
                data = self.hub.latest.get("frame")
                self._send(h, HTTPStatus.OK, "application/json",
                           data.split(b"data: ", 1)[1].strip() if data else b"null")
            elif url.path == "/api/stats":
                self._json(h, self.hub.stats())
            elif url.path == "/api/seek":
                if self.seek is None:
                    self._json(h, {"error": "not a bag: nothing to seek"}, HTTPStatus.NOT_FOUND)
                    return
                try:
                    t = float(parse_qs(url.query).get("t", [""])[0])
                except ValueError:
                    self._json(h, {"error": "give t=SECONDS"}, HTTPStatus.BAD_REQUEST)
                    return
                self._json(h, {"seek": self.seek(t)})
            elif url.path == "/events":
                self._events(h)
            else:
                self._json(h, {"error": f"no such page: {url.path}"}, HTTPStatus.NOT_FOUND)
        except (BrokenPipeError, ConnectionResetError):
            pass

    @staticmethod
    def _send(h: BaseHTTPRequestHandler, status: HTTPStatus, ctype: str, body: bytes) -> None:
        h.send_response(status)
        h.send_header("Content-Type", ctype)
        h.send_header("Content-Length", str(len(body)))
        h.send_header("Cache-Control", "no-store")
        h.end_headers()
        h.wfile.write(body)

    def _json(self, h: BaseHTTPRequestHandler, payload: Any, status: HTTPStatus = HTTPStatus.OK) -> None:
        self._send(h, status, "application/json", json.dumps(payload, allow_nan=False).encode())

    def _events(self, h: BaseHTTPRequestHandler) -> None:
        h.send_response(HTTPStatus.OK)
        h.send_header("Content-Type", "text/event-stream")
        h.send_header("Cache-Control", "no-store")
        h.send_header("Connection", "close")
        h.end_headers()
        h.close_connection = True
        client = self.hub.connect(f"{h.client_address[0]}:{h.client_address[1]}")
        try:
            h.wfile.write(b"retry: 1000\n\n")
            h.wfile.flush()
            while not self._stop.is_set() and not client.closed:
                data = client.take(KEEPALIVE_S)
                if data is None:
                    if client.closed:
                        break
                    data = b": keep-alive\n\n"
                else:
                    client.sent += 1
                h.wfile.write(data)
                h.wfile.flush()
        except (BrokenPipeError, ConnectionResetError, OSError):
            pass  # the page went away
        finally:
            self.hub.disconnect(client)
