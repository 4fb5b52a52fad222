"""What the console needs from the sites it shows: the ``Sites`` protocol.

Two implementations: ``fleetlink.console.local.LocalSite`` (the edge's own site, in process,
through its ``AdminService``) and ``fleetlink.console.remote.ZenohSites`` (every site of the
fleet, through the Zenoh admin space ``fleetlink/<site>/admin/**``). Both answer with the admin
space's envelopes, so pages and tests do not care where a site runs.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal, Protocol

from fleetlink.console.envelope import Envelope

Process = Literal["edge", "uplink"]


class Sites(Protocol):
    """The sites a console shows, and how it reads and changes them (``LocalSite``, ``ZenohSites``)."""

    @property
    def process(self) -> Process:
        """The process serving the console."""
        ...

    def sites(self) -> list[dict[str, Any]]:
        """One summary per site that answers (``views.site_summary``)."""
        ...

    def read(self, site: str, names: Sequence[str] | None = None) -> dict[str, Envelope]:
        """The site's ``robots``, ``topics``, ``mappings``, ``robot_types``, ``health`` (or only
        the admin collections in ``names``) and ``status`` answers (a part may be missing or an
        error)."""
        ...

    def ask(self, site: str, path: str, *, op: str | None = None, body: Any = None) -> Envelope:
        """One admin request: ``path`` below ``fleetlink/<site>/admin/`` (``mappings``,
        ``mappings/<name>``, ``dry-run``), ``op`` as the admin space takes it."""
        ...

    def delivery(self, site: str | None) -> list[dict[str, Any]] | None:
        """Every uplink's delivery figures for ``site`` (every site: ``None``), as each uplink
        answers them on ``fleetlink/<site>/delivery/<uplink>``; ``None`` when this process has
        no way to ask."""
        ...

    def latest(self, site: str, robot: str) -> Envelope | None:
        """The latest values of the robot's mapped topics (``{"robot", "values": {topic: ...}}``),
        as the site's edge reads them; ``None`` when this process cannot ask."""
        ...

    def commands(self) -> dict[str, Any]:
        """Command routing status: ``{"available": false, "reason"}`` where there is none."""
        ...
