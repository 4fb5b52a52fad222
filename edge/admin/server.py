"""``EdgeAdmin``: everything administrative of one edge process, started and stopped as one.

    admin = EdgeAdmin(config, token=load_token())     # no I/O yet
    agent = EdgeAgent(admin.load(), ...)              # the config file + saved admin changes
    agent.start(); admin.attach(agent)                # HTTP API, /metrics, /health, Zenoh admin space
    ...
    admin.stop(); agent.stop()

The HTTP server runs when a listen address is given (default: the config's ``admin.listen``);
the Zenoh admin space runs on the session given to ``start`` (``attach`` uses the agent's).

Parts served beside the API (the web console) are *extensions*: the layer that assembles the
edge process passes factories for them, so the admin never imports what is built on top of it.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, Protocol

import zenoh
from fastapi import FastAPI
from pydantic import SecretStr

from fleetlink.common.exposure import check_exposure
from fleetlink.common.metrics import HttpServer, PrometheusMetrics
from fleetlink.edge.admin.agent_backend import AgentBackend
from fleetlink.edge.admin.backend import AdminBackend, EdgeSnapshot
from fleetlink.edge.admin.changes import effective
from fleetlink.edge.admin.errors import AdminError
from fleetlink.edge.admin.http import create_app
from fleetlink.edge.admin.overlay import Overlay, config_data
from fleetlink.edge.admin.service import AdminService
from fleetlink.edge.admin.store import OverlayStore, default_overlay_path
from fleetlink.edge.admin.telemetry import EdgeTelemetry
from fleetlink.edge.admin.zenoh_admin import ZenohAdmin
from fleetlink.edge.config import EdgeConfig

if TYPE_CHECKING:
    from fleetlink.edge.agent import EdgeAgent

log = logging.getLogger(__name__)


class AdminExtension(Protocol):
    """Something served beside the admin API: routes on its HTTP app, keys on its Zenoh session."""

    def mount(self, app: FastAPI) -> None:
        """Add the extension's routes to the admin HTTP app."""
        ...

    def start(self, session: zenoh.Session) -> object:
        """Start serving the extension's keys on ``session``."""
        ...

    def stop(self) -> None:
        """Stop serving; the extension may be started again."""
        ...


ExtensionFactory = Callable[
    [AdminService, Callable[[], EdgeSnapshot], Callable[[], Mapping[str, Any]] | None], AdminExtension
]
"""Makes an extension from the admin service, the snapshot of the edge and its raw counters."""


class EdgeAdmin:
    """Everything administrative of one edge process: the overlay store, the admin service, the HTTP
    server, the Zenoh admin space and extensions such as the console."""

    def __init__(
        self,
        base: EdgeConfig,
        *,
        overlay_path: Path | None = None,
        token: SecretStr | None = None,
        listen: str | None = None,
        metrics: PrometheusMetrics | None = None,
        extensions: Sequence[ExtensionFactory] = (),
    ) -> None:
        self.base = base
        self.store = OverlayStore(overlay_path or default_overlay_path(Path(base.spool.dir)))
        self.token = token
        configured = base.admin.listen if base.admin is not None else None
        self.listen = listen if listen is not None else configured
        if self.listen:  # closed by default: before any socket opens
            check_exposure(
                self.listen,
                has_token=token is not None,
                key="admin.listen",
                what="the edge admin API and console",
                credentials_from="FLEETLINK_ADMIN_TOKEN or FLEETLINK_ADMIN_TOKEN_FILE",
                log=log,
            )
        self.metrics = metrics if metrics is not None else PrometheusMetrics("edge")
        self.service: AdminService | None = None
        self.http: HttpServer | None = None
        self.zenoh: ZenohAdmin | None = None
        self.extension_factories = tuple(extensions)
        self.extensions: list[AdminExtension] = []
        self._overlay: Overlay | None = None
        self._agent_backend: AgentBackend | None = None

    def load(self) -> EdgeConfig:
        """Read the saved overlay; returns the config to run (``OverlayError`` if it no longer fits)."""
        self._overlay = self.store.load()
        return effective(config_data(self.base), self._overlay, source=str(self.store.path))

    def start(self, backend: AdminBackend, session: zenoh.Session | None = None) -> EdgeAdmin:
        """Serve the admin API over ``backend``: the HTTP server when a listen address is set, the Zenoh
        admin space and the extensions when ``session`` is given; returns ``self``.

        Does nothing when already started; on failure whatever had started is stopped again."""
        if self.service is not None:
            return self
        overlay = self._overlay if self._overlay is not None else self.store.load()
        service = AdminService(
            self.base, backend, overlay=overlay, store=self.store, telemetry=EdgeTelemetry(self.metrics)
        )
        raw = self._agent_backend.agent.snapshot if self._agent_backend is not None else None
        self.extensions = [make(service, backend.snapshot, raw) for make in self.extension_factories]
        try:
            if self.listen:
                app = create_app(service, token=self.token, metrics=self.metrics)
                for extension in self.extensions:
                    extension.mount(app)  # e.g. the web console under /console/
                self.http = HttpServer(app, self.listen, name="edge-admin").start()
            if session is not None:
                self.zenoh = ZenohAdmin(
                    session, service, edge_id=self.base.edge_id, token=self.token, metrics=self.metrics
                ).start()
                for extension in self.extensions:
                    extension.start(session)  # e.g. fleetlink/<site>/console/status
        except BaseException:
            self.stop()
            raise
        self.service = service
        return self

    def attach(self, agent: EdgeAgent) -> EdgeAdmin:
        """``start`` on a started agent: its table, counters, graph and Zenoh session."""
        self._agent_backend = AgentBackend(agent).start()
        try:
            return self.start(self._agent_backend, agent.session)
        except BaseException:
            self.stop()  # the backend too, unless start's own cleanup already stopped it
            raise

    def stop(self) -> None:
        """Stop the extensions, the Zenoh admin space, the HTTP server and the agent's graph watcher."""
        for extension in self.extensions:
            extension.stop()
        self.extensions = []
        if self.zenoh is not None:
            self.zenoh.stop()
            self.zenoh = None
        if self.http is not None:
            self.http.stop()
            self.http = None
        if self._agent_backend is not None:
            self._agent_backend.stop()
            self._agent_backend = None
        self.service = None

    @property
    def url(self) -> str:
        """The admin HTTP API's base URL; raises ``AdminError`` when it is not running."""
        if self.http is None:
            raise AdminError("the admin HTTP API is not running")
        return self.http.url

    def __enter__(self) -> EdgeAdmin:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()
