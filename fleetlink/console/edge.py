"""``EdgeConsole``: the console of one edge (its own site), beside the admin API.

    console = EdgeConsole(service, edge_id="edge-1", token=token, snapshot=backend.snapshot,
                          raw_snapshot=agent.snapshot)
    console.mount(admin_app)          # pages and JSON under /console/ of the admin HTTP server
    console.start(session)            # fleetlink/<site>/console/** for the fleet console; history
    ...
    console.stop()

The status key answers the counters the admin space does not carry (spool depth and age, WAN
totals, per-topic sample counters: the graph's topic rates), with the admin token checked on
the query's attachment like every admin query.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable, Mapping
from types import TracebackType
from typing import TYPE_CHECKING, Any

import zenoh
from fastapi import FastAPI
from pydantic import SecretStr

from fleetlink.common.names import key_chunk_problem
from fleetlink.common.pooled_queryable import PooledQueryable
from fleetlink.console.app import Operations, create_console_app
from fleetlink.console.audit import MemoryAudit
from fleetlink.console.envelope import Envelope
from fleetlink.console.history import History
from fleetlink.console.latest import LatestValues
from fleetlink.console.local import LocalSite
from fleetlink.console.remote import latest_key, status_key
from fleetlink.console.sampler import HistorySampler
from fleetlink.console.status import site_status
from fleetlink.console.users import User, load_users
from fleetlink.edge.admin.auth import authorized
from fleetlink.edge.admin.backend import EdgeSnapshot
from fleetlink.edge.admin.service import AdminService
from fleetlink.edge.admin.space import envelope
from fleetlink.edge.runtime.types import schema_distro
from fleetlink.schemas.typestore import load_typestore

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

log = logging.getLogger(__name__)

PATH = "/console"


class EdgeConsole:
    """The console of one edge: pages and JSON under ``/console/`` of the admin app, the keys
    ``fleetlink/<site>/console/**`` for the fleet console, and the sampler of the site's history."""

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
        users: Mapping[str, User] | None = None,
        history: History | None = None,
    ) -> None:
        self.service = service
        self.edge_id = edge_id
        self.token = token
        self.users = dict(users or {})
        self._snapshot = snapshot
        self._raw = raw_snapshot
        self._clock = clock
        self._session: zenoh.Session | None = None
        self._typestore: Typestore | None = None
        self.latest_values = LatestValues(
            lambda: self._session, service.config.ros.domain_id, self._decode, clock=clock
        )
        self.site = LocalSite(service, edge_id=edge_id, status=self.status, latest=self.latest)
        self.poll_interval_s = poll_interval_s
        self.history = history if history is not None else History()
        self.sampler = HistorySampler(self.site, self.history, clock=clock)
        self.audit = MemoryAudit()
        self._queryable = PooledQueryable(self._answer, workers=2, name="edge-console")
        self.answered = 0

    def status(self) -> dict[str, Any]:
        """The edge's spool, WAN and per-topic counters for the health panel and the graph."""
        raw = self._raw() if self._raw is not None else None
        return site_status(self._snapshot(), raw, now_ms=int(self._clock() * 1000))

    def _decode(self, payload: bytes, typename: str) -> Any:
        if self._typestore is None:
            ros = self.service.config.ros
            self._typestore = load_typestore(schema_distro(ros.distro), ros.message_paths)
        return self._typestore.deserialize_cdr(payload, typename)

    def latest(self, robot: str) -> Envelope:
        """The latest value of each topic of ``robot`` that a mapping takes."""
        site = self.service.site
        topics = [t.topic for t in self.service.topics() if any(m.robot == robot for m in t.mappings)]
        values = self.latest_values.read(topics)
        return Envelope(status=200, site=site, edge_id=self.edge_id, body={"robot": robot, "values": values})

    def mount(self, app: FastAPI) -> None:
        """Serve the console under ``/console/`` of ``app`` (its own routes, not in the admin
        API's OpenAPI document)."""
        app.mount(
            PATH,
            create_console_app(
                self.site,
                token=self.token,
                users=self.users,
                ops=Operations(audit=self.audit, history=self.history, clock=self._clock),
                poll_interval_s=self.poll_interval_s,
            ),
        )

    # -- the console keys ------------------------------------------------------------------------
    def start(self, session: zenoh.Session) -> EdgeConsole:
        """Answer the console keys on ``session`` and start sampling the history; returns the console."""
        self._session = session
        self.site.session = session
        self._queryable.start(session, f"fleetlink/{self.service.site}/console/**")
        self.sampler.start()
        return self

    def stop(self) -> None:
        """Stop sampling the history and answering the console keys."""
        self.sampler.stop()
        self._queryable.stop()

    def __enter__(self) -> EdgeConsole:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def _answer(self, query: zenoh.Query) -> None:
        site = self.service.site
        key = str(query.key_expr)
        try:
            attachment = query.attachment.to_bytes() if query.attachment is not None else None
            if not authorized(self.token, attachment):
                part: dict[str, Any] = {
                    "error": "missing or wrong admin token (attachment 'Bearer <token>')",
                    "problems": [],
                }
                reply_key = key if "*" not in key else status_key(site)
                query.reply(reply_key, envelope(401, part, site=site, edge_id=self.edge_id))
                return
            if zenoh.KeyExpr(key).intersects(zenoh.KeyExpr(status_key(site))):
                reply = envelope(200, {"body": self.status()}, site=site, edge_id=self.edge_id)
                query.reply(status_key(site), reply)
            prefix = latest_key(site, "")
            if key.startswith(prefix) and "*" not in key and key_chunk_problem(key[len(prefix) :]) is None:
                found = self.latest(key[len(prefix) :])
                query.reply(key, json.dumps(found.as_dict()).encode())
            self.answered += 1
        except Exception as exc:  # noqa: BLE001 - one bad query must not kill the worker silently
            log.warning("console query on %s failed: %r", query.key_expr, exc)
        finally:
            query.drop()


def console_extension(
    token: SecretStr | None, edge_id: str, *, poll_interval_s: float = 1.0
) -> Callable[
    [AdminService, Callable[[], EdgeSnapshot], Callable[[], Mapping[str, Any]] | None], EdgeConsole
]:
    """The edge's console as an admin extension (``EdgeAdmin(..., extensions=[...])``); its named
    users come from ``$FLEETLINK_CONSOLE_USERS_FILE`` (read now: a bad file fails the start)."""
    users = load_users(None)

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
            users=users,
        )

    return make
