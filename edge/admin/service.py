"""The admin operations, shared by the HTTP API and the Zenoh admin space.

``AdminService`` holds the config file's data, the current overlay and the effective config.
A change is computed (``edge.admin.changes``, validated as a whole), saved (overlay file,
atomically), then installed in the running edge (``AdminBackend.install``, one atomic swap of
the mapping table). If installing fails the previous overlay file is put back, so the file
and the running edge never disagree. Changes are serialised by a lock.
"""

from __future__ import annotations

import logging
import threading
from typing import Any, Literal

from fleetlink.common.metrics import Health, NullMetrics
from fleetlink.edge.admin import changes
from fleetlink.edge.admin.backend import AdminBackend, EdgeSnapshot
from fleetlink.edge.admin.errors import FieldProblem, InvalidChangeError, NotFoundError
from fleetlink.edge.admin.listing import dry_run_matches, mapping_views, robot_views, topic_views
from fleetlink.edge.admin.overlay import Overlay, config_data
from fleetlink.edge.admin.specs import declarations
from fleetlink.edge.admin.store import OverlayStore
from fleetlink.edge.admin.telemetry import EdgeTelemetry
from fleetlink.edge.admin.views import (
    ChangeView,
    DamageAckView,
    DamageView,
    DryRunView,
    MappingView,
    RobotTypeView,
    RobotView,
    TopicView,
)
from fleetlink.edge.config import EdgeConfig
from fleetlink.edge.errors import MappingError

log = logging.getLogger(__name__)

DRY_RUN_NAME = "dry-run"


