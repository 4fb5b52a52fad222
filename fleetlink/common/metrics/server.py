"""Serve ``/metrics`` and ``/health`` over HTTP: an ASGI app run by uvicorn in a thread.

``serve_metrics(host, port, metrics, health)`` is what the uplink and the repeater start; the
edge agent mounts the same two routes in its admin API (``add_metrics_routes``).

``HttpServer`` binds its socket in ``start()`` (so "address in use" is raised there, and port
0 picks a free port: see ``.port``) and stops in ``stop()``; it is a context manager.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections.abc import Callable
from types import TracebackType
from typing import Any

import uvicorn
from fastapi import FastAPI
from fastapi.responses import JSONResponse, Response

from fleetlink.common.metrics.errors import ServeError
from fleetlink.common.metrics.health import Health
from fleetlink.common.metrics.prometheus import CONTENT_TYPE, PrometheusMetrics

log = logging.getLogger(__name__)

HealthSource = Callable[[], Health]


def split_listen(listen: str) -> tuple[str, int]:
    """``"127.0.0.1:8480"`` / ``"[::1]:8480"`` -> host and port (port 0: any free port)."""
    host, sep, port = listen.rpartition(":")
    if not sep or not host or not port.isdigit() or int(port) > 65535:
        raise ServeError("not host:port", listen=listen)
    return host.removeprefix("[").removesuffix("]"), int(port)


def add_metrics_routes(
    app: FastAPI,
    metrics: PrometheusMetrics,
    health: HealthSource,
    *,
    refresh: Callable[[], None] | None = None,
) -> None:
    """``GET /metrics`` (Prometheus text) and ``GET /health`` (JSON; 503 when failed).

    ``refresh`` runs before each answer: the place to copy a component's running totals into
    ``metrics`` (pull model, nothing on the hot path).
    """

    @app.get(
        "/metrics",
        tags=["observability"],
        response_class=Response,
        responses={200: {"content": {CONTENT_TYPE: {}}, "description": "Prometheus text format"}},
    )
    def get_metrics() -> Response:
        if refresh is not None:
            refresh()
        metrics.set_health(health().state)
        return Response(content=metrics.render(), media_type=CONTENT_TYPE)

    @app.get(
        "/health",
        tags=["observability"],
        response_model=None,
        responses={200: {"description": "ok or degraded"}, 503: {"description": "failed"}},
    )
    def get_health() -> JSONResponse:
        if refresh is not None:
            refresh()
        report = health()
        metrics.set_health(report.state)
        return JSONResponse(report.as_dict(), status_code=report.http_status)


class HttpServer:
    """One ASGI app on one socket, served by uvicorn on a daemon thread."""

    def __init__(self, app: Any, listen: str, *, name: str = "http", start_timeout_s: float = 10.0) -> None:
        self.app = app
        self.listen = listen
        self.name = name
        self.start_timeout_s = start_timeout_s
        self._server: uvicorn.Server | None = None
        self._thread: threading.Thread | None = None
        self._socket: socket.socket | None = None

    @property
    def port(self) -> int:
        """The port the socket is bound to (the free one picked for port 0).

        Raises ``ServeError`` before ``start()``.
        """
        if self._socket is None:
            raise ServeError("not started", listen=self.listen)
        port: int = self._socket.getsockname()[1]
        return port

    @property
    def url(self) -> str:
        """The server's base URL, ``http://host:port`` (IPv6 hosts in brackets)."""
        host, _ = split_listen(self.listen)
        shown = f"[{host}]" if ":" in host else host
        return f"http://{shown}:{self.port}"

    def start(self) -> HttpServer:
        """Bind the socket, start uvicorn on its thread and wait until it serves; returns ``self``.

        Does nothing when already started. Raises ``ServeError`` when the address cannot be bound or
        the server does not start within ``start_timeout_s``.
        """
        if self._server is not None:
            return self
        host, port = split_listen(self.listen)
        sock = _bind(host, port, self.listen)
        config = uvicorn.Config(
            self.app,
            log_config=None,
            access_log=False,
            lifespan="off",
            log_level=logging.WARNING,
            timeout_graceful_shutdown=2,
        )
        server = uvicorn.Server(config)
        thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, name=self.name, daemon=True)
        thread.start()
        deadline = time.monotonic() + self.start_timeout_s
        while not server.started:
            if not thread.is_alive() or time.monotonic() > deadline:
                server.should_exit = True
                sock.close()
                raise ServeError("the HTTP server did not start", listen=self.listen)
            time.sleep(0.005)
        self._server, self._thread, self._socket = server, thread, sock
        log.info("%s serving on %s", self.name, self.url)
        return self

    def stop(self) -> None:
        """Ask uvicorn to exit, wait up to 5 s for its thread and close the socket (no-op when stopped)."""
        server, thread, sock = self._server, self._thread, self._socket
        self._server = self._thread = None
        if server is not None:
            server.should_exit = True
        if thread is not None:
            thread.join(timeout=5)
        if sock is not None:
            sock.close()
            self._socket = None

    def __enter__(self) -> HttpServer:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()


def _bind(host: str, port: int, listen: str) -> socket.socket:
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except OSError as exc:
        raise ServeError(f"cannot resolve host: {exc.strerror}", listen=listen) from None
    family, kind, proto, _, address = infos[0]
    sock = socket.socket(family, kind, proto)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(address)
    except OSError as exc:
        sock.close()
        raise ServeError(f"cannot listen: {exc.strerror}", listen=listen) from None
    sock.set_inheritable(True)
    return sock


def metrics_app(
    metrics: PrometheusMetrics,
    health: HealthSource | None = None,
    *,
    refresh: Callable[[], None] | None = None,
) -> FastAPI:
    """A small app with ``/metrics`` and ``/health`` only (uplink, repeater)."""
    app = FastAPI(title=f"fleetlink {metrics.component}", docs_url=None, redoc_url=None)
    add_metrics_routes(app, metrics, health or (lambda: Health.of(())), refresh=refresh)
    return app


def serve_metrics(
    host: str,
    port: int,
    metrics: PrometheusMetrics,
    health: HealthSource | None = None,
    *,
    refresh: Callable[[], None] | None = None,
) -> HttpServer:
    """Start serving ``/metrics`` and ``/health`` on ``host:port``; returns the started server."""
    shown = f"[{host}]" if ":" in host else host
    app = metrics_app(metrics, health, refresh=refresh)
    return HttpServer(app, f"{shown}:{port}", name=f"{metrics.component}-metrics").start()
