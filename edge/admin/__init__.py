"""The edge's admin API: list and change robots' mappings at runtime, over HTTP and over Zenoh.

- pure core: ``overlay`` (what was changed, applied on top of the config file), ``changes``
  (validate a whole change, nothing half-applied), ``problems`` (YAML-path errors), ``specs``,
  ``listing`` (views), ``health``, ``space`` (Zenoh keys -> operations);
- ``service.AdminService``: the operations, on an ``AdminBackend`` (the running edge);
- adapters: ``http`` (FastAPI, OpenAPI), ``zenoh_admin`` (queryable on
  ``fleetlink/<site>/admin/**``), ``store`` (the overlay file), ``server.EdgeAdmin`` (all of it).

See docs/admin.md.
"""

from fleetlink.edge.admin.auth import load_token
from fleetlink.edge.admin.backend import AdminBackend, EdgeSnapshot, MappingCounts, RobotStatus
from fleetlink.edge.admin.errors import AdminError, FieldProblem, InvalidChangeError, OverlayError
from fleetlink.edge.admin.overlay import Overlay
from fleetlink.edge.admin.server import EdgeAdmin
from fleetlink.edge.admin.service import AdminService
from fleetlink.edge.admin.store import OverlayStore, default_overlay_path

__all__ = [
    "AdminBackend",
    "AdminError",
    "AdminService",
    "EdgeAdmin",
    "EdgeSnapshot",
    "FieldProblem",
    "InvalidChangeError",
    "MappingCounts",
    "Overlay",
    "OverlayError",
    "OverlayStore",
    "RobotStatus",
    "default_overlay_path",
    "load_token",
]