class AdminService:
    """The admin operations over an ``AdminBackend``: reads, dry runs and changes that are validated, saved
    to the overlay file and installed in the running edge. Changes are serialised by a lock."""

    def __init__(
        self,
        base: EdgeConfig,
        backend: AdminBackend,
        *,
        overlay: Overlay | None = None,
        store: OverlayStore | None = None,
        telemetry: EdgeTelemetry | None = None,
    ) -> None:
        self._base = config_data(base)
        self._overlay = overlay if overlay is not None else Overlay()
        self._config = changes.effective(self._base, self._overlay)
        self.backend = backend
        self.store = store
        self.telemetry = telemetry if telemetry is not None else EdgeTelemetry(NullMetrics())
        self._lock = threading.RLock()
        self.changes = 0

    @property
    def site(self) -> str:
        """The site name of the effective config."""
        return self._config.site

    @property
    def config(self) -> EdgeConfig:
        """The effective config: the config file with the admin changes applied."""
        return self._config

    @property
    def overlay(self) -> Overlay:
        """The admin changes applied on top of the config file."""
        return self._overlay

    # -- reads -----------------------------------------------------------------------------------
    def mappings(self) -> list[MappingView]:
        """Every declared mapping with its counters, stage counters, robots and issues."""
        with self._lock:
            config, overlay = self._config, self._overlay
        return mapping_views(config, overlay, self.backend.mapping_table(), self._snapshot())

    def mapping(self, name: str) -> MappingView:
        """The mapping ``name`` with its counters; raises ``NotFoundError`` when there is none."""
        found = [view for view in self.mappings() if view.name == name]
        if not found:
            raise NotFoundError(f"no mapping named {name!r}")
        return found[0]

    def robot_types(self) -> list[RobotTypeView]:
        """Every robot type with its match, mappings, registered robots and origin."""
        with self._lock:
            config, overlay = self._config, self._overlay
        robots = self.backend.mapping_table().robots()
        return [
            RobotTypeView(
                name=name,
                match=rt.match,
                mappings=[m.name for m in rt.mappings],
                robots=sorted(r for r, t in robots.items() if t == name),
                origin="admin" if name in overlay.robot_types else "config",
            )
            for name, rt in config.robot_types.items()
        ]

    def robots(self) -> list[RobotView]:
        """The robots the edge knows, sorted by name."""
        return robot_views(self.backend.robots())

    def topics(self) -> list[TopicView]:
        """The discovered ROS topics with their publishers and the mappings that match them."""
        return topic_views(self.backend.topics(), self.backend.mapping_table())

    def dry_run(self, body: Any) -> DryRunView:
        """Which discovered topics the mapping in ``body`` would match now (nothing is changed)."""
        if isinstance(body, dict) and "name" not in body:
            body = {**body, "name": DRY_RUN_NAME}
        with self._lock:
            config, name = changes.candidate_mapping(self._base, self._overlay, body)
        return dry_run_matches(config, name, self.backend.topics(), self.backend.mapping_table())

    def spool_damage(self) -> list[DamageView]:
        """Every damage finding of the durable spool, acknowledged or not."""
        return [DamageView.model_validate(dict(f)) for f in self.backend.spool_damage()]

    def acknowledge_spool_damage(self) -> DamageAckView:
        """An operator looked at the spool's damage: the edge stops reporting it as degraded."""
        done = [DamageView.model_validate(dict(f)) for f in self.backend.acknowledge_spool_damage()]
        log.info("admin: %d spool damage finding(s) acknowledged", len(done))
        return DamageAckView(acknowledged=done)

    def health(self) -> Health:
        """The edge's health now (also reports the counters' increase to the metrics)."""
        return self.telemetry.observe(self._snapshot(), robots=len(self.backend.mapping_table().robots()))

    # -- changes ---------------------------------------------------------------------------------
    def add_mapping(self, body: Any) -> ChangeView:
        """Add the mapping in ``body``, save the overlay and install it in the running edge."""
        with self._lock:
            proposal = changes.add_mapping(self._base, self._overlay, body)
            name = str(body["name"])
            return self._commit(proposal, "mapping", name, "created")

    def change_mapping(self, name: str, body: Any) -> ChangeView:
        """Replace the mapping ``name`` with ``body``, save the overlay and install it."""
        with self._lock:
            proposal = changes.change_mapping(self._base, self._overlay, name, body)
            return self._commit(proposal, "mapping", name, "changed")

    def remove_mapping(self, name: str) -> ChangeView:
        """Remove the mapping ``name``, save the overlay and install the result."""
        with self._lock:
            proposal = changes.remove_mapping(self._base, self._overlay, name)
            return self._commit(proposal, "mapping", name, "removed")

    def put_robot_type(self, name: str, body: Any) -> ChangeView:
        """Create or change the robot type ``name`` from ``body``, save the overlay and install it."""
        with self._lock:
            proposal = changes.put_robot_type(self._base, self._overlay, name, body)
            return self._commit(proposal, "robot_type", name, "created" if proposal.created else "changed")

    def remove_robot_type(self, name: str) -> ChangeView:
        """Remove the robot type ``name`` with its mappings, save the overlay and install the result."""
        with self._lock:
            proposal = changes.remove_robot_type(self._base, self._overlay, name)
            return self._commit(proposal, "robot_type", name, "removed")

    def _commit(
        self,
        proposal: changes.Proposal,
        kind: Literal["mapping", "robot_type"],
        name: str,
        status: Literal["created", "changed", "removed"],
    ) -> ChangeView:
        previous = self._overlay
        if self.store is not None:
            self.store.save(proposal.overlay)
        try:
            robot_types, mappings = declarations(proposal.config, self.backend.mapping_table())
            self.backend.install(proposal.config, robot_types, mappings)
        except MappingError as exc:
            self._restore(previous)
            problem = FieldProblem(path="<root>", message=str(exc))
            raise InvalidChangeError("the mapping table refused the change", (problem,)) from exc
        except BaseException:
            self._restore(previous)
            raise
        self._overlay, self._config = proposal.overlay, proposal.config
        self.changes += 1
        log.info("admin: %s %s %s", kind, name, status)
        return ChangeView(
            status=status,
            kind=kind,
            name=name,
            overlay=str(self.store.path) if self.store is not None else None,
        )

    def _restore(self, previous: Overlay) -> None:
        if self.store is not None:
            self.store.save(previous)

    def _snapshot(self) -> EdgeSnapshot:
        return self.backend.snapshot()
