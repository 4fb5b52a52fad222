"""``LocalSite``: the edge's own site, answered in process by its ``AdminService``.

Requests go through the Zenoh admin space's own dispatch (``edge.admin.space.targets`` and
``execute``), so the console gets exactly the answers (statuses, error lists) a remote
console gets over Zenoh, without a network hop.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import zenoh

from fleetlink.console.envelope import Envelope, failure, from_parts
from fleetlink.console.remote import delivery_answers
from fleetlink.console.sources import Process
from fleetlink.console.views import site_summary
from fleetlink.edge.admin.service import AdminService
from fleetlink.edge.admin.space import execute, targets

NOT_HERE = "not available on this process: command status is kept by the uplink (see its console)"
_READS = ("robots", "topics", "mappings", "robot_types", "health")


class LocalSite:
    """The edge's own site as a ``Sites`` source, answered in process through the admin space's dispatch."""

    def __init__(
        self,
        service: AdminService,
        *,
        edge_id: str,
        status: Callable[[], dict[str, Any]],
        latest: Callable[[str], Envelope] | None = None,
    ) -> None:
        self.service = service
        self.edge_id = edge_id
        self._status = status
        self._latest = latest
        self.session: zenoh.Session | None = None
        """The edge's Zenoh session, once started: the uplinks' delivery figures for this site."""
        self.timeout_s = 1.0

    @property
    def process(self) -> Process:
        """The process serving the console: ``edge``."""
        return "edge"

    @property
    def site(self) -> str:
        """The site this edge serves."""
        return self.service.site

    def sites(self) -> list[dict[str, Any]]:
        """This edge's site, summarised from its health."""
        return [site_summary(self.site, self.ask(self.site, "health"))]

    def read(self, site: str, names: Sequence[str] | None = None) -> dict[str, Envelope]:
        """The site's admin collections (those in ``names``), plus this edge's ``status`` counters."""
        out = {name: self.ask(site, name) for name in (_READS if names is None else names)}
        if site == self.site:
            out["status"] = Envelope(status=200, site=site, edge_id=self.edge_id, body=self._status())
        return out

    def ask(self, site: str, path: str, *, op: str | None = None, body: Any = None) -> Envelope:
        """One admin request, executed in process (404 for another site or an unknown resource)."""
        if site != self.site:
            return failure(404, f"this edge serves site {self.site!r}, not {site!r}", site=site)
        key = f"fleetlink/{site}/admin/{path}"
        found = targets(site, key, op, body is not None, lambda _resource: ())
        if len(found) != 1:
            return failure(404, f"no admin resource at {key!r}", site=site)
        status, part = execute(self.service, found[0], body)
        return from_parts(status, part, site=site, edge_id=self.edge_id)

    def latest(self, site: str, robot: str) -> Envelope | None:
        """The latest values of ``robot``'s mapped topics (``None``: this edge cannot read them)."""
        if site != self.site:
            return failure(404, f"this edge serves site {self.site!r}, not {site!r}", site=site)
        return None if self._latest is None else self._latest(robot)

    def delivery(self, site: str | None) -> list[dict[str, Any]] | None:
        """Every uplink's delivery figures for ``site`` (``None``: this edge's site), over Zenoh;
        ``None`` until the console has a session."""
        if self.session is None:
            return None
        return delivery_answers(self.session, self.site if site is None else site, self.timeout_s)

    def commands(self) -> dict[str, Any]:
        """Always unavailable: command status is kept by the uplink."""
        return {"available": False, "reason": NOT_HERE}
