"""The admin API over Zenoh: one queryable on ``fleetlink/<site>/admin/**`` (see ``edge.admin.space``).

Queries are answered off the Zenoh callback thread (a small pool), each reply on a concrete
key. With an admin token configured, a query must carry ``Bearer <token>`` as its attachment
(401 otherwise; after a few wrong tokens every query waits out a lockout, 429); the WAN link's
mutual TLS and per-site ACLs decide who can reach the key at all. Without a token the space is
read-only: every change is refused (403), since anyone on the site network or in the cloud can
reach it.
"""

from __future__ import annotations

import logging
from types import TracebackType
from typing import Any

import zenoh
from pydantic import SecretStr

from fleetlink.common.login_limiter import LoginLimiter
from fleetlink.common.metrics import Metrics, NullMetrics
from fleetlink.common.pooled_queryable import PooledQueryable
from fleetlink.edge.admin.auth import authorized
from fleetlink.edge.admin.listing import declared
from fleetlink.edge.admin.service import AdminService
from fleetlink.edge.admin.space import Target, envelope, execute, parse_body, targets
from fleetlink.wire.keys import admin_key

log = logging.getLogger(__name__)

CHANGES = frozenset({"add", "put", "delete"})
_CLIENT = "zenoh"
"""Zenoh queries carry no trustworthy sender: wrong tokens are counted for the space as a whole."""


class ZenohAdmin:
    """The admin API as a Zenoh queryable on ``fleetlink/<site>/admin/**``, answered by a small pool."""

    def __init__(
        self,
        session: zenoh.Session,
        service: AdminService,
        *,
        edge_id: str,
        token: SecretStr | None = None,
        metrics: Metrics | None = None,
    ) -> None:
        self.metrics: Metrics = metrics if metrics is not None else NullMetrics()
        self.session = session
        self.service = service
        self.edge_id = edge_id
        self.token = token
        self.key = admin_key(service.site)
        self._queryable = PooledQueryable(self._answer, workers=2, name="edge-admin-zenoh")
        self.answered = 0
        self.logins = LoginLimiter()
        self.refused_changes = 0
        """Changes refused because no admin token is configured."""

    def start(self) -> ZenohAdmin:
        """Declare the queryable on the session (once); returns ``self``."""
        if not self._queryable.running:
            self._queryable.start(self.session, self.key)
            log.info("admin queries served on %s", self.key)
        return self

    def stop(self) -> None:
        """Undeclare the queryable and stop its answering threads."""
        self._queryable.stop()

    def __enter__(self) -> ZenohAdmin:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def _answer(self, query: zenoh.Query) -> None:
        try:
            key = str(query.key_expr)
            payload = query.payload.to_bytes() if query.payload is not None else None
            attachment = query.attachment.to_bytes() if query.attachment is not None else None
            op = query.parameters.get("op")
            names = self._names
            found = targets(self.service.site, key, op, bool(payload), names)
            if not found:
                return
            denied = self._denied(attachment, found)
            if denied is not None:
                self._reply(query, Target(found[0].key, ""), denied[0], {"error": denied[1], "problems": []})
                return
            body, problem = parse_body(payload)
            for target in found:
                if problem is not None:
                    self._reply(query, target, 400, {"error": problem, "problems": []})
                    continue
                status, part = execute(self.service, target, body)
                self._reply(query, target, status, part)
        except Exception as exc:  # noqa: BLE001 - one bad query must not kill the pool worker silently
            log.warning("admin query on %s failed: %r", query.key_expr, exc)
        finally:
            query.drop()

    def _denied(self, attachment: bytes | None, found: list[Target]) -> tuple[int, str] | None:
        """(status, reason) when the query may not do what it asks; None when it may."""
        if self.token is None:
            if any(t.op in CHANGES for t in found):
                self.refused_changes += 1
                self.metrics.on_admin_refused("read_only")
                return 403, "changes over Zenoh need an admin token (FLEETLINK_ADMIN_TOKEN on the edge)"
            return None
        wait = self.logins.retry_after(_CLIENT)
        if wait > 0:
            self.metrics.on_admin_refused("locked_out")
            return 429, f"too many wrong tokens: try again in {wait:.0f} s"
        if authorized(self.token, attachment):
            self.logins.success(_CLIENT)
            return None
        if attachment is not None:
            self.logins.failure(_CLIENT)
            self.metrics.on_admin_refused("wrong_token")
        return 401, "missing or wrong admin token (attachment 'Bearer <token>')"

    def _names(self, resource: str) -> list[str]:
        if resource == "mappings":
            return [m.name for m, _ in declared(self.service.config)]
        return list(self.service.config.robot_types)

    def _reply(self, query: zenoh.Query, target: Target, status: int, part: Any) -> None:
        query.reply(target.key, envelope(status, part, site=self.service.site, edge_id=self.edge_id))
        self.answered += 1
