"""``EdgeConsole``: the console of one edge (its own site), beside the admin API.

    console = EdgeConsole(service, edge_id="edge-1", token=token, snapshot=backend.snapshot,
                          raw_snapshot=agent.snapshot)
    console.mount(admin_app)          # pages and JSON under /console/ of the admin HTTP server
    console.start(session)            # fleetlink/<site>/console/status for the fleet console
    ...
    console.stop()

The status key answers the counters the admin space does not carry (spool depth and age, WAN
totals, per-topic sample counters: the graph's topic rates), with the admin token checked on
the query's attachment like every admin query.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from types import TracebackType
from typing import Any

import zenoh
from fastapi import FastAPI
from pydantic import SecretStr

from fleetlink.common.pooled_queryable import PooledQueryable
from fleetlink.console.app import create_console_app
from fleetlink.console.local import LocalSite
from fleetlink.console.remote import status_key
from fleetlink.console.status import site_status
from fleetlink.edge.admin.auth import authorized
from fleetlink.edge.admin.backend import EdgeSnapshot
from fleetlink.edge.admin.service import AdminService
from fleetlink.edge.admin.space import envelope

log = logging.getLogger(__name__)

PATH = "/console"


class EdgeConsole:
    def __init__(
        self,
        service: AdminService,
        *,
        edge_id: str,
        token: SecretStr | None,
        snapshot: Callable[[], EdgeSnapshot],
        raw_snapshot: Callable[[], Mapping[str, Any]] | None = None,
        poll_interval_s: float = 1.0,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.service = service
        self.edge_id = edge_id
        self.token = token
        self._snapshot = snapshot
        self._raw = raw_snapshot
        self._clock = clock
        self.site = LocalSite(service, edge_id=edge_id, status=self.status)
        self.poll_interval_s = poll_interval_s
        self._queryable = PooledQueryable(self._answer, workers=1, name="edge-console-status")
        self.answered = 0

    def status(self) -> dict[str, Any]:
        raw = self._raw() if self._raw is not None else None
        return site_status(self._snapshot(), raw, now_ms=int(self._clock() * 1000))

    def mount(self, app: FastAPI) -> None:
        """Serve the console under ``/console/`` of ``app`` (its own routes, not in the admin
        API's OpenAPI document)."""
        app.mount(
            PATH,
            create_console_app(
                self.site, token=self.token, poll_interval_s=self.poll_interval_s, clock=self._clock
            ),
        )

    # -- the status key --------------------------------------------------------------------------
    def start(self, session: zenoh.Session) -> EdgeConsole:
        self._queryable.start(session, status_key(self.service.site))
        self.site.session = session
        return self

    def stop(self) -> None:
        self._queryable.stop()

    def __enter__(self) -> EdgeConsole:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def _answer(self, query: zenoh.Query) -> None:
        site = self.service.site
        try:
            attachment = query.attachment.to_bytes() if query.attachment is not None else None
            if authorized(self.token, attachment):
                part: dict[str, Any] = {"body": self.status()}
                status = 200
            else:
                part = {"error": "missing or wrong admin token (attachment 'Bearer <token>')", "problems": []}
                status = 401
            query.reply(status_key(site), envelope(status, part, site=site, edge_id=self.edge_id))
            self.answered += 1
        except Exception as exc:  # noqa: BLE001 - one bad query must not kill the worker silently
            log.warning("console status query on %s failed: %r", query.key_expr, exc)
        finally:
            query.drop()


def console_extension(
    token: SecretStr | None, edge_id: str, *, poll_interval_s: float = 1.0
) -> Callable[
    [AdminService, Callable[[], EdgeSnapshot], Callable[[], Mapping[str, Any]] | None], EdgeConsole
]:
    """The edge's console as an admin extension (``EdgeAdmin(..., extensions=[...])``)."""

    def make(
        service: AdminService,
        snapshot: Callable[[], EdgeSnapshot],
        raw: Callable[[], Mapping[str, Any]] | None,
    ) -> EdgeConsole:
        return EdgeConsole(
            service,
            edge_id=edge_id,
            token=token,
            snapshot=snapshot,
            raw_snapshot=raw,
            poll_interval_s=poll_interval_s,
        )

    return make
