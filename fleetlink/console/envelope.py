"""The answer to one admin request, as the Zenoh admin space writes it (``edge.admin.space``).

``{"status": 200, "site", "edge_id", "body"}`` or ``{"status": 4xx, "site", "edge_id", "error",
"problems": [{"path", "message", "config_path"}]}``. The console speaks this one shape to every
site, local or remote, so a page does not care where its site runs. Pure.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True, slots=True)
class Envelope:
    """One admin answer: its status, the site and edge that gave it, and its body or error and problems."""

    status: int
    site: str = ""
    edge_id: str = ""
    body: Any = None
    error: str | None = None
    problems: tuple[dict[str, Any], ...] = field(default=())

    @property
    def ok(self) -> bool:
        """Whether the status is 2xx."""
        return 200 <= self.status < 300

    def as_dict(self) -> dict[str, Any]:
        """The envelope as the admin space writes it: ``body`` when ok, else ``error`` and ``problems``."""
        if self.ok:
            return {"status": self.status, "site": self.site, "edge_id": self.edge_id, "body": self.body}
        return {
            "status": self.status,
            "site": self.site,
            "edge_id": self.edge_id,
            "error": self.error,
            "problems": list(self.problems),
        }


def from_parts(status: int, part: dict[str, Any], *, site: str, edge_id: str) -> Envelope:
    """``edge.admin.space.execute``'s (status, part) -> an envelope."""
    problems = tuple(p for p in part.get("problems", ()) if isinstance(p, dict))
    return Envelope(
        status=status,
        site=site,
        edge_id=edge_id,
        body=part.get("body"),
        error=part.get("error"),
        problems=problems,
    )


def parse(payload: bytes, *, key: str = "") -> Envelope:
    """A reply payload -> an envelope; an unreadable one becomes a 502 envelope saying why."""
    try:
        data = json.loads(payload)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        return Envelope(status=502, error=f"unreadable reply on {key or 'the admin space'}: {exc}")
    if not isinstance(data, dict) or not isinstance(data.get("status"), int):
        return Envelope(status=502, error=f"unexpected reply on {key or 'the admin space'}: no status")
    site, edge_id = data.get("site"), data.get("edge_id")
    return from_parts(
        int(data["status"]),
        data,
        site=site if isinstance(site, str) else "",
        edge_id=edge_id if isinstance(edge_id, str) else "",
    )


def failure(status: int, message: str, *, site: str = "") -> Envelope:
    """An error envelope made by the console itself (a bad name, no edge answering)."""
    return Envelope(status=status, site=site, error=message)
