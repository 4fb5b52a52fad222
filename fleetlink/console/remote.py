"""``ZenohSites``: every site of the fleet, through the Zenoh admin space (the uplink's console).

- sites: a query on ``fleetlink/*/admin/health``; each edge answers on its concrete key, so the
  key names the site;
- a site's view: one query on ``fleetlink/<site>/admin/*`` (every collection answers on its own
  key) and one on ``fleetlink/<site>/console/status`` (the edge console's counters), in parallel;
- a change: one query on the concrete key with ``?op=`` and a JSON payload.

Every query carries the console's token as its attachment (``Bearer <token>``), as the admin
space expects. Queries wait at most ``timeout_s``; a site that does not answer in time is shown
as such, never waited on forever.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from typing import Any

import zenoh
from pydantic import SecretStr

from fleetlink.common.names import key_chunk_problem, key_path_problem, site_problem
from fleetlink.console.envelope import Envelope, failure, parse
from fleetlink.console.sources import Process
from fleetlink.console.views import site_summary


def _admin_path_problem(path: str) -> str | None:
    """An admin resource is one or two key chunks (``robots``, ``mappings/imu``)."""
    return key_path_problem(path) or (None if path.count("/") <= 1 else "has more than two chunks")


def status_key(site: str) -> str:
    """Where an edge console answers with its site's counters."""
    return f"fleetlink/{site}/console/status"


def delivery_answers(session: zenoh.Session, site: str | None, timeout_s: float) -> list[dict[str, Any]]:
    """Every uplink's delivery figures for ``site`` (or every site), one answer per uplink and site."""
    if site is not None and site_problem(site) is not None:
        return []
    selector = f"fleetlink/{site or '*'}/delivery/*"
    out = []
    for reply in session.get(selector, target=zenoh.QueryTarget.ALL, timeout=timeout_s):
        if reply.ok is None:
            continue
        try:
            data = json.loads(reply.ok.payload.to_bytes())
        except (UnicodeDecodeError, json.JSONDecodeError):
            continue
        if isinstance(data, dict) and (site is None or data.get("site") == site):
            out.append(data)
    return out


def latest_key(site: str, robot: str) -> str:
    """Where an edge console answers the latest values of a robot's mapped topics."""
    return f"fleetlink/{site}/console/latest/{robot}"


def _site_of(key: str) -> str | None:
    parts = key.split("/")
    return parts[1] if len(parts) > 2 and parts[0] == "fleetlink" else None


class ZenohSites:
    """Every site of the fleet as a ``Sites`` source, queried over the Zenoh admin space with the
    console's token."""

    def __init__(
        self,
        session: zenoh.Session,
        *,
        token: SecretStr | None,
        timeout_s: float = 3.0,
        commands: Callable[[], dict[str, Any]] | None = None,
    ) -> None:
        self.session = session
        self.timeout_s = timeout_s
        self._attachment = None if token is None else f"Bearer {token.get_secret_value()}".encode()
        self._commands = commands

    @property
    def process(self) -> Process:
        """The process serving the console: ``uplink``."""
        return "uplink"

    def _get(self, selector: str, payload: Any = None) -> Any:
        body = None if payload is None else json.dumps(payload).encode()
        return self.session.get(selector, payload=body, attachment=self._attachment, timeout=self.timeout_s)

    @staticmethod
    def _replies(handler: Any) -> list[tuple[str, Envelope]]:
        out = []
        for reply in handler:
            if reply.ok is not None:
                key = str(reply.ok.key_expr)
                out.append((key, parse(reply.ok.payload.to_bytes(), key=key)))
            else:
                text = reply.err.payload.to_bytes().decode("utf-8", "replace")
                out.append(("", failure(502, f"error reply: {text}")))
        return out

    def sites(self) -> list[dict[str, Any]]:
        """A summary of each site whose edge answered the health query, sorted by site."""
        found: dict[str, dict[str, Any]] = {}
        for key, env in self._replies(self._get("fleetlink/*/admin/health")):
            site = _site_of(key) or env.site
            if site and site not in found:
                found[site] = site_summary(site, env)
        return [found[s] for s in sorted(found)]

    def read(self, site: str, names: Sequence[str] | None = None) -> dict[str, Envelope]:
        """The site's admin collections (those in ``names``) and console counters as its edge
        answered them (400 for a bad site name, 504 when no edge answered)."""
        if site_problem(site) is not None:
            return {"health": failure(400, f"not a site name: {site!r}", site=site)}
        prefix = f"fleetlink/{site}/admin/"
        admin = [self._get(prefix + name) for name in (["*"] if names is None else names)]
        status = self._get(status_key(site))
        out: dict[str, Envelope] = {}
        for replies in admin:
            for key, env in self._replies(replies):
                if key.startswith(prefix):
                    out.setdefault(key[len(prefix) :], env)
        for key, env in self._replies(status):
            if key == status_key(site):
                out.setdefault("status", env)
        if not out:
            message = f"no edge of site {site!r} answered within {self.timeout_s:g} s"
            return {"health": failure(504, message, site=site)}
        return out

    def ask(self, site: str, path: str, *, op: str | None = None, body: Any = None) -> Envelope:
        """One admin request on the resource's key (``?op=`` when given): the answer on that key, else the
        first one (400 for a bad resource, 504 when no edge answered)."""
        if site_problem(site) is not None or _admin_path_problem(path) is not None:
            return failure(400, f"not an admin resource: {site!r} {path!r}", site=site)
        key = f"fleetlink/{site}/admin/{path}"
        selector = key if op is None else f"{key}?op={op}"
        replies = self._replies(self._get(selector, body))
        for reply_key, env in replies:
            if reply_key == key:
                return env
        if replies:
            return replies[0][1]
        return failure(504, f"no edge of site {site!r} answered within {self.timeout_s:g} s", site=site)

    def delivery(self, site: str | None) -> list[dict[str, Any]] | None:
        """Every uplink's delivery figures for ``site`` (``None``: every site)."""
        return delivery_answers(self.session, site, self.timeout_s)

    def latest(self, site: str, robot: str) -> Envelope | None:
        """The latest values of ``robot``'s mapped topics, read by its site's edge (400 for a bad name,
        504 when no edge answered)."""
        if site_problem(site) is not None or key_chunk_problem(robot) is not None:
            return failure(400, f"not a site and robot: {site!r} {robot!r}", site=site)
        key = latest_key(site, robot)
        for reply_key, env in self._replies(self._get(key)):
            if reply_key == key:
                return env
        return failure(504, f"no edge of site {site!r} answered within {self.timeout_s:g} s", site=site)

    def commands(self) -> dict[str, Any]:
        """The command router's status (unavailable when this process routes none)."""
        if self._commands is None:
            return {"available": False, "reason": "not available on this process"}
        return self._commands()
