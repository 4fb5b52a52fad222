"""``EdgeAdmin``: everything administrative of one edge process, started and stopped as one.

    admin = EdgeAdmin(config, token=load_token())     # no I/O yet
    agent = EdgeAgent(admin.load(), ...)              # the config file + saved admin changes
    agent.start(); admin.attach(agent)                # HTTP API, /metrics, /health, Zenoh admin space
    ...
    admin.stop(); agent.stop()

The HTTP server runs when a listen address is given (default: the config's ``admin.listen``);
the Zenoh admin space runs on the session given to ``start`` (``attach`` uses the agent's).
"""

from __future__ import annotations

from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING

import zenoh
from pydantic import SecretStr

from edge.admin.agent_backend import AgentBackend
from edge.admin.backend import AdminBackend
from edge.admin.changes import effective
from edge.admin.errors import AdminError
from edge.admin.http import create_app
from edge.admin.overlay import Overlay, config_data
from edge.admin.service import AdminService
from edge.admin.store import OverlayStore, default_overlay_path
from edge.admin.telemetry import EdgeTelemetry
from edge.admin.zenoh_admin import ZenohAdmin
from edge.config import EdgeConfig
from fleetlink.console.edge import EdgeConsole
from fleetlink.metrics import HttpServer, PrometheusMetrics

if TYPE_CHECKING:
    from edge.agent import EdgeAgent


class EdgeAdmin:
    def __init__(
        self,
        base: EdgeConfig,
        *,
        overlay_path: Path | None = None,
        token: SecretStr | None = None,
        listen: str | None = None,
        metrics: PrometheusMetrics | None = None,
    ) -> None:
        self.base = base
        self.store = OverlayStore(overlay_path or default_overlay_path(Path(base.spool.dir)))
        self.token = token
        configured = base.admin.listen if base.admin is not None else None
        self.listen = listen if listen is not None else configured
        self.metrics = metrics if metrics is not None else PrometheusMetrics("edge")
        self.service: AdminService | None = None
        self.http: HttpServer | None = None
        self.zenoh: ZenohAdmin | None = None
        self.console: EdgeConsole | None = None
        self._overlay: Overlay | None = None
        self._agent_backend: AgentBackend | None = None

    def load(self) -> EdgeConfig:
        """Read the saved overlay; returns the config to run (``OverlayError`` if it no longer fits)."""
        self._overlay = self.store.load()
        return effective(config_data(self.base), self._overlay, source=str(self.store.path))

    def start(self, backend: AdminBackend, session: zenoh.Session | None = None) -> EdgeAdmin:
        if self.service is not None:
            return self
        overlay = self._overlay if self._overlay is not None else self.store.load()
        service = AdminService(self.base, backend, overlay=overlay, store=self.store,
                               telemetry=EdgeTelemetry(self.metrics))
        raw = self._agent_backend.agent.snapshot if self._agent_backend is not None else None
        self.console = EdgeConsole(service, edge_id=self.base.edge_id, token=self.token,
                                   snapshot=backend.snapshot, raw_snapshot=raw)
        try:
            if self.listen:
                app = create_app(service, token=self.token, metrics=self.metrics)
                self.console.mount(app)  # the web console under /console/
                self.http = HttpServer(app, self.listen, name="edge-admin").start()
            if session is not None:
                self.zenoh = ZenohAdmin(session, service, edge_id=self.base.edge_id, token=self.token).start()
                self.console.start(session)  # fleetlink/<site>/console/status for the fleet console
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
            self._agent_backend.stop()
            self._agent_backend = None
            raise

    def stop(self) -> None:
        if self.console is not None:
            self.console.stop()
            self.console = None
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
        if self.http is None:
            raise AdminError("the admin HTTP API is not running")
        return self.http.url

    def __enter__(self) -> EdgeAdmin:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()
